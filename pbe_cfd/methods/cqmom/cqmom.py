"""Conditional quadrature method of moments (CQMOM) for granule mass and binder.

Transported moment set of one cell (non-dimensional: SI M_ij per m3 divided by
N_ref p_ref^(i+j), N_ref = params[NUMBER_SCALE] [1/m3], p_ref = params[MASS_SCALE] [kg]),
with N1 = config[ORDER] size nodes and N2 = config[BINDER_NODES] conditional nodes:

    [M_00, M_10, ..., M_(2N1-1)0]                pure size moments, 2 N1 entries
    [M_0l, M_1l, ..., M_(N1-1)l], l = 1..2N2-1   mixed moments, N1 entries per l (bivariate)
    [E]                                          evaporated liquid (only with drying)
    [n_d]                                        free droplets (only with separate droplets)

N1 (2 N2 + 1) moments in all; with N2 = 1 this is exactly the QMOM state (and method).

Inversion (Yuan and Fox 2011): the Gauss rule of the size moments (Wheeler, Golub-Welsch; as
QMOM) gives masses p_a and weights w_a; the bounded binder solve of QMOM gives each node's mean
binder <b>_a in [0, p_a] reproducing M01 exactly; the Vandermonde solve of M_kl, k < N1, gives
the conditional moments <b^l>_a, l < 2 N2; per node the binder fraction y = b/p has the
conditional moments <y^l>_a = <b^l>_a / p_a^l, and their Gauss rule on [0, 1]
(``conditional.gauss_unit_interval``) gives N2 fractions y_ab with weights r_ab. The population
is the N1 N2 points (p_a, b_ab = y_ab p_a) with weights w_a r_ab. The conditional variable is
the fraction, not b itself, because its support [0, 1] is bounded and the same at every node:
b <= p holds at every point by construction, and a conditional set that is not realizable is
projected onto the nearest realizable one (an atom on 0 or 1, or fewer nodes) instead of failing.

Sources (``methods.cqmom_sources``) are quadratures over the points of the aggregation
integrals (every kernel and efficiency), droplet capture (droplets a population of their own),
injection and breakage (``physics.breakage``: selection at the node's mass, the daughter
rule's moment factors), with gains written as sums of non-negative terms so that M10 and M01
get exactly nothing from aggregation and breakage.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid_entry
from ...physics.properties import N_PROPS
from .conditional import fraction_moments, gauss_unit_interval, restore_binder_mass
from ..qmom.qmom import qmom_conserved
from ..quadrature.binder import solve_node_binder
from ..quadrature.drying_sources import tail_entries
from ..quadrature.gauss import wheeler_nodes

_as_strided = np.lib.stride_tricks.as_strided

#: Re-projection mismatch of the size moments (relative to each moment) up to which a set whose
#: quadrature lost nodes is accepted as on the realizable boundary (as QMOM).
PROJECTION_TOLERANCE = 1.0e-8
MAX_SIZE_NODES = 4
MAX_BINDER_NODES = 3


def state_length(nodes, binder_nodes, bivariate, separate_droplets, drying=False):
    """Number of entries of one cell's CQMOM state."""
    mixed = nodes * (2 * binder_nodes - 1) if bivariate else 0
    return (2 * nodes + mixed + (1 if drying else 0) + (1 if separate_droplets else 0)
            + (1 if drying and separate_droplets else 0))


def state_names(nodes, binder_nodes, bivariate, separate_droplets, drying=False):
    """Names of the state entries: 'M{i}{j}' in state order, 'droplet_liquid' (drying with
    separate droplets), 'evaporated_liquid' (with drying: the liquid evaporated so far, scaled
    as a mass moment, as QMOM), then 'droplet_number_density'."""
    names = [f"M{k}0" for k in range(2 * nodes)]
    if bivariate:
        for l in range(1, 2 * binder_nodes):
            names += [f"M{k}{l}" for k in range(nodes)]
    if drying and separate_droplets:
        names.append("droplet_liquid")
    if drying:
        names.append("evaporated_liquid")
    if separate_droplets:
        names.append("droplet_number_density")
    return names


# ---- work layout (flat offsets; n size nodes, m conditional nodes, np = n m points) ---------
# [0, n) size nodes x_a   [n, 2n) weights w_a   [2n, 3n) mean binder <b>_a
# [3n, 3n + 3np) points: masses, binder masses, weights (point a m + b)
# then n counts of points per size node, n flags (node fixed on a bound), 2 n m fraction moments
# then scratch; property rows (np + 1 rows, the last the droplet); powers x_a^k (n x 2n) and
# b_i^l (np x 2m); 6 x 2m accumulators; the projection target; the inversion memo.
@nb.njit(cache=True, inline="always")
def off_points(n):
    return 3 * n


