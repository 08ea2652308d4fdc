"""Binder droplet source (docs/physics.md section 7): pure-binder droplets of mass p_d, b = p_d."""
import math

import numba as nb


def droplet_mass(diameter, binder_density):
    """Mass [kg] of a binder droplet of diameter [m] and density [kg/m3]."""
    return binder_density * math.pi / 6.0 * diameter ** 3


@nb.njit(cache=True)
def injection_moment_rate(rate, droplet_mass, i, j):
    """Source of the mixed moment M_ij [kg^(i+j)/(m3 s)] of droplets injected as ordinary
    particles at ``rate`` droplets/(m3 s): S_ij = rate p_d^(i+j)."""
    return rate * droplet_mass ** (i + j)
