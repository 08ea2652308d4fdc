"""The per-cell time loop: step control, realizability, and the auto switch between schemes.

``integrate_cell(method, scheme, ...)`` takes the method's functions (a ``MethodFunctions``
of first-class functions, ``kernel_types``) and the scheme code as a compile-time constant (a
numba integer literal): the scheme's step functions are chosen at typing time
(``_explicit``, ``_jacobian``, ``_implicit`` below), so an explicit scene never compiles the
Rosenbrock code and an implicit one never the explicit pair.

Auto (as LSODA switches between Adams and BDF): a cell starts explicit. An accepted explicit
step whose stiffness estimate h rho exceeds STIFF_H_RHO (the step is near the pair's stability
or positivity limit: R(z) of the explicit pair turns negative at z = -1.6) counts towards a
switch; after N_STIFF such steps in a row the cell goes implicit. An implicit step pays for
itself when it is COST_RATIO = (n + 3) / 3 times longer than the explicit step the cell could
take instead (max of its last explicit step and 1.6 / rho(J), rho from power iteration); after
N_SLOW implicit steps in a row that are not, the cell goes back to explicit and waits a number
of steps (doubling after each unproductive episode) before it may switch again. The scheme a
cell ended with is remembered in the sign of its step memory (negative: implicit).

In a droplet transient auto integrates the capture exactly (``_capture_chosen``: the
exponential pair of ``exponential``), judged on what is left of the rates after the capture;
the capture column is kept for the call. The explicit pair reuses its last stage's rate for the
next step when the projection moved the state by round-off only. A call that opened on a
transient hands the next call its opening step (with transport every split step opens on one).
"""
import math

import numba as nb
import numpy as np
from numba.core import types
from numba.extending import overload

from ..methods.entry import WORK_SIZE
from ..physics import parameters as P
from ..physics.injection import droplet_liquid, droplet_liquid_entry, evaporated_entry
from .codes import (ACCEPT, ACCEPTED, AUTO, EXPLICIT, EXPONENTIAL_STEPS, F0, FTMP, GCOL,
                    IMPLICIT, IMPLICIT_STEPS, JACOBIANS, KC, N_BUF, NOT_FINITE, OK,
                    REJECT_ERROR, REJECT_NOT_FINITE,
                    REJECT_REALIZABILITY, REJECT_SWITCH, REJECTED_ERROR,
                    REJECTED_REALIZABILITY, REJECTED_SWITCH, RHS_CALLS, STEP_BELOW_FLOOR,
                    STOKES_EVENTS, SWITCHES, TOO_MANY_STEPS, UNREALIZABLE_START, YNEW, YTMP)
from .explicit import bs3_attempt
from .exponential import capture_column, exp_bs3_attempt
from .kernel_types import MethodFunctions
from .rosenbrock import rodas3_attempt, secant_jacobian, spectral_radius
from .switches import held_params, locate_next, located, location_memory, release

STIFF_H_RHO = 1.0        # h rho above which an explicit step counts as stability-limited
N_STIFF = 15             # such steps in a row before an auto cell goes implicit
N_SLOW = 8               # implicit steps in a row not worth their cost before going back
POSITIVITY_LIMIT = 1.6   # |h lambda| up to which the explicit pair keeps a decay positive
MAX_WAIT = 4096          # longest wait (explicit steps) before another implicit attempt
CAPTURE_DOMINANCE = 10.0  # droplet / remaining relative rates above which capture is exact
CAPTURE_SHARE = 0.1      # share of the error budget the droplets' own decay may use unnoticed
OPENING_MARGIN = 2.0     # step growth below which a call's first step counts as tight
FSAL_CHANGE = 8.0 * 2.220446049250313e-16   # projection change (relative) up to which
#                                             f(y_new) is reused: round-off only

# switch memory of one cell (float array)
SW_STIFF = 0             # stability-limited explicit steps in a row
SW_WAIT = 1              # explicit steps still to wait before the next switch
SW_BACKOFF = 2           # the wait after the next unproductive implicit episode
SW_SLOW = 3              # implicit steps in a row that did not pay
SW_H_EXPLICIT = 4        # last accepted explicit step [s]
SW_GOOD = 5              # implicit steps of this episode that paid
N_SW = 6