@nb.njit(cache=True, inline="always")
def off_counts(n, m):
    return 3 * n + 3 * n * m


@nb.njit(cache=True, inline="always")
def off_cond(n, m):
    return 5 * n + 3 * n * m


@nb.njit(cache=True, inline="always")
def off_scratch(n, m):
    return 5 * n + 5 * n * m


@nb.njit(cache=True, inline="always")
def off_props(n, m):
    return off_scratch(n, m) + (2 * n + 1) * (2 * n + 1) + 9 * n + n * (n + 1) + 61


@nb.njit(cache=True, inline="always")
def off_powers(n, m):
    return off_props(n, m) + (n * m + 1) * N_PROPS


@nb.njit(cache=True, inline="always")
def off_bpowers(n, m):
    return off_powers(n, m) + 2 * n * n


@nb.njit(cache=True, inline="always")
def off_acc(n, m):
    return off_bpowers(n, m) + 2 * n * m * m


@nb.njit(cache=True, inline="always")
def off_target(n, m):
    return off_acc(n, m) + 12 * m


@nb.njit(cache=True, inline="always")
def off_cache(n, m):
    return off_target(n, m) + 2 * n * m + n + 1


_CACHE_TAG = -3.817263512093871e-211
_CACHE_HEADER = 4


@nb.njit(cache=True)
def work_size(n, m):
    """Length of the float work array the CQMOM functions need for n size and m conditional
    nodes."""
    return off_cache(n, m) + _CACHE_HEADER + 2 * n * m + n + 1


@nb.njit(cache=True, inline="always")
def mixed_index(n, k, l):
    """State index of M_kl, l >= 1, k < n."""
    return 2 * n + (l - 1) * n + k


@nb.njit(cache=True, inline="always")
def _sort_points(ys, rs, cnt):
    """Order the conditional points of one size node by binder fraction (insertion sort of
    ys with their weights rs): a point keeps its place, and its row, however the conditional
    inversion lists them (interior and boundary points come in either order)."""
    for i in range(1, cnt):
        y = ys[i]
        r = rs[i]
        j = i - 1
        while j >= 0 and ys[j] > y:
            ys[j + 1] = ys[j]
            rs[j + 1] = rs[j]
            j -= 1
        ys[j + 1] = y
        rs[j + 1] = r


@nb.njit(cache=True, error_model="numpy")
def _points_of_nodes(n_max, m, n, work, bivariate):
    """Points of the n size nodes from their conditional fraction moments (scaled units)."""
    x = work[0:n_max]
    w = work[n_max:2 * n_max]
    op = off_points(n_max)
    npt = n_max * m
    px = work[op:op + npt]
    pb = work[op + npt:op + 2 * npt]
    pw = work[op + 2 * npt:op + 3 * npt]
    counts = work[off_counts(n_max, m):off_counts(n_max, m) + n_max]
    fixed = work[off_counts(n_max, m) + n_max:off_counts(n_max, m) + 2 * n_max]
    oc = off_cond(n_max, m)
    scratch = work[off_scratch(n_max, m):off_props(n_max, m)]
    ys = scratch[0:3]
    rs = scratch[3:6]
    gw = scratch[6:]
    for a in range(n):
        base = a * m
        if not bivariate:
            cnt = 1
            ys[0] = 0.0
            rs[0] = 1.0
        elif fixed[a] != 0.0 or m == 1:
            cnt = 1
            ys[0] = min(max(work[oc + a * 2 * m + 1], 0.0), 1.0)
            rs[0] = 1.0
        else:
            cnt = gauss_unit_interval(work[oc + a * 2 * m:oc + (a + 1) * 2 * m], m, ys, rs, gw)
            _sort_points(ys, rs, cnt)
        counts[a] = cnt
        for b in range(cnt):
            px[base + b] = x[a]
            pb[base + b] = ys[b] * x[a]
            pw[base + b] = w[a] * rs[b]
        for b in range(cnt, m):
            px[base + b] = 0.0
            pb[base + b] = 0.0
            pw[base + b] = 0.0
    for a in range(n, n_max):
        counts[a] = 0.0


