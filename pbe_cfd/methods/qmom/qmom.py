"""Quadrature method of moments with node-wise binder (docs/physics.md section 9).

State of one cell (non-dimensional: SI moment M_ij per m3 divided by N_ref p_ref^(i+j), with
N_ref = params[NUMBER_SCALE] [1/m3] and p_ref = params[MASS_SCALE] [kg] for both masses):

    [M_00, M_10, ..., M_(2N-1)0]                 size moments, 2N entries
    [M_01, M_11, ..., M_(N-1)1]                  binder-weighted moments (bivariate only), N entries
    [L_d]                                        free droplets' liquid (drying, separate droplets)
    [E]                                          evaporated liquid (drying)
    [n_d]                                        free droplets (only with separate droplets)

The N-node quadrature (Wheeler, Golub-Welsch) of the size moments gives masses p_a and weights
w_a; the binder moments M_k1 = sum_a w_a p_a^k b_a, k < N, give one binder mass b_a per node.
Moment sources are quadratures of the aggregation integrals over the nodes (and the droplets),
and of the breakage integrals (``methods.breakage_sources``) where the scene asks for them.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.drying import cell_gas
from ...physics.injection import droplet_liquid, droplet_liquid_entry
from ...physics.kernels import kernel_cell_factor, kernel_uses_d43
from ...physics.properties import DIAMETER, N_PROPS
from ...physics.rates import pair_rate, particle_properties
from ..quadrature.aggregation_sources import add_pair_sources
from ..quadrature.breakage_sources import add_qmom_breakage
from ..quadrature.drying_sources import (add_droplet_class_terms, add_qmom_drying,
                                         droplet_point, set_droplet_invariants, tail_entries)
from ..quadrature.binder import binder_within_mass, solve_node_binder
from ..quadrature.gauss import wheeler_nodes

_as_strided = np.lib.stride_tricks.as_strided

#: Re-projection mismatch (relative to each moment's size) up to which a moment set whose
#: quadrature lost nodes is still accepted as (numerically) on the realizable boundary.
PROJECTION_TOLERANCE = 1.0e-8
#: Binder moments M_k1 of a state on the closure (``qmom_on_closure``) are reproduced by the
#: clipped per-node binder within this share of their bound M_(k+1)0 (b <= p). The per-node
#: binder solve is a Vandermonde system whose conditioning follows the spread of the weights:
#: a node carrying 1e-11 of the number (a few early aggregates among droplets) has its binder
#: fixed by the moments only to ~1e-6 of M_k1, so a tighter test would send states that are on
#: the closure up to integration error to the projection.
BINDER_TOLERANCE = 1.0e-6



def state_length(nodes, bivariate, separate_droplets, drying=False):
    """Number of entries of one cell's QMOM state."""
    return (2 * nodes + (nodes if bivariate else 0) + (1 if drying else 0)
            + (1 if separate_droplets else 0) + (1 if drying and separate_droplets else 0))


def state_names(nodes, bivariate, separate_droplets, drying=False):
    """Names of the state entries: moment names 'M{i}{j}', 'droplet_liquid' (with drying and
    separate droplets: the free droplets' liquid, scaled as a mass moment), 'evaporated_liquid'
    (with drying: the liquid evaporated so far, scaled as a mass moment), then
    'droplet_number_density'."""
    names = [f"M{k}0" for k in range(2 * nodes)]
    if bivariate:
        names += [f"M{k}1" for k in range(nodes)]
    if drying and separate_droplets:
        names.append("droplet_liquid")
    if drying:
        names.append("evaporated_liquid")
    if separate_droplets:
        names.append("droplet_number_density")
    return names


@nb.njit(cache=True)
def work_size(n_max):
    """Length of the float work array the QMOM functions need for n_max nodes."""
    return _off_cache(n_max) + _CACHE_HEADER + 3 * n_max + 2


# ---- work layout (flat offsets; no reshape in the per-call path) -----------------------------
# [0, 3n)                  nodes, weights, binder per node (scaled units)
# [3n, 3n + W)             scratch of the Wheeler recurrence and the binder solve,
#                          W = (2n + 1)^2 + 4n
# then (n + 1) * N_PROPS   property rows of the nodes and the droplet (row n)
# then 3n + 2              moments of the quadrature (re-projection target)
# then 5 + n_state         inversion memo: tag, key, node count, checksum of the first 3n
#                          entries, and the state they are the quadrature of (see _invert_work)
@nb.njit(cache=True, inline="always")
def _off_scratch(n_max):
    return 3 * n_max


