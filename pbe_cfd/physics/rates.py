"""Aggregation rate of a pair: collision frequency times success probability [m3/s].

Combines the two registries (``kernels``, ``efficiency``) with the droplet rules of
docs/physics.md section 7: where droplets are a population of their own, droplets never
aggregate with each other and a droplet meets a granule at ``droplet_factor`` times the
kernel. ``pair_rate`` works on precomputed property rows (the fast path of the moment methods;
``particle_properties`` fills them with what the scene's kernel and factors read);
``aggregation_rate`` and ``droplet_capture_rate`` are the single-pair forms used where
particles come one pair at a time (Monte Carlo, tensor builds).
"""
import numba as nb
import numpy as np

from . import parameters as P
from .injection import droplet_liquid
from .efficiency import efficiency_property_groups, pair_success_probability
from .kernels import kernel_cell_factor, kernel_property_groups, pair_collision_frequency
from .properties import N_PROPS, fill_properties


@nb.njit(cache=True, inline="always")
def particle_properties(p, b, params, config, props, row):
    """Fill ``props[row]`` for a particle of mass p [kg] holding binder b [kg]: the property
    columns the kernel config[KERNEL] and the efficiency factors switched on in ``config`` read
    (others 0; see ``physics.properties``)."""
    groups = kernel_property_groups(config[P.KERNEL]) | efficiency_property_groups(config)
    fill_properties(p, b, params, groups, props, row)


@nb.njit(cache=True, inline="always")
def pair_rate(props, a, c, cell_factor, u0, params, config):
    """Aggregation rate beta * psi [m3/s] of property rows a and c (see physics.properties);
    cell_factor from ``kernel_cell_factor``, u0 the collision velocity [m/s]."""
    beta = pair_collision_frequency(config[P.KERNEL], props, a, c, cell_factor, params)
    if beta == 0.0:
        return 0.0
    return beta * pair_success_probability(props, a, c, u0, params, config)


@nb.njit(cache=True)
def aggregation_rate(p1, b1, p2, b2, alpha, theta, u0, d43, params, config):
    """Aggregation rate beta * psi [m3/s] of two granules (p [kg], b [kg]) in a cell with
    alpha [-], theta [m2/s2], collision velocity u0 [m/s] and volume-mean diameter d43 [m]."""
    props = np.empty((2, N_PROPS))
    particle_properties(p1, b1, params, config, props, 0)
    particle_properties(p2, b2, params, config, props, 1)
    factor = kernel_cell_factor(config[P.KERNEL], alpha, theta, d43, params)
    # the scene's own slots only: a single pair's Stokes decision is never held
    return pair_rate(props, 0, 1, factor, u0, params[:P.N_PARAMS], config)


@nb.njit(cache=True)
def droplet_capture_rate(p, b, alpha, theta, u0, d43, params, config):
    """Rate [m3/s] at which one granule (p, b) [kg] captures one binder droplet:
    droplet_factor times the pair aggregation rate with the droplet (p_d, b_d) (b_d = p_d for a
    pure-liquid binder, (1 - s) p_d for a solution: physics.injection)."""
    pd = params[P.DROPLET_MASS]
    return params[P.DROPLET_FACTOR] * aggregation_rate(p, b, pd, droplet_liquid(params), alpha,
                                                       theta, u0, d43, params, config)


@nb.njit(cache=True, nogil=True)
def aggregation_rate_matrix(p1, b1, p2, b2, alpha, theta, u0, d43, params, config, out):
    """out[s, t] = aggregation_rate((p1[s], b1[s]), (p2[t], b2[t])) [m3/s] for two sets of
    particles (masses p, b [kg]) in one cell (alpha [-], theta [m2/s2], u0 [m/s], d43 [m]).

    Each particle's properties are computed once, not once per pair: the same values as the
    single-pair form, at a fraction of its cost on a tensor build's node sets."""
    n1 = p1.shape[0]
    n2 = p2.shape[0]
    props = np.empty((n1 + n2, N_PROPS))
    for s in range(n1):
        particle_properties(p1[s], b1[s], params, config, props, s)
    for t in range(n2):
        particle_properties(p2[t], b2[t], params, config, props, n1 + t)
    factor = kernel_cell_factor(config[P.KERNEL], alpha, theta, d43, params)
    own = params[:P.N_PARAMS]
    for s in range(n1):
        for t in range(n2):
            out[s, t] = pair_rate(props, s, n1 + t, factor, u0, own, config)


@nb.njit(cache=True, nogil=True)
def symmetric_aggregation_rate_matrix(p, b, alpha, theta, u0, d43, params, config, out):
    """out[s, t] = aggregation_rate((p[s], b[s]), (p[t], b[t])) [m3/s] for one set of particles
    (masses p, b [kg]) in one cell (alpha [-], theta [m2/s2], u0 [m/s], d43 [m]); one
    evaluation per unordered pair (the rate is symmetric), properties once per particle."""
    n = p.shape[0]
    props = np.empty((n, N_PROPS))
    for s in range(n):
        particle_properties(p[s], b[s], params, config, props, s)
    factor = kernel_cell_factor(config[P.KERNEL], alpha, theta, d43, params)
    own = params[:P.N_PARAMS]
    for s in range(n):
        for t in range(s, n):
            r = pair_rate(props, s, t, factor, u0, own, config)
            out[s, t] = r
            out[t, s] = r