@nb.njit(cache=True, error_model="numpy")
def invert(state, config, work):
    """CQMOM inversion of one cell's state into the front of ``work`` (see the layout above):
    size nodes, weights, mean binder per node, and the points (mass, binder, weight; scaled)
    with their count per size node. Returns the number of size nodes (0: empty cell).

    Fewer size nodes than config[ORDER] mean a degenerate or non-realizable size set; fewer or
    boundary conditional points a degenerate or non-realizable conditional set; whether the
    state is reproduced is for the caller to check (``cqmom_realizable``)."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    bivariate = config[P.BIVARIATE] == 1
    x = work[0:n_max]
    w = work[n_max:2 * n_max]
    bbar = work[2 * n_max:3 * n_max]
    scratch = work[off_scratch(n_max, m):off_props(n_max, m)]
    n = wheeler_nodes(state, n_max, x, w, scratch)
    for a in range(n, n_max):
        x[a] = 0.0
        w[a] = 0.0
        bbar[a] = 0.0
    counts = off_counts(n_max, m)
    if n == 0:
        for a in range(n_max):
            work[counts + a] = 0.0
        return 0
    fixed = work[counts + n_max:counts + 2 * n_max]
    if bivariate:
        solve_node_binder(state, n_max, n, x, w, bbar, scratch)
        restore_binder_mass(state[2 * n_max], n, x, w, bbar)
        cond = work[off_cond(n_max, m):off_scratch(n_max, m)]
        fraction_moments(state, 2 * n_max, n_max, n, x, w, bbar, m, cond, fixed, scratch)
    else:
        for a in range(n):
            bbar[a] = 0.0
            fixed[a] = 1.0
    _points_of_nodes(n_max, m, n, work, bivariate)
    return n


@nb.njit(cache=True, inline="always")
def _checksum(work, count):
    total = 0.0
    for i in range(count):
        total += work[i] * (i + 1.5)
    return total


@nb.njit(cache=True, error_model="numpy")
def invert_cached(state, config, work):
    """``invert``, remembered in ``work``: a call with a bit-identical state and configuration
    whose result entries still match their checksum reuses them (a stage's realizability check
    and its RHS invert the same state; as QMOM)."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    n_state = config[P.N_STATE]
    key = float(n_state * 100000 + n_max * 1000 + m * 10 + config[P.BIVARIATE])
    c = off_cache(n_max, m)
    s0 = c + _CACHE_HEADER
    result = off_scratch(n_max, m)
    if work[c] == _CACHE_TAG and work[c + 1] == key:
        same = True
        for k in range(n_state):
            if work[s0 + k] != state[k]:
                same = False
                break
        if same and work[c + 3] == _checksum(work, result):
            return int(work[c + 2])
    n = invert(state, config, work)
    work[c] = _CACHE_TAG
    work[c + 1] = key
    work[c + 2] = n
    work[c + 3] = _checksum(work, result)
    for k in range(n_state):
        work[s0 + k] = state[k]
    return n


@nb.njit(cache=True, inline="always")
def props_view(work, n, m):
    o = off_props(n, m)
    rows = n * m + 1
    return _as_strided(work[o:o + rows * N_PROPS], shape=(rows, N_PROPS),
                       strides=(N_PROPS * 8, 8))


