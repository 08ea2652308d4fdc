"""Bivariate Laguerre reduced-order model (seed 000 section III): numba RHS and helpers.

State of one cell (float64, non-dimensional; contract with ``integrate.py``):
``state[i*m + j] = M_ij / (N_ref p_ref^(i+j))`` for i, j < m (M_ij the SI mixed moment of the
granule population per m3, N_ref = params[NUMBER_SCALE] [1/m3], p_ref = params[MASS_SCALE] [kg],
binder mass on the same scale), and, if config[SEPARATE_DROPLETS] == 1,
``state[m*m] = n_d / N_ref`` (free binder droplets of mass p_d = params[DROPLET_MASS]).

dM~_a/dt = k0 N_ref F_cell sum_{k<=l} Q[k,l,a](u0) M~_k M~_l              (aggregation)
         + k0 N_ref F_cell n~_d sum_k Cd[k,a](u0) M~_k                   (droplet capture)
         + injection,
dn~_d/dt = -k0 N_ref F_cell n~_d sum_k Cd0[k](u0) M~_k + INJECTION / N_ref,

F_cell = g0(alpha) sqrt(Theta) d43^(3/2) for the ktgf kernel (1 otherwise); d43 [m] from the
reconstruction: d43 = (6 / (pi rho_s))^(1/3) int p^(4/3) n / int p n, free droplets included
(they are particles of the cell, as in the cNMC), falling back to the log-convex moment estimate
M_(4/3) = M_1^(2/3) M_2^(1/3) (or M_1 (M_1/M_0)^(1/3) for m = 2) if the reconstruction gives a
non-positive value. Q, Cd, Cd0 are tabulated in ln(u0) when the physical efficiency is on and
the tensor was built on a Theta grid (grid u0 = 4 sqrt(Theta / pi)); at RHS time u0 =
cell[COLLISION_VELOCITY] [m/s], or 4 sqrt(cell[THETA] / pi) if that is not positive; linear
interpolation in ln u0, clamped at the grid ends. Otherwise one slice (fixed u0).
Formulas and the aux layout: ``laguerre_tensor``.
"""
import math

import numba as nb
import numpy as np
from scipy.special import gammaincc

from ..physics import parameters as P
from ..physics.kernels import kernel_cell_factor
from . import laguerre_tensor as LT
from .laguerre_tensor import (AUX_B_MAX, AUX_CHECK_LEVEL, AUX_CONSISTENT, AUX_DROPLET_MASS, AUX_N_B, AUX_N_P,
                              AUX_NMOM, AUX_NPAIR, AUX_NSLICE, AUX_OFF_CD, AUX_OFF_CD0,
                              AUX_OFF_F43, AUX_OFF_LOGU, AUX_OFF_Q, AUX_ORDER, AUX_P_MAX,
                              AUX_SEPARATE, build_aux, log_theta_grid, theta_to_u0)

__all__ = ["laguerre_rhs", "laguerre_realizable", "laguerre_project", "laguerre_conserved",
           "build_aux",
           "moments_from_state", "escaped_mass_share", "reconstruct", "reconstructed_moment",
           "initial_state", "state_size", "strictly_realizable", "log_theta_grid", "theta_to_u0"]

KTGF = 4   # kernel code of ktgf in physics.kernels.KERNELS


def state_size(order, separate_droplets):
    """Length of one cell's state: m*m moments (+1 for free droplets)."""
    return order * order + (1 if separate_droplets else 0)


# ---- numba core ---------------------------------------------------------------------------
@nb.njit(cache=True)
def _slice_position(cell, aux):
    """(index of the lower u0 slice, interpolation weight of the upper one)."""
    ns = int(aux[AUX_NSLICE])
    if ns <= 1:
        return 0, 0.0
    u0 = cell[P.COLLISION_VELOCITY]
    if not (u0 > 0.0):
        theta = cell[P.THETA]
        if not (theta > 0.0):
            return 0, 0.0
        u0 = 4.0 * math.sqrt(theta / math.pi)
    lu = math.log(u0)
    o = int(aux[AUX_OFF_LOGU])
    if lu <= aux[o]:
        return 0, 0.0
    if lu >= aux[o + ns - 1]:
        return ns - 2, 1.0
    lo = 0
    hi = ns - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if aux[o + mid] <= lu:
            lo = mid
        else:
            hi = mid
    return lo, (lu - aux[o + lo]) / (aux[o + lo + 1] - aux[o + lo])


