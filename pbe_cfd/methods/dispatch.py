"""One entry point per operation for every moment method, built from the method registry.

Each method's entry (``methods.registry``) provides ``rhs``, ``realizable``, ``project`` and
``conserved`` with the signatures ``(state, [out, cell,] aux, params, config, work)`` and
``(config, params, pivots, coefs)``; ``work`` is a float scratch array of ``WORK_SIZE``
allocated once per cell so that no call allocates.

Two ways in:

* The integration kernel and the transport's mixture repair take the method's functions
  themselves, as numba first-class functions (``integrate.kernel_types``): a scene compiles
  only the method it uses.
* ``method_rhs``, ``method_realizable``, ``method_project`` choose by ``config[METHOD]`` at run
  time (a chain of inlined branches, one per method registered when one of them is first
  named, as ``physics.registry`` builds the kernels' dispatch; every method is compiled); for
  callers that do not know the method at compile time (benchmarks). They are built on first
  use (this module's ``__getattr__``), since building them imports every method package.
"""
import numba as nb
import numpy as np

from ..physics import parameters as P
from .entry import WORK_SIZE  # noqa: F401 - the per-cell work array's length
from . import registry


# ---- run-time dispatch on config[METHOD]: chains built from the registry ----------------------
@nb.njit(cache=True, inline="always")
def _unknown_rhs(state, out, cell, aux, params, config, work):
    """An unknown code: NaN, which stops the cell, never wrong numbers."""
    for k in range(out.shape[0]):
        out[k] = np.nan


@nb.njit(cache=True, inline="always")
def _unknown_realizable(state, aux, params, config, work):
    return False


@nb.njit(cache=True, inline="always")
def _unknown_project(state, aux, params, config, work):
    pass


def _rhs_link(code, function, rest):
    @nb.njit(cache=True, inline="always")
    def link(state, out, cell, aux, params, config, work):
        if config[P.METHOD] == code:
            function(state, out, cell, aux, params, config, work)
        else:
            rest(state, out, cell, aux, params, config, work)
    return link


def _state_link(code, function, rest):
    @nb.njit(cache=True, inline="always")
    def link(state, aux, params, config, work):
        if config[P.METHOD] == code:
            return function(state, aux, params, config, work)
        return rest(state, aux, params, config, work)
    return link


def _chain(field, unknown, link):
    chain = unknown
    for entry in reversed([m for m in registry.METHOD_REGISTRY if m.integrated]):
        chain = link(entry.code, getattr(entry, field), chain)
    return chain


def _run_time_dispatch() -> dict:
    """The run-time dispatch functions over the methods registered now (name -> function)."""
    rhs_chain = _chain("rhs", _unknown_rhs, _rhs_link)
    realizable_chain = _chain("realizable", _unknown_realizable, _state_link)
    project_chain = _chain("project", _unknown_project, _state_link)

    @nb.njit(cache=True)
    def method_rhs(state, out, cell, aux, params, config, work):
        """d(state)/dt [scaled units per s] of one cell for the method config[METHOD]."""
        rhs_chain(state, out, cell, aux, params, config, work)

    @nb.njit(cache=True)
    def method_realizable(state, aux, params, config, work):
        """True if the state is a realizable moment set for the method config[METHOD]."""
        return realizable_chain(state, aux, params, config, work)

    @nb.njit(cache=True)
    def method_project(state, aux, params, config, work):
        """Re-project an accepted state onto the method's realizable set, in place."""
        project_chain(state, aux, params, config, work)

    return {"method_rhs": method_rhs, "method_realizable": method_realizable,
            "method_project": method_project}


def __getattr__(name):
    if name in ("method_rhs", "method_realizable", "method_project"):
        globals().update(_run_time_dispatch())
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
