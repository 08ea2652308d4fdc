"""One entry point per operation for every moment method, chosen by config[METHOD].

The integrator calls ``method_rhs``, ``method_realizable`` and ``method_project``; each method
module provides the three functions with the same signature
``(state, [out, cell,] aux, params, config)``. numba caches compiled code only for a static call
graph, so the choice is an if-chain on the method code rather than a function argument.
"""
import numba as nb

from ..physics import parameters as P
from .qmom import qmom_project, qmom_realizable, qmom_rhs

QMOM = 0
LAGUERRE = 1
METHOD_CODES = {"qmom": QMOM, "laguerre": LAGUERRE}


@nb.njit(cache=True)
def method_rhs(state, out, cell, aux, params, config):
    """d(state)/dt [scaled units per s] of one cell for the method config[METHOD]."""
    qmom_rhs(state, out, cell, aux, params, config)


@nb.njit(cache=True)
def method_realizable(state, aux, params, config):
    """True if the state is a realizable moment set for the method config[METHOD]."""
    return qmom_realizable(state, aux, params, config)


@nb.njit(cache=True)
def method_project(state, aux, params, config):
    """Re-project an accepted state onto the method's realizable set, in place."""
    qmom_project(state, aux, params, config)