def _scheme(scheme):
    return scheme.literal_value if isinstance(scheme, types.IntegerLiteral) else None


def _explicit(scheme, method, y, h, buf, phis, expo, cell, aux, params, config, work, rtol,
              atol, d, n):
    raise NotImplementedError("numba only")


def _capture(scheme, method, y, buf, cell, aux, params, config, work, d, n):
    raise NotImplementedError("numba only")


def _implicit(scheme, method, y, h, buf, jac, lu, piv, cell, aux, params, config, work, rtol,
              atol, n):
    raise NotImplementedError("numba only")


def _jacobian(scheme, method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config,
              work, rtol, atol, n, h_scale):
    raise NotImplementedError("numba only")


@overload(_explicit, prefer_literal=True)
def _explicit_impl(scheme, method, y, h, buf, phis, expo, cell, aux, params, config, work, rtol,
                   atol, d, n):
    code = _scheme(scheme)
    if code is None:
        return None
    if code == IMPLICIT:      # never called: an implicit scene does not compile the pair
        def stub(scheme, method, y, h, buf, phis, expo, cell, aux, params, config, work, rtol,
                 atol, d, n):
            return REJECT_NOT_FINITE, 0.0, 0.0, 0
        return stub
    if code == EXPLICIT:
        def pair(scheme, method, y, h, buf, phis, expo, cell, aux, params, config, work, rtol,
                 atol, d, n):
            return bs3_attempt(method, y, h, buf, cell, aux, params, config, work, rtol, atol, n)
        return pair

    def either(scheme, method, y, h, buf, phis, expo, cell, aux, params, config, work, rtol,
               atol, d, n):
        if expo:
            return exp_bs3_attempt(method, y, h, buf, phis, cell, aux, params, config, work,
                                   rtol, atol, d, n)
        return bs3_attempt(method, y, h, buf, cell, aux, params, config, work, rtol, atol, n)
    return either


@overload(_capture, prefer_literal=True)
def _capture_impl(scheme, method, y, buf, cell, aux, params, config, work, d, n):
    code = _scheme(scheme)
    if code is None:
        return None
    if code != AUTO:          # never called
        return lambda scheme, method, y, buf, cell, aux, params, config, work, d, n: 0.0
    return lambda scheme, method, y, buf, cell, aux, params, config, work, d, n: \
        capture_column(method, y, buf, cell, aux, params, config, work, d, n)


@overload(_implicit, prefer_literal=True)
def _implicit_impl(scheme, method, y, h, buf, jac, lu, piv, cell, aux, params, config, work,
                   rtol, atol, n):
    code = _scheme(scheme)
    if code is None:
        return None
    if code == EXPLICIT:      # never called
        return lambda scheme, method, y, h, buf, jac, lu, piv, cell, aux, params, config, \
            work, rtol, atol, n: (REJECT_NOT_FINITE, 0.0, 0)
    return lambda scheme, method, y, h, buf, jac, lu, piv, cell, aux, params, config, work, \
        rtol, atol, n: rodas3_attempt(method, y, h, buf, jac, lu, piv, cell, aux, params,
                                      config, work, rtol, atol, n)


@overload(_jacobian, prefer_literal=True)
def _jacobian_impl(scheme, method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params,
                   config, work, rtol, atol, n, h_scale):
    code = _scheme(scheme)
    if code is None:
        return None
    if code == EXPLICIT:      # never called
        return lambda scheme, method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, \
            config, work, rtol, atol, n, h_scale: 0
    return lambda scheme, method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, \
        config, work, rtol, atol, n, h_scale: secant_jacobian(
            method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config, work, rtol,
            atol, n, h_scale)


@nb.njit(cache=True)
def _after_explicit(h_try, h_rho, sw):
    """Auto: bookkeeping after an accepted explicit step; True if the cell goes implicit."""
    sw[SW_H_EXPLICIT] = h_try
    sw[SW_WAIT] -= 1.0
    if h_rho > STIFF_H_RHO:
        sw[SW_STIFF] += 1.0
    else:
        sw[SW_STIFF] = 0.0
    if sw[SW_STIFF] >= N_STIFF and sw[SW_WAIT] <= 0.0:
        sw[SW_STIFF] = 0.0
        sw[SW_SLOW] = 0.0
        sw[SW_GOOD] = 0.0
        return True
    return False


