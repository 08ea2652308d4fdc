"""Conditional quadrature method of moments (CQMOM) for granule mass and binder.

Transported moment set of one cell (non-dimensional: SI M_ij per m3 divided by
N_ref p_ref^(i+j), N_ref = params[NUMBER_SCALE] [1/m3], p_ref = params[MASS_SCALE] [kg]),
with N1 = config[ORDER] size nodes and N2 = config[BINDER_NODES] conditional nodes:

    [M_00, M_10, ..., M_(2N1-1)0]                pure size moments, 2 N1 entries
    [M_0l, M_1l, ..., M_(N1-1)l], l = 1..2N2-1   mixed moments, N1 entries per l (bivariate)
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

Sources are quadratures over the points of the aggregation integrals (every kernel and
efficiency), droplet capture (droplets a population of their own) and injection, with gains
written as sums of non-negative terms so that M10 and M01 get exactly nothing from aggregation.
"""
import math

import numba as nb
import numpy as np

from ..physics import parameters as P
from ..physics.efficiency import pair_success_probability
from ..physics.kernels import kernel_cell_factor, pair_collision_frequency
from ..physics.properties import DIAMETER, N_PROPS, particle_properties
from .conditional import fraction_moments, gauss_unit_interval, restore_binder_mass
from .qmom import solve_node_binder
from .quadrature import wheeler_nodes

_as_strided = np.lib.stride_tricks.as_strided

#: Re-projection mismatch of the size moments (relative to each moment) up to which a set whose
#: quadrature lost nodes is accepted as on the realizable boundary (as QMOM).
PROJECTION_TOLERANCE = 1.0e-8
MAX_SIZE_NODES = 4
MAX_BINDER_NODES = 3


def state_length(nodes, binder_nodes, bivariate, separate_droplets):
    """Number of entries of one cell's CQMOM state."""
    mixed = nodes * (2 * binder_nodes - 1) if bivariate else 0
    return 2 * nodes + mixed + (1 if separate_droplets else 0)


def state_names(nodes, binder_nodes, bivariate, separate_droplets):
    """Names of the state entries: 'M{i}{j}' in state order, then 'droplet_number_density'."""
    names = [f"M{k}0" for k in range(2 * nodes)]
    if bivariate:
        for l in range(1, 2 * binder_nodes):
            names += [f"M{k}{l}" for k in range(nodes)]
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
def _off_points(n):
    return 3 * n


@nb.njit(cache=True, inline="always")
def _off_counts(n, m):
    return 3 * n + 3 * n * m


@nb.njit(cache=True, inline="always")
def _off_cond(n, m):
    return 5 * n + 3 * n * m


@nb.njit(cache=True, inline="always")
def _off_scratch(n, m):
    return 5 * n + 5 * n * m


@nb.njit(cache=True, inline="always")
def _off_props(n, m):
    return _off_scratch(n, m) + (2 * n + 1) * (2 * n + 1) + 9 * n + n * (n + 1) + 61


@nb.njit(cache=True, inline="always")
def _off_powers(n, m):
    return _off_props(n, m) + (n * m + 1) * N_PROPS


@nb.njit(cache=True, inline="always")
def _off_bpowers(n, m):
    return _off_powers(n, m) + 2 * n * n


@nb.njit(cache=True, inline="always")
def _off_acc(n, m):
    return _off_bpowers(n, m) + 2 * n * m * m


@nb.njit(cache=True, inline="always")
def _off_target(n, m):
    return _off_acc(n, m) + 12 * m


@nb.njit(cache=True, inline="always")
def _off_cache(n, m):
    return _off_target(n, m) + 2 * n * m + n + 1


_CACHE_TAG = -3.817263512093871e-211
_CACHE_HEADER = 4


@nb.njit(cache=True)
def work_size(n, m):
    """Length of the float work array the CQMOM functions need for n size and m conditional
    nodes."""
    return _off_cache(n, m) + _CACHE_HEADER + 2 * n * m + n + 1


@nb.njit(cache=True, inline="always")
def _mixed_index(n, k, l):
    """State index of M_kl, l >= 1, k < n."""
    return 2 * n + (l - 1) * n + k


