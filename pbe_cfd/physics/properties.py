"""Per-particle properties computed once per particle (or quadrature node) per evaluation.

The pair rates need diameters, cube roots and exponentials of each particle; computing them
once per particle instead of once per pair is what makes the N^2 pair loop cheap. A particle's
properties are one row of a float array ``props`` with the columns named here.

Columns come in groups; each kernel and efficiency factor of the registries
(``physics.kernels``, ``physics.efficiency``) declares the groups it reads, and only those are
computed (the others are 0). ``physics.rates.particle_properties`` picks the groups of a
scene's kernel and factors; ``fill_properties`` computes given groups.
"""
import math

import numba as nb

from . import parameters as P

MASS = 0                 # p [kg]
BINDER = 1               # b [kg]
DIAMETER = 2             # d = (6 p / (pi rho_s))^(1/3) [m]
INV_DIAMETER_CUBED = 3   # 1 / d^3 [1/m3]
EKE_CBRT = 4             # x^(1/3), x = p / (rho_s v_ref) [-]
EKE_INV = 5              # 1 / x [-]
ACCESSIBLE_BINDER = 6    # eta(y) of the geometric factor [-]
LAYER_CBRT = 7           # phi(y)^(1/3) of the binder layer [-]
N_PROPS = 8

# ---- property groups (bit flags): MASS and BINDER are always filled ----------------------
DIAMETERS = 1            # DIAMETER, INV_DIAMETER_CUBED
EKE_SIZES = 2            # EKE_CBRT, EKE_INV
WETTING = 4              # ACCESSIBLE_BINDER
BINDER_LAYER = 8         # LAYER_CBRT
ALL_GROUPS = DIAMETERS | EKE_SIZES | WETTING | BINDER_LAYER


@nb.njit(cache=True, inline="always")
def fill_properties(p, b, params, groups, props, row):
    """Fill ``props[row]`` for a particle of mass p [kg] holding binder b [kg]: the columns of
    the property ``groups`` (bit flags above), the others 0.

    Inlined into its callers (numba IR inlining): a call with three array arguments costs as
    much as the arithmetic here, and the QMOM right-hand side calls it once per node.
    """
    props[row, MASS] = p
    props[row, BINDER] = b
    rho = params[P.DENSITY]
    if groups & DIAMETERS:
        d = (6.0 * p / (math.pi * rho)) ** (1.0 / 3.0)
        props[row, DIAMETER] = d
        props[row, INV_DIAMETER_CUBED] = 1.0 / (d * d * d)
    else:
        props[row, DIAMETER] = 0.0
        props[row, INV_DIAMETER_CUBED] = 0.0
    if groups & EKE_SIZES:
        x = p / (params[P.REFERENCE_VOLUME] * rho)
        props[row, EKE_CBRT] = x ** (1.0 / 3.0)
        props[row, EKE_INV] = 1.0 / x
    else:
        props[row, EKE_CBRT] = 0.0
        props[row, EKE_INV] = 0.0
    y = b / p if p > 0.0 else 0.0
    if groups & WETTING:
        props[row, ACCESSIBLE_BINDER] = 1.0 / (1.0 + math.exp(-params[P.GEO_SLOPE]
                                                               * (y - params[P.GEO_CENTRE])))
    else:
        props[row, ACCESSIBLE_BINDER] = 0.0
    if groups & BINDER_LAYER:
        # phi^(1/3) = exp(f (y - g) / 3)
        props[row, LAYER_CBRT] = math.exp(params[P.PHI_SLOPE] * (y - params[P.PHI_CENTRE]) / 3.0)
    else:
        props[row, LAYER_CBRT] = 0.0
