"""Realizable adaptive time stepping of the per-cell moment equations.

Three schemes (``[method] integrator``, config[INTEGRATOR]):

* ``explicit``: the Bogacki-Shampine RK3(2) pair (``explicit``), error control on the scaled
  state, every stage checked for realizability (a stage outside the set rejects the step and
  halves it).
* ``implicit``: the linearly implicit Rosenbrock method RODAS3 (``rosenbrock``) with a
  finite-difference Jacobian; the same realizability checks on every stage argument; linear
  invariants (granule and binder mass) kept exact through the Jacobian's conserved rows.
* ``auto`` (default): explicit until a cell's steps are limited by stiffness, then implicit
  for as long as that pays, per cell (``cell``).

Cells are independent: each of the run's threads integrates every n-th cell
(``integrate_cells_kernel`` releases the GIL), so the cells of a spray zone, next to each
other in the mesh, are shared between the threads. The well-mixed run is the one-cell case of
the same function the mesh coupling calls. Only the method and the scheme a scene uses are
compiled: the scheme is a compile-time constant of the kernel, the method's functions are
its arguments (``kernel_types``); the compiled code is cached on disk.

What compiles as a function of its own: numba generates machine code for every function it
compiles separately, and again for each of its callees, linked into the caller's module. So
the integrator's functions that call the method (the schemes' attempts, the Jacobians, the
switch location, ``integrate_cell``) are inlined into their callers (``inline="always"``),
and the kernel calls the method's functions through their addresses, never linking them:
the method's functions and the small helpers are compiled once each, the integrator once,
in the kernel, for every method alike (docs/results/first-run.md).
"""
import time
from collections import namedtuple

import numpy as np

from ..physics import parameters as P
from ..util.threads import run_shares, run_threads
from . import faults
from .cell import integrate_cell, integrate_cells_kernel  # noqa: F401
from .codes import (ACCEPTED, AUTO, EXPLICIT, EXPONENTIAL_STEPS, IMPLICIT,  # noqa: F401
                    IMPLICIT_STEPS, JACOBIANS,
                    MAX_STEPS_PER_INTERVAL, METHOD_RAISED, N_STATS, NOT_FINITE, OK, REJECTED_ERROR,
                    REJECTED_REALIZABILITY, REJECTED_SWITCH, RHS_CALLS, SCHEMES,
                    STOKES_EVENTS, STATUS_TEXT, STEP_BELOW_FLOOR,
                    SWITCHES, TOO_MANY_STEPS, UNREALIZABLE_START)
from .kernel_types import (addresses_of, functions_of, kernel_signature, layout_key,
                           probe_args, signatures)


def integrate_cells(states, cells, aux, params, config, t_start, t_end, steps, rtol, atol,
                    max_steps, stats, status, reached):
    """Advance every cell (row of ``states``) from t_start to t_end [s], on the run's threads
    (``util.threads.run_threads``; each cell's numbers do not depend on their count).

    states (n_cells, n_state) scaled moments, modified in place; cells (n_cells, N_CELL) local
    fields; aux the method's auxiliary array; params, config the packed scene
    (``physics.parameters``; config[METHOD] and config[INTEGRATOR] choose the compiled
    kernel); steps (n_cells,) step memory [s] (negative: an auto cell is implicit);
    rtol, atol [-] tolerances on the scaled state; max_steps per cell and call;
    stats (n_cells, N_STATS) counters accumulated; status (n_cells,) int codes and
    reached (n_cells,) the time [s] each cell got to. A cell whose method functions raise an
    exception (which numba's entry points cannot pass on: ``faults``) is put back to its
    start with status METHOD_RAISED.
    """
    # the method's functions take C-contiguous rows: another layout runs on a copy
    given = states
    states, cells = np.ascontiguousarray(states), np.ascontiguousarray(cells)
    args = CallArgs(states, cells, aux, params, config, float(t_start), float(t_end), steps,
                    float(rtol), float(atol), int(max_steps), stats, status, reached)
    method, scheme = int(config[P.METHOD]), int(config[P.INTEGRATOR])
    share = kernel(method, scheme, args)
    threads = min(run_threads(), max(1, states.shape[0]))
    before = {name: getattr(args, name).copy() for name in _WRITTEN}
    # share k: the rows k, k + threads, ...; every share done when this returns
    caught = run_shares(lambda k: faults.watched(share, k, threads), range(threads), "cells")
    if any(f.count for f in caught):
        _stop_raising_cells(method, scheme, args, before)
    if states is not given:
        given[...] = states