@nb.njit(cache=True, error_model="numpy")
def _points_of_nodes(n_max, m, n, work, bivariate):
    """Points of the n size nodes from their conditional fraction moments (scaled units)."""
    x = work[0:n_max]
    w = work[n_max:2 * n_max]
    op = _off_points(n_max)
    npt = n_max * m
    px = work[op:op + npt]
    pb = work[op + npt:op + 2 * npt]
    pw = work[op + 2 * npt:op + 3 * npt]
    counts = work[_off_counts(n_max, m):_off_counts(n_max, m) + n_max]
    fixed = work[_off_counts(n_max, m) + n_max:_off_counts(n_max, m) + 2 * n_max]
    oc = _off_cond(n_max, m)
    scratch = work[_off_scratch(n_max, m):_off_props(n_max, m)]
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
    scratch = work[_off_scratch(n_max, m):_off_props(n_max, m)]
    n = wheeler_nodes(state, n_max, x, w, scratch)
    for a in range(n, n_max):
        x[a] = 0.0
        w[a] = 0.0
        bbar[a] = 0.0
    counts = _off_counts(n_max, m)
    if n == 0:
        for a in range(n_max):
            work[counts + a] = 0.0
        return 0
    fixed = work[counts + n_max:counts + 2 * n_max]
    if bivariate:
        solve_node_binder(state, n_max, n, x, w, bbar, scratch)
        restore_binder_mass(state[2 * n_max], n, x, w, bbar)
        cond = work[_off_cond(n_max, m):_off_scratch(n_max, m)]
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
def _invert_work(state, config, work):
    """``invert``, remembered in ``work``: a call with a bit-identical state and configuration
    whose result entries still match their checksum reuses them (a stage's realizability check
    and its RHS invert the same state; as QMOM)."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    n_state = config[P.N_STATE]
    key = float(n_state * 100000 + n_max * 1000 + m * 10 + config[P.BIVARIATE])
    c = _off_cache(n_max, m)
    s0 = c + _CACHE_HEADER
    result = _off_scratch(n_max, m)
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
def _props_view(work, n, m):
    o = _off_props(n, m)
    rows = n * m + 1
    return _as_strided(work[o:o + rows * N_PROPS], shape=(rows, N_PROPS),
                       strides=(N_PROPS * 8, 8))


@nb.njit(cache=True, inline="always")
def _fill_properties(work, n_max, m, n, params, config):
    """Property rows of every point and the powers x_a^k (k < 2 N1), b_i^l (l < 2 N2);
    returns d43 [m] of the granules (for the ktgf kernel, else 0)."""
    op = _off_points(n_max)
    npt = n_max * m
    props = _props_view(work, n_max, m)
    xpow = _off_powers(n_max, m)
    bpow = _off_bpowers(n_max, m)
    counts = _off_counts(n_max, m)
    mass_scale = params[P.MASS_SCALE]
    ktgf = config[P.KERNEL] == 4
    num43 = 0.0
    den43 = 0.0
    for a in range(n):
        xa = work[a]
        power = 1.0
        for k in range(2 * n_max):
            work[xpow + a * 2 * n_max + k] = power
            power *= xa
        for b in range(int(work[counts + a])):
            i = a * m + b
            bi = work[op + npt + i]
            particle_properties(xa * mass_scale, bi * mass_scale, params, config, props, i)
            power = 1.0
            for l in range(2 * m):
                work[bpow + i * 2 * m + l] = power
                power *= bi
        if ktgf:
            wx = work[n_max + a] * xa
            num43 += wx * props[a * m, DIAMETER]
            den43 += wx
    return num43 / den43 if den43 > 0.0 else 0.0


@nb.njit(cache=True, error_model="numpy")
def _aggregation(out, work, n_max, m, n, factor, u0, params, config, bivariate):
    """Granule-granule aggregation over unordered pairs of points (scaled moments per s).

    Per pair of size nodes (a, c) the collision frequency (a function of the masses only) is
    evaluated once; per pair of their points the success probability. With s = x_a + x_c,
    t = b_i + b_j, the gain of M_kl is
      s^k t^l - x_a^k b_i^l - x_c^k b_j^l = x_a^k (t^l - b_i^l) + x_c^k (t^l - b_j^l) + G_k t^l,
    G_k = s^k - x_a^k - x_c^k >= 0 (k >= 1), and for k = 0: t^l - b_i^l - b_j^l; all terms are
    non-negative, the number loses exactly the pair and M10, M01 get exactly nothing.
    """
    op = _off_points(n_max)
    npt = n_max * m
    counts = _off_counts(n_max, m)
    props = _props_view(work, n_max, m)
    bpow = _off_bpowers(n_max, m)
    xpow = _off_powers(n_max, m)
    acc = _off_acc(n_max, m)
    lmax = 2 * m if bivariate else 1
    n_size = 2 * n_max
    number_scale = params[P.NUMBER_SCALE]
    code = config[P.KERNEL]
    for a in range(n):
        xa = work[a]
        for c in range(a, n):
            beta = pair_collision_frequency(code, props, a * m, c * m, factor, params)
            if beta == 0.0:
                continue
            beta *= number_scale
            xc = work[c]
            for q in range(4 * lmax):
                work[acc + q] = 0.0
            total = 0.0
            for b in range(int(work[counts + a])):
                i = a * m + b
                wi = work[op + 2 * npt + i]
                bi = work[op + npt + i]
                for d in range(b if a == c else 0, int(work[counts + c])):
                    j = c * m + d
                    rate = wi * work[op + 2 * npt + j] * beta * pair_success_probability(
                        props, i, j, u0, params, config)
                    if i == j:
                        rate *= 0.5
                    total += rate
                    if bivariate and rate != 0.0:
                        bj = work[op + npt + j]
                        t = bi + bj
                        tl = 1.0
                        ha = 0.0
                        hc = 0.0
                        g = 0.0
                        for l in range(1, lmax):
                            bil = work[bpow + i * 2 * m + l - 1]
                            bjl = work[bpow + j * 2 * m + l - 1]
                            ha = t * ha + bj * bil
                            hc = t * hc + bi * bjl
                            if l >= 2:
                                g = t * g + bj * bil + bi * bjl
                            tl *= t
                            work[acc + l] += rate * ha
                            work[acc + lmax + l] += rate * hc
                            work[acc + 2 * lmax + l] += rate * tl
                            work[acc + 3 * lmax + l] += rate * g
            if total == 0.0:
                continue
            out[0] -= total
            # size moments: G_k by G_k = s G_(k-1) + x_c x_a^(k-1) + x_a x_c^(k-1), G_1 = 0
            s = xa + xc
            g = 0.0
            for k in range(2, n_size):
                g = s * g + xc * work[xpow + a * n_size + k - 1] + xa * work[xpow + c * n_size
                                                                           + k - 1]
                out[k] += total * g
            if bivariate:
                _mixed_gains(out, work, n_max, lmax, a, c, xpow, acc)


@nb.njit(cache=True, inline="always")
def _mixed_gains(out, work, n_max, lmax, a, c, xpow, acc):
    """Add the mixed-moment gains of the size-node pair (a, c) from the accumulators of its
    point pairs (see ``_aggregation``)."""
    n_size = 2 * n_max
    xa = work[a]
    xc = work[c]
    s = xa + xc
    for l in range(2, lmax):
        out[_mixed_index(n_max, 0, l)] += work[acc + 3 * lmax + l]
    g = 0.0
    for k in range(1, n_max):
        if k >= 2:
            g = s * g + xc * work[xpow + a * n_size + k - 1] + xa * work[xpow + c * n_size + k - 1]
        xak = work[xpow + a * n_size + k]
        xck = work[xpow + c * n_size + k]
        for l in range(1, lmax):
            out[_mixed_index(n_max, k, l)] += (xak * work[acc + l] + xck * work[acc + lmax + l]
                                               + g * work[acc + 2 * lmax + l])


@nb.njit(cache=True, error_model="numpy")
def _droplet_capture(out, state, work, n_max, m, n, factor, u0, params, config, bivariate):
    """Capture of free droplets (mass x_d, pure binder) by the granule points: a granule
    (x, b) becomes (x + x_d, b + x_d), so M_kl gains
      (x + x_d)^k (b + x_d)^l - x^k b^l = H_k (b + x_d)^l + x^k ((b + x_d)^l - b^l),
    H_k = (x + x_d)^k - x^k, all terms non-negative; the droplets lose what is captured."""
    n_state = config[P.N_STATE]
    nd = state[n_state - 1]
    op = _off_points(n_max)
    npt = n_max * m
    counts = _off_counts(n_max, m)
    props = _props_view(work, n_max, m)
    xpow = _off_powers(n_max, m)
    acc = _off_acc(n_max, m)
    lmax = 2 * m if bivariate else 1
    n_size = 2 * n_max
    pd = params[P.DROPLET_MASS]
    xd = pd / params[P.MASS_SCALE]
    drop = n_max * m
    particle_properties(pd, pd, params, config, props, drop)
    droplet_factor = params[P.NUMBER_SCALE] * params[P.DROPLET_FACTOR]
    code = config[P.KERNEL]
    captured = 0.0
    for a in range(n):
        beta = pair_collision_frequency(code, props, a * m, drop, factor, params)
        if beta == 0.0:
            continue
        beta *= droplet_factor * nd
        for q in range(2 * lmax):
            work[acc + 8 * m + q] = 0.0
        flux_a = 0.0
        for b in range(int(work[counts + a])):
            i = a * m + b
            flux = work[op + 2 * npt + i] * beta * pair_success_probability(props, i, drop, u0,
                                                                             params, config)
            flux_a += flux
            if bivariate:
                bi = work[op + npt + i]
                sb = bi + xd
                h = 0.0
                total = 1.0
                bl = 1.0
                for l in range(1, lmax):
                    h = sb * h + xd * bl          # (b + x_d)^l - b^l
                    bl *= bi
                    total *= sb                   # (b + x_d)^l
                    work[acc + 8 * m + l] += flux * total
                    work[acc + 8 * m + lmax + l] += flux * h
        captured += flux_a
        xa = work[a]
        s = xa + xd
        h = 0.0
        for k in range(1, n_size):
            h = s * h + xd * work[xpow + a * n_size + k - 1]
            out[k] += flux_a * h
            if bivariate and k < n_max:
                for l in range(1, lmax):
                    out[_mixed_index(n_max, k, l)] += (h * work[acc + 8 * m + l]
                                                       + work[xpow + a * n_size + k]
                                                       * work[acc + 8 * m + lmax + l])
        if bivariate:
            for l in range(1, lmax):
                out[_mixed_index(n_max, 0, l)] += work[acc + 8 * m + lmax + l]
    out[n_state - 1] -= captured


@nb.njit(cache=True, error_model="numpy")
def cqmom_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt of one cell [scaled moments per s] (layout in the module docstring).

    cell: (alpha [-], theta [m2/s2], collision velocity [m/s], injection [droplets/(m3 s)]);
    work: float array of at least ``work_size(N1, N2)``. No allocation.
    """
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    bivariate = config[P.BIVARIATE] == 1
    separate = config[P.SEPARATE_DROPLETS] == 1
    n_state = config[P.N_STATE]
    for k in range(n_state):
        out[k] = 0.0
    n = _invert_work(state, config, work)
    u0 = cell[P.COLLISION_VELOCITY]
    factor = 0.0
    if n > 0:
        d43 = _fill_properties(work, n_max, m, n, params, config)
        factor = kernel_cell_factor(config[P.KERNEL], cell[P.ALPHA], cell[P.THETA], d43, params)
    if factor != 0.0:
        _aggregation(out, work, n_max, m, n, factor, u0, params, config, bivariate)
    # breakage (issue 16) adds its birth and death terms here: a quadrature over the same
    # points (work[_off_points:]) with the daughter moments of each broken point.
    inj = cell[P.INJECTION] / params[P.NUMBER_SCALE]
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    if separate:
        if state[n_state - 1] > 0.0 and factor != 0.0 and n > 0:
            _droplet_capture(out, state, work, n_max, m, n, factor, u0, params, config,
                             bivariate)
        out[n_state - 1] += inj
    elif inj != 0.0:
        # droplets as ordinary particles: S_kl = rate x_d^(k + l)
        value = inj
        for k in range(2 * n_max):
            out[k] += value
            value *= xd
        if bivariate:
            for l in range(1, 2 * m):
                value = inj * xd ** l
                for k in range(n_max):
                    out[_mixed_index(n_max, k, l)] += value
                    value *= xd


