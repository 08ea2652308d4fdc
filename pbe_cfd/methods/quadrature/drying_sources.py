"""Drying as a drift in the binder coordinate (docs/physics.md section 15), for the quadrature
methods: each point (x, b) [scaled masses] of weight w drifts at dx/dt = db/dt = -e(x, b)
(``physics.drying.drying_rate``), so a moment M_kl = sum w x^k b^l gains

    dM_kl/dt = -sum w e (k x^(k-1) b^l + l x^k b^(l-1)),

and the evaporated liquid E (a state entry of its own) gains sum w e. ``drift_moment_rate``
is that term for one point and one moment, for any quadrature method (QMOM, CQMOM, and an
EQMOM's secondary points); ``add_qmom_drying`` sums it over the QMOM nodes.

Realizability: e vanishes with b linearly (the falling-rate period, X < X_cr), so a node's
liquid decays exponentially and M_k1 stays positive; the dry mass x - b of every node is
unchanged, so b <= x holds.
"""
import numba as nb

from ...physics import parameters as P
from ...physics.drying import drying_rate


@nb.njit(cache=True, inline="always")
def point_drying_rate(x, b, params):
    """Evaporation rate [scaled mass per s] of a point of scaled mass x and liquid b (scaled by
    params[MASS_SCALE] [kg]) at the scene's slip velocity (params[DRY_SLIP] [m/s])."""
    scale = params[P.MASS_SCALE]
    return drying_rate(x * scale, b * scale, params[P.DRY_SLIP], params) / scale


@nb.njit(cache=True, inline="always")
def drift_moment_rate(k, l, x, b, rate):
    """d(x^k b^l)/dt [scaled units per s] of one point (x, b) drying at ``rate`` (dx/dt =
    db/dt = -rate): -rate (k x^(k-1) b^l + l x^k b^(l-1)), each term 0 where its power is."""
    value = 0.0
    if k > 0:
        value += k * x ** (k - 1) * b ** l
    if l > 0:
        value += l * x ** k * b ** (l - 1)
    return -rate * value


@nb.njit(cache=True)
def add_qmom_drying(out, nodes, weights, binder, n, params, config):
    """Add the drying drift of the n QMOM nodes (scaled mass, weight, liquid) to ``out``: the
    size moments M_k0 (entries k < 2N), the binder moments M_k1 (entries 2N + k, k < N), and the
    evaporated liquid (entry N_STATE - 1 - SEPARATE_DROPLETS)."""
    n_max = config[P.ORDER]
    n_size = 2 * n_max
    evaporated = config[P.N_STATE] - 1 - config[P.SEPARATE_DROPLETS]
    for a in range(n):
        x = nodes[a]
        b = min(max(binder[a], 0.0), x)
        rate = weights[a] * point_drying_rate(x, b, params)
        if rate == 0.0:
            continue
        out[evaporated] += rate
        for k in range(1, n_size):
            out[k] += drift_moment_rate(k, 0, x, b, rate)
        for k in range(n_max):
            out[n_size + k] += drift_moment_rate(k, 1, x, b, rate)
