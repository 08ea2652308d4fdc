"""The rows of aggregation and droplet capture on the classes' point measures: those of order
<= 2 (``[method] number_closure = "points"``; docs/physics.md section 9.2, "The rows of order
0-2 on the point measures"), or every wet row (``"points-all"``, ``every_row``: the same pair
sums of every moment W_ij, expanded binomially without cancellation; "Every wet row on the
point measures").

Aggregation alone lowers the granule number: for any positive population
d(M00)/dt = -1/2 of the double integral of beta psi n n <= 0. The tensors apply the kernel to
the signed m-term reconstruction; for a broad wet class (carried shape below 1) their number
row can be off several-fold and turn positive (``number_watch``; docs/results/laguerre.md, the
batch proxy). With this closure the wet-wet rows of W00, W20, W11 and W02 are instead pair sums
of the physics' own pair rate (``physics.rates.pair_rate``: the scene's kernel and
efficiencies at the cell's u0) over the positive point measure of the wet class with its
carried moments, ``drying.wet_points`` (two gamma-Gauss mass nodes from W00, W10, W20, each
with its conditional liquid points from W01, W11, W02, W12):

    dW~ij/dt = 1/2 N_ref sum_s sum_t w_s w_t beta_st [(x_s + x_t)^i (b_s + b_t)^j
                                                      - x_s^i b_s^j - x_t^i b_t^j],

i.e. -1/2 for W00, 2 x_s x_t for W20, x_s b_t + x_t b_s for W11, 2 b_s b_t for W02 [scaled
moments per s]. The four rows move together as the moments of one positive measure under
aggregation, so this term alone keeps W00 W20 >= W10^2, W00 W02 >= W01^2 and the second
moments' matrix as aggregation does for a population (W00 alone on the points, with W20
from the tensors, would not). W00 is clipped at 0 from above and the gains at 0
from below (a node's continued liquid pair may carry a small negative weight,
``drying._node_points``). W10 and W01 (exactly 0) and the rows of order 3 and 4 keep the
tensors' sources.

The dry-wet aggregation and the droplet capture act on the same measures: the dry class's
two-node gamma rule (``dry_points``, from D0, D1, D2) and the wet points; the droplet is the
cell's droplet point (p_d, b_d) (its current one where droplets evaporate). Per pair of a
dry point r and a wet point s, and per captured droplet,

    dD~_e/dt = -N_ref w_r w_s beta_rs x_r^e  (e < 3),   wet gain (x_r + x_s)^i b_s^j - x_s^i b_s^j,
    dry + droplet: L_e = n~_d N_ref f sum_r w_r beta_rd x_r^e leaves D_e and enters every wet
                   row as sum_e C(i, e) x_d^(i - e) x_l^j L_e  (``capture.capture_gain``),
    wet + droplet: the wet rows of order <= 2 of (x_s + x_d)^i (b_s + x_l)^j - x_s^i b_s^j,

f the droplet factor, the droplets lost the sum of both captures. What the dry class and the
droplets lose, the wet class gains, pair by pair: M10 and M01 stay exact. A dry class at one
mass (the start of wet granulation) then feeds a wet class at one mass, on the boundary
W00 W20 = W10^2 and not outside it; the tensors on the dry class's signed reconstruction
gave the young wet class W00 W20 / W10^2 = 0.83 on the bed batch's cell
(docs/results/laguerre.md). The wet rows of order 3 and 4 of the dry-wet and wet capture terms,
and the dry rows of order >= 3, keep the tensors' sources.
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import collision_velocity, kernel_cell_factor
from ...physics.properties import N_PROPS
from ...physics.rates import pair_rate, particle_properties
from .capture import capture_gain
from .drying import N_POINTS, _point, gamma_nodes, wet_points
from .layout import AUX_ORDER


#: property rows of ``add_point_terms``: the wet points, then the dry points, the droplet
DRY_ROW = N_POINTS
DROPLET_ROW = N_POINTS + 2
N_ROWS = N_POINTS + 3
#: the dry class's rows on its points: D_e for e < DRY_POINT_ORDERS (those its two-node rule
#: reproduces)
DRY_POINT_ORDERS = 3


@nb.njit(cache=True)
def dry_points(state, m):
    """(x1, x2, a1, a2): the dry class's two-node gamma rule from D0, D1, D2 [scaled]
    (``drying.gamma_nodes``; one node at the mean where its variance is not positive)."""
    K = m * m
    return gamma_nodes(state[K], state[K + 1], state[K + 2] if m >= 3 else 0.0, m >= 3)


@nb.njit(cache=True)
def dry_powers(state, m, dry_mass, dry_weights, out):
    """Write out[r, e] [scaled]: the e-th powers of the dry points' masses, the factors of the
    dry rows D_e that a dry point's collisions remove; returns ``out`` (2 x m). Where the rule
    has one node (a class at one mass, or past it by round-off: variance not positive) the
    rows e < DRY_POINT_ORDERS take the carried D_e / D0 instead of x^e, so that a loss removes
    the same share of each carried moment and keeps D0 D2 / D1^2 (x^2 = (D1 / D0)^2 would
    remove D0-proportional amounts from a D2 below D1^2 / D0, and the class would leave the
    realizable set as it empties)."""
    K = m * m
    for r in range(2):
        v = 1.0
        for e in range(m):
            out[r, e] = v
            v *= dry_mass[r]
    if dry_weights[1] == 0.0 and state[K] > 0.0:
        for e in range(min(m, DRY_POINT_ORDERS)):
            out[0, e] = max(state[K + e], 0.0) / state[K]
    return out


@nb.njit(cache=True)
def _powers_into(values, m, out, first):
    """out[first + q, k] = values[q]^k for k < m (scaled masses or liquids of the points)."""
    for q in range(len(values)):
        v = 1.0
        for k in range(m):
            out[first + q, k] = v
            v *= values[q]


@nb.njit(cache=True)
def _choose_into(m, out, first):
    """out[first + n, k] = C(n, k) for n, k < m."""
    for n in range(m):
        for k in range(m):
            out[first + n, k] = 0.0
        out[first + n, 0] = 1.0
        for k in range(1, n + 1):
            out[first + n, k] = out[first + n, k - 1] * (n - k + 1) / k


#: rows of the table ``point_tables`` fills (each of length m): the wet points' mass powers,
#: their liquid powers, the droplet's mass and liquid powers, the dry points' powers
#: (``dry_powers``), then C(n, k) (m rows)
TAB_MASS = 0
TAB_LIQUID = N_POINTS
TAB_DROPLET_MASS = 2 * N_POINTS
TAB_DROPLET_LIQUID = 2 * N_POINTS + 1
TAB_DRY = 2 * N_POINTS + 2
TAB_CHOOSE = 2 * N_POINTS + 4


@nb.njit(cache=True)
def point_tables(m, mass, liquid):
    """The table of powers and binomial coefficients the every-row sums read (rows TAB_*;
    the droplet's and the dry points' rows are filled where they are known)."""
    tab = np.ones((TAB_CHOOSE + m, m))
    _powers_into(mass, m, tab, TAB_MASS)
    _powers_into(liquid, m, tab, TAB_LIQUID)
    _choose_into(m, tab, TAB_CHOOSE)
    return tab


@nb.njit(cache=True)
def _wet_pair_rates(props, weights, factor, u0, params, config, rates):
    """Fill rates[s, t] = w_s w_t beta_st over the wet points (symmetric; 0 for a point of no
    weight) and return the number the pairs remove, 1/2 the ordered double sum [scaled]."""
    number = 0.0
    for s in range(N_POINTS):
        for t in range(N_POINTS):
            rates[s, t] = 0.0
    for s in range(N_POINTS):
        ws = weights[s]
        if ws == 0.0:
            continue
        for t in range(s, N_POINTS):
            wt = weights[t]
            if wt == 0.0:
                continue
            f = ws * wt * pair_rate(props, s, t, factor, u0, params, config)
            rates[s, t] = f
            rates[t, s] = f
            number += (0.5 if t == s else 1.0) * f
    return number


@nb.njit(cache=True)
def _point_moment_rates(m, weights, tab, rates, scratch):
    """scratch[a * K + c] = sum_s sum_t rates[s, t] P_s(a) P_t(c) for the wet moments a, c (a
    = i m + j, P_s(a) = x_s^i b_s^j); rates: N_POINTS x N_POINTS, symmetric."""
    K = m * m
    for s in range(N_POINTS):               # G[s, c] = sum_t rates[s, t] P_t(c)
        for c in range(K):
            scratch[K * K + s * K + c] = 0.0
        if weights[s] == 0.0:
            continue
        for t in range(N_POINTS):
            r = rates[s, t]
            if r == 0.0:
                continue
            for i in range(m):
                xi = r * tab[TAB_MASS + t, i]
                for j in range(m):
                    scratch[K * K + s * K + i * m + j] += xi * tab[TAB_LIQUID + t, j]
    for a in range(K):                      # R[a, c] = sum_s P_s(a) G[s, c]
        for c in range(K):
            scratch[a * K + c] = 0.0
    for s in range(N_POINTS):
        if weights[s] == 0.0:
            continue
        for i in range(m):
            for j in range(m):
                ps = tab[TAB_MASS + s, i] * tab[TAB_LIQUID + s, j]
                a = i * m + j
                for c in range(K):
                    scratch[a * K + c] += ps * scratch[K * K + s * K + c]


@nb.njit(cache=True)
def _wet_wet_every_row(out, m, props, weights, tab, rates, scratch, factor, u0, params, config):
    """The wet-wet aggregation's every wet row over the wet points: W00 loses 1/2 sum w_s
    w_t beta_st, each row (i, j) of order >= 2 gains 1/2 sum_(a,c) C(i,a) C(j,c) R[(a,c),
    (i-a,j-c)] over (a, c) other than (0, 0) and (i, j), R the pair-rate-weighted products of
    the points' moments (``_point_moment_rates``): the merged pairs' moments less the
    partners'; the rows of order 1 do not change. tab: ``point_tables``; rates: N_POINTS x
    N_POINTS, scratch: K^2 + N_POINTS K entries of scratch, apart."""
    K = m * m
    number = _wet_pair_rates(props, weights, factor, u0, params, config, rates)
    _point_moment_rates(m, weights, tab, rates, scratch)
    nref = params[P.NUMBER_SCALE]
    out[0] += min(-nref * number, 0.0)
    choose = tab[TAB_CHOOSE:TAB_CHOOSE + m]
    for i in range(m):
        for j in range(m):
            if i + j < 2:
                continue
            gain = 0.0
            for a in range(i + 1):
                for c in range(j + 1):
                    if (a == 0 and c == 0) or (a == i and c == j):
                        continue
                    gain += (choose[i, a] * choose[j, c]
                             * scratch[(a * m + c) * K + (i - a) * m + (j - c)])
            if gain != 0.0:
                out[i * m + j] += max(0.5 * nref * gain, 0.0)


@nb.njit(cache=True)
def _wet_wet(out, m, props, mass, liquid, weights, rates, factor, u0, params, config):
    """The wet-wet rows W00, W20, W11, W02 over the wet points (module docstring); rates:
    N_POINTS x N_POINTS of scratch."""
    number = _wet_pair_rates(props, weights, factor, u0, params, config, rates)
    pp = 0.0                            # each sum: 1/2 of the ordered double sum
    pb = 0.0
    bb = 0.0
    for s in range(N_POINTS):
        for t in range(s, N_POINTS):
            f = (0.5 if t == s else 1.0) * rates[s, t]
            if f == 0.0:
                continue
            pp += f * mass[s] * mass[t]
            pb += f * (mass[s] * liquid[t] + mass[t] * liquid[s])
            bb += f * liquid[s] * liquid[t]
    nref = params[P.NUMBER_SCALE]
    out[0] += min(-nref * number, 0.0)
    out[2 * m] += max(2.0 * nref * pp, 0.0)
    out[m + 1] += max(nref * pb, 0.0)
    out[2] += max(2.0 * nref * bb, 0.0)


@nb.njit(cache=True)
def _dry_wet(out, m, props, dry_pow, dry_weights, mass, liquid, weights, factor, u0, params,
             config):
    """Dry + wet -> wet over the dry x wet points: dD_e = -sum w_r w_s beta x_r^e (e < 3),
    dW10 = -dD_1, dW20 = sum w_r w_s beta (x_r^2 + 2 x_r x_s), dW11 = sum w_r w_s beta x_r b_s
    (W00, W01, W02 unchanged; x_r^e: ``dry_powers``)."""
    K = m * m
    nref = params[P.NUMBER_SCALE]
    number = 0.0
    first = 0.0
    second = 0.0
    gain20 = 0.0
    gain11 = 0.0
    for r in range(2):
        wr = dry_weights[r]
        if wr == 0.0:
            continue
        xr = dry_pow[r, 1]
        xr2 = dry_pow[r, 2] if m > 2 else xr * xr
        for s in range(N_POINTS):
            ws = weights[s]
            if ws == 0.0:
                continue
            f = nref * wr * ws * pair_rate(props, DRY_ROW + r, s, factor, u0, params, config)
            number += f
            first += f * xr
            second += f * xr2
            gain20 += f * (xr2 + 2.0 * xr * mass[s])
            gain11 += f * xr * liquid[s]
    if not (number > 0.0 and first > 0.0):
        return
    out[K] -= number
    out[K + 1] -= first
    if m > 2:
        out[K + 2] -= second
    out[m] += first
    out[2 * m] += max(gain20, 0.0)
    out[m + 1] += max(gain11, 0.0)


@nb.njit(cache=True)
def _dry_capture_on_points(out, m, props, dry_pow, dry_weights, xd, xl, kd, factor, u0, params,
                           config):
    """Dry + droplet -> wet: L_e = kd sum_r w_r beta_rd x_r^e (e < 3; x_r^e: ``dry_powers``)
    leaves D_e and enters every wet row as sum_e C(i, e) x_d^(i - e) x_l^j L_e; returns L_0,
    the droplets lost."""
    K = m * m
    lost = 0.0
    for r in range(2):
        wr = dry_weights[r]
        if wr == 0.0:
            continue
        f = kd * wr * pair_rate(props, DRY_ROW + r, DROPLET_ROW, factor, u0, params, config)
        lost += f
        for e in range(min(m, DRY_POINT_ORDERS)):
            xe = dry_pow[r, e]
            out[K + e] -= f * xe
            out[e * m] += f * xe
            capture_gain(out, f * xe, e * m, m, xd, xl, 0)
    return lost


@nb.njit(cache=True)
def _wet_capture_on_points(out, m, props, mass, liquid, weights, xd, xl, kd, factor, u0, params,
                           config):
    """Wet + droplet -> wet: the wet rows of order <= 2 of (x_s + x_d)^i (b_s + x_l)^j -
    x_s^i b_s^j, kd sum_s w_s beta_sd per row; returns the droplets lost (0 where the sum is
    not positive: then nothing is added)."""
    lost = 0.0
    g20 = 0.0
    g11 = 0.0
    g02 = 0.0
    for s in range(N_POINTS):
        ws = weights[s]
        if ws == 0.0:
            continue
        f = kd * ws * pair_rate(props, s, DROPLET_ROW, factor, u0, params, config)
        lost += f
        g20 += f * (2.0 * mass[s] * xd + xd * xd)
        g11 += f * (mass[s] * xl + liquid[s] * xd + xd * xl)
        g02 += f * (2.0 * liquid[s] * xl + xl * xl)
    if not lost > 0.0:
        return 0.0
    out[m] += lost * xd
    out[1] += lost * xl
    out[2 * m] += max(g20, 0.0)
    out[m + 1] += max(g11, 0.0)
    out[2] += max(g02, 0.0)
    return lost


@nb.njit(cache=True)
def _dry_wet_every_row(out, m, props, dry_weights, weights, tab, rows, factor, u0, params,
                       config):
    """Dry + wet -> wet over the dry x wet points, every wet row: a wet row (i, j) with
    i >= 1 gains sum w_r w_s beta [(x_r + x_s)^i - x_s^i] b_s^j (its binomial terms with
    x_r^k, k >= 1), the rows i = 0 do not change; the dry rows e < DRY_POINT_ORDERS lose
    sum w_r w_s beta x_r^e (x_r^e: ``dry_powers``, rows TAB_DRY of tab). rows: K + m entries
    of scratch."""
    K = m * m
    nref = params[P.NUMBER_SCALE]
    choose = tab[TAB_CHOOSE:TAB_CHOOSE + m]
    rows[:K + m] = 0.0
    for r in range(2):
        wr = dry_weights[r]
        if wr == 0.0:
            continue
        xr = tab[TAB_DRY + r]
        for s in range(N_POINTS):
            ws = weights[s]
            if ws == 0.0:
                continue
            f = nref * wr * ws * pair_rate(props, DRY_ROW + r, s, factor, u0, params, config)
            for e in range(m):
                rows[K + e] += f * xr[e]
            for i in range(1, m):
                for k in range(1, i + 1):
                    g = f * choose[i, k] * xr[k] * tab[TAB_MASS + s, i - k]
                    for j in range(m):
                        rows[i * m + j] += g * tab[TAB_LIQUID + s, j]
    if not (rows[K] > 0.0 and rows[K + 1] > 0.0):
        return
    for e in range(min(m, DRY_POINT_ORDERS)):
        out[K + e] -= rows[K + e]
    out[m] += rows[K + 1]
    for i in range(1, m):
        for j in range(m):
            if i + j >= 2:
                out[i * m + j] += max(rows[i * m + j], 0.0)


@nb.njit(cache=True)
def _wet_capture_every_row(out, m, props, weights, tab, rows, xd, xl, kd, factor, u0, params,
                           config):
    """Wet + droplet -> wet, every wet row: (x_s + x_d)^i (b_s + x_l)^j - x_s^i b_s^j, i.e.
    sum over (a, c) other than (i, j) of C(i,a) C(j,c) x_d^(i-a) x_l^(j-c) V_ac, V_ac = kd
    sum_s w_s beta_sd x_s^a b_s^c (no term cancels); returns the droplets lost (0 where the
    sum is not positive: then nothing is added). tab: ``point_tables`` with the droplet's
    rows; rows: K entries of scratch."""
    K = m * m
    choose = tab[TAB_CHOOSE:TAB_CHOOSE + m]
    dp = tab[TAB_DROPLET_MASS]
    lp = tab[TAB_DROPLET_LIQUID]
    for a in range(K):
        rows[a] = 0.0
    lost = 0.0
    for s in range(N_POINTS):
        ws = weights[s]
        if ws == 0.0:
            continue
        f = kd * ws * pair_rate(props, s, DROPLET_ROW, factor, u0, params, config)
        lost += f
        for i in range(m):
            fx = f * tab[TAB_MASS + s, i]
            for j in range(m):
                rows[i * m + j] += fx * tab[TAB_LIQUID + s, j]
    if not lost > 0.0:
        return 0.0
    out[m] += lost * xd
    out[1] += lost * xl
    for i in range(m):
        for j in range(m):
            if i + j < 2:
                continue
            gain = 0.0
            for a in range(i + 1):
                for c in range(j + 1):
                    if a == i and c == j:
                        continue
                    gain += (choose[i, a] * choose[j, c] * dp[i - a] * lp[j - c]
                             * rows[a * m + c])
            if gain != 0.0:
                out[i * m + j] += max(gain, 0.0)
    return lost


@nb.njit(cache=True)
def add_point_terms(state, out, cell, aux, params, config, d43, nd, pd, bd, cross,
                    every_row=False):
    """Add the rows of order <= 2 of aggregation and droplet capture on the point measures
    [scaled moments per s] to ``out``; return the droplets captured [scaled per s]. state:
    scaled moments; cell: the cell's row (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s]:
    4 sqrt(Theta / pi) where not positive); d43 [m]: the cell's volume-mean diameter (the
    ktgf kernel's cell factor); nd: the free droplets [scaled]; pd, bd: one droplet's mass
    and liquid [kg]; params: the cell's params, where the integrator extends them with the
    switch memory (physics.parameters.HELD) each pair of property rows (the wet points
    0 .. N_POINTS - 1 in ``_point``'s order, the dry points DRY_ROW + r, the droplet
    DROPLET_ROW) holds its sharp Stokes decision within a step, as QMOM's nodes do.

    Always the wet-wet rows W00, W20, W11, W02 (module docstring); with ``cross`` also the
    dry-wet aggregation's wet rows of order <= 2 and dry rows D_e (e < 3) over the dry points
    x wet points, the capture of nd droplets by the dry points (its dry loss L_e, e < 3,
    mapped to every wet row as (p + p_d)^i b_d^j) and by the wet points (their wet rows of
    order <= 2), and the droplets lost. The rows left to the tensors: ``rhs.points_rows``
    and ``rhs.low_rows``."""
    m = int(aux[AUX_ORDER])
    factor = kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA], d43, params)
    if factor == 0.0:
        return 0.0
    u0 = cell[P.COLLISION_VELOCITY]
    if not u0 > 0.0:
        u0 = collision_velocity(cell[P.THETA])
    pref = params[P.MASS_SCALE]
    pts = wet_points(state, m)
    props = np.zeros((N_ROWS, N_PROPS))
    x0, b0, w0 = _point(0, pts)
    x1, b1, w1 = _point(1, pts)
    x2, b2, w2 = _point(2, pts)
    x3, b3, w3 = _point(3, pts)
    x4, b4, w4 = _point(4, pts)
    x5, b5, w5 = _point(5, pts)
    mass = (x0, x1, x2, x3, x4, x5)           # N_POINTS = 6; tuples: only props allocated
    liquid = (b0, b1, b2, b3, b4, b5)
    weights = (w0, w1, w2, w3, w4, w5)
    for q in range(N_POINTS):
        if weights[q] != 0.0:
            particle_properties(mass[q] * pref, liquid[q] * pref, params, config, props, q)
    tab = point_tables(m, mass, liquid)         # the dry points' powers go in it too
    K = m * m
    scratch = np.empty(K * K + N_POINTS * K + N_POINTS * N_POINTS + K + m)
    rates = scratch[K * K + N_POINTS * K:K * K + N_POINTS * K
                    + N_POINTS * N_POINTS].reshape((N_POINTS, N_POINTS))
    rows = scratch[K * K + N_POINTS * K + N_POINTS * N_POINTS:]
    if every_row:
        _wet_wet_every_row(out, m, props, weights, tab, rates, scratch, factor, u0, params,
                           config)
    else:
        _wet_wet(out, m, props, mass, liquid, weights, rates, factor, u0, params, config)
    if not cross:
        return 0.0
    dx1, dx2, da1, da2 = dry_points(state, m)
    dry_mass = (dx1, dx2)
    dry_weights = (da1, da2)
    for r in range(2):
        if dry_weights[r] != 0.0:
            particle_properties(dry_mass[r] * pref, 0.0, params, config, props, DRY_ROW + r)
    dry_pow = dry_powers(state, m, dry_mass, dry_weights, tab[TAB_DRY:TAB_DRY + 2])
    if every_row:
        _dry_wet_every_row(out, m, props, dry_weights, weights, tab, rows, factor, u0, params,
                           config)
    else:
        _dry_wet(out, m, props, dry_pow, dry_weights, mass, liquid, weights, factor, u0,
                 params, config)
    if not (nd > 0.0 and pd > 0.0 and config[P.SEPARATE_DROPLETS] == 1):
        return 0.0
    particle_properties(pd, bd, params, config, props, DROPLET_ROW)
    kd = params[P.NUMBER_SCALE] * nd * params[P.DROPLET_FACTOR]   # [1/s per (m3/s) of pair rate]
    xd = pd / pref
    xl = bd / pref
    lost = _dry_capture_on_points(out, m, props, dry_pow, dry_weights, xd, xl, kd, factor,
                                  u0, params, config)
    if every_row:
        for k in range(1, m):
            tab[TAB_DROPLET_MASS, k] = tab[TAB_DROPLET_MASS, k - 1] * xd
            tab[TAB_DROPLET_LIQUID, k] = tab[TAB_DROPLET_LIQUID, k - 1] * xl
        return lost + _wet_capture_every_row(out, m, props, weights, tab, rows, xd, xl, kd,
                                             factor, u0, params, config)
    return lost + _wet_capture_on_points(out, m, props, mass, liquid, weights, xd, xl, kd,
                                         factor, u0, params, config)