@nb.njit(cache=True)
def _after_implicit(h_try, sw, jac, buf, n):
    """Auto: bookkeeping after an accepted implicit step (jac: its Jacobian). Returns the
    explicit step to continue with [s] if the cell goes back to explicit, else 0."""
    rho = spectral_radius(jac, buf[YTMP], buf[FTMP], n)
    h_stable = POSITIVITY_LIMIT / rho if rho > 0.0 else math.inf
    h_ref = max(sw[SW_H_EXPLICIT], h_stable)
    if h_try >= (n + 3.0) / 3.0 * h_ref:
        sw[SW_GOOD] += 1.0
        sw[SW_SLOW] = 0.0
        return 0.0
    sw[SW_SLOW] += 1.0
    if sw[SW_SLOW] < N_SLOW:
        return 0.0
    if sw[SW_GOOD] > 0.0:
        sw[SW_BACKOFF] = N_STIFF
    else:
        sw[SW_BACKOFF] = min(2.0 * max(sw[SW_BACKOFF], N_STIFF), MAX_WAIT)
    sw[SW_WAIT] = sw[SW_BACKOFF]
    sw[SW_STIFF] = 0.0
    return min(h_try, h_ref)


@nb.njit(cache=True)
def _droplet_rates(state, f0, g, d, liquid, n, rtol, atol):
    """(relative rate of the droplets |dn_d/dt| / n_d, fastest relative rate of the other
    entries) [1/s]; with ``g`` (a capture column d f / d n_d) the other entries' rates count
    only what is left after the capture, f - g n_d, else all of f. The droplets' liquid
    (entry ``liquid``, -1: none) is the droplet population's, not another entry: the capture
    column moves it with n_d, and what is left of its rate is the sprayed droplets' liquid,
    R b_d, the twin of the droplet entry's R (counted, it is R / n_d >= the capture rate at
    a quasi-steady droplet number, and the test could never pass)."""
    floor = atol / rtol
    nd = state[d]
    rate_d = abs(f0[d]) / max(nd, floor)
    rate_g = 0.0
    for i in range(n):
        if i != d and i != liquid:
            rate = f0[i] - g[i] * nd if g.shape[0] > 0 else f0[i]
            rate_g = max(rate_g, abs(rate) / max(abs(state[i]), floor))
    return rate_d, rate_g


@nb.njit(cache=True)
def _capture_pays(state, f0, g, d, liquid, n, rtol, atol):
    """Auto: True if the next explicit step should integrate the droplet capture exactly
    (g: buf[GCOL], the capture column d f / d n_d at this state or a recent one, or an empty
    array where none is known yet; then the test counts all of the other entries' rates).

    It pays where the droplets, not the granules, limit the explicit pair's step: in a
    droplet transient, where the droplets' relative rate |dn_d/dt| / n_d exceeds
    CAPTURE_DOMINANCE times the fastest relative rate of the other entries (fresh droplets
    after a transport step, an initial charge being captured). With a capture column the other
    entries count only what is left after the capture, f - g n_d: the capture's own share is
    integrated exactly by the exponential step, and counting it (the binder entries of dry
    granules grow at the droplets' rate) kept the plain pair resolving those transients.
    Elsewhere the plain pair is used: with quasi-steady droplets it is as accurate per step
    and cheaper, and where their capture is stiff (h lambda above the pair's limit) the
    Rosenbrock method is more accurate than the exponential step, which has classical order 3
    only (measured: 3.8 times longer steps for RODAS3 at lambda = 1e6 /s, rtol 1e-8)."""
    if state[d] <= 0.0:
        return True
    rate_d, rate_g = _droplet_rates(state, f0, g, d, liquid, n, rtol, atol)
    return rate_d > CAPTURE_DOMINANCE * rate_g


