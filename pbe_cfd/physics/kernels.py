"""Collision frequencies beta [m3/s] of the aggregation kernels (DESIGN section 3).

Each kernel is a numba function ``f(props, a, c, cell_factor, params)`` of two rows a, c of the
per-particle property array (``physics.properties``) and the cell factor of
``kernel_cell_factor`` (k0, or for ktgf k0 g0(alpha) sqrt(Theta) d43^(3/2), which is the same for
every pair of a cell). A new kernel is one function plus one entry in ``KERNELS`` (and its
branch in the two dispatchers: numba needs a static call graph to cache compiled code).
"""
import math

import numba as nb
import numpy as np

from . import parameters as P
from .properties import (DIAMETER, EKE_CBRT, EKE_INV, INV_DIAMETER_CUBED, MASS, N_PROPS,
                         particle_properties)


@nb.njit(cache=True)
def particle_diameter(p, density):
    """Volume-equivalent diameter [m] of a particle of mass p [kg] and density [kg/m3]."""
    return (6.0 * p / (math.pi * density)) ** (1.0 / 3.0)


@nb.njit(cache=True, inline="always")
def radial_distribution(alpha, alpha_max):
    """Sinclair-Jackson radial distribution g0 = 1/(1 - (alpha/alpha_max)^(1/3)) [-].

    alpha, alpha_max: solids fractions [-]; alpha >= alpha_max returns +inf.
    """
    if alpha <= 0.0:
        return 1.0
    ratio = alpha / alpha_max
    if ratio >= 1.0:
        return math.inf
    return 1.0 / (1.0 - ratio ** (1.0 / 3.0))


@nb.njit(cache=True, inline="always")
def constant_kernel(props, a, c, cell_factor, params):
    """beta = k0 [m3/s]; cell_factor = k0 in m3/s."""
    return cell_factor


@nb.njit(cache=True, inline="always")
def sum_kernel(props, a, c, cell_factor, params):
    """beta = k0 (p1 + p2) [m3/s]; masses in kg, k0 in m3/(kg s)."""
    return cell_factor * (props[a, MASS] + props[c, MASS])


@nb.njit(cache=True, inline="always")
def product_kernel(props, a, c, cell_factor, params):
    """beta = k0 p1 p2 [m3/s]; masses in kg, k0 in m3/(kg2 s)."""
    return cell_factor * props[a, MASS] * props[c, MASS]


@nb.njit(cache=True, inline="always")
def eke_kernel(props, a, c, cell_factor, params):
    """Equipartition of kinetic energy (Hounslow 1998) [m3/s].

    beta = k0 (x1^(1/3) + x2^(1/3))^2 sqrt(1/x1 + 1/x2), x = v / v_ref, v = p / rho_s;
    k0 in m3/s, v_ref = params[REFERENCE_VOLUME] in m3.
    """
    s = props[a, EKE_CBRT] + props[c, EKE_CBRT]
    return cell_factor * s * s * math.sqrt(props[a, EKE_INV] + props[c, EKE_INV])


@nb.njit(cache=True, inline="always")
def ktgf_kernel(props, a, c, cell_factor, params):
    """Kinetic-theory kernel (seed 001 eq. 5.3.5) [m3/s].

    beta = k0 g0(alpha) sqrt(Theta) (d1 + d2)^2 sqrt(d43^3 (1/d1^3 + 1/d2^3)); the pair part
    is (d1 + d2)^2 sqrt(1/d1^3 + 1/d2^3) [m^(1/2)], the cell factor k0 g0 sqrt(Theta) d43^(3/2)
    [m^(5/2)/s], k0 dimensionless, Theta [m2/s2], diameters [m] from the particle density.
    """
    s = props[a, DIAMETER] + props[c, DIAMETER]
    return cell_factor * s * s * math.sqrt(props[a, INV_DIAMETER_CUBED]
                                           + props[c, INV_DIAMETER_CUBED])


# name -> (code, function, unit of k0)
KERNELS = {
    "constant": (0, constant_kernel, "m3/s"),
    "sum": (1, sum_kernel, "m3/(kg s)"),
    "product": (2, product_kernel, "m3/(kg2 s)"),
    "eke": (3, eke_kernel, "m3/s"),
    "ktgf": (4, ktgf_kernel, "dimensionless"),
}
KERNEL_USES_CELL = {"ktgf": ("solids_fraction", "granular_temperature", "d43")}


@nb.njit(cache=True, inline="always")
def kernel_cell_factor(code, alpha, theta, d43, params):
    """The part of the kernel shared by every pair of a cell: k0, or for ktgf
    k0 g0(alpha) sqrt(Theta) d43^(3/2) (alpha [-], Theta [m2/s2], d43 [m]).

    Like OpenFOAM's radial models, g0 is evaluated at min(alpha, alpha_min_friction) where
    params[ALPHA_MIN_FRICTION] > 0 (the scene's ``alpha_min_friction``; unset: no cap).
    """
    if code == 4:
        cap = params[P.ALPHA_MIN_FRICTION]
        if cap > 0.0 and alpha > cap:
            alpha = cap
        g0 = radial_distribution(alpha, params[P.ALPHA_MAX])
        return params[P.RATE] * g0 * math.sqrt(max(theta, 0.0)) * d43 ** 1.5
    return params[P.RATE]


@nb.njit(cache=True, inline="always")
def pair_collision_frequency(code, props, a, c, cell_factor, params):
    """Collision frequency [m3/s] of property rows a, c for the kernel with code ``code``."""
    if code == 0:
        return constant_kernel(props, a, c, cell_factor, params)
    elif code == 1:
        return sum_kernel(props, a, c, cell_factor, params)
    elif code == 2:
        return product_kernel(props, a, c, cell_factor, params)
    elif code == 3:
        return eke_kernel(props, a, c, cell_factor, params)
    else:
        return ktgf_kernel(props, a, c, cell_factor, params)


@nb.njit(cache=True)
def collision_frequency(code, p1, p2, alpha, theta, d43, params):
    """Collision frequency [m3/s] of two particles of masses p1, p2 [kg] in a cell with
    alpha [-], theta [m2/s2] and d43 [m]: the single-pair form of the registry kernels."""
    props = np.empty((2, N_PROPS))
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.KERNEL] = code
    particle_properties(p1, 0.0, params, config, props, 0)
    particle_properties(p2, 0.0, params, config, props, 1)
    factor = kernel_cell_factor(code, alpha, theta, d43, params)
    return pair_collision_frequency(code, props, 0, 1, factor, params)