@nb.njit(cache=True, error_model="numpy")
def _project_into(state, target, config, work, n):
    """Moments of the points of the last inversion (n size nodes) into target[0:n_state]."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    n_state = config[P.N_STATE]
    op = off_points(n_max)
    npt = n_max * m
    counts = off_counts(n_max, m)
    for k in range(n_state):
        target[k] = 0.0
    lmax = 2 * m if config[P.BIVARIATE] == 1 else 1
    for a in range(n):
        power = work[n_max + a]
        for k in range(2 * n_max):
            target[k] += power
            power *= work[a]
        for b in range(int(work[counts + a])):
            i = a * m + b
            bi = work[op + npt + i]
            bl = work[op + 2 * npt + i]
            for l in range(1, lmax):
                bl *= bi
                power = bl
                for k in range(n_max):
                    target[mixed_index(n_max, k, l)] += power
                    power *= work[a]
    for k in range(n_state - tail_entries(config), n_state):
        target[k] = state[k]         # the droplets' and the evaporated liquid, the droplets


@nb.njit(cache=True)
def cqmom_conserved(config, params, pivots, coefs):
    """Linear invariants of the CQMOM state for the time integrator (granule mass M10, binder
    mass M01, each plus the free droplets' mass): the QMOM ones, since both states hold M10 at
    entry 1, M01 at entry 2 N1 (``mixed_index(N1, 0, 1)``) and the droplets last. Returns the
    number of invariants."""
    return qmom_conserved(config, params, pivots, coefs)


@nb.njit(cache=True, error_model="numpy")
def cqmom_realizable(state, aux, params, config, work):
    """True if the cell's state is a realizable moment set for CQMOM.

    Checks finiteness, non-negative number and droplets; the size moments as QMOM (a reduced
    quadrature must reproduce the discarded moments within PROJECTION_TOLERANCE); and the
    conditions every population with 0 <= b <= p meets: M_kl >= 0 and, where M_(k+l)0 is
    carried, M_kl <= M_(k+l)0 (for M01: the binder mass within the granule mass).

    Conditional moments recovered from the moments of a general population are often not
    realizable (measured: 70-80% of random populations of 1-14 atoms); that is the closure's
    gap, not a broken state: the inversion uses the nearest realizable conditional set and the
    accepted state is projected onto it (``cqmom_project``). Rejecting such states instead would
    tie the step to the projection tolerance (measured on the seed scenario: 52,000 steps with
    120,000 rejections instead of 1,700 steps, the same moments). An all-zero (empty) state is
    realizable.
    """
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    separate = config[P.SEPARATE_DROPLETS]
    for k in range(n_state):
        if not math.isfinite(state[k]):
            return False
    if separate == 1 and state[n_state - 1] < 0.0:
        return False
    if config[P.DRYING] == 1 and state[n_state - 1 - separate] < 0.0:
        return False
    if droplet_liquid_entry(config) >= 0 and state[droplet_liquid_entry(config)] < 0.0:
        return False
    if state[0] == 0.0:
        for k in range(n_state - tail_entries(config)):
            if state[k] != 0.0:
                return False
        return True
    if state[0] < 0.0:
        return False
    n = invert_cached(state, config, work)
    if n == 0:
        return False
    if n < n_max:
        ot = off_target(n_max, m)
        target = work[ot:ot + n_state]
        _project_into(state, target, config, work, n)
        for k in range(2 * n_max):
            if abs(target[k] - state[k]) > PROJECTION_TOLERANCE * abs(state[k]):
                return False
    if config[P.BIVARIATE] == 1:
        for l in range(1, 2 * m):
            for k in range(n_max):
                value = state[mixed_index(n_max, k, l)]
                if value < 0.0:
                    return False
                if k + l < 2 * n_max and value > state[k + l] * (1.0 + PROJECTION_TOLERANCE):
                    return False
    return True


@nb.njit(cache=True, error_model="numpy")
def representation_error(state, config, work):
    """Largest mismatch |M_kl(points) - M_kl| / sum_a w_a p_a^(k+l) over the mixed moments,
    l >= 1 [-]: 0 (to round-off) for a state the points represent, e.g. after
    ``cqmom_project``; how far the conditional moments were from realizable otherwise."""
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    if state[0] <= 0.0 or config[P.BIVARIATE] != 1:
        return 0.0
    n = invert_cached(state, config, work)
    ot = off_target(n_max, m)
    target = work[ot:ot + n_state]
    _project_into(state, target, config, work, n)
    worst = 0.0
    for l in range(1, 2 * m):
        for k in range(n_max):
            bound = 0.0
            for a in range(n):
                bound += work[n_max + a] * work[a] ** (k + l)
            i = mixed_index(n_max, k, l)
            if bound > 0.0:
                worst = max(worst, abs(target[i] - state[i]) / bound)
    return worst


@nb.njit(cache=True, error_model="numpy")
def cqmom_project(state, aux, params, config, work):
    """Re-project an accepted state, in place, where its size quadrature lost nodes (as QMOM
    does): every moment but M00, M10, M01 (and the droplets) becomes that of the points.
    Number, mass and binder mass are never touched.

    With every size node present the mixed moments stay as carried: the points are the
    nearest realizable reading of them. Snapping them onto the points after every step biases
    them: the conditional sets that are not realizable are mostly negative variances, and
    clipping those only ever adds variance (measured on the seed scenario, N1 = N2 = 2: M02
    +47% against the cNMC after 10 s with that projection, within 0.5% without); and where
    the bounded per-node binder clips a node (droplets as ordinary particles next to dry
    granules), projecting M_k1 onto it loses the exact M11 of the constant kernel (measured on
    study-analytic, N1 = N2 = 2: 33% off; carried, it stays exact).
    """
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    if state[0] <= 0.0:
        return
    n = invert_cached(state, config, work)
    if n == 0 or n == n_max:
        return
    ot = off_target(n_max, m)
    target = work[ot:ot + n_state]
    _project_into(state, target, config, work, n)
    m01 = 2 * n_max
    for k in range(2, n_state - tail_entries(config)):
        if k != m01:
            state[k] = target[k]


def quadrature_of(state, config):
    """Points of one cell's state: masses, weights and binder masses (scaled units, numpy
    arrays, binder within [0, mass]); Python helper for outputs and tests."""
    n_max = int(config[P.ORDER])
    m = int(config[P.BINDER_NODES])
    work = np.zeros(work_size(n_max, m))
    n = invert(np.ascontiguousarray(state, dtype=np.float64), config, work)
    op = 3 * n_max
    npt = n_max * m
    counts = work[off_counts(n_max, m):off_counts(n_max, m) + n_max].astype(int)
    pick = [a * m + b for a in range(n) for b in range(counts[a])]
    x = work[op:op + npt][pick]
    b = work[op + npt:op + 2 * npt][pick]
    w = work[op + 2 * npt:op + 3 * npt][pick]
    return x, w, np.clip(b, 0.0, x)
