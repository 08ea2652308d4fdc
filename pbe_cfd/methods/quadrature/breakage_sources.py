"""Breakage sources of a quadrature: nodes, weights and binder per node -> moment sources.

A quadrature (QMOM's N nodes, or the nodes of any other quadrature method such as a conditional
QMOM) represents the granules as n_a = w_a particles of mass x_a holding binder b_a. The
breakage source of a mixed moment (``physics.breakage``) is then the sum over the nodes

    dM_ij/dt = sum_a w_a S(x_a) (F(i + j) - 1) x_a^i b_a^j,

S the selection function [1/s] at the node's mass, F the daughter rule's moment factor. It is
exact for every moment the quadrature reproduces when S is constant; for S = s0 (p / p_ref)^a
it is the quadrature's closure of int p^(i+a) b^j n. F(1) = 1 makes the mass and binder
sources (i + j = 1) exactly zero, node by node.

Units: nodes and binder in the method's scaled mass (SI mass / params[MASS_SCALE]), weights in
its scaled number density; sources in scaled moment units per second. No allocation.

``add_qmom_breakage`` adds QMOM's whole state layout at once.
"""
import numba as nb

from ...physics import parameters as P
from ...physics.breakage import cell_selection_factor, daughter_moment_factor, selection_function

__all__ = ["cell_selection_factor", "node_selection_rate", "add_qmom_breakage"]


@nb.njit(cache=True, inline="always")
def node_selection_rate(x, factor, params, config):
    """Selection rate S [1/s] of a node of scaled mass x, given the cell factor [1/s] from
    ``cell_selection_factor(cell, params, config)`` (0: nothing breaks)."""
    if factor == 0.0:
        return 0.0
    return selection_function(config[P.BREAKAGE_SELECTION], x * params[P.MASS_SCALE], factor,
                              params)


@nb.njit(cache=True, inline="always")
def add_qmom_breakage(out, nodes, weights, binder, n, cell, params, config):
    """Add the breakage sources of QMOM's state to ``out`` (layout of ``methods.qmom``: size
    moments M_k0, k < 2N, then binder moments M_k1, k < N, if config[BIVARIATE] == 1; the free
    droplets never break). cell: the cell row (ALPHA, THETA, COLLISION_VELOCITY, ...)."""
    factor = cell_selection_factor(cell, params, config)
    if factor == 0.0:
        return
    n_max = config[P.ORDER]
    n_size = 2 * n_max
    bivariate = config[P.BIVARIATE] == 1
    code = config[P.BREAKAGE_DAUGHTERS]
    for a in range(n):
        rate = node_selection_rate(nodes[a], factor, params, config)
        if rate == 0.0:
            continue
        flux = weights[a] * rate
        x = nodes[a]
        ba = binder[a]
        power = flux                      # w S x^k
        for k in range(n_size):
            if k != 1:                    # F(1) = 1: the mass moment gets exactly nothing
                out[k] += power * (daughter_moment_factor(code, float(k)) - 1.0)
            if bivariate and k < n_max and k != 0:     # M_k1: order k + 1; M01 exact
                out[n_size + k] += power * ba * (daughter_moment_factor(code, float(k + 1))
                                                 - 1.0)
            power *= x