#: the arguments of ``integrate_cells_kernel`` from the states on, by name
CallArgs = namedtuple("CallArgs", "states cells aux params config t_start t_end steps rtol atol "
                                  "max_steps stats status reached")
#: the arrays a call writes, and those with a row per cell (these and the cells' fields)
_WRITTEN = ("states", "steps", "stats", "status", "reached")
_PER_CELL = _WRITTEN + ("cells",)


def _stop_raising_cells(method, scheme, args, before):
    """After a call of the kernel (``args``: ``CallArgs``) in which the method's functions
    raised (``faults``): every cell integrated again alone from the call's start (``before``:
    the written arrays as they were, by name); a cell that raises again is put back to its
    start with status METHOD_RAISED, the others keep their result (the same as in the shared
    call: a cell's numbers do not depend on the others)."""
    for name, then in before.items():
        getattr(args, name)[...] = then
    raising = []
    for c in np.flatnonzero(before["status"] == OK):
        one = slice(c, c + 1)
        row = args._replace(**{name: getattr(args, name)[one] for name in _PER_CELL})
        if faults.watched(kernel(method, scheme, row), 0, 1).count:
            raising.append(c)
    if not raising:
        raise faults.MethodRaised(
            "the method's functions raised an exception inside the integrator "
            f"({faults.last_text()}), and no cell raised it again when integrated alone")
    for c in raising:
        for name, then in before.items():
            getattr(args, name)[c] = then[c]
        args.status[c] = METHOD_RAISED
        args.reached[c] = args.t_start


_KERNELS = {}


def kernel(method, scheme, args):
    """The compiled ``integrate_cells_kernel`` for the method with code ``method``, the scheme
    code ``scheme`` as a compile-time constant and the types of ``args`` (compiled, or loaded
    from the disk cache, on first use; a direct entry point and the method's entry points
    afterwards, found by the arguments' layout, so a call costs no type resolution). Returns
    ``share(first, stride)``, the kernel over the rows first, first + stride, ... of the
    cells in ``args``."""
    key = (method, scheme) + tuple(layout_key(a) for a in args)
    found = _KERNELS.get(key)
    if found is None:
        sigs = signatures(*args[2:5])
        sig = kernel_signature(scheme, args, sigs)
        integrate_cells_kernel.compile(sig)
        found = (integrate_cells_kernel.overloads[sig].entry_point, addresses_of(method, sigs))
        _KERNELS[key] = found
    entry, functions = found
    return lambda first, stride: entry(*functions, scheme, *args, first, stride)


def failure_reason(code, stats, params, config) -> str:
    """Why a cell stopped: STATUS_TEXT of its status code and, for a stalled step controller,
    what the cell's counters (stats row) say about the cause."""
    text = STATUS_TEXT[int(code)]
    if code == METHOD_RAISED:
        return f"{text} (it raised {faults.last_text()})"
    if code not in (STEP_BELOW_FLOOR, TOO_MANY_STEPS):
        return text
    if stalled_on_a_jump(code, stats):
        # a step controller that rejects as often as it accepts sits on a jump of the rates
        text += ("; the steps were rejected by the error test as often as accepted: the rates "
                 "jump (a discontinuous right-hand side) and the cell stays on the jump")
        if sharp_stokes_switch(params, config):
            text += (", here where a pair crosses the critical Stokes number (sharp viscous "
                     "Stokes criterion): give material.stokes_switch_width (a smooth "
                     "switch; docs/results/hard-cases.md says how much its width moves the "
                     "result)")
    elif int(config[P.INTEGRATOR]) == EXPLICIT:
        text += "; the rates are stiff for the explicit integrator: use integrator = \"auto\""
    return text


