"""One entry point per operation for every moment method, chosen by config[METHOD].

The integrator calls ``method_rhs``, ``method_realizable`` and ``method_project``; each method
module provides the three functions with the same signature
``(state, [out, cell,] aux, params, config, work)``, ``work`` a float scratch array of
``WORK_SIZE`` allocated once per cell so that no call allocates. numba caches compiled code only for a static call
graph, so the choice is an if-chain on the method code rather than a function argument.
"""
import numba as nb

from ..physics import parameters as P
from .laguerre import laguerre_project, laguerre_realizable, laguerre_rhs
from .qmom import qmom_project, qmom_realizable, qmom_rhs

#: method codes (config[P.METHOD]); the registry of methods is ``pbe_cfd.methods.registry``
QMOM = 0
LAGUERRE = 1


#: length of the per-cell float work array handed to every method function
WORK_SIZE = 2048


@nb.njit(cache=True)
def method_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt [scaled units per s] of one cell for the method config[METHOD]."""
    if config[P.METHOD] == LAGUERRE:
        laguerre_rhs(state, out, cell, aux, params, config, work)
    else:
        qmom_rhs(state, out, cell, aux, params, config, work)


@nb.njit(cache=True)
def method_realizable(state, aux, params, config, work):
    """True if the state is a realizable moment set for the method config[METHOD]."""
    if config[P.METHOD] == LAGUERRE:
        return laguerre_realizable(state, aux, params, config, work)
    return qmom_realizable(state, aux, params, config, work)


@nb.njit(cache=True)
def method_project(state, aux, params, config, work):
    """Re-project an accepted state onto the method's realizable set, in place."""
    if config[P.METHOD] == LAGUERRE:
        laguerre_project(state, aux, params, config, work)
    else:
        qmom_project(state, aux, params, config, work)
