"""One entry point per operation for every moment method.

Each method module provides ``*_rhs``, ``*_realizable``, ``*_project`` and ``*_conserved`` with
the signatures ``(state, [out, cell,] aux, params, config, work)`` and ``(config, params,
pivots, coefs)``; ``work`` is a float scratch array of ``WORK_SIZE`` allocated once per cell so
that no call allocates.

Two ways in:

* ``rhs(method, ...)``, ``realizable(method, ...)``, ``project(method, ...)``,
  ``conserved(method, ...)`` take the method code as their first argument. Called with a
  compile-time constant code (an ``IntegerLiteral``, see ``numba.literally``) they compile into
  the caller as that method's function alone, so a scene compiles only the method it uses
  (numba prunes no branch on literal integers; the choice is made at typing time here).
* ``method_rhs``, ``method_realizable``, ``method_project`` choose by ``config[METHOD]`` at run
  time (an if-chain: every method is compiled); for callers that do not know the method at
  compile time (benchmarks, the transport's repair pass).
"""
import numba as nb
import numpy as np
from numba.core import types
from numba.extending import overload

from ..physics import parameters as P
from .cqmom.cqmom import cqmom_conserved, cqmom_project, cqmom_realizable
from .cqmom.sources import cqmom_rhs
from .laguerre.rhs import (laguerre_conserved, laguerre_project, laguerre_realizable,
                           laguerre_rhs)
from .eqmom.sources import eqmom_conserved, eqmom_project, eqmom_realizable, eqmom_rhs
from .qmom.qmom import qmom_conserved, qmom_project, qmom_realizable, qmom_rhs

#: method codes (config[P.METHOD]); the registry of methods is ``pbe_cfd.methods.registry``
QMOM = 0
LAGUERRE = 1
CQMOM = 2
EQMOM = 3

#: length of the per-cell float work array handed to every method function
WORK_SIZE = 2048


def _code(method):
    """The literal method code of a numba type, or None if not a literal."""
    if isinstance(method, types.IntegerLiteral):
        return method.literal_value
    return None


# ---- literal dispatch: the stubs run only through numba --------------------------------------
def rhs(method, state, out, cell, aux, params, config, work):
    """d(state)/dt [scaled units per s] of one cell for the method with code ``method``."""
    raise NotImplementedError("numba only")


def realizable(method, state, aux, params, config, work):
    """True if the state is a realizable moment set for the method ``method``."""
    raise NotImplementedError("numba only")


def project(method, state, aux, params, config, work):
    """Re-project an accepted state onto the method's realizable set, in place."""
    raise NotImplementedError("numba only")


def conserved(method, config, params, pivots, coefs):
    """Linear invariants of the method's state (rows of coefs, pivot entries); returns count."""
    raise NotImplementedError("numba only")


@overload(rhs, prefer_literal=True)
def _rhs(method, state, out, cell, aux, params, config, work):
    code = _code(method)
    if code == EQMOM:
        return lambda method, state, out, cell, aux, params, config, work: eqmom_rhs(
            state, out, cell, aux, params, config, work)
    if code == LAGUERRE:
        return lambda method, state, out, cell, aux, params, config, work: laguerre_rhs(
            state, out, cell, aux, params, config, work)
    if code == QMOM:
        return lambda method, state, out, cell, aux, params, config, work: qmom_rhs(
            state, out, cell, aux, params, config, work)
    if code == CQMOM:
        return lambda method, state, out, cell, aux, params, config, work: cqmom_rhs(
            state, out, cell, aux, params, config, work)
    return None


@overload(realizable, prefer_literal=True)
def _realizable(method, state, aux, params, config, work):
    code = _code(method)
    if code == EQMOM:
        return lambda method, state, aux, params, config, work: eqmom_realizable(
            state, aux, params, config, work)
    if code == LAGUERRE:
        return lambda method, state, aux, params, config, work: laguerre_realizable(
            state, aux, params, config, work)
    if code == QMOM:
        return lambda method, state, aux, params, config, work: qmom_realizable(
            state, aux, params, config, work)
    if code == CQMOM:
        return lambda method, state, aux, params, config, work: cqmom_realizable(
            state, aux, params, config, work)
    return None


@overload(project, prefer_literal=True)
def _project(method, state, aux, params, config, work):
    code = _code(method)
    if code == EQMOM:
        return lambda method, state, aux, params, config, work: eqmom_project(
            state, aux, params, config, work)
    if code == LAGUERRE:
        return lambda method, state, aux, params, config, work: laguerre_project(
            state, aux, params, config, work)
    if code == QMOM:
        return lambda method, state, aux, params, config, work: qmom_project(
            state, aux, params, config, work)
    if code == CQMOM:
        return lambda method, state, aux, params, config, work: cqmom_project(
            state, aux, params, config, work)
    return None


@overload(conserved, prefer_literal=True)
def _conserved(method, config, params, pivots, coefs):
    code = _code(method)
    if code == EQMOM:
        return lambda method, config, params, pivots, coefs: eqmom_conserved(
            config, params, pivots, coefs)
    if code == LAGUERRE:
        return lambda method, config, params, pivots, coefs: laguerre_conserved(
            config, params, pivots, coefs)
    if code == QMOM:
        return lambda method, config, params, pivots, coefs: qmom_conserved(
            config, params, pivots, coefs)
    if code == CQMOM:
        return lambda method, config, params, pivots, coefs: cqmom_conserved(
            config, params, pivots, coefs)
    return None


# ---- run-time dispatch on config[METHOD] -----------------------------------------------------
@nb.njit(cache=True)
def method_rhs(state, out, cell, aux, params, config, work):
    """d(state)/dt [scaled units per s] of one cell for the method config[METHOD]."""
    if config[P.METHOD] == LAGUERRE:
        laguerre_rhs(state, out, cell, aux, params, config, work)
    elif config[P.METHOD] == CQMOM:
        cqmom_rhs(state, out, cell, aux, params, config, work)
    elif config[P.METHOD] == QMOM:
        qmom_rhs(state, out, cell, aux, params, config, work)
    elif config[P.METHOD] == EQMOM:
        eqmom_rhs(state, out, cell, aux, params, config, work)
    else:                       # an unknown code: NaN, which stops the cell, never wrong numbers
        for k in range(out.shape[0]):
            out[k] = np.nan


@nb.njit(cache=True)
def method_realizable(state, aux, params, config, work):
    """True if the state is a realizable moment set for the method config[METHOD]."""
    if config[P.METHOD] == LAGUERRE:
        return laguerre_realizable(state, aux, params, config, work)
    if config[P.METHOD] == CQMOM:
        return cqmom_realizable(state, aux, params, config, work)
    if config[P.METHOD] == QMOM:
        return qmom_realizable(state, aux, params, config, work)
    if config[P.METHOD] == EQMOM:
        return eqmom_realizable(state, aux, params, config, work)
    return False


@nb.njit(cache=True)
def method_project(state, aux, params, config, work):
    """Re-project an accepted state onto the method's realizable set, in place."""
    if config[P.METHOD] == LAGUERRE:
        laguerre_project(state, aux, params, config, work)
    elif config[P.METHOD] == CQMOM:
        cqmom_project(state, aux, params, config, work)
    elif config[P.METHOD] == QMOM:
        qmom_project(state, aux, params, config, work)
    elif config[P.METHOD] == EQMOM:
        eqmom_project(state, aux, params, config, work)
