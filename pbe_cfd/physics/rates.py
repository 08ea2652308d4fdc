"""Aggregation rate of a pair: collision frequency times success probability [m3/s].

Combines ``kernels`` and ``efficiency`` with the droplet rules of DESIGN section 3: where droplets
are a population of their own, droplets never aggregate with each other and a droplet meets a
granule at ``droplet_factor`` times the kernel.
"""
import numba as nb

from . import parameters as P
from .efficiency import success_probability
from .kernels import collision_frequency


@nb.njit(cache=True)
def aggregation_rate(p1, b1, p2, b2, alpha, theta, u0, d43, params, config):
    """Aggregation rate beta * psi [m3/s] of two granules (p [kg], b [kg]).

    alpha [-], theta [m2/s2], u0 [m/s] and d43 [m] are the cell's local values.
    """
    beta = collision_frequency(config[P.KERNEL], p1, p2, alpha, theta, d43, params)
    if beta == 0.0:
        return 0.0
    return beta * success_probability(p1, b1, p2, b2, u0, params, config)


@nb.njit(cache=True)
def droplet_capture_rate(p, b, alpha, theta, u0, d43, params, config):
    """Rate [m3/s] at which one granule (p, b) [kg] captures one binder droplet.

    droplet_factor times the pair aggregation rate with the droplet (p_d, b = p_d).
    """
    pd = params[P.DROPLET_MASS]
    return params[P.DROPLET_FACTOR] * aggregation_rate(p, b, pd, pd, alpha, theta, u0, d43,
                                                       params, config)
