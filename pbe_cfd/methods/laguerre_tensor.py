"""Bivariate Laguerre ROM (seed 000 section III): basis, quadrature, coefficient tensors, aux.

Everything here runs once per scene (or once per cache key) in Python/numpy with one numba loop
for the kernel matrix; ``laguerre.py`` holds the numba right-hand side that reads the flat
``aux`` array built here.

Formulas (derived from the definitions, docs/physics.md section 9; seed 000 eqs. 8-16)
---------------------------------------------------------------------------
Internal coordinates u = p / c, v = b / d (c, d the weight means [kg]). Weights are gamma
densities of mean 1,

    g_l(u) = l^l u^(l-1) exp(-l u) / Gamma(l)          (shape l = lambda in u, gamma in v).

Polynomials L_n^(l-1)(l u) = sum_i l_ni u^i with

    l_ni = (-1)^i Gamma(n + l) l^i / ((n - i)! Gamma(l + i) i!),   i <= n,

orthogonal: int g_l L_n L_k du = h_n delta_nk, h_n = Gamma(n + l) / (Gamma(l) n!).
Expansion n(u, v) = g_l(u) g_g(v) sum_{n, q < m} kappa_nq L_n(u) L_q(v); projecting on
L_n L_q gives kappa_nq = sum_{i<=n, j<=q} l_ni l'_qj M_ij / (h_n h'_q) (M in internal units).
Collecting terms by moment, n = sum_{ij} M_ij phi_ij with separable basis functions

    phi_ij(u, v) = psi_i(u) chi_j(v),  psi_i(u) = g_l(u) sum_s C_is u^s,
    C_is = sum_{n >= max(i, s)}^{m-1} l_ni l_ns / h_n   (C = inverse of the Hankel moment matrix
                                                       of g_l, a check used in the tests),

so int u^k psi_i du = delta_ik for k < m on the whole quadrant: the plain (seed) projection.

Moment-consistent correction (default): G[a, k] = int_S u^i v^j phi_k over the support
S = {b <= p, p <= p_max, b <= b_max} with the quadrature below, and phi~ = phi G^-1, so the
reconstruction n = sum_a M_a phi~_a reproduces all m x m moments exactly on S.

RHS (docs/physics.md section 2): dM_a/dt = 1/2 int_S int_S beta(r, r') D_a(r, r') n(r) n(r') with
D_a = A_a(r + r') - A_a(r) - A_a(r'), A_a = p^i b^j. Expanding (p+p')^i (b+b')^j binomially,
D_a = sum_{e <= a, e != 0, e != a} C(a, e) A_e(r) A_{a-e}(r') for a != 0 (all terms
non-negative, no cancellation) and D_0 = -1, so with Psi[s, (e, k)] = w_s A_e(r_s) phi_k(r_s) and the symmetric kernel matrix
B[s, t] = beta(r_s, r_t) (evaluated once per unordered pair: the pair symmetry of seed 000
eq. 21), Z = Psi^T B Psi and

    T[a, k, l] = 1/2 sum_e C(a, e) Z[(e, k), (a - e, l)],   symmetric in (k, l).

Droplets as a population of their own (density n_d, mass p_d, b = p_d):
dM_a/dt += n_d int_S k_d(r) [A_a(r + r_d) - A_a(r)] n(r),  dn_d/dt -= n_d int_S k_d(r) n(r),
k_d = droplet_capture_rate. Both are linear in M: matrices Cd[a, k] and Cd0[k].

Quadrature ("uniform", table III): n_p x n_b cell midpoints p_j = (j + 1/2) p_max / n_p,
b_q = (q + 1/2) b_max / n_b, kept where b_q <= p_j. ("fraction"): n_p uniform cells in p and n_b
uniform cells in y = b/p on [0, min(1, b_max/p_j)] -- the efficiencies are steep in y (sigmoid
slope 35.1 around y = 0.129, i.e. b ~ 7e-11 kg for a primary particle, a third of one table III
b-cell), so this spacing resolves them; it is the scenes' default. Both use product-midpoint
weights that integrate the singular weight factors u^(l-1), v^(g-1) exactly over each cell
(gamma = 0.2 puts b^-0.8 at b = 0, where the plain midpoint rule would miss two thirds of the
first cell's integral).

Scaling: the state holds M~_a = M_a / (N_ref p_ref^(i+j)); internal moments are
M_int_a = M~_a r_a with r_a = p_ref^(i+j) / (c^i d^j). Tensors are stored in state units with
the kernel rate k0 and N_ref factored out: dM~_a/dt = k0 N_ref [mult] sum_{k<=l} Q[k,l,a] M~_k M~_l.
"""
import hashlib
import json
import math
import os
import time
from math import comb, lgamma

