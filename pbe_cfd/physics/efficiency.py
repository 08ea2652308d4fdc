"""Success probability psi of a collision (docs/physics.md section 6): the efficiency registry.

Each factor is a numba function ``f(props, a, c, u0, params)`` of two rows of the per-particle
property array (``physics.properties``: masses p, binder b [kg], diameters [m], eta(y),
phi(y)^(1/3)) and the collision velocity u0 [m/s]; it returns a probability in [0, 1]. The
factors a scene lists multiply; none means psi = 1. Factor number ``code`` is switched on by
``config[P.EFFICIENCY_SWITCHES + code]``.

Adding a factor (see CONTRIBUTING.md): write its numba function (``inline="always"``) and add
one ``Efficiency`` entry to ``EFFICIENCY_REGISTRY`` with the next code. The scene accepts its
name and checks the material keys it lists, its switch slot and product branch follow from the
code, the properties it reads are computed, and the registry tests check it.
"""
import math
from typing import Callable, NamedTuple

import numba as nb
import numpy as np
from numba.core import types
from numba.extending import overload

from . import parameters as P
from .properties import (ACCESSIBLE_BINDER, BINDER, BINDER_LAYER, DIAMETER,
                         DIAMETERS, LAYER_CBRT, MASS, N_PROPS, WETTING, fill_properties)
from .registry import switched_product, switched_union

# ---- efficiency codes, in the order of P.EFFICIENCY_FACTORS (switch: EFFICIENCY_SWITCHES + code)
GEOMETRIC = P.USE_GEOMETRIC - P.EFFICIENCY_SWITCHES
PHYSICAL = P.USE_PHYSICAL - P.EFFICIENCY_SWITCHES
SATURATION = P.USE_SATURATION - P.EFFICIENCY_SWITCHES


@nb.njit(cache=True, inline="always")
def geometric_efficiency(props, a, c, u0, params):
    """Geometric factor psi_g = 1 - (1 - eta1)(1 - eta2) [-], eta = 1/(1 + exp(-b_s (y - c_s))):
    the chance that at least one of the two contact points is wet."""
    return 1.0 - (1.0 - props[a, ACCESSIBLE_BINDER]) * (1.0 - props[c, ACCESSIBLE_BINDER])


@nb.njit(cache=True, inline="always")
def stokes_number(props, a, c, u0, params):
    """Viscous Stokes number of a pair [-]: St = 4 rho u0 d1 d2 (d1+d2)^2 / (9 mu (d1^3+d2^3)),
    collision velocity u0 [m/s], rho the particle density, mu the binder viscosity."""
    d1 = props[a, DIAMETER]
    d2 = props[c, DIAMETER]
    return (4.0 * params[P.DENSITY] * u0 * d1 * d2 * (d1 + d2) ** 2
            / (9.0 * params[P.BINDER_VISCOSITY] * (d1 * d1 * d1 + d2 * d2 * d2)))


@nb.njit(cache=True, inline="always")
def critical_stokes_number(props, a, c, params):
    """Critical Stokes number St* = 2 ln(lambda / h_a) [-] (0 if the layer is thinner than h_a);
    lambda = r_g (phi1^(1/3) + phi2^(1/3)) [m], phi = exp(f (y - g))."""
    layer = params[P.GYRATION_RADIUS] * (props[a, LAYER_CBRT] + props[c, LAYER_CBRT])
    ratio = layer / params[P.ASPERITY]
    if ratio <= 1.0:
        return 0.0
    return 2.0 * math.log(ratio)


def held_decision(on, a, c, params):
    """The sharp Stokes decision [-] (0 or 1) of property rows a, c: ``on`` as evaluated, or
    the decision held in the switch memory of an extended params (physics.parameters.HELD)."""
    raise NotImplementedError("numba only")


@overload(held_decision, inline="always")
def _held_decision(on, a, c, params):
    if isinstance(params, types.Array) and not params.mutable:
        return lambda on, a, c, params: on      # a read-only params holds nothing

    def held(on, a, c, params):
        # the event function of the pair is g = St - St* (physics.md, "the sharp Stokes step")
        if params.shape[0] < P.N_PARAMS_HELD or params[P.STOKES_HOLD] == 0.0:
            return on
        if a >= P.HELD_ROWS or c >= P.HELD_ROWS:
            return on
        k = P.STOKES_HELD + a * P.HELD_ROWS + c
        kept = params[k]
        if kept < 0.0:
            params[k] = on
            return on
        if kept != on:
            params[P.STOKES_CROSSED] = 1.0
        return kept
    return held


