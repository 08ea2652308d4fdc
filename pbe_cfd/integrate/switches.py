"""The sharp viscous Stokes step in the per-cell integration: held decisions, switching
times located, restarts (docs/physics.md section 6.2, "Integrating across the step").

Under the sharp step (``material.stokes_switch_width = 0``) the rates jump where a pair of
property rows crosses St = St*. The integrator hands the rates a per-cell copy of params
with the switch memory of physics.parameters.HELD (``held_params``): each pair's decision is
held as first evaluated until ``release``, so every step integrates smooth rates; a stage
whose own decision differs sets STOKES_CROSSED. A step across a switch is kept if it locates
the switching time closely enough (``located``; bisection of its bracket: ``locate_next``),
within N_SLIDE steps of the last switch (sliding) as it is; the cell then restarts from its
end with the decisions released.
"""
import math

import numba as nb
import numpy as np

from ..physics import parameters as P
from .codes import FTMP, REJECT_SWITCH, RHS_CALLS, YNEW, YTMP

N_SLIDE = 8              # accepted steps after a Stokes switch within which the next is kept
LOCATE_PRECISION = 1e-6  # a Stokes switching time is located to this share of its step,
LOCATE_FLOOR = 1e3       # and never closer than this many step floors (params STEP_FLOOR)

@nb.njit(cache=True)
def held_params(params, config):
    """A cell's copy of params [SI] for its rates: with the viscous Stokes criterion on and
    sharp, extended by the switch memory of the step (physics.parameters.HELD), holding and
    all decisions released; else the same values, holding nothing. Returns (the copy, room
    to save its decisions: empty where it holds nothing)."""
    hold = config[P.USE_PHYSICAL] == 1 and params[P.STOKES_WIDTH] == 0.0
    local = np.empty(P.N_PARAMS_HELD if hold else params.shape[0])
    for i in range(min(params.shape[0], local.shape[0])):
        local[i] = params[i]
    if hold:
        local[P.STOKES_HOLD] = 1.0
        release(local)
    return local, np.empty(P.N_PARAMS_HELD - P.STOKES_HELD if hold else 0)


@nb.njit(cache=True)
def release(local):
    """Forget the held Stokes decisions of ``local`` (``held_params``): the next evaluation of
    each pair holds its decision anew; clears STOKES_CROSSED."""
    for k in range(P.STOKES_HELD, P.N_PARAMS_HELD):
        local[k] = -1.0
    local[P.STOKES_CROSSED] = 0.0


@nb.njit(cache=True, inline="always")
def _switch_defect(method, state, h, buf, cell, aux, local, config, work, rtol, atol, n):
    """Error norm [-] of a step of h [s] from ``state`` to buf[YNEW] within which a pair's
    sharp Stokes decision switched (the held rates f_held were integrated to the step's end):
    the rates of the decisions at the step's end, f_new, apply from the unlocated switching
    time on, so the step is off by at most h |f_new - f_held| there, in the norm of the pair's
    error test, max_i over atol + rtol max(|y_i|, |y_new_i|). Leaves the decisions of
    buf[YNEW] held; two RHS calls (buf[FTMP], buf[YTMP] overwritten)."""
    y_new = buf[YNEW]
    method.rhs(y_new, buf[FTMP], cell, aux, local, config, work)
    release(local)
    method.rhs(y_new, buf[YTMP], cell, aux, local, config, work)
    err = 0.0
    for i in range(n):
        sc = atol + rtol * max(abs(state[i]), abs(y_new[i]))
        err = max(err, h * abs(buf[YTMP, i] - buf[FTMP, i]) / sc)
    return err


# location memory of one cell's Stokes switch (float array of N_LOC)
LOC_T_HI = 0             # end of the last step that crossed unlocated [s] (inf: none)
LOC_H_NEED = 1           # crossing steps up to this long are kept [s] (0: not locating)
LOC_SINCE = 2            # accepted steps since the last kept crossing
N_LOC = 3


@nb.njit(cache=True)
def location_memory():
    """A cell's fresh location memory (LOC_*): no bracket, not locating, no recent switch."""
    loc = np.empty(N_LOC)
    loc[LOC_T_HI] = math.inf
    loc[LOC_H_NEED] = 0.0
    loc[LOC_SINCE] = N_SLIDE + 1.0
    return loc


@nb.njit(cache=True, inline="always")
def located(method, t, state, h, buf, cell, aux, local, config, work, rtol, atol, n, stats,
             saved, loc, outcome, err):
    """An accepted step from t [s] of h [s] across which a sharp Stokes decision switched: kept
    within N_SLIDE steps of the last switch (sliding), if no longer than the locating step
    loc[LOC_H_NEED], or if ``_switch_defect`` is within the tolerance; else REJECT_SWITCH with
    the held decisions restored from ``saved`` and the switching time bracketed by t + h
    (loc[LOC_T_HI]; the first time, the step that would be close enough, h / defect, not
    below LOCATE_PRECISION h nor LOCATE_FLOOR step floors, is kept in loc[LOC_H_NEED]).
    Returns (outcome, error norm)."""
    if loc[LOC_SINCE] <= N_SLIDE or (loc[LOC_H_NEED] > 0.0 and h <= loc[LOC_H_NEED]):
        return outcome, err
    for k in range(saved.shape[0]):
        saved[k] = local[P.STOKES_HELD + k]
    err_switch = _switch_defect(method, state, h, buf, cell, aux, local, config, work, rtol,
                                atol, n)
    stats[RHS_CALLS] += 2
    if err_switch <= 1.0:
        return outcome, err
    for k in range(saved.shape[0]):
        local[P.STOKES_HELD + k] = saved[k]
    local[P.STOKES_CROSSED] = 0.0
    if loc[LOC_H_NEED] == 0.0:
        loc[LOC_H_NEED] = max(h * max(0.9 / err_switch, LOCATE_PRECISION),
                              LOCATE_FLOOR * local[P.STEP_FLOOR])
    loc[LOC_T_HI] = t + h
    return REJECT_SWITCH, err_switch


@nb.njit(cache=True)
def locate_next(crossed, t, h, loc):
    """After an accepted step ending at t [s] (``crossed``: a switch within it was kept): the
    next step [s], h as the controller proposes, shortened while a switching time is being
    located to halve its bracket (t, loc[LOC_T_HI]), or to reach it where it is no longer
    than the locating step (the step that ends there then crosses and is kept)."""
    if crossed:
        loc[LOC_SINCE] = 0.0
        loc[LOC_H_NEED] = 0.0
        loc[LOC_T_HI] = math.inf
        return h
    loc[LOC_SINCE] += 1.0
    if loc[LOC_H_NEED] == 0.0:
        return h
    rest = loc[LOC_T_HI] - t
    if rest <= 0.0:                    # the switch was not where the bracket said
        loc[LOC_H_NEED] = 0.0
        loc[LOC_T_HI] = math.inf
        return h
    if rest <= loc[LOC_H_NEED]:
        return min(h, rest)
    return min(h, max(0.5 * rest, loc[LOC_H_NEED]))