@nb.njit(cache=True)
def laguerre_d43(state, aux, params, config):
    """Volume-mean diameter d43 [m] of the cell's population (granules + free droplets)."""
    m = int(aux[AUX_ORDER])
    K = m * m
    pref = params[P.MASS_SCALE]
    o = int(aux[AUX_OFF_F43])
    m43 = 0.0
    for k in range(K):
        m43 += aux[o + k] * state[k]
    m0 = state[0]
    m1 = state[m] if m > 1 else 0.0
    m2 = state[2 * m] if m > 2 else 0.0
    if config[P.SEPARATE_DROPLETS] == 1 and config[P.N_STATE] > K:
        nd = state[K]
        x = params[P.DROPLET_MASS] / pref
        m43 += nd * x ** (4.0 / 3.0)
        m0 += nd
        m1 += nd * x
        m2 += nd * x * x
    if not (m1 > 0.0):
        return 0.0
    if not (m43 > 0.0):
        if m > 2 and m2 > 0.0:
            m43 = m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
        elif m0 > 0.0:
            m43 = m1 * (m1 / m0) ** (1.0 / 3.0)
        else:
            return 0.0
    return (6.0 * pref / (math.pi * params[P.DENSITY])) ** (1.0 / 3.0) * m43 / m1


@nb.njit(cache=True)
def laguerre_rhs(state, out, cell, aux, params, config, work=None):
    """d(state)/dt [scaled state units per s] of one cell; writes ``out`` (length N_STATE).

    state: scaled moments (module doc); cell: (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY
    [m/s], INJECTION [droplets/(m3 s)]); aux: from build_aux; params, config: physics arrays;
    work: the integrator's scratch array (optional, unused: the RHS allocates nothing).
    """
    m = int(aux[AUX_ORDER])
    K = m * m
    n = config[P.N_STATE]
    for a in range(n):
        out[a] = 0.0
    nref = params[P.NUMBER_SCALE]
    if config[P.KERNEL] == KTGF:
        d43 = laguerre_d43(state, aux, params, config)
        mult = nref * kernel_cell_factor(KTGF, cell[P.ALPHA], cell[P.THETA], d43, params)
    else:
        mult = params[P.RATE] * nref
    i0, t = _slice_position(cell, aux)
    npair = int(aux[AUX_NPAIR])
    stride_q = npair * K
    b0 = int(aux[AUX_OFF_Q]) + i0 * stride_q
    interp = t > 0.0
    s0 = 1.0 - t
    if mult != 0.0:
        pos = b0
        for k in range(K):
            mk = mult * state[k]
            for l in range(k, K):
                prod = mk * state[l]
                if interp:
                    for a in range(K):
                        out[a] += prod * (s0 * aux[pos + a] + t * aux[pos + stride_q + a])
                else:
                    for a in range(K):
                        out[a] += prod * aux[pos + a]
                pos += K
    inj = cell[P.INJECTION]
    if config[P.SEPARATE_DROPLETS] == 1:
        nd = state[K]
        if nd != 0.0 and mult != 0.0 and aux[AUX_SEPARATE] == 1.0:
            stride_c = K * K
            c0 = int(aux[AUX_OFF_CD]) + i0 * stride_c
            stride_d = K
            d0 = int(aux[AUX_OFF_CD0]) + i0 * stride_d
            loss = 0.0
            for k in range(K):
                w = mult * nd * state[k]
                pos = c0 + k * K
                if interp:
                    for a in range(K):
                        out[a] += w * (s0 * aux[pos + a] + t * aux[pos + stride_c + a])
                    loss += w * (s0 * aux[d0 + k] + t * aux[d0 + stride_d + k])
                else:
                    for a in range(K):
                        out[a] += w * aux[pos + a]
                    loss += w * aux[d0 + k]
            out[K] = -loss
        out[K] += inj / nref
    elif inj != 0.0:
        x = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
        src = inj / nref
        for i in range(m):
            for j in range(m):
                out[i * m + j] += src * x ** (i + j)


