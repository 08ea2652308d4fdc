"""Success probability psi of a collision (DESIGN section 3).

Each factor is a numba function ``f(props, a, c, u0, params)`` of two rows of the per-particle
property array (``physics.properties``: masses p, binder b [kg], diameters [m], eta(y),
phi(y)^(1/3)) and the collision velocity u0 [m/s]; it returns a probability in [0, 1]. The
factors that apply multiply; none means psi = 1. A new factor is one function, one entry in
``EFFICIENCIES`` and one switch in ``parameters``.
"""
import math

import numba as nb
import numpy as np

from . import parameters as P
from .properties import (ACCESSIBLE_BINDER, BINDER, DIAMETER, LAYER_CBRT, MASS, N_PROPS,
                         all_properties_config, particle_properties)


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


@nb.njit(cache=True, inline="always")
def physical_efficiency(props, a, c, u0, params):
    """Viscous Stokes criterion psi_p [-]: 1 if St <= St*, else 0.

    With params[STOKES_WIDTH] = w > 0 the step becomes the smooth switch
    0.5 (1 - tanh((St - St*) / (w St*))), which tends to the step as w -> 0.
    """
    st = stokes_number(props, a, c, u0, params)
    st_crit = critical_stokes_number(props, a, c, params)
    width = params[P.STOKES_WIDTH]
    if width <= 0.0 or st_crit <= 0.0:
        return 1.0 if st <= st_crit else 0.0
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


# name -> (config switch, function, material keys it needs)
EFFICIENCIES = {
    "geometric": (P.USE_GEOMETRIC, geometric_efficiency,
                  ("accessible_binder_slope", "accessible_binder_centre")),
    "physical": (P.USE_PHYSICAL, physical_efficiency,
                 ("binder_viscosity", "binder_layer_slope", "binder_layer_centre",
                  "asperity", "gyration_radius")),
    "saturation": (P.USE_SATURATION, saturation_efficiency,
                   ("binder_density", "porosity", "saturation_max")),
}


@nb.njit(cache=True, inline="always")
def pair_success_probability(props, a, c, u0, params, config):
    """Product of the efficiency factors switched on in ``config`` [-], 1 if none."""
    psi = 1.0
    if config[P.USE_GEOMETRIC] == 1:
        psi *= geometric_efficiency(props, a, c, u0, params)
    if config[P.USE_PHYSICAL] == 1:
        if psi > 0.0:
            psi *= physical_efficiency(props, a, c, u0, params)
    if config[P.USE_SATURATION] == 1:
        psi *= saturation_efficiency(props, a, c, u0, params)
    return psi


@nb.njit(cache=True)
def success_probability(p1, b1, p2, b2, u0, params, config):
    """Success probability [-] of two particles (p, b in kg) at collision velocity u0 [m/s]:
    the single-pair form of ``pair_success_probability``."""
    props = np.empty((2, N_PROPS))
    full = all_properties_config(config)
    particle_properties(p1, b1, params, full, props, 0)
    particle_properties(p2, b2, params, full, props, 1)
    return pair_success_probability(props, 0, 1, u0, params, config)


@nb.njit(cache=True)
def single_pair(fn_code, p1, b1, p2, b2, u0, params):
    """One named factor (code = position in EFFICIENCIES) of two particles; for tests/tools."""
    props = np.empty((2, N_PROPS))
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.USE_GEOMETRIC] = 1
    config[P.USE_PHYSICAL] = 1
    particle_properties(p1, b1, params, config, props, 0)
    particle_properties(p2, b2, params, config, props, 1)
    if fn_code == 0:
        return geometric_efficiency(props, 0, 1, u0, params)
    elif fn_code == 1:
        return physical_efficiency(props, 0, 1, u0, params)
    return saturation_efficiency(props, 0, 1, u0, params)