@nb.njit(cache=True)
def _capture_worth_testing(state, f0, h, d, rtol, atol):
    """Auto: True if a capture column is worth one RHS call to test ``_capture_pays`` on
    what is left after the capture: the droplets' own change over the step h [s] would use
    more than CAPTURE_SHARE of the pair's error budget. The pair's embedded estimate of a decay
    at rate r is (r h)^3 / 48 (relative), so that is h |dn_d/dt| / n_d above
    (48 CAPTURE_SHARE rtol)^(1/3) (0.017 at rtol 1e-6): a droplet transient, or a step long
    compared with the droplets' rate. Quasi-steady droplets (spraying balanced by capture)
    change at the granules' slow rates; they pass only on long steps, and then the capture
    column is evaluated once per call and the test keeps the plain pair."""
    limit = (48.0 * CAPTURE_SHARE * rtol) ** (1.0 / 3.0)
    return h * abs(f0[d]) > limit * max(state[d], atol / rtol)


@nb.njit(cache=True)
def _projection_small(state, y_new, n):
    """True if the accepted state differs from the step's candidate y_new by round-off only
    (FSAL_CHANGE relative in every entry): then f(y_new), which the pair's last stage
    evaluated, serves as the rate of the next step. Anything larger (nodes lost, a binder
    clipped, droplets absorbed) may turn a rate across the realizable set's boundary: a
    vanishing entry with the old, negative rate would reject every later step."""
    for i in range(n):
        if abs(state[i] - y_new[i]) > FSAL_CHANGE * abs(y_new[i]):
            return False
    return True


# what a cell's capture column buf[GCOL] is (int array of N_CAP)
CAP_KNOWN = 0            # 1: it holds the capture column of this or a recent state
CAP_FRESH = 1            # 1: recent enough for an exponential step
CAP_AGE = 2              # accepted steps since it was evaluated
N_CAP = 3


@nb.njit(cache=True, inline="always")
def _capture_chosen(scheme, method, state, h, buf, cap, cell, aux, params, config, work, rtol,
                    atol, d, n, stats):
    """Auto: True if the next explicit step of h [s] integrates the droplet capture exactly
    (``_capture_pays``); evaluates the capture column (one RHS call, counted in stats) where
    the test needs it or the exponential step does."""
    f0 = buf[F0]
    g = buf[GCOL]
    liquid = droplet_liquid_entry(config)
    if state[d] <= 0.0:
        expo = cell[P.INJECTION] > 0.0
    elif cap[CAP_KNOWN] == 1:
        expo = (_capture_pays(state, f0, g, d, liquid, n, rtol, atol)
                or _capture_pays(state, f0, g[:0], d, liquid, n, rtol, atol))
    else:
        expo = _capture_pays(state, f0, g[:0], d, liquid, n, rtol, atol)
        if not expo and _capture_worth_testing(state, f0, h, d, rtol, atol):
            _capture(scheme, method, state, buf, cell, aux, params, config, work, d, n)
            stats[RHS_CALLS] += 1
            cap[CAP_KNOWN] = 1
            cap[CAP_FRESH] = 1
            cap[CAP_AGE] = 0
            expo = _capture_pays(state, f0, g, d, liquid, n, rtol, atol)
    if expo and cap[CAP_FRESH] == 0:
        _capture(scheme, method, state, buf, cell, aux, params, config, work, d, n)
        stats[RHS_CALLS] += 1
        cap[CAP_KNOWN] = 1
        cap[CAP_FRESH] = 1
        cap[CAP_AGE] = 0
    return expo


@nb.njit(cache=True, inline="always")
def _rate_after_step(method, explicit, expo, crossed, state, buf, cell, aux, params, config,
                     work, n, stats):
    """buf[F0] = f(state) after an accepted step: first same as last where the explicit pair's
    last stage evaluated f(y_new) and the projection moved the state by round-off only
    (``_projection_small``), else one RHS call (counted in stats). After a step across a
    switch of the sharp Stokes step (``crossed``) the decisions are released first: the next
    step restarts here with the decisions of this state."""
    f0 = buf[F0]
    if crossed:
        release(params)
        stats[STOKES_EVENTS] += 1
    if explicit and not crossed and _projection_small(state, buf[YNEW], n):
        last_rate = buf[FTMP] if expo else buf[KC]
        for i in range(n):
            f0[i] = last_rate[i]
    else:
        method.rhs(state, f0, cell, aux, params, config, work)
        stats[RHS_CALLS] += 1