@nb.njit(cache=True, inline="always")
def _off_props(n_max):
    return 3 * n_max + (2 * n_max + 1) * (2 * n_max + 1) + 4 * n_max


@nb.njit(cache=True, inline="always")
def _off_target(n_max):
    return _off_props(n_max) + (n_max + 1) * N_PROPS


@nb.njit(cache=True, inline="always")
def _off_cache(n_max):
    return _off_target(n_max) + 3 * n_max + 2


#: marks a valid inversion memo in the work array (an arbitrary, unlikely bit pattern)
_CACHE_TAG = -7.291038457712983e-217
_CACHE_HEADER = 4


@nb.njit(cache=True, error_model="numpy")
def invert(state, config, nodes, weights, binder, work):
    """Quadrature of one cell's state: fills nodes (scaled mass), weights (scaled number) and
    binder (scaled binder mass per node, within [0, node mass]); returns the node count (0 for
    an empty cell).

    A node count below config[ORDER] means the size moments were degenerate or not realizable;
    whether the binder moments are reproduced is for the caller to check (re-projection).
    """
    n_max = config[P.ORDER]
    n_eff = wheeler_nodes(state, n_max, nodes, weights, work)
    for a in range(n_eff, n_max):
        nodes[a] = 0.0
        weights[a] = 0.0
        binder[a] = 0.0
    if n_eff == 0:
        return 0
    if config[P.BIVARIATE] == 1:
        solve_node_binder(state, n_max, n_eff, nodes, weights, binder, work)
    else:
        for a in range(n_eff):
            binder[a] = 0.0
    return n_eff


@nb.njit(cache=True, inline="always")
def _checksum(work, count):
    total = 0.0
    for i in range(count):
        total += work[i] * (i + 1.5)
    return total


@nb.njit(cache=True, error_model="numpy")
def _invert_work(state, config, work):
    """``invert`` into the fixed slots of ``work`` (nodes, weights, binder at the front),
    remembered: the integrator checks a stage for realizability and then evaluates its RHS, two
    inversions of the same state. The memo after the last inversion into ``work`` holds the
    configuration key, the node count, a checksum of the 3 n_max result entries and a copy of
    the state; a call with a bit-identical state and key whose result entries still match the
    checksum reuses them (any other call inverts and overwrites the memo). The check makes
    reuse safe whatever ``work`` held before (it is allocated uninitialised)."""
    n_max = config[P.ORDER]
    n_state = config[P.N_STATE]
    key = float(n_state * 1000 + n_max * 10 + config[P.BIVARIATE])
    c = _off_cache(n_max)
    s0 = c + _CACHE_HEADER
    if work[c] == _CACHE_TAG and work[c + 1] == key:
        same = True
        for k in range(n_state):
            if work[s0 + k] != state[k]:
                same = False
                break
        if same and work[c + 3] == _checksum(work, 3 * n_max):
            return int(work[c + 2])
    o = _off_scratch(n_max)
    n = invert(state, config, work[0:n_max], work[n_max:2 * n_max],
               work[2 * n_max:3 * n_max], work[o:_off_props(n_max)])
    work[c] = _CACHE_TAG
    work[c + 1] = key
    work[c + 2] = n
    work[c + 3] = _checksum(work, 3 * n_max)
    for k in range(n_state):
        work[s0 + k] = state[k]
    return n


@nb.njit(cache=True, inline="always")
def _props_view(work, n_max):
    """The property rows of ``work`` as a 2-D (n_max + 1, N_PROPS) view (no reshape cost)."""
    o = _off_props(n_max)
    return _as_strided(work[o:o + (n_max + 1) * N_PROPS], shape=(n_max + 1, N_PROPS),
                       strides=(N_PROPS * 8, 8))


