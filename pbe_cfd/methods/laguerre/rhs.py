"""Bivariate Laguerre reduced-order model (seed 000 section III): numba RHS and helpers.

State of one cell (float64, non-dimensional; contract with ``integrate.py``), m the order,
K = m*m, N_ref = params[NUMBER_SCALE] [1/m3], p_ref = params[MASS_SCALE] [kg]:
``state[i*m + j] = W_ij / (N_ref p_ref^(i+j))`` for i, j < m, the mixed moments of the wet
granules (binder b > 0; binder mass on the same scale as p);
``state[K + k] = D_k / (N_ref p_ref^k)`` for k < m, the moments in p of the dry granules (b = 0
exactly: wet granulation starts dry, see ``laguerre_dry``); and, if
config[SEPARATE_DROPLETS] == 1, ``state[K + m] = n_d / N_ref`` (free binder droplets of mass
p_d = params[DROPLET_MASS]). The population's moments are M_ij = W_ij + D_i delta_j0 (+ free
droplets n_d p_d^(i+j) in the output columns).

dW~_a/dt = mult [sum_{k<=l} Q[k,l,a] W~_k W~_l + sum_{k,l} X[k,l,a] D~_k W~_l
                 + n~_d sum_k Cd[k,a] W~_k + sum_e CAPMAP[e,a] L~_e]          (+ injection),
dD~_e/dt = mult [sum_{k<=l} Qdd[k,l,e] D~_k D~_l + sum_{k,l} XL[k,l,e] D~_k W~_l] - L~_e,
dn~_d/dt = -mult n~_d sum_k Cd0[k] W~_k - L~_0 + INJECTION / N_ref,
L~_e = mult n~_d sum_k Cdd[k,e] D~_k   (droplets captured by dry granules),

mult = k0 N_ref F_cell, F_cell = g0(alpha) sqrt(Theta) d43^(3/2) for the ktgf kernel (1
otherwise); d43 [m] from the reconstruction: d43 = (6 / (pi rho_s))^(1/3) int p^(4/3) n /
int p n of the granules of both classes, free droplets excluded as in every method
(docs/physics.md, "d43"), falling back to the log-convex moment estimate
M_(4/3) = M_1^(2/3) M_2^(1/3) (or M_1 (M_1/M_0)^(1/3) for m = 2) if the reconstruction gives a non-positive value. All tensors
are tabulated in ln(u0) when the physical efficiency is on and the tensor was built on a Theta
grid (grid u0 = 4 sqrt(Theta / pi)); at RHS time u0 = cell[COLLISION_VELOCITY] [m/s], or
4 sqrt(cell[THETA] / pi) if that is not positive; linear interpolation in ln u0, clamped at the
grid ends. Otherwise one slice (fixed u0). With adaptive weights the wet tensors (Q, Cd, Cd0,
X, XL, F43) are also tabulated on a log grid of the wet weight means (c, d), and the terms are
blended bilinearly in (ln c, ln d) at c = p_ref W~10/W~00, d = p_ref W~01/W~00 (the wet
class's mean mass and binder [kg]; clamped at the grid ends). Every blend weight multiplies a
complete closure, so exactness for the constant kernel and the exact mass bookkeeping hold for
the blend. Formulas: ``laguerre_wet``, ``laguerre_dry``; the aux layout: ``laguerre_layout``.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import KTGF, kernel_cell_factor
from .layout import (AUX_CHECK_LEVEL, AUX_FOLLOWING, AUX_MASS_SCALE, AUX_NPAIR, AUX_NSLICE,
                     AUX_NWC, AUX_NWD, AUX_NWL, AUX_OFF_CAPMAP, AUX_OFF_CD, AUX_OFF_CD0, AUX_OFF_CDD,
                     AUX_OFF_F43, AUX_OFF_F43D, AUX_OFF_LOGU, AUX_OFF_LOGW, AUX_OFF_Q,
                     AUX_OFF_QDD, AUX_OFF_SUPPORT, AUX_OFF_X, AUX_OFF_XL, AUX_ORDER, AUX_P_MAX,
                     AUX_SEPARATE, _corner, state_names, state_size, weight_corner,
                     weight_corners, wet_support)
from .drying import add_linear_terms
from .tensor import (basis_values, build_aux, dry_particles, dry_support_functionals,
                     escaped_mass_share, fraction_basis_values, initial_state, projection_matrix,
                     theta_to_u0, univariate_values, unpack_basis, wet_particles)

__all__ = ["laguerre_rhs", "laguerre_realizable", "laguerre_project", "laguerre_conserved",
           "build_aux",
           "moments_from_state", "escaped_mass_share", "reconstruct", "reconstructed_moment",
           "initial_state", "state_size", "state_names", "strictly_realizable", "theta_to_u0"]

#: the dry class is merged into the wet one once it holds less than this share of the granules
DRY_MERGE_SHARE = 1e-12


# ---- numba core ---------------------------------------------------------------------------
@nb.njit(cache=True)
def _log_position(lx, aux, o, n):
    """(lower index, weight of the upper point) of lx on the sorted grid aux[o:o+n], clamped
    at the ends."""
    if n <= 1:
        return 0, 0.0
    if lx <= aux[o]:
        return 0, 0.0
    if lx >= aux[o + n - 1]:
        return n - 2, 1.0
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if aux[o + mid] <= lx:
            lo = mid
        else:
            hi = mid
    return lo, (lx - aux[o + lo]) / (aux[o + lo + 1] - aux[o + lo])


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
    return _log_position(math.log(u0), aux, int(aux[AUX_OFF_LOGU]), ns)


@nb.njit(cache=True)
def _weight_position(state, aux, m):
    """Adaptive weights: (ic, tc, jd, td, il, tl), the (lower index, upper weight) of the wet
    class's mean mass W10/W00 and mean binder W01/W00 [kg] on the weight grid (following
    support: the mass-weighted mean mass W20 / W10 [kg], the binder fraction W01 / W10 [-]
    and the carried gamma shape W10^2 / (W00 W20 - W10^2) [-], all in logs; the shape index
    is (0, 0.0) without a shape axis)."""
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    if nwc * nwd <= 1 or not (state[0] > 0.0) or not (state[m] > 0.0):
        return 0, 0.0, 0, 0.0, 0, 0.0
    o = int(aux[AUX_OFF_LOGW])
    pref = aux[AUX_MASS_SCALE]
    il, tl = 0, 0.0
    if aux[AUX_FOLLOWING] == 1.0:          # mass-weighted mean mass W20 / W10
        if not (state[2 * m] > 0.0):
            return 0, 0.0, 0, 0.0, 0, 0.0
        ic, tc = _log_position(math.log(state[2 * m] / state[m] * pref), aux, o, nwc)
        nwl = int(aux[AUX_NWL])
        if nwl > 1:
            var = state[0] * state[2 * m] - state[m] * state[m]
            if var > 0.0:
                il, tl = _log_position(math.log(state[m] * state[m] / var), aux,
                                       o + nwc + nwd, nwl)
            else:                          # a delta: the narrowest shape
                il, tl = nwl - 2, 1.0
    else:
        ic, tc = _log_position(math.log(state[m] / state[0] * pref), aux, o, nwc)
    if not (state[1] > 0.0):
        return ic, tc, 0, 0.0, il, tl
    if aux[AUX_FOLLOWING] == 1.0:          # ratio d / c = W01 / W10
        jd, td = _log_position(math.log(state[1] / state[m]), aux, o + nwc, nwd)
    else:
        jd, td = _log_position(math.log(state[1] / state[0] * pref), aux, o + nwc, nwd)
    return ic, tc, jd, td, il, tl


@nb.njit(cache=True)
def _any_nonzero(state, start, stop):
    for k in range(start, stop):
        if state[k] != 0.0:
            return True
    return False


@nb.njit(cache=True)
def laguerre_d43(state, aux, params, config):
    """Volume-mean diameter d43 [m] of the cell's granules, the ktgf kernel's d43 (free
    droplets excluded, docs/physics.md "d43")."""
    m = int(aux[AUX_ORDER])
    K = m * m
    pref = params[P.MASS_SCALE]
    wpos = _weight_position(state, aux, m)
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    m43 = 0.0
    for q in range(8):
        w, f = weight_corner(q, wpos, nwc, nwd)
        if f == 0.0:
            continue
        o = int(aux[AUX_OFF_F43]) + w * K
        acc = 0.0
        for k in range(K):
            acc += aux[o + k] * state[k]
        m43 += f * acc
    od = int(aux[AUX_OFF_F43D])
    for k in range(m):
        m43 += aux[od + k] * state[K + k]
    m0 = state[0] + state[K]
    m1 = state[m] + state[K + 1] if m > 1 else 0.0
    m2 = state[2 * m] + state[K + 2] if m > 2 else 0.0
    if not (m1 > 0.0):
        return 0.0
    if aux[AUX_FOLLOWING] == 1.0 and m > 2 and m0 > 0.0 and m2 > 0.0:
        # the signed reconstruction of a broad population can put M_(4/3) anywhere: keep it
        # within the bounds of any positive measure with these M0, M1, M2 (ln M_s convex in s)
        lo = m1 * (m1 / m0) ** (1.0 / 3.0)
        hi = m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
        m43 = min(max(m43, lo), hi)
    if not (m43 > 0.0):
        if m > 2 and m2 > 0.0:
            m43 = m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
        elif m0 > 0.0:
            m43 = m1 * (m1 / m0) ** (1.0 / 3.0)
        else:
            return 0.0
    return (6.0 * pref / (math.pi * params[P.DENSITY])) ** (1.0 / 3.0) * m43 / m1


@nb.njit(cache=True)
def _quadratic_form(state, first, n, out, out_first, aux, base, mult):
    """out[out_first + a] += mult sum_{k<=l<n} T[k,l,a] s_k s_l for a < n, s =
    state[first:first+n], T the pair-major block at aux[base]."""
    pos = base
    for k in range(n):
        mk = mult * state[first + k]
        for l in range(k, n):
            prod = mk * state[first + l]
            for a in range(n):
                out[out_first + a] += prod * aux[pos + a]
            pos += n


@nb.njit(cache=True)
def _dry_wet_aggregation(state, out, aux, m, px, pl, mult):
    """Dry + wet -> wet: out[a] += mult X D W (a with i >= 1), out[K + e] += mult XL D W, X
    and XL of one (weight, slice) at aux[px], aux[pl]."""
    K = m * m
    for k in range(m):
        dk = mult * state[K + k]
        if dk == 0.0:
            px += K * K
            pl += K * m
            continue
        for l in range(K):
            prod = dk * state[l]
            for a in range(m, K):
                out[a] += prod * aux[px + a]
            for e in range(m):
                out[K + e] += prod * aux[pl + e]
            px += K
            pl += m


@nb.njit(cache=True)
def _wet_capture(state, out, aux, m, c0, d0, w):
    """Droplets captured by wet granules: out[a] += w sum_k Cd[k, a] W_k; returns
    w sum_k Cd0[k] W_k, the droplets lost (w = mult n~_d times the corner weight)."""
    K = m * m
    loss = 0.0
    for k in range(K):
        wk = w * state[k]
        pos = c0 + k * K
        for a in range(K):
            out[a] += wk * aux[pos + a]
        loss += wk * aux[d0 + k]
    return loss


@nb.njit(cache=True)
def _dry_capture(state, out, aux, m, c0, w):
    """Droplets captured by dry granules: L_e = w sum_k Cdd[k, e] D_k leaves the dry class
    and enters the wet one through CAPMAP; returns L_0, the droplets lost."""
    K = m * m
    cap = int(aux[AUX_OFF_CAPMAP])
    loss = 0.0
    for e in range(m):
        acc = 0.0
        for k in range(m):
            acc += state[K + k] * aux[c0 + k * m + e]
        lost = w * acc
        out[K + e] -= lost
        for a in range(K):
            out[a] += aux[cap + e * K + a] * lost
        if e == 0:
            loss = lost
    return loss


@nb.njit(cache=True)
def _aggregation_and_capture(state, out, aux, m, mult, nd, wet, dry, wpos, i0, t):
    """Every aggregation and capture term, blended over the slice (u0) and weight corners;
    returns the droplets captured per unit time (scaled)."""
    K = m * m
    ns = int(aux[AUX_NSLICE])
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    npair = int(aux[AUX_NPAIR])
    capture = nd != 0.0 and aux[AUX_SEPARATE] == 1.0
    loss = 0.0
    for sc in range(2):
        s, ws = _corner(sc, i0, t)
        if ws == 0.0:
            continue
        if dry:
            npd = m * (m + 1) // 2
            _quadratic_form(state, K, m, out, K, aux, int(aux[AUX_OFF_QDD]) + s * npd * m,
                            mult * ws)
            if capture:
                loss += _dry_capture(state, out, aux, m, int(aux[AUX_OFF_CDD]) + s * m * m,
                                     mult * ws * nd)
        if not wet:
            continue
        for q in range(8):
            w, fw = weight_corner(q, wpos, nwc, nwd)
            f = ws * fw
            if f == 0.0:
                continue
            ws_ = w * ns + s
            _quadratic_form(state, 0, K, out, 0, aux, int(aux[AUX_OFF_Q]) + ws_ * npair * K,
                            mult * f)
            if dry:
                _dry_wet_aggregation(state, out, aux, m,
                                     int(aux[AUX_OFF_X]) + ws_ * m * K * K,
                                     int(aux[AUX_OFF_XL]) + ws_ * m * K * m, mult * f)
            if capture:
                loss += _wet_capture(state, out, aux, m, int(aux[AUX_OFF_CD]) + ws_ * K * K,
                                     int(aux[AUX_OFF_CD0]) + ws_ * K, mult * f * nd)
    return loss


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
    separate = config[P.SEPARATE_DROPLETS] == 1
    nd = state[K + m] if separate else 0.0
    wet = _any_nonzero(state, 0, K)
    dry = _any_nonzero(state, K, K + m)
    if mult != 0.0 and (wet or dry):
        i0, t = _slice_position(cell, aux)
        loss = _aggregation_and_capture(state, out, aux, m, mult, nd, wet, dry,
                                        _weight_position(state, aux, m), i0, t)
        if separate:
            out[K + m] = -loss
    if config[P.BREAKAGE] == 1 or config[P.DRYING] == 1:     # laguerre_breakage, _drying
        add_linear_terms(state, out, cell, aux, params, config,
                         _weight_position(state, aux, m))
    inj = cell[P.INJECTION]
    if separate:
        out[K + m] += inj / nref
    elif inj != 0.0:
        x = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
        xl = params[P.DROPLET_MASS] * (1.0 - params[P.DROPLET_SOLIDS]) / params[P.MASS_SCALE]
        for i in range(m):
            for j in range(m):
                out[i * m + j] += inj / nref * (x ** (i + j) if xl == x else x ** i * xl ** j)


@nb.njit(cache=True)
def _wet_checks(state, m, top, level, tol, rel):
    """Sign, b <= p and Cauchy-Schwarz conditions on the wet moments (laguerre_realizable)."""
    if state[0] < 0.0:
        return False
    for i in range(m):
        for j in range(m):
            if i + j <= top and state[i * m + j] < -tol:
                return False
    if m > 1 and state[1] > state[m] * (1.0 + rel) + tol:     # W01 <= W10
        return False
    if level < 1:
        return True
    # b <= p: W_(i,j+1) <= W_(i+1,j)
    for i in range(m - 1):
        for j in range(m - 1):
            if i + j + 1 > top:
                continue
            if state[i * m + j + 1] > state[(i + 1) * m + j] * (1.0 + rel) + tol:
                return False
    # Cauchy-Schwarz W_(e+f)^2 <= W_(2e) W_(2f)
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
def _moment_checks(state, config, level):
    """Admissibility of a scaled state at a check level (see laguerre_realizable)."""
    m = config[P.ORDER]
    K = m * m
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
    for k in range(K + m, n):                   # free droplets
        if state[k] < -tol:
            return False
    top = 2 * (m - 1) if level >= 2 else 2      # highest total order i + j checked
    if not _wet_checks(state, m, top, level, tol, rel):
        return False
    for k in range(m):                          # dry class
        if k <= top and state[K + k] < -tol:
            return False
    if level >= 1:                              # Hankel: D_(e+f)^2 <= D_2e D_2f
        for e in range((m - 1) // 2 + 1):
            for f in range(e + 1, (m - 1) // 2 + 1):
                if max(2 * e, 2 * f) > top:
                    continue
                mid = state[K + e + f]
                if mid * mid > state[K + 2 * e] * state[K + 2 * f] * (1.0 + rel) + tol * tol:
                    return False
    return True


@nb.njit(cache=True)
def laguerre_realizable(state, aux, params, config, work=None):
    """True if the scaled state is admissible for the ROM (used to accept RK stages).

    Level aux[AUX_CHECK_LEVEL] (build_aux(check_level=...)), tol = 1e-12 max|state|,
    relative slack 1e-10 (an exact monodisperse start with equalities passes):
    0 (default): every entry finite; W00 >= 0; W10, W01, W11, W20, W02 >= -tol (the wet
      moments of total order <= 2); W01 <= W10 (b <= p); D0, D1, D2 >= -tol; free droplets
      n_d >= -tol.
    1: also W02 <= W11 <= W20 and Cauchy-Schwarz W10^2 <= W00 W20, W01^2 <= W00 W02,
      W11^2 <= W20 W02, D1^2 <= D0 D2.
    2: all of these for every carried order (W_(i,j+1) <= W_(i+1,j), W_(e+f)^2 <= W_2e W_2f,
      D_(e+f)^2 <= D_2e D_2f, every entry >= -tol).
    The reconstruction is a signed expansion and is not checked. Why level 0 is the default:
    from the seed scenario's dry delta start (on the Cauchy-Schwarz boundary, variance 0) the
    m = 4 consistent ROM's vector field points outward (its p-variance shrinks at t = 0), so
    level 1 stalls the integrator at t ~ 3e-7 s; W21, W22 go transiently negative for m = 3.
    """
    return _moment_checks(state, config, int(aux[AUX_CHECK_LEVEL]))


def strictly_realizable(state, config, level=2):
    """True if the moment conditions of ``level`` (default: all orders) hold."""
    return bool(_moment_checks(np.asarray(state, float), np.asarray(config, np.int64), level))


@nb.njit(cache=True)
def laguerre_conserved(config, params, pivots, coefs):
    """Linear invariants of the ROM state for the time integrator: rows c of ``coefs``
    (n_inv, N_STATE) with c . d(state)/dt independent of the state (the injection only):
    granule mass M10 = W10 + D1 (wet and dry classes) and binder mass M01 = W01 (the dry
    class holds none), each plus the droplets' x_d n_d (x_d = p_d / p_ref) and drying's E.
    ``pivots[r]`` is the entry with coefficient 1 (W10, W01). Returns the count."""
    m = config[P.ORDER]
    n = config[P.N_STATE]
    K = m * m
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    for r in range(2):
        for k in range(n):
            coefs[r, k] = 0.0
        pivots[r] = m if r == 0 else 1          # W10 at (1, 0), W01 at (0, 1)
        coefs[r, pivots[r]] = 1.0
        if r == 0:
            coefs[r, K + 1] = 1.0               # dry D1
        if config[P.SEPARATE_DROPLETS] == 1 and n > K + m:
            coefs[r, K + m] = xd
        coefs[r, n - 1] += config[P.DRYING]     # E, the last entry, with drying
    return 2


@nb.njit(cache=True)
def laguerre_project(state, aux, params, config, work=None):
    """In-place fix after an accepted step: clips a negative free-droplet density to 0, and
    merges a dry class holding less than DRY_MERGE_SHARE of the granules into the wet class
    (W_k0 += D_k, D = 0: mass and number conserved, the dry tensors no longer evaluated).

    The moments themselves are otherwise left untouched (the ROM has no cheaper admissible
    neighbour).
    """
    m = config[P.ORDER]
    K = m * m
    if config[P.SEPARATE_DROPLETS] == 1 and config[P.N_STATE] > K + m:
        if state[K + m] < 0.0:
            state[K + m] = 0.0
    d0 = state[K]
    if d0 != 0.0 and abs(d0) <= DRY_MERGE_SHARE * (state[0] + abs(d0)):
        for k in range(m):
            state[k * m] += state[K + k]
            state[K + k] = 0.0


# ---- Python helpers ---------------------------------------------------------------------
def moments_from_state(state_rows, params, config, m, aux=None):
    """SI moments of one state or of rows of states (shape (n, N_STATE)).

    Returns dict of arrays (shape (n,), or floats for a 1-D state):
    "M{i}{j}" [kg^(i+j)/m3], i, j < m: the whole population, free droplets included (docs/physics.md
    section 11); "granule_M{i}{j}": granules only (wet + dry); "wet_M{i}{j}",
    "dry_M{i}0": each class; if droplets are separate, "droplet_number_density" [1/m3]. For
    m = 2, "M20" and "M02" are not carried: with ``aux`` they are added from the
    reconstruction on the support (an estimate), otherwise absent.
    """
    rows = np.asarray(state_rows, dtype=float)
    one = rows.ndim == 1
    rows = np.atleast_2d(rows)
    K = m * m
    nref = params[P.NUMBER_SCALE]
    pref = params[P.MASS_SCALE]
    sep = int(config[P.SEPARATE_DROPLETS]) == 1 and rows.shape[1] > K + m
    nd = rows[:, K + m] * nref if sep else np.zeros(rows.shape[0])
    pd = params[P.DROPLET_MASS]
    out = {}
    for i in range(m):
        out[f"dry_M{i}0"] = rows[:, K + i] * nref * pref ** i
        for j in range(m):
            w = rows[:, i * m + j] * nref * pref ** (i + j)
            out[f"wet_M{i}{j}"] = w
            g = w + out[f"dry_M{i}0"] if j == 0 else w
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


def reconstruct(state, aux, params, config, p, b, clip_support=True):
    """Reconstructed density n(p, b) [1/(m3 kg2)] of the wet granules at masses p, b [kg]
    (arrays); the dry granules (a line density at b = 0): ``reconstruct_dry``. With adaptive
    weights the neighbouring weight slices' reconstructions are blended as the RHS blends them.

    clip_support: zero outside the support b <= p, p <= p_max, b <= b_max (where the ROM
    lives); False evaluates the expansion everywhere (the plain projection is defined on the
    whole quadrant).
    """
    p = np.asarray(p, float)
    b = np.asarray(b, float)
    shape = np.broadcast(p, b).shape
    pp = np.broadcast_to(p, shape).ravel()
    bb = np.broadcast_to(b, shape).ravel()
    n = np.zeros(pp.shape)
    for w, frac in weight_corners(state, aux):
        B = unpack_basis(aux, w)
        K = B["m"] ** 2
        coef = B["Ginv"] @ (np.asarray(state[:K], float) * B["r"])
        values = fraction_basis_values if aux[AUX_FOLLOWING] == 1.0 else basis_values
        phi = values(pp / B["c"], bb / B["d"], B["Cp"], B["Cb"], B["lam"], B["gam"])
        part = frac * (phi @ coef) * params[P.NUMBER_SCALE] / (B["c"] * B["d"])
        if clip_support:
            p_max, b_max = wet_support(aux, w)
            part = np.where((bb <= pp) & (pp <= p_max) & (bb <= b_max), part, 0.0)
        n += part
    return n.reshape(shape)


def reconstruct_dry(state, aux, params, p, clip_support=True):
    """Reconstructed density n_dry(p) [1/(m3 kg)] of the dry granules at masses p [kg]."""
    B = unpack_basis(aux)
    m = B["m"]
    p = np.asarray(p, float)
    coef = B["Ginv_dry"] @ (np.asarray(state[m * m:m * m + m], float) * B["r_dry"])
    psi = univariate_values(p.ravel() / B["c_dry"], projection_matrix(m, B["lam_dry"]),
                               B["lam_dry"])
    n = psi @ coef * params[P.NUMBER_SCALE] / B["c_dry"]
    if clip_support:
        n = np.where(p.ravel() <= aux[AUX_P_MAX], n, 0.0)
    return n.reshape(p.shape)


def reconstructed_moment(state, aux, params, config, i, j):
    """int_S p^i b^j n [kg^(i+j)/m3] of the reconstruction (wet, plus dry for j = 0) over the
    support, with the same quadrature as the tensors (so it returns the carried moments
    exactly when consistent)."""
    w, p, b = wet_particles(state, aux)
    val = np.sum(w * p ** i * b ** j)
    if j == 0:
        wd, pdry, _ = dry_particles(state, aux)
        val += np.sum(wd * pdry ** i)
    return float(val * params[P.NUMBER_SCALE])


def support_share(state, aux, params, config):
    """(number, mass) carried by the reconstruction on the support relative to M00, M10 of
    the granules [-]: 1 for the consistent variant by construction; the plain projection's
    deficit otherwise."""
    m = int(aux[AUX_ORDER])
    K = m * m
    s = np.asarray(state[:K], float)
    dry = np.asarray(state[K:K + m], float)
    dn, dm = dry_support_functionals(aux)
    number = dn @ dry
    mass = dm @ dry
    for w, frac in weight_corners(state, aux):
        o = int(aux[AUX_OFF_SUPPORT]) + w * 2 * K
        number += frac * (aux[o:o + K] @ s)
        mass += frac * (aux[o + K:o + 2 * K] @ s)
    return float(number / (s[0] + dry[0])), float(mass / (s[m] + dry[1]))
