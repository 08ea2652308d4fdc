"""Minimum fluidisation velocity of a granular bed: Wen & Yu (1966), docs/physics.md section 14.

Re_mf = sqrt(33.7^2 + 0.0408 Ar) - 33.7,  Ar = rho_g (rho_s - rho_g) g d^3 / mu^2,
U_mf = Re_mf mu / (rho_g d).

Wen & Yu's correlation of the Ergun equation at incipient fluidisation, with their two
empirical groups 1/(phi eps_mf^3) ~ 14 and (1 - eps_mf)/(phi^2 eps_mf^3) ~ 11 (Wen, C. Y. and
Yu, Y. H., "A generalized method for predicting the minimum fluidization velocity", AIChE J.
12 (1966) 610-612). All SI.
"""
from __future__ import annotations

import math

#: standard gravity [m/s2]
GRAVITY = 9.81


def archimedes(d: float, rho_s: float, rho_g: float, mu: float, g: float = GRAVITY) -> float:
    """Archimedes number Ar [-] of a particle of diameter d [m] and density rho_s [kg/m3] in a
    gas of density rho_g [kg/m3] and viscosity mu [Pa s]."""
    return rho_g * (rho_s - rho_g) * g * d ** 3 / mu ** 2


def minimum_fluidisation_velocity(d: float, rho_s: float, rho_g: float, mu: float,
                                  g: float = GRAVITY) -> float:
    """Wen & Yu's minimum fluidisation velocity U_mf [m/s] (superficial) of a bed of particles
    of diameter d [m] and density rho_s [kg/m3] in a gas of density rho_g [kg/m3] and viscosity
    mu [Pa s]."""
    if not (d > 0 and rho_s > rho_g > 0 and mu > 0):
        raise ValueError(f"minimum_fluidisation_velocity: expected d > 0 m, rho_s > rho_g > 0 "
                         f"kg/m3, mu > 0 Pa s; got d={d!r}, rho_s={rho_s!r}, rho_g={rho_g!r}, "
                         f"mu={mu!r}")
    ar = archimedes(d, rho_s, rho_g, mu, g)
    re_mf = math.sqrt(33.7 ** 2 + 0.0408 * ar) - 33.7
    return re_mf * mu / (rho_g * d)