@nb.njit(cache=True, error_model="numpy", inline="always")
def _droplet_sources(state, out, cell, params, config, nodes, weights, binder, props, n, factor,
                     u0):
    """Add the droplet terms of qmom_rhs to ``out``: with separate droplets their capture by
    the n nodes (property rows ``props``, the droplet in row n_max) and their injection into
    the droplet count, otherwise the injection of droplets as ordinary particles (scaled
    moments per s)."""
    n_max = config[P.ORDER]
    bivariate = config[P.BIVARIATE] == 1
    n_state = config[P.N_STATE]
    n_size = 2 * n_max
    number_scale = params[P.NUMBER_SCALE]
    mass_scale = params[P.MASS_SCALE]
    inj = cell[P.INJECTION] / number_scale
    pd, bd = droplet_point(state, params, config)   # one droplet now (p_d, b_d: fresh)
    xd = pd / mass_scale
    xl = bd / mass_scale                          # the droplet's liquid (xl = xd: pure)
    if config[P.SEPARATE_DROPLETS] == 1:
        nd = state[n_state - 1]
        captured = 0.0
        if (nd > 0.0 and factor != 0.0 and n > 0
                and (pd > 0.0 or droplet_liquid_entry(config) < 0)):
            particle_properties(pd, bd, params, config, props, n_max)
            droplet_factor = number_scale * params[P.DROPLET_FACTOR]
            for a in range(n):
                rate = droplet_factor * pair_rate(props, a, n_max, factor, u0, params, config)
                flux = nd * weights[a] * rate
                captured += flux
                xa = nodes[a]
                s = xa + xd
                # H_k = (x_a + x_d)^k - x_a^k
                h = 0.0
                pa = 1.0
                for k in range(1, n_size):
                    h = s * h + xd * pa
                    pa *= xa
                    out[k] += flux * h
                if bivariate:
                    ba = binder[a]
                    h = 0.0
                    pa = 1.0
                    total = 1.0     # (x + xd)^k, built up from k = 0
                    for k in range(n_max):
                        # (x+xd)^k (b + xl) - x^k b = b H_k + xl (x + xd)^k
                        out[n_size + k] += flux * (ba * h + xl * total)
                        h = s * h + xd * pa
                        pa *= xa
                        total *= s
            out[n_state - 1] -= captured
        out[n_state - 1] += inj
        add_droplet_class_terms(state, out, inj, captured, xl,
                                cell_gas(cell, params, config), params, config)
    elif inj != 0.0:
        value = inj
        for k in range(n_size):
            out[k] += value
            if bivariate and k < n_max:
                out[n_size + k] += value * xl
            value *= xd