import numba as nb
import numpy as np

from ..physics import parameters as P
from ..physics.rates import aggregation_rate, droplet_capture_rate

# ---- aux layout (float64 header; offsets are element indices into aux) ---------------------
AUX_VERSION = 0          # layout version (1)
AUX_ORDER = 1            # m
AUX_NMOM = 2             # K = m * m
AUX_NPAIR = 3            # K (K + 1) / 2
AUX_NSLICE = 4           # number of collision-velocity slices (1 = fixed u0 or no dependence)
AUX_CONSISTENT = 5       # 1 = moment-consistent reconstruction, 0 = plain seed projection
AUX_OFF_LOGU = 6         # offset of ln(u0 [m/s]) per slice (NSLICE values)
AUX_OFF_Q = 7            # offset of Q[slice, pair, a]  (NSLICE * NPAIR * K), pair = (k <= l)
AUX_OFF_CD = 8           # offset of Cd[slice, k, a]    (NSLICE * K * K)
AUX_OFF_CD0 = 9          # offset of Cd0[slice, k]      (NSLICE * K)
AUX_OFF_F43 = 10         # offset of F43[k]: int_S (p/p_ref)^(4/3) phi~_k  (K)
AUX_OFF_BASIS = 11       # offset of the reconstruction block (see _basis_block)
AUX_MASS_SCALE = 12      # p_ref [kg] the aux was built for
AUX_P_MAX = 13           # p_max [kg]
AUX_B_MAX = 14           # b_max [kg]
AUX_N_P = 15             # n_p
AUX_N_B = 16             # n_b
AUX_N_NODES = 17         # quadrature nodes kept on the support
AUX_DROPLET_MASS = 18    # p_d [kg] the aux was built for
AUX_SEPARATE = 19        # 1 if droplet capture matrices were built
AUX_COND_G = 20          # condition number of the equilibrated G, 1 for the plain variant
AUX_U0_FIXED = 21        # u0 [m/s] of a single slice (0 if none was needed or a grid is used)
AUX_OFF_SUPPORT = 22     # offset of the mass-on-support functionals (2 * K): int_S u phi~_k
AUX_CHECK_LEVEL = 23     # realizability check level of laguerre_realizable (0, 1, 2)
AUX_SPACING = 24         # quadrature spacing code (SPACINGS: 0 uniform in (p, b), 1 in (p, b/p))
AUX_HEADER = 32
AUX_LAYOUT_VERSION = 1.0

# basis block (offset AUX_OFF_BASIS): c [kg], d [kg], lambda, gamma, then Cp (m*m), Cb (m*m),
# Ginv (K*K, internal units, identity for the plain variant), r (K)
_ALGO_TAG = "laguerre-rom-1"

TABLE_III = dict(weights=dict(c=1e-9, d=1e-9, lam=1.0, gam=0.2),
                 support=dict(p_max=1e-8, b_max=4e-9, n_p=20, n_b=20))


def moment_index(m):
    """List of (i, j) exponents in state order (i-major, i, j < m)."""
    return [(i, j) for i in range(m) for j in range(m)]


# ---- 1-D Laguerre algebra ---------------------------------------------------------------
def laguerre_coefficients(m, shape):
    """Monomial coefficients l[n, i] of L_n^(shape-1)(shape * u), n, i < m, and norms h[n].

    u is the coordinate scaled by the weight mean (dimensionless).
    """
    lcoef = np.zeros((m, m))
    h = np.zeros(m)
    for n in range(m):
        h[n] = math.exp(lgamma(n + shape) - lgamma(shape) - lgamma(n + 1))
        for i in range(n + 1):
            lcoef[n, i] = ((-1) ** i * math.exp(lgamma(n + shape) - lgamma(n - i + 1)
                                                - lgamma(shape + i) - lgamma(i + 1))
                           * shape ** i)
    return lcoef, h