@nb.njit(cache=True)
def _moment_checks(state, config, level):
    """Admissibility of a scaled moment set at a check level (see laguerre_realizable)."""
    m = config[P.ORDER]
    n = config[P.N_STATE]
    big = 0.0
    for i in range(n):
        v = state[i]
        if not math.isfinite(v):
            return False
        if abs(v) > big:
            big = abs(v)
    tol = 1e-12 * big
    rel = 1e-10
    if state[0] < 0.0:
        return False
    for k in range(m * m, n):                   # free droplets
        if state[k] < -tol:
            return False
    top = 2 * (m - 1) if level >= 2 else 2      # highest total order i + j checked
    for i in range(m):
        for j in range(m):
            if i + j <= top and state[i * m + j] < -tol:
                return False
    if m > 1 and state[1] > state[m] * (1.0 + rel) + tol:     # M01 <= M10
        return False
    if level < 1:
        return True
    # b <= p: M_(i,j+1) <= M_(i+1,j)
    for i in range(m - 1):
        for j in range(m - 1):
            if i + j + 1 > top:
                continue
            if state[i * m + j + 1] > state[(i + 1) * m + j] * (1.0 + rel) + tol:
                return False
    # Cauchy-Schwarz M_(e+f)^2 <= M_(2e) M_(2f)
    h = (m - 1) // 2
    for e1 in range(h + 1):
        for e2 in range(h + 1):
            for f1 in range(h + 1):
                for f2 in range(h + 1):
                    if f1 * (h + 1) + f2 <= e1 * (h + 1) + e2:
                        continue
                    s1 = e1 + f1
                    s2 = e2 + f2
                    if s1 >= m or s2 >= m:
                        continue
                    if max(2 * (e1 + e2), 2 * (f1 + f2)) > top:
                        continue
                    mid = state[s1 * m + s2]
                    if mid * mid > (state[2 * e1 * m + 2 * e2] * state[2 * f1 * m + 2 * f2]
                                    * (1.0 + rel) + tol * tol):
                        return False
    return True


@nb.njit(cache=True)
def laguerre_realizable(state, aux, params, config, work=None):
    """True if the scaled state is admissible for the ROM (used to accept RK stages).

    Level aux[AUX_CHECK_LEVEL] (build_aux(check_level=...)), tol = 1e-12 max|state|,
    relative slack 1e-10 (an exact monodisperse start with equalities passes):
    0 (default): every entry finite; M00 >= 0; M10, M01, M11, M20, M02 >= -tol (the moments
      of total order <= 2); M01 <= M10 (b <= p); free droplets n_d >= -tol.
    1: also M02 <= M11 <= M20 and Cauchy-Schwarz M10^2 <= M00 M20, M01^2 <= M00 M02,
      M11^2 <= M20 M02.
    2: all of these for every carried order (M_(i,j+1) <= M_(i+1,j), M_(e+f)^2 <= M_2e M_2f,
      every M_ij >= -tol).
    The reconstruction is a signed expansion and is not checked. Why level 0 is the default:
    from the seed scenario's dry delta start (on the Cauchy-Schwarz boundary, variance 0) the
    m = 4 consistent ROM's vector field points outward (its p-variance shrinks at t = 0), so
    level 1 stalls the integrator at t ~ 3e-7 s; M21, M22 go transiently negative for m = 3.
    """
    return _moment_checks(state, config, int(aux[AUX_CHECK_LEVEL]))


def strictly_realizable(state, config, level=2):
    """True if the moment conditions of ``level`` (default: all orders) hold."""
    return bool(_moment_checks(np.asarray(state, float), np.asarray(config, np.int64), level))


@nb.njit(cache=True)
def laguerre_conserved(config, params, pivots, coefs):
    """Linear invariants of the ROM state for the time integrator: rows c of ``coefs``
    (n_inv, N_STATE) with c . d(state)/dt independent of the state (the injection only):
    granule mass M10 and binder mass M01, each plus the free droplets' mass x_d n_d
    (x_d = p_d / p_ref). ``pivots[r]`` is the entry with coefficient 1. Returns the count."""
    m = config[P.ORDER]
    n = config[P.N_STATE]
    K = m * m
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    for r in range(2):
        for k in range(n):
            coefs[r, k] = 0.0
        pivots[r] = m if r == 0 else 1          # M10 at (1, 0), M01 at (0, 1)
        coefs[r, pivots[r]] = 1.0
        if config[P.SEPARATE_DROPLETS] == 1 and n > K:
            coefs[r, K] = xd
    return 2


