"""Collision frequencies beta(p, p') [m3/s] of the aggregation kernels (DESIGN section 3).

Each kernel is a numba function ``f(p1, p2, alpha, theta, d43, params)`` of the two particle
masses p1, p2 [kg], the cell's solids fraction alpha [-], granular temperature theta [m2/s2]
and volume-mean diameter d43 [m]; ``params`` is the float array of ``physics.parameters``.
A new kernel is one function plus one entry in ``KERNELS``; ``collision_frequency`` dispatches
on the integer code (numba needs a static call graph to cache compiled code).
"""
import math

import numba as nb

from . import parameters as P


@nb.njit(cache=True)
def particle_diameter(p, density):
    """Volume-equivalent diameter [m] of a particle of mass p [kg] and density [kg/m3]."""
    return (6.0 * p / (math.pi * density)) ** (1.0 / 3.0)


@nb.njit(cache=True)
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


@nb.njit(cache=True)
def constant_kernel(p1, p2, alpha, theta, d43, params):
    """beta = k0 [m3/s]; k0 = params[RATE] in m3/s."""
    return params[P.RATE]


@nb.njit(cache=True)
def sum_kernel(p1, p2, alpha, theta, d43, params):
    """beta = k0 (p1 + p2) [m3/s]; masses in kg, k0 in m3/(kg s)."""
    return params[P.RATE] * (p1 + p2)


@nb.njit(cache=True)
def product_kernel(p1, p2, alpha, theta, d43, params):
    """beta = k0 p1 p2 [m3/s]; masses in kg, k0 in m3/(kg2 s)."""
    return params[P.RATE] * p1 * p2


@nb.njit(cache=True)
def eke_kernel(p1, p2, alpha, theta, d43, params):
    """Equipartition of kinetic energy (Hounslow 1998) [m3/s].

    beta = k0 (x1^(1/3) + x2^(1/3))^2 sqrt(1/x1 + 1/x2), x = v / v_ref, v = p / rho_s;
    k0 in m3/s, v_ref = params[REFERENCE_VOLUME] in m3.
    """
    vref = params[P.REFERENCE_VOLUME] * params[P.DENSITY]   # reference mass [kg]
    x1 = p1 / vref
    x2 = p2 / vref
    s = x1 ** (1.0 / 3.0) + x2 ** (1.0 / 3.0)
    return params[P.RATE] * s * s * math.sqrt(1.0 / x1 + 1.0 / x2)


@nb.njit(cache=True)
def ktgf_kernel(p1, p2, alpha, theta, d43, params):
    """Kinetic-theory kernel (seed 001 eq. 5.3.5) [m3/s].

    beta = k0 g0(alpha) sqrt(theta) (d1 + d2)^2 sqrt(d43^3 (1/d1^3 + 1/d2^3)), k0 dimensionless,
    theta [m2/s2], diameters [m] from the particle density, d43 the cell's volume-mean diameter.
    """
    rho = params[P.DENSITY]
    d1 = particle_diameter(p1, rho)
    d2 = particle_diameter(p2, rho)
    g0 = radial_distribution(alpha, params[P.ALPHA_MAX])
    d43c = d43 * d43 * d43
    return (params[P.RATE] * g0 * math.sqrt(max(theta, 0.0)) * (d1 + d2) ** 2
            * math.sqrt(d43c * (1.0 / (d1 * d1 * d1) + 1.0 / (d2 * d2 * d2))))


# name -> (code, function, rate unit, needs local fields)
KERNELS = {
    "constant": (0, constant_kernel, "m3/s"),
    "sum": (1, sum_kernel, "m3/(kg s)"),
    "product": (2, product_kernel, "m3/(kg2 s)"),
    "eke": (3, eke_kernel, "m3/s"),
    "ktgf": (4, ktgf_kernel, "dimensionless"),
}
KERNEL_USES_CELL = {"ktgf": ("solids_fraction", "granular_temperature", "d43")}


@nb.njit(cache=True)
def collision_frequency(code, p1, p2, alpha, theta, d43, params):
    """Collision frequency [m3/s] of the kernel with registry code ``code`` (see KERNELS)."""
    if code == 0:
        return constant_kernel(p1, p2, alpha, theta, d43, params)
    elif code == 1:
        return sum_kernel(p1, p2, alpha, theta, d43, params)
    elif code == 2:
        return product_kernel(p1, p2, alpha, theta, d43, params)
    elif code == 3:
        return eke_kernel(p1, p2, alpha, theta, d43, params)
    else:
        return ktgf_kernel(p1, p2, alpha, theta, d43, params)
