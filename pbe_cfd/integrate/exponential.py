"""One step of the Bogacki-Shampine pair with the droplet capture integrated exactly.

Free droplets are captured at a rate linear in their number n_d: d(state)/dt = A(g) + n_d G(g)
(g the granule moments, G the capture column: what one droplet per unit time adds to each
moment, and -lambda, the capture rate per droplet, in the droplet entry). The step freezes
G_n = G(g_n) at its start and integrates the linear part L y = G_n y_d exactly, the rest
N(y) = f(y) - L y with the explicit pair: an exponential Runge-Kutta method (Hochbruck &
Ostermann, Acta Numerica 2010) whose coefficients are the functions
phi_k(z) = sum_m z^m / (m + k)! of h L. L has rank one with L^2 = -lambda L, so every
coefficient g(hL) = g(0) I + (g(Z) - g(0)) / Z hL with the scalar Z = -lambda h: no matrix
function is formed.

Coefficients (stage times 0, 1/2, 3/4, 1; they reduce to the pair's at Z = 0):
    b1 = phi1 - b2 - b3, b2 = 6 phi2 - 16 phi3, b3 = (32 phi3 - 8 phi2) / 3
    (sum b_i = phi1, sum b_i c_i = phi2, sum b_i c_i^2 / 2 = phi3: order 3),
    a21 = phi1(Z/2) / 2, a31 + a32 = 3/4 phi1(3Z/4), a32 = 6 phi3 / (32 phi3 - 8 phi2)
    (b3 a32 c2 = phi3), error estimate h (-5/72 N1 + 1/12 N2 + 1/9 N3 - 1/8 N4) as the pair's.
Measured order 3 on a test problem with a capture rate 50 (1 + ...) varying with g.

Why: the droplet number decays as e^(-lambda t) after every transport step (and at rates up to
1e6 /s next to packing); the explicit pair must resolve that decay (about 50 steps per 0.25 s
split step in the bundled transport scene at rtol 1e-6, where lambda h is only 0.03); with the
decay integrated exactly the same cells take 4 steps. The droplet entry of every stage is a
positive combination (e^(-lambda c h) n_d + injection), and the linear invariants (granule and
binder mass) see only polynomial weights (c . L = 0), so they stay exact as in the pair.
"""
import math

import numba as nb

from ..physics import parameters as P
from ..physics.injection import droplet_liquid, droplet_liquid_entry
from .codes import (ACCEPT, F0, FTMP, GCOL, KA, KB, KC, REJECT_ERROR, REJECT_NOT_FINITE,
                    REJECT_REALIZABILITY, STAGE, YNEW, YTMP)


@nb.njit(cache=True)
def phi_functions(z, out):
    """phi_0(z) .. phi_5(z) into out[0:6] (Taylor series for |z| < 0.5, else recurrence)."""
    if abs(z) < 0.5:
        for k in range(6):
            term = 1.0 / math.gamma(k + 1.0)
            total = term
            m = 1
            while m < 30:
                term *= z / (m + k)
                total += term
                if abs(term) <= 1e-17 * abs(total):
                    break
                m += 1
            out[k] = total
    else:
        out[0] = math.exp(z)
        fact = 1.0
        for k in range(1, 6):
            out[k] = (out[k - 1] - 1.0 / fact) / z
            fact *= k


@nb.njit(cache=True, inline="always")
def capture_column(method, y, buf, cell, aux, params, config, work, d, n):
    """buf[GCOL] = d f / d n_d at y (exact: the RHS is linear in the droplet number), from one
    RHS evaluation at y with n_d raised (buf[F0] = f(y)). Returns the capture rate lambda
    [1/s] (minus the droplet entry). With a droplet-liquid entry (drying) the droplets' liquid
    is raised with their number at the class's liquid per droplet (a fresh droplet's where
    there are none): the RHS is linear in the droplet population (n_d, L_d) at a fixed liquid
    per droplet, so the column is that population's, and the exact part moves L_d with n_d."""
    yp = buf[YTMP]
    g = buf[GCOL]
    fp = buf[FTMP]
    f0 = buf[F0]
    for i in range(n):
        yp[i] = y[i]
    delta = y[d] if y[d] > 0.0 else 1.0
    yp[d] = y[d] + delta
    liquid = droplet_liquid_entry(config)
    if liquid >= 0:
        per_droplet = (y[liquid] / y[d] if y[d] > 0.0
                       else droplet_liquid(params) / params[P.MASS_SCALE])
        yp[liquid] = y[liquid] + delta * per_droplet
    method.rhs(yp, fp, cell, aux, params, config, work)
    step = yp[d] - y[d]
    for i in range(n):
        g[i] = (fp[i] - f0[i]) / step
    return -g[d]


