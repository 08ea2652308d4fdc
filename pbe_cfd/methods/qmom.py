"""Quadrature method of moments with node-wise binder (DESIGN section 3).

State of one cell (non-dimensional: SI moment M_ij per m3 divided by N_ref p_ref^(i+j), with
N_ref = params[NUMBER_SCALE] [1/m3] and p_ref = params[MASS_SCALE] [kg] for both masses):

    [M_00, M_10, ..., M_(2N-1)0]                 size moments, 2N entries
    [M_01, M_11, ..., M_(N-1)1]                  binder-weighted moments (bivariate only), N entries
    [n_d]                                        free droplets (only with separate droplets)

The N-node quadrature (Wheeler, Golub-Welsch) of the size moments gives masses p_a and weights
w_a; the binder moments M_k1 = sum_a w_a p_a^k b_a, k < N, give one binder mass b_a per node.
Moment sources are quadratures of the aggregation integrals over the nodes (and the droplets).
"""
import math

import numba as nb
import numpy as np

from ..physics import parameters as P
from ..physics.rates import aggregation_rate, droplet_capture_rate
from .quadrature import solve_vandermonde, wheeler_nodes

#: Re-projection mismatch (relative to each moment's size) up to which a moment set whose
#: quadrature lost nodes is still accepted as (numerically) on the realizable boundary.
PROJECTION_TOLERANCE = 1.0e-8
MAX_NODES = 6


def state_length(nodes, bivariate, separate_droplets):
    """Number of entries of one cell's QMOM state."""
    return 2 * nodes + (nodes if bivariate else 0) + (1 if separate_droplets else 0)


def state_names(nodes, bivariate, separate_droplets):
    """Names of the state entries: moment names 'M{i}{j}', then 'droplet_number_density'."""
    names = [f"M{k}0" for k in range(2 * nodes)]
    if bivariate:
        names += [f"M{k}1" for k in range(nodes)]
    if separate_droplets:
        names.append("droplet_number_density")
    return names


@nb.njit(cache=True)
def _binomial(n, k):
    result = 1.0
    for i in range(1, k + 1):
        result = result * (n - k + i) / i
    return result


@nb.njit(cache=True)
def _power_gain(x, y, k):
    """(x + y)^k - x^k, as a binomial sum so that it is exactly 0 for k = 0."""
    total = 0.0
    for j in range(k):
        total += _binomial(k, j) * x ** j * y ** (k - j)
    return total


@nb.njit(cache=True)
def _pair_gain(x, y, k):
    """(x + y)^k - x^k - y^k, exactly -1 for k = 0 and exactly 0 for k = 1."""
    if k == 0:
        return -1.0
    total = 0.0
    for j in range(1, k):
        total += _binomial(k, j) * x ** j * y ** (k - j)
    return total