def projection_matrix(m, shape):
    """C[i, s] with psi_i(u) = g(u) sum_s C[i, s] u^s, the dual basis of 1, u, ..., u^(m-1)
    with respect to the gamma weight of mean 1 and the given shape (dimensionless)."""
    lcoef, h = laguerre_coefficients(m, shape)
    return (lcoef.T / h) @ lcoef


def gamma_weight(u, shape):
    """Gamma density of mean 1 and the given shape at u >= 0 (dimensionless, per unit u)."""
    u = np.asarray(u, dtype=float)
    out = np.zeros_like(u)
    pos = u > 0
    out[pos] = np.exp(shape * math.log(shape) + (shape - 1.0) * np.log(u[pos]) - shape * u[pos]
                      - lgamma(shape))
    zero = u == 0
    out[zero] = np.inf if shape < 1.0 else (shape if shape == 1.0 else 0.0)
    return out


def basis_values(u, v, Cp, Cb, lam, gam):
    """Raw basis phi_k(u, v), k = (i, j) in state order, at points u, v (internal units).

    Returns an array of shape (len(u), K), per unit u and v.
    """
    m = Cp.shape[0]
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    up = u[:, None] ** np.arange(m)[None, :]
    vp = v[:, None] ** np.arange(m)[None, :]
    psi = gamma_weight(u, lam)[:, None] * (up @ Cp.T)      # (N, m)
    chi = gamma_weight(v, gam)[:, None] * (vp @ Cb.T)
    return (psi[:, :, None] * chi[:, None, :]).reshape(len(u), m * m)


# ---- quadrature -----------------------------------------------------------------------------
SPACINGS = {"uniform": 0, "fraction": 1}


def quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing=0):
    """Nodes (u, v) [internal units, u = p/c, v = b/d] and weights [du dv] on the support
    b <= p, p <= p_max, b <= b_max.

    spacing 0 ("uniform", seed 000 table III): cell midpoints of a uniform n_p x n_b grid in
    (p, b), kept where b <= p. spacing 1 ("fraction"): n_p uniform cells in p and, at each
    p-cell midpoint p_j, n_b uniform cells in the binder fraction y = b/p on
    [0, min(1, b_max/p_j)] (b = p_j y, db = p_j dy), which resolves the efficiencies' steep
    dependence on y for small granules. Both use product-midpoint weights exact for the
    singular weight factors u^(lam-1) and v^(gam-1) (resp. y^(gam-1)) over each cell.
    """
    du = p_max / c / n_p
    ue = np.arange(n_p + 1) * du
    um = 0.5 * (ue[1:] + ue[:-1])
    wu = (ue[1:] ** lam - ue[:-1] ** lam) / (lam * um ** (lam - 1.0))
    if int(spacing) == 1:
        pj = um * c
        ytop = np.minimum(1.0, b_max / pj)                          # (n_p,)
        t = np.arange(n_b + 1) / n_b
        ye = ytop[:, None] * t[None, :]                             # (n_p, n_b + 1)
        ym = 0.5 * (ye[:, 1:] + ye[:, :-1])
        wy = (ye[:, 1:] ** gam - ye[:, :-1] ** gam) / (gam * ym ** (gam - 1.0))
        U = np.broadcast_to(um[:, None], ym.shape)
        V = pj[:, None] * ym / d
        W = wu[:, None] * wy * (pj[:, None] / d)
        return U.ravel().copy(), V.ravel().copy(), W.ravel().copy()
    dv = b_max / d / n_b
    ve = np.arange(n_b + 1) * dv
    vm = 0.5 * (ve[1:] + ve[:-1])
    wv = (ve[1:] ** gam - ve[:-1] ** gam) / (gam * vm ** (gam - 1.0))
    U, V = np.meshgrid(um, vm, indexing="ij")
    W = wu[:, None] * wv[None, :]
    keep = (V * d) <= (U * c) * (1.0 + 1e-12)
    return U[keep], V[keep], W[keep]


