"""Realizable adaptive time stepping of the per-cell moment equations.

An embedded Runge-Kutta 3(2) pair (Bogacki-Shampine) with error control on the non-dimensional
state. Every stage is checked for realizability; a stage outside the realizable set rejects the
step and halves it (after Nguyen et al., J. Comput. Phys. 2016), so no stored state ever leaves
it. Cells are independent and run in parallel (``numba.prange``): the well-mixed run is the
one-cell case of the same function the mesh coupling calls.
"""
import math

import numba as nb
import numpy as np

from .methods.dispatch import WORK_SIZE, method_project, method_realizable, method_rhs
from .physics import parameters as P

# status codes per cell
OK = 0
STEP_FLOOR = 1          # the step fell below params[STEP_FLOOR]
NOT_FINITE = 2          # the right-hand side produced a non-finite value
TOO_MANY_STEPS = 3      # the per-call step budget ran out
UNREALIZABLE_START = 4  # the state handed in was not realizable
STATUS_TEXT = {
    OK: "ok",
    STEP_FLOOR: "the step size fell below its floor",
    NOT_FINITE: "the right-hand side became non-finite",
    TOO_MANY_STEPS: "the step budget of one output interval ran out (the cell's rates are "
                    "stiff for this explicit integrator: far faster than the output interval)",
    UNREALIZABLE_START: "the initial moment set is not realizable",
}

#: accepted-or-rejected steps one cell may take within one output interval
MAX_STEPS_PER_INTERVAL = 1_000_000

# statistics columns per cell
ACCEPTED = 0
REJECTED_ERROR = 1
REJECTED_REALIZABILITY = 2
RHS_CALLS = 3
N_STATS = 4


@nb.njit(cache=True)
def _combine(y, h, k1, c1, k2, c2, k3, c3, out, n):
    for i in range(n):
        out[i] = y[i] + h * (c1 * k1[i] + c2 * k2[i] + c3 * k3[i])


@nb.njit(cache=True)
def integrate_cell(state, cell, aux, params, config, t_start, t_end, step, rtol, atol,
                   max_steps, stats):
    """Advance one cell's state from t_start to t_end [s] in place.

    ``step`` is a one-element array holding the proposed step [s] (updated for the next call).
    ``stats`` accumulates accepted/rejected steps and RHS calls. Returns (status, time reached).
    """
    n = config[P.N_STATE]
    work = np.empty(WORK_SIZE)
    if not method_realizable(state, aux, params, config, work):
        return UNREALIZABLE_START, t_start
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    stage = np.empty(n)
    y3 = np.empty(n)
    floor = params[P.STEP_FLOOR]
    t = t_start
    h = step[0]
    if not (h > 0.0):
        h = (t_end - t_start) * 1e-3
    method_rhs(state, k1, cell, aux, params, config, work)
    stats[RHS_CALLS] += 1
    for i in range(n):
        if not math.isfinite(k1[i]):
            return NOT_FINITE, t
    taken = 0
    while t < t_end:
        if taken >= max_steps:
            step[0] = h
            return TOO_MANY_STEPS, t
        last = False
        if t + h >= t_end:
            h_try = t_end - t
            last = True
        else:
            h_try = h
        if h_try < floor and not last:
            step[0] = h
            return STEP_FLOOR, t
        taken += 1
        # stage 2
        _combine(state, h_try, k1, 0.5, k1, 0.0, k1, 0.0, stage, n)
        if not method_realizable(stage, aux, params, config, work):
            stats[REJECTED_REALIZABILITY] += 1
            h = 0.5 * h_try
            continue
        method_rhs(stage, k2, cell, aux, params, config, work)
        # stage 3
        _combine(state, h_try, k1, 0.0, k2, 0.75, k2, 0.0, stage, n)
        stats[RHS_CALLS] += 1
        if not method_realizable(stage, aux, params, config, work):
            stats[REJECTED_REALIZABILITY] += 1
            h = 0.5 * h_try
            continue
        method_rhs(stage, k3, cell, aux, params, config, work)
        stats[RHS_CALLS] += 1
        _combine(state, h_try, k1, 2.0 / 9.0, k2, 1.0 / 3.0, k3, 4.0 / 9.0, y3, n)
        if not method_realizable(y3, aux, params, config, work):
            stats[REJECTED_REALIZABILITY] += 1
            h = 0.5 * h_try
            continue
        method_rhs(y3, k4, cell, aux, params, config, work)
        stats[RHS_CALLS] += 1
        err = 0.0
        finite = True
        for i in range(n):
            if not math.isfinite(k4[i]):
                finite = False
            e = h_try * (-5.0 / 72.0 * k1[i] + 1.0 / 12.0 * k2[i] + 1.0 / 9.0 * k3[i]
                         - 1.0 / 8.0 * k4[i])
            sc = atol + rtol * max(abs(state[i]), abs(y3[i]))
            r = abs(e) / sc
            if r > err:
                err = r
        if not finite:
            h = 0.5 * h_try
            stats[REJECTED_ERROR] += 1
            continue
        if err <= 1.0:
            t = t_end if last else t + h_try
            for i in range(n):
                state[i] = y3[i]
            method_project(state, aux, params, config, work)
            method_rhs(state, k1, cell, aux, params, config, work)
            stats[RHS_CALLS] += 1
            stats[ACCEPTED] += 1
            factor = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / 3.0)))
            if not last:
                h = h_try * factor
            else:
                h = max(h, h_try * factor)
        else:
            stats[REJECTED_ERROR] += 1
            h = h_try * max(0.2, 0.9 * err ** (-1.0 / 3.0))
    step[0] = h
    return OK, t


@nb.njit(cache=True, parallel=True)
def integrate_cells(states, cells, aux, params, config, t_start, t_end, steps, rtol, atol,
                    max_steps, stats, status, reached):
    """Advance every cell (row of ``states``) from t_start to t_end [s] in parallel.

    states (n_cells, n_state) scaled moments, modified in place; cells (n_cells, N_CELL) local
    fields; steps (n_cells,) step memory [s]; stats (n_cells, N_STATS) counters accumulated;
    status (n_cells,) int codes and reached (n_cells,) the time [s] each cell got to.
    """
    n_cells = states.shape[0]
    for c in nb.prange(n_cells):
        if status[c] != OK:
            continue
        code, t = integrate_cell(states[c], cells[c], aux, params, config, t_start, t_end,
                                 steps[c:c + 1], rtol, atol, max_steps, stats[c])
        status[c] = code
        reached[c] = t