@nb.njit(cache=True, error_model="numpy")
def qmom_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt of one cell [scaled moments per s] (see module docstring for the layout).

    cell: (alpha [-], theta [m2/s2], collision velocity [m/s], injection [droplets/(m3 s)]);
    work: float array of at least ``work_size(N)``. No allocation. The moment gains of a pair
    come from recurrences in k with non-negative terms (``quadrature.aggregation_sources``):
    exact zero for the mass moment (k = 1), exact -1 for the number (k = 0), no
    cancellation. d43 (ktgf) comes
    from the nodes' diameters: d^3 is proportional to the mass, so d43 = sum w x d / sum w x
    without further powers.
    """
    n_max = config[P.ORDER]
    bivariate = config[P.BIVARIATE] == 1
    n_state = config[P.N_STATE]
    for k in range(n_state):
        out[k] = 0.0
    n = _invert_work(state, config, work)
    nodes = work[0:n_max]
    weights = work[n_max:2 * n_max]
    binder = work[2 * n_max:3 * n_max]
    props = _props_view(work, n_max)
    n_size = 2 * n_max
    number_scale = params[P.NUMBER_SCALE]
    mass_scale = params[P.MASS_SCALE]
    u0 = cell[P.COLLISION_VELOCITY]
    code = config[P.KERNEL]
    with_d43 = kernel_uses_d43(code)
    num43 = 0.0
    den43 = 0.0
    for a in range(n):
        x = nodes[a]
        b = min(max(binder[a], 0.0), x)
        particle_properties(x * mass_scale, b * mass_scale, params, config, props, a)
        if with_d43:
            wx = weights[a] * x
            num43 += wx * props[a, DIAMETER]
            den43 += wx
    d43 = num43 / den43 if den43 > 0.0 else 0.0
    factor = kernel_cell_factor(code, cell[P.ALPHA], cell[P.THETA], d43, params)
    # granule-granule aggregation, each unordered pair once (non-negative recurrences)
    if factor != 0.0:
        add_pair_sources(out, nodes, weights, binder, n, props, factor, u0, number_scale,
                         n_size, n_max, bivariate, params, config)
    if config[P.BREAKAGE] == 1:
        add_qmom_breakage(out, nodes, weights, binder, n, cell, params, config)
    if config[P.DRYING] == 1:
        add_qmom_drying(out, nodes, weights, binder, n, state[2 * n_max],
                        cell_gas(cell, params, config), params, config)
    _droplet_sources(state, out, cell, params, config, nodes, weights, binder, props, n, factor,
                     u0)


@nb.njit(cache=True)
def qmom_conserved(config, params, pivots, coefs):
    """Linear invariants of the QMOM state for the time integrator: rows c of ``coefs``
    (n_inv, N_STATE) with c . d(state)/dt independent of the state (the injection only):
    granule mass M10 plus the free droplets' mass x_d n_d, and (bivariate) binder mass M01 plus
    their liquid x_l n_d, x_d = p_d / p_ref, x_l = b_d / p_ref. ``pivots[r]`` is the entry with
    coefficient 1 (M10, M01). Returns the number of invariants."""
    n_max = config[P.ORDER]
    n_state = config[P.N_STATE]
    separate = config[P.SEPARATE_DROPLETS] == 1
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    xl = droplet_liquid(params) / params[P.MASS_SCALE]
    count = 2 if config[P.BIVARIATE] == 1 else 1
    for r in range(count):
        for k in range(n_state):
            coefs[r, k] = 0.0
        pivots[r] = 1 if r == 0 else 2 * n_max
        coefs[r, pivots[r]] = 1.0
        if separate and not set_droplet_invariants(coefs, r, params, config):
            coefs[r, n_state - 1] = xd if r == 0 else xl
        if config[P.DRYING] == 1:        # what evaporates leaves M10 and M01 for this entry
            coefs[r, n_state - 1 - config[P.SEPARATE_DROPLETS]] = 1.0
    return count


@nb.njit(cache=True, error_model="numpy")
def _project_into(state, target, config, nodes, weights, binder, n):
    """Moments of the quadrature (nodes, weights, binder; n nodes) into target."""
    n_max = config[P.ORDER]
    for k in range(2 * n_max):
        target[k] = 0.0
    if config[P.BIVARIATE] == 1:
        for k in range(n_max):
            target[2 * n_max + k] = 0.0
    for a in range(n):
        power = weights[a]
        for k in range(2 * n_max):
            target[k] += power
            if k < n_max and config[P.BIVARIATE] == 1:
                target[2 * n_max + k] += power * binder[a]
            power *= nodes[a]
    for k in range(2 * n_max + (n_max if config[P.BIVARIATE] == 1 else 0),
                   config[P.N_STATE]):
        target[k] = state[k]         # the evaporated liquid and the droplets, as carried


@nb.njit(cache=True, error_model="numpy", inline="always")
def _check_state(state, config, work, on_closure):
    """The tests of ``qmom_realizable`` (on_closure False) or ``qmom_on_closure`` (True)."""
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    for k in range(n_state):
        if not math.isfinite(state[k]):
            return False
    if config[P.SEPARATE_DROPLETS] == 1 and state[n_state - 1] < 0.0:
        return False
    if config[P.DRYING] == 1 and state[n_state - 1 - config[P.SEPARATE_DROPLETS]] < 0.0:
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
    n = _invert_work(state, config, work)
    nodes = work[0:n_max]
    weights = work[n_max:2 * n_max]
    binder = work[2 * n_max:3 * n_max]
    target = work[_off_target(n_max):_off_target(n_max) + 3 * n_max + 2]
    if n == 0:
        return False
    if n < n_max:
        _project_into(state, target, config, nodes, weights, binder, n)
        for k in range(2 * n_max):
            if abs(target[k] - state[k]) > PROJECTION_TOLERANCE * abs(state[k]):
                return False
    if config[P.BIVARIATE] == 1:
        if not binder_within_mass(state, 2 * n_max, n_max, PROJECTION_TOLERANCE):
            return False
        if not on_closure:
            return True
        # binder moments reproduced by the bounded per-node binder
        _project_into(state, target, config, nodes, weights, binder, n)
        for k in range(n_max):
            i = 2 * n_max + k
            if abs(target[i] - state[i]) > BINDER_TOLERANCE * abs(state[k + 1]):
                return False
    return True


@nb.njit(cache=True, error_model="numpy")
def qmom_realizable(state, aux, params, config, work):
    """True if the cell's state is a realizable moment set (within PROJECTION_TOLERANCE): what
    a step must keep to be accepted.

    Checks finiteness, non-negative number and droplets, positive nodes, the consistency of the
    moments a reduced quadrature discards, and the binder: 0 <= M_k1 <= M_(k+1)0 (b <= p in
    every particle). Binder moments that no per-node binder within 0 <= b_a <= p_a reproduces
    are the closure's limit, not the moment set's (docs/physics.md section 9):
    ``qmom_project`` puts them on the clipped binder after every accepted step, and
    ``qmom_on_closure`` is the test for them. An all-zero (empty) state is realizable.
    """
    return _check_state(state, config, work, False)


@nb.njit(cache=True, error_model="numpy")
def qmom_on_closure(state, aux, params, config, work):
    """True if the cell's state is realizable and on QMOM's closure: what a state mixed by
    transport must be to go without ``qmom_project``.

    The tests of ``qmom_realizable`` and besides the binder moments M_k1 reproduced by binder
    per node clipped to 0 <= b_a <= p_a (within BINDER_TOLERANCE of M_(k+1)0). Nearly
    coincident nodes make the per-node binder solve ill-conditioned, so the test is on the
    moments it reproduces, not on the raw per-node values.
    """
    return _check_state(state, config, work, True)


@nb.njit(cache=True, error_model="numpy")
def qmom_project(state, aux, params, config, work):
    """Re-project an accepted state onto its quadrature, in place: where nodes were lost, every
    moment but M00, M10 and M01 becomes that of the reduced quadrature; the binder moments
    M_k1 (k >= 1) become those of the bounded per-node binder. The conserved number, mass and
    binder mass are never touched."""
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    if state[0] <= 0.0:
        return
    n = _invert_work(state, config, work)
    nodes = work[0:n_max]
    weights = work[n_max:2 * n_max]
    binder = work[2 * n_max:3 * n_max]
    target = work[_off_target(n_max):_off_target(n_max) + 3 * n_max + 2]
    if n == 0:
        return
    _project_into(state, target, config, nodes, weights, binder, n)
    if n < n_max:
        # keep the number and mass moments exactly as carried (they are conserved quantities)
        for k in range(n_state):
            if k != 0 and k != 1 and k != 2 * n_max:
                state[k] = target[k]
    elif config[P.BIVARIATE] == 1:
        # binder moments of the bounded per-node binder (M01, the binder mass, kept)
        for k in range(1, n_max):
            state[2 * n_max + k] = target[2 * n_max + k]


@nb.njit(cache=True, error_model="numpy")
def quadrature_rows(states, config, nodes, weights, binder, counts):
    """``invert`` of every row of ``states`` (rows, n_state; scaled units) into the rows of
    nodes, weights, binder (rows, n_max; unclipped binder) and the node counts (rows,); each
    row with a fresh zeroed work array, as ``quadrature_of``."""
    n_max = config[P.ORDER]
    work = np.zeros(work_size(n_max))
    for r in range(states.shape[0]):
        work[:] = 0.0
        counts[r] = invert(states[r], config, nodes[r], weights[r], binder[r], work)


def quadrature_rows_of(states, config):
    """Nodes, weights, binder per node (scaled units, each (rows, n_max), zero beyond a row's
    node count, binder within [0, node]) and the node counts of every row of ``states``;
    equal entry by entry to ``quadrature_of`` of each row."""
    n_max = int(config[P.ORDER])
    states = np.ascontiguousarray(np.atleast_2d(states), dtype=np.float64)
    rows = states.shape[0]
    nodes, weights, binder = (np.zeros((rows, n_max)) for _ in range(3))
    counts = np.zeros(rows, dtype=np.int64)
    if rows:
        quadrature_rows(states, config, nodes, weights, binder, counts)
    return nodes, weights, np.clip(binder, 0.0, nodes), counts


def quadrature_of(state, config):
    """Nodes, weights and binder per node (scaled units) of one cell's state; Python helper."""
    n_max = int(config[P.ORDER])
    nodes = np.zeros(n_max)
    weights = np.zeros(n_max)
    binder = np.zeros(n_max)
    work = np.zeros(work_size(n_max))
    n = invert(np.ascontiguousarray(state, dtype=np.float64), config, nodes, weights, binder, work)
    return nodes[:n], weights[:n], np.clip(binder[:n], 0.0, nodes[:n])
