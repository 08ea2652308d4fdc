"""Laguerre ROM: the state layout and the layout of the flat ``aux`` array.

State of one cell (scaled by N_ref [1/m3] and p_ref [kg]):
``[W_ij (i, j < m, i-major), D_k (k < m), L_d (drying with separate droplets), E (drying),
n_d (if droplets are separate)]`` -- the wet granules' mixed moments, the dry granules' moments
in p, the free droplets' liquid, the evaporated liquid, the free droplets' number.

The aux array is a float64 header (slots below) followed by blocks at the offsets the header
holds. Tensors depend on the collision velocity u0 (``slice`` s, NSLICE values of ln u0) and,
with adaptive weights, on the wet weight means (``weight`` w = ic * NWD + id on a log grid of
NWC means c and NWD means d; with the following support, w = (il * NWC + ic) * NWD + id over
NWL gamma shapes lambda in p, NWC mass-weighted means c_m and NWD binder fractions y, and each
weight slice integrates over its own support p <= span c_m, b <= p: docs/physics.md
section 9.2);
the dry-only blocks depend on the slice alone. Block shapes:

    Q[w, s, pair(k <= l < K), a < K]     wet + wet -> wet
    Cd[w, s, k, a], Cd0[w, s, k]         droplets captured by wet granules (with
                                         CAPTURE_MOMENTS: Cd[w, s, k, f] the captured
                                         granules' moments, a the droplet's point mapped in
                                         at the RHS)
    X[w, s, k < m, l < K, a < K]         dry k + wet l -> wet moment a
    XL[w, s, k < m, l < K, e < m]        the same pair's loss of dry moment e
    Qdd[s, pair(k <= l < m), a < m]      dry + dry -> dry
    Cdd[s, k < m, e < m]                 droplets captured by dry granules
    F43[w, k], SUPPORT[w, 2K], BASIS[w, BASIS_SIZE]   wet functionals and reconstruction
    WET_SUPPORT[w, 2]                    p_max, b_max [kg] of each weight slice's support
    CAPMAP[e < m, a < K], F43D[k], DRY_BASIS           dry-class data
    BREAK: Lwet[w, k < K, a < K], then Ldry[k < m, e < m]   breakage (if any)
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_number_entry, evaporated_entry  # noqa: F401
from ...physics.parameters import numbered
from ..quadrature.drying_sources import droplet_point

#: the header's slots in order (each name's value is its index)
HEADER = (
    ("AUX_VERSION", "layout version (AUX_LAYOUT_VERSION)"),
    ("AUX_ORDER", "m"),
    ("AUX_NMOM", "K = m * m"),
    ("AUX_NPAIR", "K (K + 1) / 2"),
    ("AUX_NSLICE", "number of collision-velocity slices (1 = fixed u0 or no dependence)"),
    ("AUX_CONSISTENT", "1 = moment-consistent reconstruction, 0 = plain seed projection"),
    ("AUX_OFF_LOGU", "offset of ln(u0 [m/s]) per slice (NSLICE values)"),
    ("AUX_OFF_Q", "offset of Q  (w = 0, s = 0 first: pair-major, a fastest)"),
    ("AUX_OFF_CD", "offset of Cd"),
    ("AUX_OFF_CD0", "offset of Cd0"),
    ("AUX_OFF_F43", "offset of F43[w, k]: int_S (p/p_ref)^(4/3) phi~_k"),
    ("AUX_OFF_BASIS", "offset of the wet reconstruction blocks (BASIS_SIZE per weight)"),
    ("AUX_MASS_SCALE", "p_ref [kg] the aux was built for"),
    ("AUX_P_MAX", "p_max [kg]"),
    ("AUX_B_MAX", "b_max [kg]"),
    ("AUX_N_P", "n_p"),
    ("AUX_N_B", "n_b"),
    ("AUX_N_NODES", "quadrature nodes kept on the support"),
    ("AUX_DROPLET_MASS", "p_d [kg] the aux was built for"),
    ("AUX_SEPARATE", "1 if droplet capture matrices were built"),
    ("AUX_COND_G", "largest condition number of the equilibrated G (1 if plain)"),
    ("AUX_U0_FIXED", "u0 [m/s] of a single slice (0 if none was needed or a grid is used)"),
    ("AUX_OFF_SUPPORT", "offset of the on-support functionals SUPPORT[w, 2K]"),
    ("AUX_CHECK_LEVEL", "realizability check level of laguerre_realizable (0, 1, 2)"),
    ("AUX_SPACING", "quadrature spacing code (SPACINGS: 0 uniform in (p, b), 1 in (p, b/p))"),
    ("AUX_OFF_QDD", "offset of Qdd"),
    ("AUX_OFF_X", "offset of X"),
    ("AUX_OFF_XL", "offset of XL"),
    ("AUX_OFF_CDD", "offset of Cdd"),
    ("AUX_OFF_CAPMAP", "offset of CAPMAP"),
    ("AUX_OFF_F43D", "offset of F43D[k]: int (p/p_ref)^(4/3) psi~_k  (m)"),
    ("AUX_OFF_DRY_BASIS", "n_dry, c_dry [kg], lam_dry, Ginv_dry (m*m), r_dry (m), support (2m)"),
    ("AUX_COND_DRY", "condition number of the equilibrated G_dry (1 if plain)"),
    ("AUX_N_DRY", "nodes of the dry quadrature in p"),
    ("AUX_NWC", "weight means c on the adaptive grid (1: fixed weights)"),
    ("AUX_NWD", "weight means d on the adaptive grid (1: fixed weights)"),
    ("AUX_OFF_LOGW", "offset of ln c [kg] (NWC values), then ln d [kg] (NWD values)"),
    ("AUX_OFF_CONDW", "offset of cond(G) of each weight slice (NWC * NWD values)"),
    ("AUX_OFF_BREAK", "offset of the breakage block (laguerre_breakage; 0: no breakage)"),
    ("AUX_FOLLOWING", "1: following support (weight grid in (ln c, ln d/c), a support per slice)"),
    ("AUX_OFF_WET_SUPPORT", "offset of (p_max, b_max) [kg] of each weight slice (NWC * NWD "
                            "pairs)"),
    ("AUX_NWL", "gamma shapes lambda in p on the following grid (1: a fixed shape); the "
                "weight index is w = (il * NWC + ic) * NWD + jd"),
    ("AUX_OFF_DRYING", "offset of the drying block (laguerre_drying; 0: no drying)"),
    ("AUX_CAPTURE_MOMENTS", "1: Cd holds int k_d A_f phi~_k, the moments of the granules that "
                            "capture, mapped at the RHS's droplet point (evaporating droplets); "
                            "0: the wet gain at the sprayed droplet (p_d, b_d)"),
    ("AUX_NUMBER_POINTS", "the rows of aggregation and capture (NUMBER_CLOSURES): 0 the "
                          "tensors', 1 those of order <= 2 on the point measures "
                          "(number_points), 2 every wet row on them"),
)
AUX_HEADER = numbered(HEADER, globals())
AUX_LAYOUT_VERSION = 9.0

#: ``[method] number_closure`` -> aux[AUX_NUMBER_POINTS] (docs/physics.md 9.2)
NUMBER_CLOSURES = {"tensor": 0.0, "points": 1.0, "points-all": 2.0}
#: aux[AUX_NUMBER_POINTS] of the closure that takes every wet row of aggregation and capture
#: from the point measures
EVERY_ROW_ON_POINTS = 2.0

TABLE_III = dict(weights=dict(c=1e-9, d=1e-9, lam=1.0, gam=0.2),
                 support=dict(p_max=1e-8, b_max=4e-9, n_p=20, n_b=20))


def state_offsets(m):
    """(first dry entry, droplet entry without a droplet-liquid entry) of the state of order m:
    K = m*m and K + m."""
    return m * m, m * m + m


def free_droplets(rows, params, config):
    """(n_d [1/m3], mass [kg], liquid [kg]) of the free droplets of each row of scaled states
    (arrays of the rows' length; n_d 0 without droplets of their own): one droplet of each row
    as the RHS takes it (``quadrature.drying_sources.droplet_point``: (p_d, b_d), or with a
    droplet-liquid entry the class's mean point (s p_d + l, l))."""
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    params = np.asarray(params, dtype=np.float64)
    config = np.asarray(config, dtype=np.int64)
    points = np.empty((len(rows), 2))
    if int(config[P.SEPARATE_DROPLETS]) != 1 or rows.shape[1] < int(config[P.N_STATE]):
        points[:] = droplet_point(np.zeros(int(config[P.N_STATE])), params, config)
        return np.zeros(len(rows)), points[:, 0], points[:, 1]
    for r, row in enumerate(rows):
        points[r] = droplet_point(np.ascontiguousarray(row), params, config)
    return rows[:, -1] * float(params[P.NUMBER_SCALE]), points[:, 0], points[:, 1]


def state_size(order, separate_droplets, drying=False):
    """Length of one cell's state: m*m wet moments, m dry moments (+1 for free droplets, +1
    for the evaporated liquid with drying, +1 for the free droplets' liquid with both)."""
    return len(state_names(order, separate_droplets, drying))


def state_names(order, separate_droplets, drying=False):
    """Names of the state entries: wet granules' M_ij ("wet_M{i}{j}", i-major, i, j < order),
    dry granules' M_k0 ("dry_M{k}0"), then with drying and droplets of their own the
    droplets' liquid "droplet_liquid" (they evaporate), with drying "evaporated_liquid" (the
    liquid evaporated so far; both scaled as mass moments), and "droplet_number_density" last
    if droplets are separate (the tail of every method: ``physics.injection``)."""
    names = [f"wet_M{i}{j}" for i in range(order) for j in range(order)]
    names += [f"dry_M{k}0" for k in range(order)]
    if drying and separate_droplets:
        names.append("droplet_liquid")
    if drying:
        names.append("evaporated_liquid")
    if separate_droplets:
        names.append("droplet_number_density")
    return names


def basis_size(m):
    """Length of one weight's wet reconstruction block: c, d, lambda, gamma, Cp, Cb, Ginv, r."""
    return 4 + 2 * m * m + m ** 4 + m * m


def n_weights(aux):
    """Number of weight slices (NWL * NWC * NWD)."""
    return int(aux[AUX_NWC]) * int(aux[AUX_NWD]) * max(1, int(aux[AUX_NWL]))


def carried_shape(w00, w10, w20):
    """Gamma shape [-] of the carried number moments (W00, W10, W20): mean^2 / variance =
    W10^2 / (W00 W20 - W10^2); inf for a delta or a set without a positive variance, 0 for
    a set with no number or mass."""
    if not (w00 > 0.0 and w10 > 0.0):
        return 0.0
    var = w00 * w20 - w10 * w10
    return w10 * w10 / var if var > 0.0 else math.inf


def unpack_basis(aux, w=0):
    """Reconstruction data of weight slice w: dict(c, d [kg], lam, gam, Cp, Cb, Ginv, r, m) of
    the wet class, and Ginv_dry, r_dry, n_dry, c_dry [kg], lam_dry of the dry class."""
    m = int(aux[AUX_ORDER])
    K = m * m
    o = int(aux[AUX_OFF_BASIS]) + w * basis_size(m)
    c, d, lam, gam = aux[o:o + 4]
    o += 4
    Cp = aux[o:o + m * m].reshape(m, m)
    o += m * m
    Cb = aux[o:o + m * m].reshape(m, m)
    o += m * m
    Ginv = aux[o:o + K * K].reshape(K, K)
    o += K * K
    r = aux[o:o + K]
    o = int(aux[AUX_OFF_DRY_BASIS])
    n_dry, c_dry, lam_dry = int(aux[o]), aux[o + 1], aux[o + 2]
    Ginv_dry = aux[o + 3:o + 3 + m * m].reshape(m, m)
    r_dry = aux[o + 3 + m * m:o + 3 + m * m + m]
    return dict(c=c, d=d, lam=lam, gam=gam, Cp=Cp, Cb=Cb, Ginv=Ginv, r=r, m=m,
                Ginv_dry=Ginv_dry, r_dry=r_dry, n_dry=n_dry, c_dry=c_dry, lam_dry=lam_dry)


def corner_condition(state, aux):
    """Largest condition number of the equilibrated G among the weight slices the state's
    RHS blends (``weight_corners``): what bounds its round-off, 100 eps cond."""
    o = int(aux[AUX_OFF_CONDW])
    return max(float(aux[o + w]) for w, _ in weight_corners(state, aux))


def dry_support_functionals(aux):
    """(number, mass) functionals of the dry class on [0, p_max] in state units (2 x m)."""
    m = int(aux[AUX_ORDER])
    o = int(aux[AUX_OFF_DRY_BASIS]) + 3 + m * m + m
    return aux[o:o + m], aux[o + m:o + 2 * m]


def _log_position(x, grid):
    """(lower index, weight of the upper point) of x on a sorted log grid, clamped."""
    n = len(grid)
    if n <= 1 or not (x > 0.0):
        return 0, 0.0
    lx = math.log(x)
    if lx <= grid[0]:
        return 0, 0.0
    if lx >= grid[-1]:
        return n - 2, 1.0
    i = int(np.searchsorted(grid, lx) - 1)
    return i, (lx - grid[i]) / (grid[i + 1] - grid[i])


def weight_corners(state, aux):
    """[(weight slice w, blend weight)] of a scaled state: the wet weight means follow the wet
    class's mean mass W10/W00 and mean binder W01/W00 on the adaptive grid (bilinear in
    ln c, ln d, as the RHS blends; with the following support in the mass-weighted mean mass
    W20/W10, the binder fraction W01/W10 and the carried gamma shape (``carried_shape``), all
    in logs, on the Kuhn simplex of ``weight_corner``); [(0, 1.0)] for fixed weights."""
    nwc, nwd = int(aux[AUX_NWC]), int(aux[AUX_NWD])
    if nwc * nwd <= 1:
        return [(0, 1.0)]
    m = int(aux[AUX_ORDER])
    o = int(aux[AUX_OFF_LOGW])
    pref = aux[AUX_MASS_SCALE]
    w00 = float(state[0])
    c = state[m] / w00 * pref if w00 > 0 else 0.0
    d = state[1] / w00 * pref if w00 > 0 else 0.0
    if aux[AUX_FOLLOWING] == 1.0:
        ok = w00 > 0 and state[m] > 0
        c = state[2 * m] / state[m] * pref if ok else 0.0
        d = state[1] / state[m] if ok else 0.0
    ic, tc = _log_position(c, aux[o:o + nwc])
    jd, td = _log_position(d, aux[o + nwc:o + nwc + nwd])
    nwl = max(1, int(aux[AUX_NWL]))
    il, tl = 0, 0.0
    if nwl > 1:
        lam = carried_shape(w00, float(state[m]), float(state[2 * m]))
        grid = aux[o + nwc + nwd:o + nwc + nwd + nwl]
        il, tl = (nwl - 2, 1.0) if lam == math.inf else _log_position(lam, grid)
    if nwl <= 1:
        out = []
        for a, wa in ((0, 1.0 - tc), (1, tc)):
            for b, wb in ((0, 1.0 - td), (1, td)):
                if wa * wb > 0.0:
                    out.append(((ic + a) * nwd + jd + b, wa * wb))
        return out
    # the shape axis: the Kuhn simplex of the cube holding (tc, td, tl), as weight_corner
    order = sorted(((tc, 0), (td, 1), (tl, 2)), key=lambda x: -x[0])
    bits = [0, 0, 0]
    ts = [1.0] + [t for t, _ in order] + [0.0]
    out = []
    for q in range(N_CORNERS):
        if q > 0:
            bits[order[q - 1][1]] = 1
        f = ts[q] - ts[q + 1]
        if f > 0.0:
            out.append((((il + bits[2]) * nwc + ic + bits[0]) * nwd + jd + bits[1], f))
    return out


def separate_droplets(config):
    """True if free droplets are a state entry of their own."""
    return int(config[P.SEPARATE_DROPLETS]) == 1


def wet_support(aux, w=0):
    """(p_max, b_max) [kg] of weight slice w's support: its own with the following support,
    the one fixed support otherwise."""
    if aux[AUX_FOLLOWING] == 1.0:
        o = int(aux[AUX_OFF_WET_SUPPORT]) + 2 * w
        return float(aux[o]), float(aux[o + 1])
    return float(aux[AUX_P_MAX]), float(aux[AUX_B_MAX])


#: the most weight-grid corners one state blends (bilinear: 4; with the shape axis the
#: simplex's 4)
N_CORNERS = 4


@nb.njit(cache=True, inline="always")
def _corner(k, i, t):
    """(index, weight) of corner k (0 lower, 1 upper) of a linear interpolation at (i, t)."""
    if k == 0:
        return i, 1.0 - t
    return i + 1, t


@nb.njit(cache=True, inline="always")
def weight_corner(q, wpos, nwc, nwd):
    """(weight slice w, blend weight) of corner q < N_CORNERS of the weight position wpos
    (``_weight_position``); w = (il * nwc + ic) * nwd + jd. Without a shape axis (il < 0):
    bilinear in (ln c, ln d), bit 0 of q the mass axis, bit 1 the binder axis. With it: the
    Kuhn simplex of the cell's cube that holds the point (docs/physics.md 9.2), corner q the
    lower corner plus the unit steps along the q axes of largest fractional coordinate, blend
    weight t_(q) - t_(q+1) (t_(0) = 1 >= t_(1) >= t_(2) >= t_(3) >= t_(4) = 0): exact for
    any function linear in (ln c_m, ln y_bar, ln lambda), four corners instead of eight."""
    ic, tc, jd, td, il, tl = wpos
    if il < 0:
        i, wa = _corner(q & 1, ic, tc)
        j, wb = _corner((q >> 1) & 1, jd, td)
        return i * nwd + j, wa * wb
    # axes (0 mass, 1 binder, 2 shape) in descending fractional coordinate
    a0, a1, a2 = 0, 1, 2
    t0, t1, t2 = tc, td, tl
    if t0 < t1:
        a0, a1, t0, t1 = a1, a0, t1, t0
    if t1 < t2:
        a1, a2, t1, t2 = a2, a1, t2, t1
    if t0 < t1:
        a0, a1, t0, t1 = a1, a0, t1, t0
    if q == 0:
        f = 1.0 - t0
        n_up = 0
    elif q == 1:
        f = t0 - t1
        n_up = 1
    elif q == 2:
        f = t1 - t2
        n_up = 2
    else:
        f = t2
        n_up = 3
    i, j, g = ic, jd, il
    for r in range(n_up):
        ax = a0 if r == 0 else (a1 if r == 1 else a2)
        if ax == 0:
            i += 1
        elif ax == 1:
            j += 1
        else:
            g += 1
    return (g * nwc + i) * nwd + j, f