@nb.njit(cache=True)
def _after_reject(outcome, err, h_try, stats):
    """Count a rejected attempt of h_try [s] and return the step to try next [s]."""
    if outcome == REJECT_ERROR:
        stats[REJECTED_ERROR] += 1
        return h_try * max(0.2, 0.9 * err ** (-1.0 / 3.0))
    if outcome == REJECT_SWITCH:     # bisect the bracket of the switching time
        stats[REJECTED_SWITCH] += 1
        return 0.5 * h_try
    if outcome == REJECT_REALIZABILITY:
        stats[REJECTED_REALIZABILITY] += 1
    else:
        stats[REJECTED_ERROR] += 1
    return 0.5 * h_try


@nb.njit(cache=True)
def _all_finite(values, n):
    for i in range(n):
        if not math.isfinite(values[i]):
            return False
    return True


@nb.njit(cache=True, inline="always")
def _absorb_droplets(method, state, d, atol, pivots, coefs, n_inv, aux, params, config, work,
                     saved):
    """A free-droplet density in (0, atol] (numerically zero: below the absolute tolerance)
    is handed to the granules along the linear invariants (their mass and binder keep
    x_d n_d), so that a decaying droplet number ends at exactly zero instead of creeping
    through denormal numbers; kept as it was if the result would not be realizable. With a
    droplet-liquid entry (drying) their liquid goes with them (its invariant coefficients)."""
    nd = state[d]
    if not (nd > 0.0 and nd <= atol):
        return
    for i in range(state.shape[0]):
        saved[i] = state[i]
    liquid = droplet_liquid_entry(config)
    for r in range(n_inv):
        p = pivots[r]
        held = coefs[r, d] * nd + (coefs[r, liquid] * state[liquid] if liquid >= 0 else 0.0)
        state[p] += held / coefs[r, p]
    state[d] = 0.0
    if liquid >= 0:
        state[liquid] = 0.0
    if not method.realizable(state, aux, params, config, work):
        for i in range(state.shape[0]):
            state[i] = saved[i]


@nb.njit(cache=True)
def _dry_out_droplets(state, d, params, config, rtol, atol):
    """With a droplet-liquid entry (drying): free droplets whose liquid is numerically zero
    (L_d in (0, atol] and below rtol of a fresh droplet's liquid per droplet) have dried; that
    liquid joins the evaporated liquid (entry N_STATE - 2; both count alike in the invariants),
    so that a pure liquid's d^2 law, whose rate grows without bound relative to L_d as it
    vanishes, ends at exactly zero instead of in ever shorter steps."""
    liquid = droplet_liquid_entry(config)
    if liquid < 0:
        return
    held = state[liquid]
    fresh = state[d] * droplet_liquid(params) / params[P.MASS_SCALE]
    if held > 0.0 and held <= atol and held < rtol * fresh:
        state[evaporated_entry(config)] += held
        state[liquid] = 0.0


@nb.njit(cache=True)
def _next_mode(auto, mode, h, h_try, h_rho, sw, jac, buf, n, stats):
    """After an accepted step of size h_try [s] in mode (0 explicit, 1 implicit): count it
    and, for an auto cell, decide the mode of the next step. Returns (mode, next step [s])."""
    if mode == 1:
        stats[IMPLICIT_STEPS] += 1
        if auto:
            h_back = _after_implicit(h_try, sw, jac, buf, n)
            if h_back > 0.0:
                stats[SWITCHES] += 1
                return 0, h_back
        return 1, h
    if auto and _after_explicit(h_try, h_rho, sw):
        stats[SWITCHES] += 1
        return 1, h
    return 0, h


@nb.njit(cache=True, inline="always")
def _memory(scheme, mode, h):
    """Step memory: the next step [s], negative if an auto cell is implicit."""
    return -h if (scheme == AUTO and mode == 1) else h


@nb.njit(cache=True, inline="always")
def _clear_crossed(local):
    """Clear STOKES_CROSSED of a cell's params copy where it carries the switch memory
    (``switches.held_params``); a copy that holds nothing has no such slot."""
    if local.shape[0] > P.STOKES_CROSSED:
        local[P.STOKES_CROSSED] = 0.0


