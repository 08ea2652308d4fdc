"""Drying in the Laguerre ROM: the drift of the wet class evaluated on the state's own
quadrature (docs/physics.md section 15, "Laguerre ROM").

A wet granule (p, b) loses liquid at e(p, b) (``physics.drying.drying_rate``), dp/dt = db/dt =
-e, so a wet moment W_ij = int p^i b^j n gains

    dW_ij/dt = - int e (i p^(i-1) b^j + j p^i b^(j-1)) n dp db,

and the evaporated liquid E gains int e n. The integral is taken over a positive point measure
built from the carried wet moments (``wet_points``), never over the signed Laguerre
reconstruction:

- the masses: the two-node Gauss quadrature of the gamma density with the class's W00, W10,
  W20 (shape k = mu^2 / var, scale theta = var / mu), nodes theta (k + 1 -+ sqrt(k + 1)) > 0,
  weights W00 (sqrt(k + 1) +- 1) / (2 sqrt(k + 1)) > 0: W00, W10, W20 exactly (one node at the
  mean where the variance is not positive);
- the liquid at each mass node: its conditional mean and second moment from W01, W11 and
  W02, W12 (the 2 x 2 Vandermonde system of the nodes, as CQMOM's conditional moments), two
  points mean -+ sigma of half the node's weight; each clipped into 0 <= b <= p keeping W01
  (then the balances stay exact);
- a node whose liquid variance v is below H^2, H = CONTINUE_SPREAD times its mean liquid c:
  the pair c -+ H with the weight t w and the point c with (1 - t) w, t = v / H^2 for v >= 0
  and tanh(v / H^2) for v < 0 (where the carried moments lie outside the realizable set:
  a negative weight on the pair, at most w). Every sum over the points is then the pair's
  continued linearly in v from v = 0 to v = H^2, matching the carried conditional second
  moment there, and smoothly (twice differentiable) held below: the RHS has no kink on the
  realizability boundary
  W00 W02 = W01^2 (a monodisperse class), where an integrator's stages go both ways (one
  liquid point, as before, put the Hankel gap into the relative rate on one side only).

The drift of W10 and W01 is that measure's -sum w e, exactly minus the evaporation, so M10 + E,
M01 + E and the binder solids M10 - M01 are invariants of the term. Every other moment W_a
drifts at the measure's relative rate, dW_a/dt = (D_a / W_a^pts) W_a: where the points match W_a
(every moment of order <= 2 when no clip acts, and all of them for a monodisperse class) this is
the measure's own drift D_a; where they do not, the carried moment keeps its sign. The relative
rates lie in [-(i + j) r, 0], r the points' largest e / b, because b <= p at every point: the
drift is no stiffer than the fastest particle of the measure. The dry class (b = 0) does not
dry, and the falling rate keeps b > 0, so no granule moves between the classes. Free droplets
of their own evaporate in the RHS's droplet class (``quadrature.drying_sources``), as in the
other moment methods.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.drying import cell_gas, drying_rate
from ..quadrature.drying_sources import CONTINUE_SPREAD, continued_pair_share
from .basis import moment_index
from .layout import AUX_OFF_DRYING, AUX_ORDER, evaporated_entry

#: state entry of the wet liquid M~01: (i, j) = (0, 1) in ``moment_index`` order (order >= 2)
WET_LIQUID = moment_index(2).index((0, 1))
#: a variance (of the mass, or of the liquid at a mass node) below this share of the squared
#: mean is a single node, ours: a spread under 1e-4 of the mean, far above the noise an
#: integrated monodisperse class's W00 W20 - W10^2 carries (~rtol of W10^2, rtol >= 1e-12),
#: whose square root would otherwise split one node in two by ~1e-6 and amplify that noise
#: through the conditional means' 1 / (x2 - x1)
SINGLE_NODE_VARIANCE = 1e-8


def drying_on(config) -> bool:
    """True if the scene has a [drying] table (config[DRYING] == 1)."""
    return int(config[P.DRYING]) == 1


def drying_blocks(params, config, m, bases, p_ref):
    """The aux block of the drying term: one marker entry (the drift needs no table: it is
    evaluated on the state's own quadrature at RHS time); empty without drying. params,
    bases, p_ref: unused (the signature of the ROM's tabulated terms)."""
    return np.ones(1) if drying_on(config) else np.zeros(0)


@nb.njit(cache=True, inline="always")
def _conditional(x1, x2, w1, w2, first, second):
    """(c1, c2): the per-node values with w1 c1 + w2 c2 = first, w1 x1 c1 + w2 x2 c2 = second."""
    det = x2 - x1
    return (x2 * first - second) / (w1 * det), (second - x1 * first) / (w2 * det)


@nb.njit(cache=True, inline="always")
def _clip_means(x1, x2, w1, w2, liquid, c1, c2):
    """The conditional liquid means moved into [0, x_a], keeping w1 c1 + w2 c2 = liquid."""
    if c1 < 0.0:
        c1 = 0.0
    elif c1 > x1:
        c1 = x1
    c2 = (liquid - w1 * c1) / w2
    if c2 < 0.0 or c2 > x2:
        c2 = min(max(c2, 0.0), x2)
        c1 = min(max((liquid - w2 * c2) / w1, 0.0), x1)
    return c1, c2


@nb.njit(cache=True, inline="always")
def _node_points(x, c, second, w):
    """A mass node's liquid points (module docstring) [scaled]: (half-width h, weight of the
    centre point c, weight of the pair c -+ h together). x the node's mass, c its mean liquid
    (in [0, x]), second its conditional second moment, w its weight."""
    reach = min(c, x - c)                   # the points stay in 0 <= b <= x
    if not (w > 0.0 and reach > 0.0):
        return 0.0, w, 0.0
    var = second - c * c
    h0 = min(CONTINUE_SPREAD * c, reach)
    if not h0 * h0 > 0.0:                   # a liquid whose square underflows: one point
        return 0.0, w, 0.0
    if var >= h0 * h0:
        return min(math.sqrt(var), reach), 0.0, w
    t = continued_pair_share(var, h0, 0.0)   # outside: tanh(t), held above -1
    return h0, (1.0 - t) * w, t * w


@nb.njit(cache=True)
def gamma_nodes(w0, w1, w2, two):
    """(x1, x2, a1, a2): the two-node Gauss rule of the gamma density with moments w0, w1, w2
    (any consistent units; shape k = mu^2 / var, scale var / mu, nodes theta (k + 1 -+
    sqrt(k + 1)), weights w0 (sqrt(k + 1) -+ 1) / (2 sqrt(k + 1)) > 0); it reproduces w0, w1,
    w2. One node at the mean (x2 = a2 = 0) where ``two`` is False or var <= SINGLE_NODE_VARIANCE
    mu^2; nothing (all 0) where w0 or w1 is not positive."""
    if not (w0 > 0.0 and w1 > 0.0):
        return 0.0, 0.0, 0.0, 0.0
    mu = w1 / w0
    var = w2 / w0 - mu * mu if two else 0.0
    if not var > SINGLE_NODE_VARIANCE * mu * mu:
        return mu, 0.0, w0, 0.0
    k = mu * mu / var
    theta = var / mu
    s = math.sqrt(k + 1.0)
    return (theta * (k + 1.0 - s), theta * (k + 1.0 + s), w0 * (s + 1.0) / (2.0 * s),
            w0 * (s - 1.0) / (2.0 * s))


@nb.njit(cache=True)
def wet_points(state, m):
    """The point measure of the wet class (module docstring) [scaled]: (x1, x2, c1, c2, h1,
    h2, a1, a2, b1, b2): mass nodes x, liquid means c, half-widths h, the centre points'
    weights a and the pairs' weights b (each of a pair's two points b / 2). Node a's points
    are (x_a, c_a) and (x_a, c_a -+ h_a). a1 + b1 = 0 where there is no wet class."""
    w00 = state[0]
    w10 = state[m]
    if not (w00 > 0.0 and w10 > 0.0):
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    w01 = min(max(state[1], 0.0), w10)
    x1, x2, w1, w2 = gamma_nodes(w00, w10, state[2 * m] if m >= 3 else 0.0, m >= 3)
    if w2 == 0.0:
        mu = x1
        c = w01 / w00
        second = state[2] / w00 if m >= 3 else c * c
        h, a, b = _node_points(mu, c, second, w00)
        return mu, mu, c, c, h, 0.0, a, 0.0, b, 0.0
    c1, c2 = _conditional(x1, x2, w1, w2, w01, state[m + 1])
    c1, c2 = _clip_means(x1, x2, w1, w2, w01, c1, c2)
    q1, q2 = _conditional(x1, x2, w1, w2, state[2], state[m + 2])
    h1, a1, b1 = _node_points(x1, c1, q1, w1)
    h2, a2, b2 = _node_points(x2, c2, q2, w2)
    return x1, x2, c1, c2, h1, h2, a1, a2, b1, b2


N_POINTS = 6                                    # per wet class: 3 per mass node


@nb.njit(cache=True, inline="always")
def _point(q, pts):
    """(x, b, w) of point q < N_POINTS of ``wet_points``: per node the centre, then the pair."""
    x1, x2, c1, c2, h1, h2, a1, a2, b1, b2 = pts
    x, c, h, a, b = (x1, c1, h1, a1, b1) if q < 3 else (x2, c2, h2, a2, b2)
    r = q % 3
    if r == 0:
        return x, c, a
    return x, c - h if r == 1 else c + h, 0.5 * b


@nb.njit(cache=True, inline="always")
def _point_rate(q, pts, scale, gas, params):
    """e [scaled mass per s] of point q of ``wet_points`` in ``gas``
    (``physics.drying.cell_gas``) times its weight (0 for a point of no weight or no
    liquid)."""
    x, b, w = _point(q, pts)
    if w == 0.0 or not b > 0.0:
        return 0.0
    return w * drying_rate(x * scale, b * scale, gas, params) / scale


@nb.njit(cache=True, inline="always")
def _point_rates(pts, scale, gas, params):
    """The N_POINTS weighted rates of ``_point_rate`` (a tuple: the RHS allocates nothing)."""
    return (_point_rate(0, pts, scale, gas, params), _point_rate(1, pts, scale, gas, params),
            _point_rate(2, pts, scale, gas, params), _point_rate(3, pts, scale, gas, params),
            _point_rate(4, pts, scale, gas, params), _point_rate(5, pts, scale, gas, params))


@nb.njit(cache=True)
def add_laguerre_drying(state, out, cell, aux, params, config):
    """Add the drying drift [scaled state units per s] of one cell to ``out``: the wet moments
    (entries 0 .. K-1) and the evaporated liquid (``evaporated_entry``), evaluated on
    ``wet_points`` in the cell's gas (``physics.drying.cell_gas``: the slip velocity [m/s]
    and gas state of the scene, or of the cell's row; masses scaled by params[MASS_SCALE]
    [kg]). W10 and W01 take the points' drift, the other moments its
    relative rate (module docstring). Nothing without the drying marker or wet liquid."""
    if int(aux[AUX_OFF_DRYING]) <= 0:
        return
    m = int(aux[AUX_ORDER])
    if not state[WET_LIQUID] > 0.0:
        return
    pts = wet_points(state, m)
    _, _, _, _, _, _, centre1, _, pair1, _ = pts
    if centre1 + pair1 == 0.0:                  # the first node's weight: no wet class
        return
    rates = _point_rates(pts, params[P.MASS_SCALE], cell_gas(cell, params, config), params)
    evaporated = 0.0
    for q in range(N_POINTS):
        evaporated += rates[q]
    if evaporated == 0.0:
        return
    for i in range(m):
        for j in range(m):
            if i + j == 0:
                continue
            drift = 0.0
            carried = 0.0                       # the points' own W_ij
            for q in range(N_POINTS):
                x, b, w = _point(q, pts)
                if w == 0.0:
                    continue
                carried += w * x ** i * b ** j
                d = 0.0
                if i > 0:
                    d += i * x ** (i - 1) * b ** j
                if j > 0:
                    d += j * x ** i * b ** (j - 1)
                drift -= rates[q] * d
            if i + j == 1:
                out[i * m + j] += drift
            elif carried > 0.0:
                out[i * m + j] += drift * (state[i * m + j] / carried)
    out[evaporated_entry(config)] += evaporated
