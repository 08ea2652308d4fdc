"""Binder droplet source (docs/physics.md section 7): droplets of sprayed binder of mass p_d, of
which the liquid b_d = (1 - s) p_d wets (the coordinate b) and the dissolved solids s p_d join
the granule's dry mass (s = params[DROPLET_SOLIDS], the solids fraction; s = 0: pure liquid,
b_d = p_d to the last bit)."""
import math

import numba as nb

from . import parameters as P


def droplet_mass(diameter, binder_density):
    """Mass [kg] of a binder droplet of diameter [m] and density [kg/m3]."""
    return binder_density * math.pi / 6.0 * diameter ** 3


@nb.njit(cache=True, inline="always")
def droplet_number_entry(config):
    """State entry of the free droplets' number n_d: the last (config[SEPARATE_DROPLETS] =
    1), -1 without droplets of their own."""
    return config[P.N_STATE] - 1 if config[P.SEPARATE_DROPLETS] == 1 else -1


@nb.njit(cache=True, inline="always")
def evaporated_entry(config):
    """State entry of the evaporated liquid E (with drying): the last, or the one before the
    droplet number."""
    return config[P.N_STATE] - 1 - config[P.SEPARATE_DROPLETS]


@nb.njit(cache=True, inline="always")
def droplet_liquid_entry(config):
    """State entry of the free droplets' liquid L_d (config[DROPLET_LIQUID] = 1: drying with
    droplets of their own; the entries end L_d, evaporated liquid, n_d), -1 without."""
    return config[P.N_STATE] - 3 if config[P.DROPLET_LIQUID] == 1 else -1


@nb.njit(cache=True, inline="always")
def droplet_liquid(params):
    """Liquid binder b_d = (1 - s) p_d [kg] of one droplet (p_d = params[DROPLET_MASS] [kg],
    s = params[DROPLET_SOLIDS] [-]); exactly p_d when s = 0."""
    return params[P.DROPLET_MASS] * (1.0 - params[P.DROPLET_SOLIDS])


def droplet_moment(droplet_mass, droplet_liquid, i, j):
    """p_d^i b_d^j [kg^(i+j)] of one droplet (mass p_d [kg], liquid b_d [kg]); p_d^(i+j) when
    the droplet is pure liquid (the same floating-point value as a pure-binder droplet's)."""
    if droplet_liquid == droplet_mass:
        return droplet_mass ** (i + j)
    return droplet_mass ** i * droplet_liquid ** j


@nb.njit(cache=True)
def injection_moment_rate(rate, droplet_mass, i, j):
    """Source of the mixed moment M_ij [kg^(i+j)/(m3 s)] of pure-liquid droplets injected as
    ordinary particles at ``rate`` droplets/(m3 s): S_ij = rate p_d^(i+j)."""
    return rate * droplet_mass ** (i + j)
