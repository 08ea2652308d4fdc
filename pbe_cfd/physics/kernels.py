"""Collision frequencies beta [m3/s] of the aggregation kernels (docs/physics.md section 4):
the kernel registry.

Each kernel is a numba function ``f(props, a, c, cell_factor, params)`` of two rows a, c of the
per-particle property array (``physics.properties``) and the cell factor, the part of the
kernel shared by every pair of a cell: k0, or a function ``g(alpha, theta, d43, params)`` of
the cell (ktgf: k0 g0(alpha) sqrt(Theta) d43^(3/2)).

Adding a kernel (see CONTRIBUTING.md): write its numba function (``inline="always"``) and add
one ``Kernel`` entry to ``KERNEL_REGISTRY`` with a new code. Everything else follows from the
entry: the scene accepts its name, the dispatchers below get its branch, the per-particle
properties it reads are computed, a cell-dependent factor is evaluated per cell (with d43 where
it asks for it), ``pbe-cfd plan`` names the cell fields it needs, and the registry tests check
it (symmetry, finiteness, dispatch).
"""
import math
from typing import Callable, NamedTuple

import numba as nb
import numpy as np

from . import parameters as P
from .properties import (DIAMETER, DIAMETERS, EKE_CBRT, EKE_INV, EKE_SIZES, INV_DIAMETER_CUBED,
                         MASS, N_PROPS, fill_properties)
from .registry import cell_dispatch, code_lookup, pair_dispatch

# ---- kernel codes (config[P.KERNEL]) ------------------------------------------------------
CONSTANT = 0
SUM = 1
PRODUCT = 2
EKE = 3
KTGF = 4


# ---- kinetic theory of granular flow --------------------------------------------------------
@nb.njit(cache=True)
def collision_velocity(theta):
    """Mean collision velocity u0 = 4 sqrt(Theta / pi) [m/s] of granules at granular temperature
    theta [m2/s2] (a float or an array; negative values count as 0). numba-compiled, so numba
    kernels call the same function."""
    return 4.0 * np.sqrt(np.maximum(theta, 0.0) / math.pi)


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


# ---- cell factors ---------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def rate_constant(alpha, theta, d43, params):
    """Cell factor of a kernel that does not depend on the cell: k0 = params[RATE]."""
    return params[P.RATE]


@nb.njit(cache=True, inline="always")
def ktgf_cell_factor(alpha, theta, d43, params):
    """Cell factor of the ktgf kernel k0 g0(alpha) sqrt(Theta) d43^(3/2) [m^(5/2)/s] (alpha
    [-], Theta [m2/s2], d43 [m]). Like OpenFOAM's radial models, g0 is evaluated at
    min(alpha, alpha_min_friction) where params[ALPHA_MIN_FRICTION] > 0 (the scene's
    ``alpha_min_friction``; unset: no cap)."""
    cap = params[P.ALPHA_MIN_FRICTION]
    if cap > 0.0 and alpha > cap:
        alpha = cap
    g0 = radial_distribution(alpha, params[P.ALPHA_MAX])
    return params[P.RATE] * g0 * math.sqrt(max(theta, 0.0)) * d43 ** 1.5


# ---- kernels --------------------------------------------------------------------------------
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


# ---- the registry ---------------------------------------------------------------------------
class Kernel(NamedTuple):
    """One aggregation kernel of the registry.

    name        the scene's ``[aggregation] kernel``
    code        config[P.KERNEL] (unique, >= 0)
    function    numba f(props, a, c, cell_factor, params) -> beta [m3/s]
    unit        unit of k0 (the scene's ``rate``)
    properties  property groups it reads (``physics.properties`` bit flags)
    cell_factor numba g(alpha, theta, d43, params) -> the factor shared by a cell's pairs
    uses_d43    True if cell_factor needs the cell's volume-mean diameter d43 [m]
    cell_fields what the cell must provide (for ``pbe-cfd plan`` and scene checks):
                "solids_fraction", "granular_temperature", "d43"
    small_size_exponent  q >= 0 with beta(x1, x2) ~ x1^(-q) as x1 -> 0 at fixed x2 [-] (0: beta
                stays finite): a number density ~ x^(l - 1) near 0 has finite aggregation
                sources only if l > q (EQMOM's kernels, docs/physics.md)
    """
    name: str
    code: int
    function: Callable
    unit: str
    properties: int = 0
    cell_factor: Callable = rate_constant
    uses_d43: bool = False
    cell_fields: tuple = ()
    small_size_exponent: float = 0.0


KERNEL_REGISTRY = (
    Kernel("constant", CONSTANT, constant_kernel, "m3/s"),
    Kernel("sum", SUM, sum_kernel, "m3/(kg s)"),
    Kernel("product", PRODUCT, product_kernel, "m3/(kg2 s)"),
    Kernel("eke", EKE, eke_kernel, "m3/s", properties=EKE_SIZES, small_size_exponent=0.5),
    Kernel("ktgf", KTGF, ktgf_kernel, "dimensionless", properties=DIAMETERS,
           cell_factor=ktgf_cell_factor, uses_d43=True,
           cell_fields=("solids_fraction", "granular_temperature", "d43"),
           small_size_exponent=0.5),
)

#: name -> registry entry
KERNEL_BY_NAME = {k.name: k for k in KERNEL_REGISTRY}
#: name -> (code, function, unit of k0)
KERNELS = {k.name: (k.code, k.function, k.unit) for k in KERNEL_REGISTRY}
#: name -> the cell fields of a kernel that depends on the cell
KERNEL_USES_CELL = {k.name: k.cell_fields for k in KERNEL_REGISTRY if k.cell_fields}

# ---- dispatch by code (numba; one branch per entry, unknown code: NaN / 0 / False) ----------
#: beta [m3/s] of property rows a, c: pair_collision_frequency(code, props, a, c, factor, params)
pair_collision_frequency = pair_dispatch((k.code, k.function) for k in KERNEL_REGISTRY)
#: the cell factor: kernel_cell_factor(code, alpha [-], theta [m2/s2], d43 [m], params)
kernel_cell_factor = cell_dispatch((k.code, k.cell_factor) for k in KERNEL_REGISTRY)
#: True if the kernel's cell factor needs d43: kernel_uses_d43(code)
kernel_uses_d43 = code_lookup(((k.code, k.uses_d43) for k in KERNEL_REGISTRY), False)
#: property groups the kernel reads: kernel_property_groups(code)
kernel_property_groups = code_lookup(((k.code, k.properties) for k in KERNEL_REGISTRY), 0)
#: q of beta ~ x1^(-q) for a small partner x1: kernel_small_size_exponent(code) [-]
kernel_small_size_exponent = code_lookup(((k.code, float(k.small_size_exponent))
                                          for k in KERNEL_REGISTRY), 0.0)


@nb.njit(cache=True)
def collision_frequency(code, p1, p2, alpha, theta, d43, params):
    """Collision frequency [m3/s] of two particles of masses p1, p2 [kg] in a cell with
    alpha [-], theta [m2/s2] and d43 [m]: the single-pair form of the registry kernels (NaN
    for an unknown code)."""
    props = np.empty((2, N_PROPS))
    groups = kernel_property_groups(code)
    fill_properties(p1, 0.0, params, groups, props, 0)
    fill_properties(p2, 0.0, params, groups, props, 1)
    factor = kernel_cell_factor(code, alpha, theta, d43, params)
    return pair_collision_frequency(code, props, 0, 1, factor, params)
