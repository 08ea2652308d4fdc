"""The ROM's terms linear in the carried moments: breakage and drying (docs/physics.md 8, 9.2,
15).

Breakage acts on each class by its own rows (``breakage``). Under the following support at
order m = 3 the dry class's rows follow it too: they are taken on the Gauss rule of the gamma
density with the dry class's carried D0, D1, D2 (docs/physics.md 9.2, "The dry class's
breakage on its own gamma"),

    dD~_e/dt = F_cell (F(e) - 1) int S_unit(p_ref x) x^e g(x) dx,    e < 3,

g the gamma density of shape k = mu^2 / var and scale theta = var / mu with the number D~0
(mu, var from D~0, D~1, D~2). With a the selection's exponent (``[breakage] exponent``; 0 for
the constant selection) the integral is D~0 theta^a Gamma(k + a) / Gamma(k) times the mean of
x^e S_unit(p_ref x) / x^a over the gamma of shape k + a, taken by that gamma's Gauss rule
(``quadrature.gamma_inversion.gamma_rule``, EQMOM's secondary rule: Golub-Welsch on the
generalised Laguerre recurrence), its nodes scaled by theta. For a power-law selection the integrand
is x^e: every row is the gamma's own closed form (D_(e+a) of the gamma) to round-off, for
any a >= 0, fractional too, and a constant selection gives exactly (F(e) - 1) F_cell D_e.
The rows are those of a positive population, so the term keeps D0 D2 >= D1^2 as breakage
does. A dry class at one mass (var <= SINGLE_NODE_VARIANCE mu^2) breaks at its mean mu:
dD~_e/dt = F_cell S_unit(p_ref mu) (F(e) - 1) D~_e, the carried D_e in place of D0 mu^e (as
``number_points.dry_powers`` takes them). At other orders, and with the fixed support, the dry
class keeps the matrix L_dry of its fixed weight.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.breakage import daughter_moment_factor, selection_function
from ..quadrature.gamma_inversion import gamma_rule
from .breakage import add_dry_breakage_matrix, add_laguerre_breakage
from .drying import SINGLE_NODE_VARIANCE, add_laguerre_drying
from .layout import AUX_FOLLOWING, AUX_ORDER

#: nodes of the dry class's gamma rule, ours: with the selection's power in the weight the
#: rows of a power-law selection are polynomials of degree <= 2 in p, exact from 2 nodes; 4
#: leave room for a selection that is not a power of p
DRY_BREAKAGE_NODES = 4
#: the order at which the dry rows follow (the following support's default order; above it
#: the dry class carries D3.., which a gamma of D0, D1, D2 does not reproduce)
DRY_FOLLOWING_ORDER = 3
#: the state entry of the dry class's D~0 at that order (the wet class's m x m moments first)
DRY_FIRST = DRY_FOLLOWING_ORDER * DRY_FOLLOWING_ORDER


@nb.njit(cache=True)
def dry_gamma_rule(d0, d1, d2, power, nodes, weights):
    """Write the Gauss rule of x^power times the gamma density with moments d0, d1, d2
    [scaled] into nodes (masses x [scaled]) and weights [scaled number x x^power]: sum_s
    weights_s f(x_s) approximates int x^power f(x) gamma(x) dx (exactly for polynomials f of
    degree < 2 DRY_BREAKAGE_NODES). Returns the number of nodes written: DRY_BREAKAGE_NODES, or
    0 where there is no gamma (d0 or d1 not positive, a class at one mass: var <=
    SINGLE_NODE_VARIANCE mu^2) or the eigen-solve did not converge."""
    if not (d0 > 0.0 and d1 > 0.0):
        return 0
    mu = d1 / d0
    var = d2 / d0 - mu * mu
    if not var > SINGLE_NODE_VARIANCE * mu * mu:
        return 0
    k = mu * mu / var
    theta = var / mu
    shape = k + power
    scale = d0 * theta ** power * math.exp(math.lgamma(shape) - math.lgamma(k))
    n = DRY_BREAKAGE_NODES
    if not gamma_rule(shape, n, nodes, weights, np.empty(2 * n)):
        return 0
    for s in range(n):
        nodes[s] *= theta
        weights[s] *= scale
    return n


@nb.njit(cache=True)
def add_dry_breakage_on_gamma(state, out, factor, params, config):
    """Add the dry class's breakage rows dD~_e/dt [scaled per s] (e < 3, module docstring) of
    an order-3 state to ``out``; F_cell = factor [1/s]. Returns False (nothing added) where the
    eigen-solve did not converge, for the caller to take the fixed weight's rows."""
    K = DRY_FIRST
    d0, d1, d2 = state[K], state[K + 1], state[K + 2]
    if not (d0 > 0.0 and d1 > 0.0):
        return True                                  # no dry class: no rows
    code = config[P.BREAKAGE_SELECTION]
    daughters = config[P.BREAKAGE_DAUGHTERS]
    p_ref = params[P.MASS_SCALE]
    if d2 * d0 <= d1 * d1 * (1.0 + SINGLE_NODE_VARIANCE):      # one node: shares of D_e
        rate = factor * selection_function(code, p_ref * d1 / d0, 1.0, params)
        for e in (0, 2):
            out[K + e] += rate * (daughter_moment_factor(daughters, float(e)) - 1.0) \
                * max(state[K + e], 0.0)
        return True
    power = max(params[P.BREAKAGE_EXPONENT], 0.0)
    nodes, weights = np.empty(DRY_BREAKAGE_NODES), np.empty(DRY_BREAKAGE_NODES)
    used = dry_gamma_rule(d0, d1, d2, power, nodes, weights)
    if used == 0:
        return False
    for e in (0, 2):
        gain = daughter_moment_factor(daughters, float(e)) - 1.0
        total = 0.0
        for s in range(used):
            x = nodes[s]
            total += weights[s] * selection_function(code, p_ref * x, 1.0, params) \
                / x ** power * x ** e
        out[K + e] += factor * gain * total
    return True


@nb.njit(cache=True)
def add_linear_terms(state, out, cell, aux, params, config, wpos):
    """The ROM's breakage (with a [breakage] table: the wet class's rows at the weight corners
    wpos of the RHS, the dry class's on its gamma or its fixed weight, module docstring) and
    drying (with a [drying] table, on the state's own points) [scaled state units per s]."""
    if config[P.BREAKAGE] == 1:
        follows = int(aux[AUX_FOLLOWING]) == 1 and int(aux[AUX_ORDER]) == DRY_FOLLOWING_ORDER
        factor = add_laguerre_breakage(state, out, cell, aux, params, config, wpos,
                                       not follows)
        if follows and factor != 0.0:
            if not add_dry_breakage_on_gamma(state, out, factor, params, config):
                add_dry_breakage_matrix(state, out, aux, factor)
    if config[P.DRYING] == 1:
        add_laguerre_drying(state, out, cell, aux, params, config)