@nb.njit(cache=True, inline="always")
def physical_efficiency(props, a, c, u0, params):
    """Viscous Stokes criterion psi_p [-]: 1 if St <= St*, else 0.

    With params[STOKES_WIDTH] = w > 0 the step becomes the smooth switch
    0.5 (1 - tanh((St - St*) / (w St*))), which tends to the step as w -> 0. The sharp step's
    decision is held within an integrator step where params carries the switch memory
    (``held_decision``).
    """
    st = stokes_number(props, a, c, u0, params)
    st_crit = critical_stokes_number(props, a, c, params)
    width = params[P.STOKES_WIDTH]
    if width <= 0.0 or st_crit <= 0.0:
        return held_decision(1.0 if st <= st_crit else 0.0, a, c, params)
    return 0.5 * (1.0 - math.tanh((st - st_crit) / (width * st_crit)))


@nb.njit(cache=True, inline="always")
def saturation_efficiency(props, a, c, u0, params):
    """Liquid-saturation factor psi_s = min(1, S / S_max) [-] (seed 001 eq. 6.4.1-6.4.2).

    S = H rho_s (1 - eps) / (rho_l eps), with H the binder-to-solid mass ratio of the pair,
    H = (b1 + b2) / (p1 + p2 - b1 - b2); a pair of pure binder is fully saturated.
    """
    binder = props[a, BINDER] + props[c, BINDER]
    solid = props[a, MASS] + props[c, MASS] - binder
    if solid <= 0.0:
        return 1.0
    eps = params[P.POROSITY]
    s = binder / solid * params[P.DENSITY] * (1.0 - eps) / (params[P.BINDER_DENSITY] * eps)
    return min(1.0, s / params[P.SATURATION_MAX])


# ---- the registry ---------------------------------------------------------------------------
class Efficiency(NamedTuple):
    """One success-probability factor of the registry.

    name        the scene's entry in ``[aggregation] efficiency``
    code        its number: switched on by config[P.EFFICIENCY_SWITCHES + code]
    function    numba f(props, a, c, u0, params) -> probability in [0, 1]
    material    ``[material]`` keys it needs (the scene refuses a scene without them)
    properties  property groups it reads (``physics.properties`` bit flags)
    uses_binder True if it depends on binder (the scene then needs binder somewhere)
    uses_collision_velocity  True if it reads u0 (from the scene, or 4 sqrt(Theta/pi))
    """
    name: str
    code: int
    function: Callable
    material: tuple = ()
    properties: int = 0
    uses_binder: bool = True
    uses_collision_velocity: bool = False

    @property
    def switch(self) -> int:
        """Its slot in ``config``."""
        return P.EFFICIENCY_SWITCHES + self.code


EFFICIENCY_REGISTRY = (
    Efficiency("geometric", GEOMETRIC, geometric_efficiency,
               material=("accessible_binder_slope", "accessible_binder_centre"),
               properties=WETTING),
    Efficiency("physical", PHYSICAL, physical_efficiency,
               material=("binder_viscosity", "binder_layer_slope", "binder_layer_centre",
                         "asperity", "gyration_radius"),
               properties=DIAMETERS | BINDER_LAYER, uses_collision_velocity=True),
    Efficiency("saturation", SATURATION, saturation_efficiency,
               material=("binder_density", "porosity", "saturation_max")),
)

#: name -> registry entry
EFFICIENCY_BY_NAME = {e.name: e for e in EFFICIENCY_REGISTRY}
#: name -> (config switch, function, material keys it needs)
EFFICIENCIES = {e.name: (e.switch, e.function, e.material) for e in EFFICIENCY_REGISTRY}

# ---- dispatch (numba; one branch per entry) ------------------------------------------------
#: psi [-] of property rows a, c: product of the factors switched on in config;
#: pair_success_probability(props, a, c, u0, params, config)
pair_success_probability = switched_product((e.switch, e.function)
                                            for e in EFFICIENCY_REGISTRY)
#: property groups any factor reads
FACTOR_GROUPS = 0
for _e in EFFICIENCY_REGISTRY:
    FACTOR_GROUPS |= _e.properties
#: property groups the switched-on factors read: efficiency_property_groups(config)
efficiency_property_groups = switched_union((e.switch, e.properties)
                                            for e in EFFICIENCY_REGISTRY)


def switch_on(config, names):
    """Set the switches of the named factors in ``config`` (int array) to 1, the others to 0."""
    for e in EFFICIENCY_REGISTRY:
        config[e.switch] = int(e.name in names)
    return config


def uses_collision_velocity(config) -> bool:
    """True if a factor switched on in ``config`` reads the collision velocity u0."""
    return any(int(config[e.switch]) == 1 and e.uses_collision_velocity
               for e in EFFICIENCY_REGISTRY)


@nb.njit(cache=True)
def success_probability(p1, b1, p2, b2, u0, params, config):
    """Success probability [-] of two particles (p, b in kg) at collision velocity u0 [m/s]:
    the single-pair form of ``pair_success_probability``."""
    props = np.empty((2, N_PROPS))
    fill_properties(p1, b1, params, FACTOR_GROUPS, props, 0)
    fill_properties(p2, b2, params, FACTOR_GROUPS, props, 1)
    # the scene's own slots only: a single pair's decision is never held
    return pair_success_probability(props, 0, 1, u0, params[:P.N_PARAMS], config)