@nb.njit(cache=True, inline="always")
def _attempt(scheme, method, mode, state, h_try, buf, phis, cap, jac, lu, piv, pivots, coefs,
             n_inv, have_jac, secant, cell, aux, local, config, work, rtol, atol, droplet, n,
             stats):
    """One attempted step of h_try [s] in mode (0 explicit, 1 implicit); the Jacobian is
    evaluated first where the implicit mode has none (``secant``: as a secant over the step,
    after a realizability rejection; ``rosenbrock.secant_jacobian``). Returns (outcome, error
    norm, h rho, whether the capture was exact, have_jac)."""
    h_rho, expo = 0.0, False
    if mode == 0:
        expo = droplet >= 0 and scheme == AUTO and _capture_chosen(
            scheme, method, state, h_try, buf, cap, cell, aux, local, config, work, rtol,
            atol, droplet, n, stats)
        _clear_crossed(local)
        outcome, err, h_rho, calls = _explicit(scheme, method, state, h_try, buf, phis, expo,
                                               cell, aux, local, config, work, rtol, atol,
                                               droplet, n)
    else:
        if not have_jac:
            stats[RHS_CALLS] += _jacobian(scheme, method, state, buf, jac, pivots, coefs,
                                          n_inv, cell, aux, local, config, work, rtol, atol, n,
                                          h_try if secant else 0.0)
            stats[JACOBIANS] += 1
            have_jac = True
        _clear_crossed(local)
        outcome, err, calls = _implicit(scheme, method, state, h_try, buf, jac, lu, piv, cell,
                                        aux, local, config, work, rtol, atol, n)
    stats[RHS_CALLS] += calls
    return outcome, err, h_rho, expo, have_jac