@nb.njit(cache=True)
def laguerre_project(state, aux, params, config, work=None):
    """In-place fix after an accepted step: clips a negative free-droplet density to 0.

    The moments themselves are left untouched (the ROM has no cheaper admissible neighbour).
    """
    m = config[P.ORDER]
    K = m * m
    if config[P.SEPARATE_DROPLETS] == 1 and config[P.N_STATE] > K:
        if state[K] < 0.0:
            state[K] = 0.0


# ---- Python helpers ---------------------------------------------------------------------
def initial_state(moments, params, config, n_droplets=0.0):
    """Scaled state from SI granule moments.

    moments: dict "M{i}{j}" -> value [kg^(i+j)/m3] or callable (i, j) -> value; missing keys
    are 0. n_droplets: free droplets [1/m3] (used iff config[SEPARATE_DROPLETS] == 1).
    For a monodisperse start (N0 particles of mass p0 and binder b0) pass
    ``lambda i, j: N0 * p0**i * b0**j``: the ROM needs only the moments of the delta.
    """
    m = int(config[P.ORDER])
    sep = int(config[P.SEPARATE_DROPLETS]) == 1
    nref = params[P.NUMBER_SCALE]
    pref = params[P.MASS_SCALE]
    out = np.zeros(state_size(m, sep))
    for i in range(m):
        for j in range(m):
            val = moments(i, j) if callable(moments) else moments.get(f"M{i}{j}", 0.0)
            out[i * m + j] = val / (nref * pref ** (i + j))
    if sep:
        out[m * m] = n_droplets / nref
    return out


def moments_from_state(state_rows, params, config, m, aux=None):
    """SI moments of one state or of rows of states (shape (n, N_STATE)).

    Returns dict of arrays (shape (n,), or floats for a 1-D state):
    "M{i}{j}" [kg^(i+j)/m3], i, j < m: the whole population, free droplets included (DESIGN
    section 4 output contract); "granule_M{i}{j}": granules only; if droplets are separate,
    "droplet_number_density" [1/m3]. For m = 2, "M20" and "M02" are not carried: with ``aux``
    they are added from the reconstruction on the support (an estimate), otherwise absent.
    """
    rows = np.asarray(state_rows, dtype=float)
    one = rows.ndim == 1
    rows = np.atleast_2d(rows)
    nref = params[P.NUMBER_SCALE]
    pref = params[P.MASS_SCALE]
    sep = int(config[P.SEPARATE_DROPLETS]) == 1 and rows.shape[1] > m * m
    nd = rows[:, m * m] * nref if sep else np.zeros(rows.shape[0])
    pd = params[P.DROPLET_MASS]
    out = {}
    for i in range(m):
        for j in range(m):
            g = rows[:, i * m + j] * nref * pref ** (i + j)
            out[f"granule_M{i}{j}"] = g
            out[f"M{i}{j}"] = g + nd * pd ** (i + j)
    if sep:
        out["droplet_number_density"] = nd
    if m == 2 and aux is not None:
        for (i, j) in ((2, 0), (0, 2)):
            g = np.array([reconstructed_moment(r, aux, params, config, i, j) for r in rows])
            out[f"granule_M{i}{j}"] = g
            out[f"M{i}{j}"] = g + nd * pd ** (i + j)
    if one:
        out = {k: float(v[0]) for k, v in out.items()}
    return out


def _coefficients(state, aux, params):
    """Raw-basis coefficients (internal units) of the reconstruction of one state."""
    B = LT.unpack_basis(aux)
    K = B["m"] ** 2
    mint = np.asarray(state[:K], float) * B["r"]
    return B, B["Ginv"] @ mint


