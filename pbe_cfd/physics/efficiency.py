"""Success probability psi of a collision (DESIGN section 3).

Each factor is a numba function ``f(p1, b1, p2, b2, u0, params)`` of the particle masses p [kg],
binder masses b [kg] and collision velocity u0 [m/s]; it returns a probability in [0, 1].
The factors that apply multiply; none means psi = 1. A new factor is one function, one entry in
``EFFICIENCIES`` and one switch in ``parameters``.
"""
import math

import numba as nb

from . import parameters as P
from .kernels import particle_diameter


@nb.njit(cache=True)
def binder_fraction(p, b):
    """Binder mass fraction y = b / p [-] of a particle of mass p [kg] holding binder b [kg]."""
    if p <= 0.0:
        return 0.0
    return b / p


@nb.njit(cache=True)
def accessible_binder(y, params):
    """Share of a particle's surface covered by accessible binder, eta(y) [-].

    eta = 1 / (1 + exp(-b_s (y - c_s))), y the binder fraction [-].
    """
    return 1.0 / (1.0 + math.exp(-params[P.GEO_SLOPE] * (y - params[P.GEO_CENTRE])))


@nb.njit(cache=True)
def geometric_efficiency(p1, b1, p2, b2, u0, params):
    """Geometric factor psi_g = 1 - (1 - eta1)(1 - eta2) [-]: at least one wet contact point."""
    e1 = accessible_binder(binder_fraction(p1, b1), params)
    e2 = accessible_binder(binder_fraction(p2, b2), params)
    return 1.0 - (1.0 - e1) * (1.0 - e2)


@nb.njit(cache=True)
def stokes_number(p1, p2, u0, params):
    """Viscous Stokes number of a pair [-]: St = 4 rho u0 d1 d2 (d1+d2)^2 / (9 mu (d1^3+d2^3)).

    Masses p [kg], collision velocity u0 [m/s]; rho the particle density, mu the binder viscosity.
    """
    rho = params[P.DENSITY]
    d1 = particle_diameter(p1, rho)
    d2 = particle_diameter(p2, rho)
    return (4.0 * rho * u0 * d1 * d2 * (d1 + d2) ** 2
            / (9.0 * params[P.BINDER_VISCOSITY] * (d1 ** 3 + d2 ** 3)))


@nb.njit(cache=True)
def critical_stokes_number(p1, b1, p2, b2, params):
    """Critical Stokes number St* = 2 ln(lambda / h_a) [-] (0 if the layer is thinner than h_a).

    lambda = r_g (phi1^(1/3) + phi2^(1/3)) [m], phi = exp(f (y - g)).
    """
    f = params[P.PHI_SLOPE]
    g = params[P.PHI_CENTRE]
    phi1 = math.exp(f * (binder_fraction(p1, b1) - g))
    phi2 = math.exp(f * (binder_fraction(p2, b2) - g))
    layer = params[P.GYRATION_RADIUS] * (phi1 ** (1.0 / 3.0) + phi2 ** (1.0 / 3.0))
    ratio = layer / params[P.ASPERITY]
    if ratio <= 1.0:
        return 0.0
    return 2.0 * math.log(ratio)


@nb.njit(cache=True)
def physical_efficiency(p1, b1, p2, b2, u0, params):
    """Viscous Stokes criterion psi_p [-]: 1 if St <= St*, else 0.

    With params[STOKES_WIDTH] = w > 0 the step becomes the smooth switch
    0.5 (1 - tanh((St - St*) / (w St*))), which tends to the step as w -> 0.
    """
    st = stokes_number(p1, p2, u0, params)
    st_crit = critical_stokes_number(p1, b1, p2, b2, params)
    width = params[P.STOKES_WIDTH]
    if width <= 0.0 or st_crit <= 0.0:
        return 1.0 if st <= st_crit else 0.0
    return 0.5 * (1.0 - math.tanh((st - st_crit) / (width * st_crit)))


@nb.njit(cache=True)
def saturation_efficiency(p1, b1, p2, b2, u0, params):
    """Liquid-saturation factor psi_s = min(1, S / S_max) [-] (seed 001 eq. 6.4.1-6.4.2).

    S = H rho_s (1 - eps) / (rho_l eps), with H the binder-to-solid mass ratio of the pair,
    H = (b1 + b2) / (p1 + p2 - b1 - b2); a pair of pure binder is fully saturated.
    """
    solid = p1 + p2 - b1 - b2
    if solid <= 0.0:
        return 1.0
    eps = params[P.POROSITY]
    ratio = (b1 + b2) / solid
    s = ratio * params[P.DENSITY] * (1.0 - eps) / (params[P.BINDER_DENSITY] * eps)
    return min(1.0, s / params[P.SATURATION_MAX])


# name -> (config switch, function, parameters it needs)
EFFICIENCIES = {
    "geometric": (P.USE_GEOMETRIC, geometric_efficiency,
                  ("accessible_binder_slope", "accessible_binder_centre")),
    "physical": (P.USE_PHYSICAL, physical_efficiency,
                 ("binder_viscosity", "binder_layer_slope", "binder_layer_centre",
                  "asperity", "gyration_radius")),
    "saturation": (P.USE_SATURATION, saturation_efficiency,
                   ("binder_density", "porosity", "saturation_max")),
}


@nb.njit(cache=True)
def success_probability(p1, b1, p2, b2, u0, params, config):
    """Product of the efficiency factors switched on in ``config`` [-], 1 if none."""
    psi = 1.0
    if config[P.USE_GEOMETRIC] == 1:
        psi *= geometric_efficiency(p1, b1, p2, b2, u0, params)
    if config[P.USE_PHYSICAL] == 1:
        psi *= physical_efficiency(p1, b1, p2, b2, u0, params)
    if config[P.USE_SATURATION] == 1:
        psi *= saturation_efficiency(p1, b1, p2, b2, u0, params)
    return psi