@nb.njit(cache=True, inline="always")
def integrate_cell(method, scheme, state, cell, aux, params, config, t_start, t_end, step,
                   rtol, atol, max_steps, stats):
    """Advance one cell's state from t_start to t_end [s] in place. method: the method's
    functions (``kernel_types.MethodFunctions``); scheme: a literal code (``codes``). ``step``:
    one-element array, the proposed step [s] (updated for the next call; its sign is the auto
    scheme's memory). ``stats`` accumulates the columns of ``codes``. Returns (status, time
    reached [s]). Under the sharp viscous Stokes step the pairs' decisions are held within a
    step and a step across a switch restarts the next from its end (``switches``)."""
    n = config[P.N_STATE]
    work = np.empty(WORK_SIZE)
    if not method.realizable(state, aux, params, config, work):
        return UNREALIZABLE_START, t_start
    local, saved = held_params(params, config)
    hold = saved.shape[0] > 0
    buf = np.empty((N_BUF, n))
    jac, lu = np.empty((n, n)), np.empty((n, n))
    piv = np.empty(n, dtype=np.int64)
    pivots, coefs = np.zeros(2, dtype=np.int64), np.zeros((2, n))
    n_inv = method.conserved(config, local, pivots, coefs)
    sw = np.zeros(N_SW)
    phis = np.empty((3, 6))
    droplet = n - 1 if config[P.SEPARATE_DROPLETS] == 1 else -1
    mode = 1 if (scheme == IMPLICIT or (scheme == AUTO and step[0] < 0.0)) else 0
    h = abs(step[0]) if abs(step[0]) > 0.0 else (t_end - t_start) * 1e-3
    method.rhs(state, buf[F0], cell, aux, local, config, work)
    stats[RHS_CALLS] += 1
    if not _all_finite(buf[F0], n):
        step[0] = _memory(scheme, mode, h)
        return NOT_FINITE, t_start
    floor = local[P.STEP_FLOOR]
    # np.bool_: a constant would be typed as a literal (one more compile of _attempt); secant:
    # after an implicit step's realizability rejection the next Jacobian is a secant over it
    t, taken, have_jac, secant = t_start, 0, np.bool_(False), np.bool_(False)
    loc = location_memory()           # locating a Stokes switching time
    cap = np.zeros(N_CAP, dtype=np.int64)   # what buf[GCOL] holds (CAP_* below)
    # the step proposed after this call's first accepted step [s]; whether that step was
    # rejected first or accepted with little margin
    h_opening, opening_tight = 0.0, False
    while t < t_end:
        if taken >= max_steps:
            step[0] = _memory(scheme, mode, h)
            return TOO_MANY_STEPS, t
        last = t + h >= t_end
        h_try = t_end - t if last else h
        if h_try < floor and not last:
            step[0] = _memory(scheme, mode, h)
            return STEP_BELOW_FLOOR, t
        taken += 1
        outcome, err, h_rho, expo, have_jac = _attempt(
            scheme, method, mode, state, h_try, buf, phis, cap, jac, lu, piv, pivots, coefs,
            n_inv, have_jac, secant, cell, aux, local, config, work, rtol, atol, droplet, n,
            stats)
        crossed = hold and outcome == ACCEPT and local[P.STOKES_CROSSED] != 0.0
        if crossed:
            outcome, err = located(method, t, state, h_try, buf, cell, aux, local, config,
                                   work, rtol, atol, n, stats, saved, loc, outcome, err)
        if outcome == ACCEPT:
            t = t_end if last else t + h_try
            for i in range(n):
                state[i] = buf[YNEW, i]
            if scheme != EXPLICIT and droplet >= 0:
                _absorb_droplets(method, state, droplet, atol, pivots, coefs, n_inv, aux,
                                 local, config, work, buf[FTMP])
            if droplet >= 0:
                _dry_out_droplets(state, droplet, local, config, rtol, atol)
            method.project(state, aux, local, config, work)
            _rate_after_step(method, mode == 0, expo, crossed, state, buf, cell, aux, local,
                             config, work, n, stats)
            stats[ACCEPTED] += 1
            if expo:
                stats[EXPONENTIAL_STEPS] += 1
            # the exponential step stays exact in the invariants and realizable-checked with a
            # capture column of an earlier state (its linear part is then the capture there;
            # the error estimate sees the rest): kept for the call, renewed after a rejection
            cap[CAP_AGE] += 1
            factor = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / 3.0)))
            h = h_try * factor if not last else max(h, h_try * factor)
            have_jac = False
            secant = np.bool_(False)
            mode, h = _next_mode(scheme == AUTO, mode, h, h_try, h_rho, sw, jac, buf, n, stats)
            if hold:
                h = locate_next(crossed, t, h, loc)
            if h_opening == 0.0:
                h_opening = h
                opening_tight = opening_tight or factor < OPENING_MARGIN
        else:
            if h_opening == 0.0:
                opening_tight = True
            if cap[CAP_AGE] > 0:
                cap[CAP_FRESH] = 0
            h = _after_reject(outcome, err, h_try, stats)
            if outcome == REJECT_REALIZABILITY and mode == 1 and not secant:   # tangent failed
                have_jac, secant = np.bool_(False), np.bool_(True)
    # a call that opened on a transient (its first attempt rejected, or its first step accepted
    # with little margin) hands the next call the step it opened with, not the one it ended
    # with: with transport every call opens on a fresh transient (droplets carried in) and the
    # step that ended the last one was rejected there three times out of four (split 0.5 s)
    step[0] = _memory(scheme, mode, min(h, h_opening) if opening_tight and h_opening > 0.0
                      else h)
    return OK, t


@nb.njit(cache=True, nogil=True)
def integrate_cells_kernel(rhs, realizable, project, conserved, scheme, states, cells, aux,
                           params, config, t_start, t_end, steps, rtol, atol, max_steps, stats,
                           status, reached, first, stride):
    """``integrate_cell`` over the rows first, first + stride, first + 2 stride, ... of
    ``states`` (one thread's share of the cells; the GIL released). rhs, realizable,
    project, conserved: the method's functions as first-class functions
    (``kernel_types``)."""
    method = MethodFunctions(rhs, realizable, project, conserved)
    n_cells = states.shape[0]
    for c in range(first, n_cells, stride):
        if status[c] != OK:
            continue
        code, t = integrate_cell(method, scheme, states[c], cells[c], aux, params, config,
                                 t_start, t_end, steps[c:c + 1], rtol, atol, max_steps,
                                 stats[c])
        status[c] = code
        reached[c] = t