def reconstruct(state, aux, params, config, p, b, clip_support=True):
    """Reconstructed granule density n(p, b) [1/(m3 kg2)] at masses p, b [kg] (arrays).

    clip_support: zero outside the support b <= p, p <= p_max, b <= b_max (where the ROM
    lives); False evaluates the expansion everywhere (the plain projection is defined on the
    whole quadrant).
    """
    B, coef = _coefficients(state, aux, params)
    p = np.asarray(p, float)
    b = np.asarray(b, float)
    shape = np.broadcast(p, b).shape
    pp = np.broadcast_to(p, shape).ravel()
    bb = np.broadcast_to(b, shape).ravel()
    phi = LT.basis_values(pp / B["c"], bb / B["d"], B["Cp"], B["Cb"], B["lam"], B["gam"])
    n = phi @ coef * params[P.NUMBER_SCALE] / (B["c"] * B["d"])
    if clip_support:
        inside = (bb <= pp) & (pp <= aux[AUX_P_MAX]) & (bb <= aux[AUX_B_MAX])
        n = np.where(inside, n, 0.0)
    return n.reshape(shape)


def reconstructed_moment(state, aux, params, config, i, j):
    """int_S p^i b^j n [kg^(i+j)/m3] of the reconstruction over the support, with the same
    quadrature as the tensor (so it returns the carried moments exactly when consistent)."""
    B, coef = _coefficients(state, aux, params)
    u, v, W = LT.quadrature(B["c"], B["d"], B["lam"], B["gam"], aux[AUX_P_MAX], aux[AUX_B_MAX],
                            int(aux[AUX_N_P]), int(aux[AUX_N_B]), int(aux[LT.AUX_SPACING]))
    phi = LT.basis_values(u, v, B["Cp"], B["Cb"], B["lam"], B["gam"])
    val = ((u * B["c"]) ** i * (v * B["d"]) ** j * W) @ (phi @ coef)
    return float(val * params[P.NUMBER_SCALE])


def escaped_mass_share(state, aux, params, config):
    """Estimated share [-] of the granule mass carried beyond p_max or b_max.

    m >= 3: gamma fits to the marginals -- in p from (M00, M10, M20), mass share beyond p_max
    = Q(k+1, p_max/theta); in b from the mass-weighted moments (M10, M11, M12), share beyond
    b_max = Q(k, b_max/theta) (Q the regularised upper incomplete gamma function). m = 2:
    exponential in p (mean M10/M00) and the Markov bound M11 / (b_max M10) in b. A (near-)delta
    marginal counts fully beyond the limit if its mean is. Returns the sum, capped at 1.
    """
    m = int(config[P.ORDER])
    s = np.asarray(state, float)
    pref = params[P.MASS_SCALE]
    pmax = aux[AUX_P_MAX] / pref
    bmax = aux[AUX_B_MAX] / pref
    M = lambda i, j: s[i * m + j]  # noqa: E731
    if not (M(0, 0) > 0 and M(1, 0) > 0):
        return 0.0

    def gamma_tail(mean, var, limit, extra):
        if not np.isfinite(mean) or mean <= 0:
            return 0.0
        if not (var > 1e-12 * mean * mean):
            return 1.0 if mean > limit else 0.0
        k = mean * mean / var
        theta = var / mean
        return float(gammaincc(k + extra, limit / theta))

    if m >= 3:
        mu = M(1, 0) / M(0, 0)
        sp = gamma_tail(mu, M(2, 0) / M(0, 0) - mu * mu, pmax, 1.0)
        mb = M(1, 1) / M(1, 0)
        sb = gamma_tail(mb, M(1, 2) / M(1, 0) - mb * mb, bmax, 0.0)
    else:
        x = pmax / (M(1, 0) / M(0, 0))
        sp = float((1.0 + x) * np.exp(-x))
        sb = float(max(M(1, 1), 0.0) / (bmax * M(1, 0)))
    return float(min(1.0, max(0.0, sp) + max(0.0, sb)))


def support_share(state, aux, params, config):
    """(number, mass) carried by the reconstruction on the support relative to M00, M10 [-]:
    1 for the consistent variant by construction; the plain projection's deficit otherwise."""
    m = int(aux[AUX_ORDER])
    K = m * m
    o = int(aux[LT.AUX_OFF_SUPPORT])
    s = np.asarray(state[:K], float)
    return float(aux[o:o + K] @ s / s[0]), float(aux[o + K:o + 2 * K] @ s / s[m])