@nb.njit(cache=True, inline="always")
def exp_bs3_attempt(method, y, h, buf, phis, cell, aux, params, config, work, rtol, atol, d,
                    n):
    """Attempt one step of size h [s] from y (buf[F0] = f(y), buf[GCOL] = G_n, d the droplet
    entry). The candidate is left in buf[YNEW]. Returns (outcome, error norm, h rho, RHS
    calls) as ``explicit.bs3_attempt``; rho from the third divided differences of the
    stages' N (the part not integrated exactly)."""
    f0 = buf[F0]
    g = buf[GCOL]
    n2 = buf[KA]
    n3 = buf[KB]
    n4 = buf[KC]
    stage = buf[STAGE]
    s2 = buf[YTMP]
    y_new = buf[YNEW]
    ft = buf[FTMP]
    z = g[d] * h                                  # Z = -lambda h
    phi_functions(z, phis[0])
    phi_functions(0.5 * z, phis[1])
    phi_functions(0.75 * z, phis[2])
    p = phis[0]
    ph = phis[1]
    pq = phis[2]
    yd = y[d]
    n1d = f0[d] - g[d] * yd                       # N1 = f0 - G yd: its droplet entry
    # stage 2 (c = 1/2): e^(hL/2) y + h/2 phi1(hL/2) N1
    coef_y = 0.5 * ph[1] * h * yd + 0.5 * h * 0.5 * ph[2] * h * n1d
    for i in range(n):
        s2[i] = y[i] + coef_y * g[i] + 0.5 * h * (f0[i] - g[i] * yd)
    if not method.realizable(s2, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 0
    method.rhs(s2, ft, cell, aux, params, config, work)
    for i in range(n):
        n2[i] = ft[i] - g[i] * s2[d]
    # stage 3 (c = 3/4): e^(3hL/4) y + 3h/4 phi1(3hL/4) N1 + h a32(hL) (N2 - N1)
    den = 32.0 * p[3] - 8.0 * p[2]
    da32 = 6.0 * (p[3] - 3.0 * p[4]) / den        # (a32(Z) - 3/4) / Z
    diff_d = n2[d] - n1d
    coef_y = (0.75 * pq[1] * h * yd + 0.75 * h * 0.75 * pq[2] * h * n1d
              + h * da32 * h * diff_d)
    for i in range(n):
        stage[i] = y[i] + coef_y * g[i] + 0.75 * h * n2[i]
    if not method.realizable(stage, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 1
    method.rhs(stage, ft, cell, aux, params, config, work)
    for i in range(n):
        n3[i] = ft[i] - g[i] * stage[d]
    # y_new = e^(hL) y + h (b1(hL) N1 + b2(hL) N2 + b3(hL) N3), b_i(hL) = b_i(0) + db_i hL
    db2 = 6.0 * p[3] - 16.0 * p[4]
    db3 = (32.0 * p[4] - 8.0 * p[3]) / 3.0
    db1 = p[2] - db2 - db3
    coef_y = p[1] * h * yd + h * h * (db1 * n1d + db2 * n2[d] + db3 * n3[d])
    for i in range(n):
        n1 = f0[i] - g[i] * yd
        y_new[i] = y[i] + coef_y * g[i] + h * (2.0 / 9.0 * n1 + 1.0 / 3.0 * n2[i]
                                               + 4.0 / 9.0 * n3[i])
    if not method.realizable(y_new, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0.0, 2
    method.rhs(y_new, ft, cell, aux, params, config, work)
    err = 0.0
    num = 0.0
    den2 = 0.0
    finite = True
    for i in range(n):
        n4[i] = ft[i] - g[i] * y_new[d]
        if not math.isfinite(n4[i]):
            finite = False
        n1 = f0[i] - g[i] * yd
        e = h * (-5.0 / 72.0 * n1 + 1.0 / 12.0 * n2[i] + 1.0 / 9.0 * n3[i] - 1.0 / 8.0 * n4[i])
        sc = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        r = abs(e) / sc
        if r > err:
            err = r
        d_state = (-8.0 / 3.0 * y[i] + 16.0 * s2[i] - 64.0 / 3.0 * stage[i]
                   + 8.0 * y_new[i]) / sc
        d_rate = (-8.0 / 3.0 * n1 + 16.0 * n2[i] - 64.0 / 3.0 * n3[i] + 8.0 * n4[i]) / sc
        num += d_rate * d_rate
        den2 += d_state * d_state
    if not finite:
        return REJECT_NOT_FINITE, 0.0, 0.0, 3
    h_rho = h * math.sqrt(num / den2) if den2 > 0.0 else 0.0
    if err <= 1.0:
        return ACCEPT, err, h_rho, 3
    return REJECT_ERROR, err, h_rho, 3