# ---- kernel matrices (numba) ----------------------------------------------------------------
@nb.njit(cache=True)
def _pair_rate_matrix(p, b, u0, params, config, out):
    """out[s, t] = aggregation_rate(node s, node t) [m3/s per unit k0]; unit ktgf multiplier
    (alpha = 0 -> g0 = 1, theta = 1, d43 = 1). One evaluation per unordered pair."""
    n = p.shape[0]
    for s in range(n):
        for t in range(s, n):
            r = aggregation_rate(p[s], b[s], p[t], b[t], 0.0, 1.0, u0, 1.0, params, config)
            out[s, t] = r
            out[t, s] = r


@nb.njit(cache=True)
def _capture_rate_vector(p, b, u0, params, config, out):
    """out[s] = droplet_capture_rate(node s) [m3/s per unit k0], unit ktgf multiplier."""
    for s in range(p.shape[0]):
        out[s] = droplet_capture_rate(p[s], b[s], 0.0, 1.0, u0, 1.0, params, config)


def _unit_params(params):
    q = np.array(params, dtype=np.float64).copy()
    q[P.RATE] = 1.0
    return q


def _aggregation_tensor(Bmat, u, v, W, Phi, m):
    """T[a, k, l] (internal units) from the kernel matrix on the nodes, see module doc."""
    K = m * m
    idx = moment_index(m)
    # Psi[s, e*K + k] = w_s u^e1 v^e2 phi_k
    mon = np.stack([u ** i * v ** j for (i, j) in idx], axis=1)           # (N, K)
    Pw = Phi * W[:, None]
    Psi = (mon[:, :, None] * Pw[:, None, :]).reshape(len(u), K * K)
    Z = Psi.T @ (Bmat @ Psi)
    Z = Z.reshape(K, K, K, K)                                               # e, k, f, l
    T = np.zeros((K, K, K))
    T[0] = -0.5 * Z[0, :, 0, :]              # a = (0, 0): D = 1 - 1 - 1 = -1
    for a, (i, j) in enumerate(idx):
        for e1 in range(i + 1):
            for e2 in range(j + 1):
                if (e1, e2) == (0, 0) or (e1, e2) == (i, j):
                    continue
                e = e1 * m + e2
                f = (i - e1) * m + (j - e2)
                T[a] += 0.5 * comb(i, e1) * comb(j, e2) * Z[e, :, f, :]
    return 0.5 * (T + T.transpose(0, 2, 1))


def _capture_matrices(kd, u, v, W, Phi, m, ud, vd):
    """Cd[a, k] = int k_d [A_a(r + r_d) - A_a(r)] phi_k, Cd0[k] = int k_d phi_k (internal)."""
    idx = moment_index(m)
    Pw = Phi * (W * kd)[:, None]
    Cd = np.zeros((m * m, m * m))
    for a, (i, j) in enumerate(idx):
        # (u + ud)^i (v + vd)^j - u^i v^j expanded to avoid cancellation
        da = np.zeros_like(u)
        for e1 in range(i + 1):
            for e2 in range(j + 1):
                if (e1, e2) == (i, j):
                    continue
                da += comb(i, e1) * comb(j, e2) * u ** e1 * v ** e2 * ud ** (i - e1) \
                    * vd ** (j - e2)
        Cd[a] = da @ Pw
    return Cd, Pw.sum(axis=0)


def _needs_u0(config):
    return int(config[P.USE_PHYSICAL]) == 1


def _source_digest():
    here = os.path.dirname(os.path.abspath(__file__))
    phys = os.path.join(os.path.dirname(here), "physics")
    h = hashlib.sha256()
    for path in (os.path.join(phys, "kernels.py"), os.path.join(phys, "efficiency.py"),
                 os.path.join(phys, "rates.py"), os.path.join(phys, "properties.py"),
                 os.path.join(phys, "parameters.py"), os.path.abspath(__file__)):
        with open(path, "rb") as fh:
            h.update(fh.read())
    return h.hexdigest()