@nb.njit(cache=True)
def invert(state, config, nodes, weights, binder, work):
    """Quadrature of one cell's state: fills nodes (scaled mass), weights (scaled number) and
    binder (scaled binder mass per node); returns the node count (0 for an empty cell).

    A node count below config[ORDER] means the size moments were degenerate or not realizable;
    binder per node is solved from the first n_eff binder moments and is not clipped here.
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
        rhs = work[0:n_max]
        sol = work[n_max:2 * n_max]
        for k in range(n_eff):
            rhs[k] = state[2 * n_max + k]
        # nodes are O(1) after scaling by the mean; solve in those units for conditioning
        mean = state[1] / state[0]
        scaled = work[2 * n_max:3 * n_max]
        for a in range(n_eff):
            scaled[a] = nodes[a] / mean
        for k in range(n_eff):
            rhs[k] = rhs[k] / mean ** k
        if not solve_vandermonde(scaled, rhs, sol, n_eff, work[3 * n_max:]):
            for a in range(n_eff):
                binder[a] = 0.0
            return n_eff
        for a in range(n_eff):
            binder[a] = sol[a] / weights[a]
    else:
        for a in range(n_eff):
            binder[a] = 0.0
    return n_eff


@nb.njit(cache=True)
def _d43(nodes, weights, n, mass_scale, density):
    """Volume-mean diameter [m] of the quadrature (0 if empty)."""
    num = 0.0
    den = 0.0
    for a in range(n):
        d = (6.0 * nodes[a] * mass_scale / (math.pi * density)) ** (1.0 / 3.0)
        num += weights[a] * d ** 4
        den += weights[a] * d ** 3
    if den <= 0.0:
        return 0.0
    return num / den


@nb.njit(cache=True)
def qmom_rhs(state, out, cell, aux, params, config):
    """d(state)/dt of one cell [scaled moments per s] (see module docstring for the layout).

    cell: (alpha [-], theta [m2/s2], collision velocity [m/s], injection [droplets/(m3 s)]).
    """
    n_max = config[P.ORDER]
    bivariate = config[P.BIVARIATE] == 1
    separate = config[P.SEPARATE_DROPLETS] == 1
    n_state = config[P.N_STATE]
    for k in range(n_state):
        out[k] = 0.0
    nodes = np.empty(n_max)
    weights = np.empty(n_max)
    binder = np.empty(n_max)
    work = np.empty((2 * n_max + 1) * (2 * n_max + 1) + 4 * n_max)
    n = invert(state, config, nodes, weights, binder, work)
    number_scale = params[P.NUMBER_SCALE]
    mass_scale = params[P.MASS_SCALE]
    alpha = cell[P.ALPHA]
    theta = cell[P.THETA]
    u0 = cell[P.COLLISION_VELOCITY]
    d43 = _d43(nodes, weights, n, mass_scale, params[P.DENSITY])
    n_size = 2 * n_max
    # granule-granule aggregation, each unordered pair once
    for a in range(n):
        for c in range(a, n):
            rate = number_scale * aggregation_rate(
                nodes[a] * mass_scale, binder[a] * mass_scale,
                nodes[c] * mass_scale, binder[c] * mass_scale,
                alpha, theta, u0, d43, params, config)
            if rate == 0.0:
                continue
            pair = weights[a] * weights[c] * rate
            if a == c:
                pair *= 0.5
            xa = nodes[a]
            xc = nodes[c]
            for k in range(n_size):
                out[k] += pair * _pair_gain(xa, xc, k)
            if bivariate:
                for k in range(1, n_max):
                    out[n_size + k] += pair * (binder[a] * _power_gain(xa, xc, k)
                                               + binder[c] * _power_gain(xc, xa, k))
    inj = cell[P.INJECTION] / number_scale
    xd = params[P.DROPLET_MASS] / mass_scale
    if separate:
        nd = state[n_state - 1]
        if nd > 0.0:
            captured = 0.0
            for a in range(n):
                rate = number_scale * droplet_capture_rate(
                    nodes[a] * mass_scale, binder[a] * mass_scale,
                    alpha, theta, u0, d43, params, config)
                flux = nd * weights[a] * rate
                captured += flux
                xa = nodes[a]
                for k in range(1, n_size):
                    out[k] += flux * _power_gain(xa, xd, k)
                if bivariate:
                    for k in range(n_max):
                        # (x+xd)^k (b + xd) - x^k b
                        out[n_size + k] += flux * (binder[a] * _power_gain(xa, xd, k)
                                                   + xd * (xa + xd) ** k)
            out[n_state - 1] -= captured
        out[n_state - 1] += inj
    elif inj != 0.0:
        for k in range(n_size):
            out[k] += inj * xd ** k
        if bivariate:
            for k in range(n_max):
                out[n_size + k] += inj * xd ** (k + 1)


@nb.njit(cache=True)
def _project_into(state, target, config, nodes, weights, binder, n):
    """Moments of the quadrature (nodes, weights, binder; n nodes) into target."""
    n_max = config[P.ORDER]
    for k in range(2 * n_max):
        acc = 0.0
        for a in range(n):
            acc += weights[a] * nodes[a] ** k
        target[k] = acc
    if config[P.BIVARIATE] == 1:
        for k in range(n_max):
            acc = 0.0
            for a in range(n):
                acc += weights[a] * nodes[a] ** k * binder[a]
            target[2 * n_max + k] = acc
    if config[P.SEPARATE_DROPLETS] == 1:
        target[config[P.N_STATE] - 1] = state[config[P.N_STATE] - 1]


@nb.njit(cache=True)
def qmom_realizable(state, aux, params, config):
    """True if the cell's state is a realizable moment set (within PROJECTION_TOLERANCE).

    Checks finiteness, non-negative number and droplets, positive nodes, the consistency of the
    moments a reduced quadrature discards, and 0 <= b_a <= p_a for the binder of every node.
    An all-zero (empty) state is realizable.
    """
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    for k in range(n_state):
        if not math.isfinite(state[k]):
            return False
    if config[P.SEPARATE_DROPLETS] == 1 and state[n_state - 1] < 0.0:
        return False
    if state[0] == 0.0:
        for k in range(n_state - config[P.SEPARATE_DROPLETS]):
            if state[k] != 0.0:
                return False
        return True
    if state[0] < 0.0:
        return False
    nodes = np.empty(n_max)
    weights = np.empty(n_max)
    binder = np.empty(n_max)
    work = np.empty((2 * n_max + 1) * (2 * n_max + 1) + 4 * n_max)
    n = invert(state, config, nodes, weights, binder, work)
    if n == 0:
        return False
    if n < n_max:
        target = np.empty(n_state)
        _project_into(state, target, config, nodes, weights, binder, n)
        for k in range(2 * n_max):
            if abs(target[k] - state[k]) > PROJECTION_TOLERANCE * abs(state[k]):
                return False
    if config[P.BIVARIATE] == 1:
        for a in range(n):
            slack = PROJECTION_TOLERANCE * nodes[a]
            if binder[a] < -slack or binder[a] > nodes[a] + slack:
                return False
    return True


@nb.njit(cache=True)
def qmom_project(state, aux, params, config):
    """Re-project an accepted state onto its quadrature where nodes were lost or binder per node
    left [0, p_a]: the state becomes the exact moments of a valid quadrature. In-place."""
    n_state = config[P.N_STATE]
    n_max = config[P.ORDER]
    if state[0] <= 0.0:
        return
    nodes = np.empty(n_max)
    weights = np.empty(n_max)
    binder = np.empty(n_max)
    work = np.empty((2 * n_max + 1) * (2 * n_max + 1) + 4 * n_max)
    n = invert(state, config, nodes, weights, binder, work)
    needed = n < n_max
    if config[P.BIVARIATE] == 1:
        for a in range(n):
            if binder[a] < 0.0:
                binder[a] = 0.0
                needed = True
            elif binder[a] > nodes[a]:
                binder[a] = nodes[a]
                needed = True
    if needed and n > 0:
        target = np.empty(n_state)
        _project_into(state, target, config, nodes, weights, binder, n)
        # keep the number and mass moments exactly as carried (they are conserved quantities)
        for k in range(n_state):
            if k != 0 and k != 1 and k != 2 * n_max:
                state[k] = target[k]


def quadrature_of(state, config):
    """Nodes, weights and binder per node (scaled units) of one cell's state; Python helper."""
    n_max = int(config[P.ORDER])
    nodes = np.zeros(n_max)
    weights = np.zeros(n_max)
    binder = np.zeros(n_max)
    work = np.zeros((2 * n_max + 1) ** 2 + 4 * n_max)
    n = invert(np.ascontiguousarray(state, dtype=np.float64), config, nodes, weights, binder, work)
    return nodes[:n], weights[:n], np.clip(binder[:n], 0.0, nodes[:n])