def stalled_on_a_jump(code, stats) -> bool:
    """True if a cell that stopped (status ``code``) had its steps rejected by the error test
    as often as accepted (counters ``stats``): the step controller sits on a jump of the rates
    (a discontinuous right-hand side)."""
    if int(code) not in (STEP_BELOW_FLOOR, TOO_MANY_STEPS):
        return False
    return int(stats[REJECTED_ERROR]) >= 0.5 * max(int(stats[ACCEPTED]), 1)


def sharp_stokes_switch(params, config) -> bool:
    """True if the viscous Stokes criterion is on and sharp (a step in St - St*)."""
    return int(config[P.USE_PHYSICAL]) == 1 and params[P.STOKES_WIDTH] == 0.0


def stats_summary(stats) -> dict:
    """JSON-able counters of the integration from a stats row (or rows, summed over cells):
    accepted and rejected steps, RHS calls, implicit steps, Jacobians, scheme switches and
    the explicit steps that integrated the droplet capture exactly."""
    st = np.asarray(stats)
    if st.ndim > 1:
        st = st.sum(axis=0)
    return {"accepted_steps": int(st[ACCEPTED]),
            "rejected_error": int(st[REJECTED_ERROR]),
            "rejected_realizability": int(st[REJECTED_REALIZABILITY]),
            "rhs_calls": int(st[RHS_CALLS]),
            "implicit_steps": int(st[IMPLICIT_STEPS]),
            "jacobians": int(st[JACOBIANS]),
            "scheme_switches": int(st[SWITCHES]),
            "exponential_steps": int(st[EXPONENTIAL_STEPS]),
            **_stokes_events(st)}


def _stokes_events(st) -> dict:
    """The counters of the sharp Stokes step's switches (``codes``), where there were any."""
    if int(st[STOKES_EVENTS]) == 0 and int(st[REJECTED_SWITCH]) == 0:
        return {}
    return {"stokes_switch_steps": int(st[STOKES_EVENTS]),
            "rejected_switch": int(st[REJECTED_SWITCH])}


def compile_kernels(aux, params, config, n_cells=1) -> float:
    """Compile (or load from the on-disk cache) the integrator kernel of one packed scene:
    its method and its scheme only. Returns the wall time it took [s] (near zero when the
    cache holds the kernel and it was loaded before in this process)."""
    start = time.perf_counter()
    integrate_cells(*probe_args(aux, params, config, n_cells))
    return time.perf_counter() - start


def kernel_ready(aux, params, config) -> bool:
    """True if the kernel of a packed scene and its method's functions are compiled in this
    process or can be loaded from numba's on-disk cache (a compile would only load them);
    False where numba has no cache interface to ask."""
    args = probe_args(aux, params, config, 1)
    method, scheme = int(config[P.METHOD]), int(config[P.INTEGRATOR])
    sigs = signatures(aux, params, config)
    wanted = [(integrate_cells_kernel, kernel_signature(scheme, args, sigs))]
    wanted += list(zip(functions_of(method), sigs))
    return all(_ready(dispatcher, sig) for dispatcher, sig in wanted)


def _ready(dispatcher, sig) -> bool:
    """True if ``dispatcher`` has ``sig`` (argument types, or a whole signature) compiled here
    or in numba's on-disk cache."""
    if getattr(sig, "args", sig) in dispatcher.overloads:
        return True
    try:
        return dispatcher._cache.load_overload(sig, dispatcher.targetctx) is not None
    except (AttributeError, TypeError):
        return False


def compile_misses(method: int) -> int:
    """numba's cache misses in this process (compiles) of the kernel and of the functions of
    the method with code ``method``: a change says that a call compiled."""
    return sum(sum(d.stats.cache_misses.values())
               for d in (integrate_cells_kernel, *functions_of(method)))