def _cache_key(params, config, order, weights, support, consistent, u0_grid):
    q = np.array(params, dtype=np.float64).copy()
    for slot in (P.RATE, P.NUMBER_SCALE, P.STEP_FLOOR):   # factored out / irrelevant
        q[slot] = 0.0
    cfg = [int(config[s]) for s in (P.KERNEL, P.USE_GEOMETRIC, P.USE_PHYSICAL,
                                    P.USE_SATURATION, P.SEPARATE_DROPLETS)]
    blob = json.dumps(dict(tag=_ALGO_TAG, src=_source_digest(), params=q.tolist(), config=cfg,
                           order=int(order),
                           weights={k: float(weights[k]) for k in ("c", "d", "lam", "gam")},
                           support={k: float(support[k]) for k in ("p_max", "b_max", "n_p",
                                                                   "n_b")},
                           spacing=_spacing_code(support),
                           consistent=bool(consistent),
                           u0=None if u0_grid is None else [float(x) for x in u0_grid]),
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _spacing_code(support):
    sp = support.get("spacing", "uniform")
    if isinstance(sp, str):
        if sp not in SPACINGS:
            raise ValueError(f"support spacing must be one of {sorted(SPACINGS)}, got {sp!r}")
        return SPACINGS[sp]
    return int(sp)


def default_cache_dir():
    """Directory of cached aux arrays: $PBE_CFD_CACHE or ~/.cache/pbe_cfd/laguerre."""
    return os.environ.get("PBE_CFD_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "pbe_cfd", "laguerre"))


def theta_to_u0(theta):
    """Collision velocity u0 = 4 sqrt(Theta / pi) [m/s] from granular temperature [m2/s2]."""
    return 4.0 * np.sqrt(np.asarray(theta, float) / math.pi)


def log_theta_grid(theta_min, theta_max, n):
    """n log-spaced granular temperatures [m2/s2] for build_aux(theta_grid=...)."""
    return np.geomspace(theta_min, theta_max, n)


BUILD_LOG = []   # (cache key, seconds, nodes, slices) of tensors built in this process


def build_aux(params, config, order, weights=None, support=None, consistent=True,
              theta_grid=None, cache_dir=None, collision_velocity=None, use_cache=True,
              check_level=0):
    """Build (or load from the disk cache) the flat float64 ``aux`` array of the Laguerre ROM.

    params, config: the arrays of ``physics.parameters`` (SI). order: m (2, 3 or 4).
    weights: dict(c [kg], d [kg], lam [-], gam [-]) -- gamma weights, mean c in p, mean d in b.
    support: dict(p_max [kg], b_max [kg], n_p, n_b[, spacing]) -- integration support, grid
    cells per side and spacing ("uniform" in (p, b), the default and seed 000's choice, or
    "fraction": uniform in p and in the binder fraction b/p, see ``quadrature``).
    Defaults: seed 000 table III. consistent: moment-consistent reconstruction (default) or the
    seed's plain projection. theta_grid: granular temperatures [m2/s2] (log-spaced) on which to
    tabulate the tensor when the physical efficiency is on and u0 = 4 sqrt(Theta / pi) comes from
    the cell; otherwise collision_velocity [m/s] fixes u0 (needed iff the physical efficiency
    is on). The kernel rate k0, N_ref and the ktgf factor g0 sqrt(Theta) d43^(3/2) are applied
    at RHS time, so they do not enter the tensor or the cache key. Cached as .npy under
    cache_dir (default ``default_cache_dir()``) keyed by a hash of everything else that
    determines the tensor, including the physics source code. check_level (0, 1, 2): which
    moment conditions laguerre_realizable enforces (stored in aux, not part of the key).
    """
    weights = dict(TABLE_III["weights"], **(weights or {}))
    support = dict(TABLE_III["support"], **(support or {}))
    m = int(order)
    if m < 1 or m > 6:
        raise ValueError(f"Laguerre order must be 1..6, got {m}")
    c, d = float(weights["c"]), float(weights["d"])
    lam, gam = float(weights["lam"]), float(weights["gam"])
    p_max, b_max = float(support["p_max"]), float(support["b_max"])
    n_p, n_b = int(support["n_p"]), int(support["n_b"])
    if min(c, d, lam, gam, p_max, b_max) <= 0 or n_p < 1 or n_b < 1:
        raise ValueError("Laguerre weights and support must be positive")
    p_ref = float(params[P.MASS_SCALE])
    if not p_ref > 0:
        raise ValueError("params[MASS_SCALE] must be set (> 0) before build_aux")
    if _needs_u0(config):
        if theta_grid is not None:
            u0_grid = np.sort(theta_to_u0(np.asarray(theta_grid, float)))
            if u0_grid.size < 1 or not np.all(u0_grid > 0):
                raise ValueError("theta_grid must hold positive granular temperatures")
        elif collision_velocity is not None and collision_velocity > 0:
            u0_grid = np.array([float(collision_velocity)])
        else:
            raise ValueError("physical efficiency on: give theta_grid or collision_velocity")
    else:
        u0_grid = None
    key = _cache_key(params, config, m, weights, support, consistent, u0_grid)
    cdir = cache_dir or default_cache_dir()
    path = os.path.join(cdir, f"aux_{key}.npy")
    if use_cache and os.path.exists(path):
        try:
            aux = np.load(path)
            if aux.dtype == np.float64 and aux[AUX_VERSION] == AUX_LAYOUT_VERSION:
                aux[AUX_CHECK_LEVEL] = check_level
                return aux
        except (OSError, ValueError):
            pass
    t0 = time.perf_counter()
    spacing = _spacing_code(support)
    aux = _build(params, config, m, c, d, lam, gam, p_max, b_max, n_p, n_b, consistent,
                 u0_grid, p_ref, spacing)
    aux[AUX_CHECK_LEVEL] = check_level
    BUILD_LOG.append((key, time.perf_counter() - t0, int(aux[AUX_N_NODES]),
                      int(aux[AUX_NSLICE])))
    if use_cache:
        try:
            os.makedirs(cdir, exist_ok=True)
            tmp = f"{path}.{os.getpid()}.tmp.npy"
            np.save(tmp, aux)
            os.replace(tmp, path)
        except OSError:
            pass
    return aux


def _build(params, config, m, c, d, lam, gam, p_max, b_max, n_p, n_b, consistent, u0_grid,
           p_ref, spacing=0):
    K = m * m
    idx = moment_index(m)
    Cp = projection_matrix(m, lam)
    Cb = projection_matrix(m, gam)
    u, v, W = quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing)
    Phi = basis_values(u, v, Cp, Cb, lam, gam)                      # raw basis (N, K)
    mon = np.stack([u ** i * v ** j for (i, j) in idx], axis=1)     # (N, K)
    G = mon.T @ (Phi * W[:, None])                                  # G[a, k]
    if consistent:
        # equilibrate rows (moments) and columns (basis functions) before inverting: G spans
        # many decades (u^3 v^3 against 1), equilibration takes cond from ~1e12 to ~1e8 (m = 4)
        dr = 1.0 / np.abs(G).max(axis=1)
        Gs = G * dr[:, None]
        dc = 1.0 / np.abs(Gs).max(axis=0)
        Gs = Gs * dc[None, :]
        Ginv = dc[:, None] * np.linalg.inv(Gs) * dr[None, :]
        cond = np.linalg.cond(Gs)
    else:
        Ginv = np.eye(K)
        cond = 1.0
    PhiC = Phi @ Ginv                                               # phi~ (N, K)
    # state <-> internal scaling: M_int = M~ * r
    r = np.array([p_ref ** (i + j) / (c ** i * d ** j) for (i, j) in idx])
    p_nodes = u * c
    b_nodes = v * d
    uparams = _unit_params(params)
    ucfg = np.asarray(config, dtype=np.int64)
    slices = [float("nan")] if u0_grid is None else list(u0_grid)
    nS = len(slices)
    npair = K * (K + 1) // 2
    iu = np.triu_indices(K)
    Q = np.zeros((nS, npair, K))
    separate = int(config[P.SEPARATE_DROPLETS]) == 1 and params[P.DROPLET_FACTOR] > 0
    Cd = np.zeros((nS, K, K))
    Cd0 = np.zeros((nS, K))
    pd = float(params[P.DROPLET_MASS])
    Bmat = np.empty((len(u), len(u)))
    kd = np.empty(len(u))
    for s, u0 in enumerate(slices):
        u0v = 0.0 if not np.isfinite(u0) else u0
        _pair_rate_matrix(p_nodes, b_nodes, u0v, uparams, ucfg, Bmat)
        T = _aggregation_tensor(Bmat, u, v, W, PhiC, m)             # internal units
        # state units: dM~_a = sum_kl T[a,k,l] (M~_k r_k)(M~_l r_l) / r_a
        Ts = T * r[None, :, None] * r[None, None, :] / r[:, None, None]
        fold = np.where(iu[0] == iu[1], 1.0, 2.0)
        Q[s] = (Ts[:, iu[0], iu[1]] * fold[None, :]).T
        if separate:
            _capture_rate_vector(p_nodes, b_nodes, u0v, uparams, ucfg, kd)
            cd, cd0 = _capture_matrices(kd, u, v, W, PhiC, m, pd / c, pd / d)
            Cd[s] = (cd * r[None, :] / r[:, None]).T                 # [k, a]
            Cd0[s] = cd0 * r
    # linear functionals in state units
    f43 = ((u * c / p_ref) ** (4.0 / 3.0) * W) @ PhiC * r
    sup = np.concatenate([(W @ PhiC) * r, ((u * c / p_ref) * W) @ PhiC * r])
    basis = np.concatenate([[c, d, lam, gam], Cp.ravel(), Cb.ravel(), Ginv.ravel(), r])
    logu = np.log(np.array([x if np.isfinite(x) else 1.0 for x in slices]))
    blocks = [logu, Q.ravel(), Cd.ravel(), Cd0.ravel(), f43, basis, sup]
    offs = []
    pos = AUX_HEADER
    for blk in blocks:
        offs.append(pos)
        pos += blk.size
    aux = np.zeros(pos)
    for o, blk in zip(offs, blocks):
        aux[o:o + blk.size] = blk
    aux[AUX_VERSION] = AUX_LAYOUT_VERSION
    aux[AUX_ORDER] = m
    aux[AUX_NMOM] = K
    aux[AUX_NPAIR] = npair
    aux[AUX_NSLICE] = nS
    aux[AUX_CONSISTENT] = 1.0 if consistent else 0.0
    aux[AUX_OFF_LOGU], aux[AUX_OFF_Q], aux[AUX_OFF_CD], aux[AUX_OFF_CD0], aux[AUX_OFF_F43], \
        aux[AUX_OFF_BASIS], aux[AUX_OFF_SUPPORT] = offs
    aux[AUX_MASS_SCALE] = p_ref
    aux[AUX_P_MAX] = p_max
    aux[AUX_B_MAX] = b_max
    aux[AUX_N_P] = n_p
    aux[AUX_N_B] = n_b
    aux[AUX_N_NODES] = len(u)
    aux[AUX_SPACING] = spacing
    aux[AUX_DROPLET_MASS] = pd
    aux[AUX_SEPARATE] = 1.0 if separate else 0.0
    aux[AUX_COND_G] = cond
    aux[AUX_U0_FIXED] = slices[0] if (nS == 1 and np.isfinite(slices[0])) else 0.0
    return aux


def unpack_basis(aux):
    """Reconstruction data from aux: dict(c, d [kg], lam, gam, Cp, Cb, Ginv, r, m)."""
    m = int(aux[AUX_ORDER])
    K = m * m
    o = int(aux[AUX_OFF_BASIS])
    c, d, lam, gam = aux[o:o + 4]
    o += 4
    Cp = aux[o:o + m * m].reshape(m, m)
    o += m * m
    Cb = aux[o:o + m * m].reshape(m, m)
    o += m * m
    Ginv = aux[o:o + K * K].reshape(K, K)
    o += K * K
    r = aux[o:o + K]
    return dict(c=c, d=d, lam=lam, gam=gam, Cp=Cp, Cb=Cb, Ginv=Ginv, r=r, m=m)


# ---- scene-level helpers (called by simulate.py) ---------------------------------------------
ESCAPE_WARN_SHARE = 1e-3     # warn when more than 0.1 % of the granule mass is beyond the support
# quadrature spacing for scenes that do not name one ([method] grid_spacing): "fraction" -- on
# the seed scenario it brings the consistent ROM from 10-13 % to within 3-9 % of the cNMC at
# table III's 20 x 20 points; "uniform" reproduces table III's increments literally.
SCENE_SPACING = "fraction"


def scene_weights_support(scene):
    """(weights, support) dicts of build_aux from the scene's [method] table (SI)."""
    m = scene.method
    weights = dict(c=m.weight_mean_mass, d=m.weight_mean_binder, lam=m.weight_shape_mass,
                   gam=m.weight_shape_binder)
    support = dict(p_max=m.support_mass, b_max=m.support_binder, n_p=m.grid_mass,
                   n_b=m.grid_binder, spacing=getattr(m, "grid_spacing", SCENE_SPACING))
    return weights, support


def aux_for_scene(scene, arrays, theta_grid=None, cache_dir=None):
    """aux of the Laguerre ROM for a scene and its packed arrays (``model.pack``).

    The collision velocity is fixed (one tensor slice) when the scene's domain gives
    ``collision_velocity`` or when no theta_grid [m2/s2] is passed (well-mixed: the cell's u0);
    otherwise the tensor is tabulated on theta_grid (u0 = 4 sqrt(Theta / pi)).
    """
    from .. import model
    weights, support = scene_weights_support(scene)
    u0 = getattr(scene.domain, "collision_velocity", None)
    if u0 is not None:
        theta_grid = None
    elif theta_grid is None:
        u0 = float(model.well_mixed_cell(scene)[0, P.COLLISION_VELOCITY])
    if not (u0 is None or u0 > 0):
        u0 = None
    return build_aux(arrays.params, arrays.config, scene.method.order, weights=weights,
                     support=support, consistent=scene.method.consistent,
                     theta_grid=theta_grid, cache_dir=cache_dir, collision_velocity=u0)


def population_for_output(state, aux, arrays):
    """The reconstruction on the quadrature nodes as weighted particles (w [1/m3], p [kg],
    b [kg]) of one cell's granules. Weights are signed (the expansion may dip below zero); for
    the consistent variant sum w p^i b^j returns every carried M_ij exactly."""
    B = unpack_basis(aux)
    K = B["m"] ** 2
    u, v, W = quadrature(B["c"], B["d"], B["lam"], B["gam"], aux[AUX_P_MAX], aux[AUX_B_MAX],
                         int(aux[AUX_N_P]), int(aux[AUX_N_B]), int(aux[AUX_SPACING]))
    phi = basis_values(u, v, B["Cp"], B["Cb"], B["lam"], B["gam"])
    coef = B["Ginv"] @ (np.asarray(state[:K], float) * B["r"])
    w = (phi @ coef) * W * arrays.number_scale
    return w, u * B["c"], v * B["d"]


def escaped_share_report(states, aux, arrays):
    """(largest escaped granule-mass share over the rows [-], warning text or "").

    states: scaled states, one row per output time (or cell)."""
    from .laguerre import escaped_mass_share
    states = np.atleast_2d(states)
    shares = np.array([escaped_mass_share(s, aux, arrays.params, arrays.config)
                       for s in states])
    k = int(np.argmax(shares)) if shares.size else 0
    share = float(shares[k]) if shares.size else 0.0
    text = ""
    if share > ESCAPE_WARN_SHARE:
        text = (f"Laguerre ROM: {share:.2%} of the granule mass lies beyond the integration "
                f"support (p_max = {aux[AUX_P_MAX]:.3g} kg, b_max = {aux[AUX_B_MAX]:.3g} kg) "
                f"at output row {k}; the tensor does not see it -- widen the support")
    return share, text