@nb.njit(cache=True, error_model="numpy")
def _project_into(state, target, config, work, n):
    """Moments of the points of the last inversion (n size nodes) into target[0:n_state]."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    n_state = config[P.N_STATE]
    op = _off_points(n_max)
    npt = n_max * m
    counts = _off_counts(n_max, m)
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
                    target[_mixed_index(n_max, k, l)] += power
                    power *= work[a]
    if config[P.SEPARATE_DROPLETS] == 1:
        target[n_state - 1] = state[n_state - 1]


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
    if state[0] == 0.0:
        for k in range(n_state - separate):
            if state[k] != 0.0:
                return False
        return True
    if state[0] < 0.0:
        return False
    n = _invert_work(state, config, work)
    if n == 0:
        return False
    if n < n_max:
        ot = _off_target(n_max, m)
        target = work[ot:ot + n_state]
        _project_into(state, target, config, work, n)
        for k in range(2 * n_max):
            if abs(target[k] - state[k]) > PROJECTION_TOLERANCE * abs(state[k]):
                return False
    if config[P.BIVARIATE] == 1:
        for l in range(1, 2 * m):
            for k in range(n_max):
                value = state[_mixed_index(n_max, k, l)]
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
    n = _invert_work(state, config, work)
    ot = _off_target(n_max, m)
    target = work[ot:ot + n_state]
    _project_into(state, target, config, work, n)
    worst = 0.0
    for l in range(1, 2 * m):
        for k in range(n_max):
            bound = 0.0
            for a in range(n):
                bound += work[n_max + a] * work[a] ** (k + l)
            i = _mixed_index(n_max, k, l)
            if bound > 0.0:
                worst = max(worst, abs(target[i] - state[i]) / bound)
    return worst


@nb.njit(cache=True, error_model="numpy")
def cqmom_project(state, aux, params, config, work):
    """Re-project an accepted state, in place, as QMOM does: where size nodes were lost, every
    moment but M00, M10 and M01 becomes that of the points; otherwise the binder-weighted
    moments M_k1 (k >= 1) become those of the bounded per-node binder (with N2 = 1 this is
    QMOM's projection exactly). Number, mass and binder mass are never touched.

    The higher mixed moments M_kl, l >= 2, stay as carried: the points are the nearest
    realizable reading of them. Snapping them onto the points after every step biases them,
    because the conditional sets that are not realizable are mostly negative variances and
    clipping those only ever adds variance: measured on the seed scenario with N1 = N2 = 2,
    M02 +47% against the cNMC after 10 s with that projection, within 0.5% without it.
    """
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    if state[0] <= 0.0:
        return
    n = _invert_work(state, config, work)
    if n == 0:
        return
    bivariate = config[P.BIVARIATE] == 1
    if n == n_max and not bivariate:
        return
    ot = _off_target(n_max, m)
    target = work[ot:ot + n_state]
    _project_into(state, target, config, work, n)
    m01 = 2 * n_max
    if n < n_max:
        for k in range(2, n_state - config[P.SEPARATE_DROPLETS]):
            if k != m01:
                state[k] = target[k]
    else:
        for k in range(1, n_max):
            state[m01 + k] = target[m01 + k]


def quadrature_of(state, config):
    """Points of one cell's state: masses, weights and binder masses (scaled units, numpy
    arrays, binder within [0, mass]); Python helper for outputs and tests."""
    n_max = int(config[P.ORDER])
    m = int(config[P.BINDER_NODES])
    work = np.zeros(work_size(n_max, m))
    n = invert(np.ascontiguousarray(state, dtype=np.float64), config, work)
    op = 3 * n_max
    npt = n_max * m
    counts = work[_off_counts(n_max, m):_off_counts(n_max, m) + n_max].astype(int)
    pick = [a * m + b for a in range(n) for b in range(counts[a])]
    x = work[op:op + npt][pick]
    b = work[op + npt:op + 2 * npt][pick]
    w = work[op + 2 * npt:op + 3 * npt][pick]
    return x, w, np.clip(b, 0.0, x)
