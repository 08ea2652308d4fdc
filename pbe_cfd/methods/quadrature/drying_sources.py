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
import math

import numba as nb

from ...physics import parameters as P
from ...physics.drying import drying_rate
from ...physics.injection import (droplet_liquid, droplet_liquid_entry, droplet_number_entry,
                                 evaporated_entry)


#: half-width of a continued liquid pair, as a share of its mean (``continued_pair_share``),
#: ours: wide enough that the difference of the pair's and the centre's sums keeps 10 digits
#: (they differ by ~(H / c)^2 = 1e-6 relative), narrow against any spread a population carries
CONTINUE_SPREAD = 1e-3


@nb.njit(cache=True, inline="always")
def continued_pair_share(var, h, linear_to):
    """The share t [-] of a node's weight on its continued liquid pair c -+ h (the centre c
    holds 1 - t) for the liquid variance var (docs/physics.md section 15): t = var / h^2,
    linear down to t = ``linear_to`` (<= 0) and below it held smoothly above -1,
    linear_to + s tanh((t - linear_to) / s) with s = 1 + linear_to (value and two
    derivatives continuous). Every sum over the points is then the centre's plus t times the
    pair's excess: linear in var across var = 0, the boundary a monodisperse liquid sits on,
    where an integrator's stages fall on both sides. For var >= h^2 the caller's own rule
    applies (t >= 1 is returned as it is)."""
    t = var / (h * h)
    if t < linear_to:
        s = 1.0 + linear_to
        t = linear_to + s * math.tanh((t - linear_to) / s)
    return t


@nb.njit(cache=True, inline="always")
def point_drying_rate(x, b, gas, params):
    """Evaporation rate [scaled mass per s] of a point of scaled mass x and liquid b (scaled by
    params[MASS_SCALE] [kg]) in the cell's ``gas`` (``physics.drying.cell_gas``: slip velocity
    [m/s] and gas state, the scene's or the CFD's)."""
    scale = params[P.MASS_SCALE]
    return drying_rate(x * scale, b * scale, gas, params) / scale


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
def add_qmom_drying(out, nodes, weights, binder, n, liquid, gas, params, config):
    """Add the drying drift of the n QMOM nodes (scaled mass, weight, liquid) in the cell's
    ``gas`` (``physics.drying.cell_gas``) to ``out``: the
    size moments M_k0 (entries k < 2N), the binder moments M_k1 (entries 2N + k, k < N), and the
    evaporated liquid (entry N_STATE - 1 - SEPARATE_DROPLETS).

    Each node dries its liquid clipped to [0, x]. Where the clipping raised the nodes' liquid
    above the carried M01 (``liquid``, scaled; negative per-node liquid from a binder solve of
    moments that the error control no longer holds to one another, a trace of liquid below
    the absolute tolerance), the nodes' liquid is scaled down to M01: the drift then
    evaporates the liquid the state carries, no more, and M01 falls no faster than its own
    falling-rate decay."""
    n_max = config[P.ORDER]
    n_size = 2 * n_max
    evaporated = evaporated_entry(config)
    clipped = 0.0
    for a in range(n):
        clipped += weights[a] * min(max(binder[a], 0.0), nodes[a])
    share = liquid / clipped if clipped > liquid >= 0.0 else 1.0
    for a in range(n):
        x = nodes[a]
        b = share * min(max(binder[a], 0.0), x)
        rate = weights[a] * point_drying_rate(x, b, gas, params)
        if rate == 0.0:
            continue
        out[evaporated] += rate
        for k in range(1, n_size):
            out[k] += drift_moment_rate(k, 0, x, b, rate)
        for k in range(n_max):
            out[n_size + k] += drift_moment_rate(k, 1, x, b, rate)


# ---- free droplets of their own (docs/physics.md section 15, "Free droplets' evaporation") --
# With drying the droplet class carries its liquid L_d (state entry ``droplet_liquid_entry``,
# scaled as a mass moment) beside its number n_d (the last entry): the one-mass closure gives
# every droplet the class's mean liquid l = L_d / n_d and its solids s p_d, so a droplet is the
# point (s p_d + l, l); it evaporates at e(s p_d + l, l) (the liquid sphere's d^2 law, then the
# skeleton's periods for a solution), E_d = n_d e(L_d / n_d), and a capture hands the granule
# that point. Without the entry (config[DROPLET_LIQUID] = 0) a droplet is (p_d, b_d).


@nb.njit(cache=True)
def droplet_point(state, params, config):
    """(mass [kg], liquid [kg]) of one free droplet of the cell's state: (p_d, b_d) without a
    droplet-liquid entry; with it (s p_d + l, l), l = L_d / n_d >= 0 the class's mean liquid
    (a fresh droplet's b_d while the class is empty)."""
    pd = params[P.DROPLET_MASS]
    bd = droplet_liquid(params)
    entry = droplet_liquid_entry(config)
    if entry < 0:
        return pd, bd
    nd = state[droplet_number_entry(config)]
    if not nd > 0.0:
        return pd, bd
    liquid = max(state[entry] / nd, 0.0) * params[P.MASS_SCALE]
    return (pd - bd) + liquid, liquid


@nb.njit(cache=True)
def add_droplet_class_terms(state, out, injection, captured, liquid, gas, params, config):
    """With a droplet-liquid entry: its injection (``injection`` scaled droplets per s, each
    with b_d), its capture (``captured`` scaled droplets per s, each with ``liquid``, scaled)
    and its evaporation n_d e(droplet point) in the cell's ``gas`` (``physics.drying.cell_gas``)
    into ``out``, the evaporated liquid (entry
    N_STATE - 2) gaining what evaporates. Without the entry nothing."""
    entry = droplet_liquid_entry(config)
    if entry < 0:
        return
    scale = params[P.MASS_SCALE]
    out[entry] += injection * (droplet_liquid(params) / scale) - captured * liquid
    nd = state[droplet_number_entry(config)]
    if not nd > 0.0:
        return
    p, b = droplet_point(state, params, config)
    rate = nd * drying_rate(p, b, gas, params) / scale
    out[entry] -= rate
    out[evaporated_entry(config)] += rate


@nb.njit(cache=True, inline="always")
def tail_entries(config):
    """Number of state entries after the moments: the droplets' liquid, the evaporated liquid
    and the droplet number, those present."""
    return (config[P.SEPARATE_DROPLETS] + config[P.DRYING]
            + (1 if droplet_liquid_entry(config) >= 0 else 0))


@nb.njit(cache=True)
def set_droplet_invariants(coefs, r, params, config):
    """Row r of the linear invariants (r = 0: mass, 1: liquid binder) for the droplet entries
    with a droplet-liquid entry: the mass row counts the droplets' solids s p_d n_d and their
    liquid L_d, the liquid row L_d. Returns False (nothing set) without the entry."""
    entry = droplet_liquid_entry(config)
    if entry < 0:
        return False
    pd = params[P.DROPLET_MASS]
    coefs[r, droplet_number_entry(config)] = ((pd - droplet_liquid(params)) / params[P.MASS_SCALE]
                                       if r == 0 else 0.0)
    coefs[r, entry] = 1.0
    return True
