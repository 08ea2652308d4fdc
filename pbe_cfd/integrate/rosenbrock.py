"""One step of the linearly implicit Rosenbrock method RODAS3, with its Jacobian.

RODAS3 (Sandu, Verwer, Blom, Spee, Carmichael, Potra, Atmos. Environ. 31, 1997): four
stages, three right-hand sides, order 3 with an embedded order-2 solution, L-stable and
stiffly accurate (both solutions are stage arguments). In the form of Hairer & Wanner
(Solving ODEs II, sec. IV.7) with A = I / (gamma h) - J, gamma = 1/2:

    A k1 = f(y)                       A k2 = f(y) + 4 k1 / h
    A k3 = f(y + 2 k1) + (k1 - k2) / h
    A k4 = f(y + 2 k1 + k3) + (k1 - k2 - 8/3 k3) / h
    y_new = y + 2 k1 + k3 + k4,       error estimate k4.

The stage arguments y + 2 k1, y + 2 k1 + k3 and y_new must be realizable, as every stage of
the explicit pair; otherwise the step is rejected and halved.

The Jacobian J = df/dy comes from central differences of the method's right-hand side (2 n
evaluations; one-sided where a side is not realizable): a Rosenbrock method is order 3 only
with J f accurate, and forward differences were not accurate enough (``jacobian``). The rows of the conserved quantities are then set from the other rows so that
c . J = 0 holds to round-off for each linear invariant c of the method (c . f does not depend
on the state): then c . k_i = gamma h c . (right-hand side of stage i) and the step changes
c . y exactly as the explicit pair does, by h times the injection (M10, M01 exact).
"""
import math

import numba as nb

from .codes import (ACCEPT, F0, FTMP, KA, KB, KC, KD, REJECT_ERROR, REJECT_NOT_FINITE,
                    REJECT_REALIZABILITY, STAGE, YNEW, YTMP)

GAMMA = 0.5
#: relative perturbation of the finite-difference Jacobian (square root of the unit round-off)
SQRT_EPS = 1.4901161193847656e-08


@nb.njit(cache=True, inline="always")
def jacobian(method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config, work,
             rtol, atol, n):
    """``secant_jacobian`` with the differences at sqrt(eps) (h_scale = 0): the Jacobian
    J = df/dy at y [1/s]. Returns the number of RHS calls."""
    return secant_jacobian(method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params,
                           config, work, rtol, atol, n, 0.0)


@nb.njit(cache=True, inline="always")
def secant_jacobian(method, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config,
                    work, rtol, atol, n, h_scale):
    """Central-difference Jacobian of the RHS at y (buf[F0] = f(y)) into jac (n, n) [1/s].

    Column j perturbs y_j by +- sqrt(eps) max(|y_j|, atol / rtol); where only one side is
    realizable it is a one-sided difference against f(y); if neither is, the column is left
    zero (the Rosenbrock step then treats that direction explicitly). With h_scale [s] > 0
    (after a realizability rejection, ``cell``) each perturbation is at least the change
    h_scale |f_j(y)| the step makes in that entry: a secant over the step, not the tangent at
    y, where the RHS is curved on a far smaller scale than the step (a quadrature node carrying
    1e-8 of the number, whose per-node binder moves by 1/w with the binder moments;
    docs/results/hard-cases.md). Central, not forward:
    near the realizability boundary the moment RHS is strongly curved (its linearisation holds
    for relative changes below ~1e-4) and its Jacobian columns are large and cancel along the
    trajectory, so the forward differences' O(delta) bias made J f wrong by 2.6% on the
    study-ktgf cell, and a Rosenbrock method with J f wrong is only first order (its steps
    grew as rtol^(-1/2), its error as rtol^(1/2)); central differences make it 2.6e-7.
    The rows of the invariants
    (pivots, coefs; see ``conserved``) are replaced by minus the combination of the other
    rows. Returns the number of RHS calls.
    """
    f0 = buf[F0]
    yp = buf[YTMP]
    fp = buf[FTMP]
    fm = buf[STAGE]
    floor = atol / rtol
    calls = 0
    for j in range(n):
        yp[j] = y[j]
    for j in range(n):
        delta = SQRT_EPS * max(abs(y[j]), floor)
        if h_scale > 0.0:
            delta = max(delta, h_scale * abs(f0[j]))
        yp[j] = y[j] + delta
        up = method.realizable(yp, aux, params, config, work)
        if up:
            method.rhs(yp, fp, cell, aux, params, config, work)
            calls += 1
        yp[j] = y[j] - delta
        down = method.realizable(yp, aux, params, config, work)
        if down:
            method.rhs(yp, fm, cell, aux, params, config, work)
            calls += 1
        yp[j] = y[j]
        if up and down:             # central: second-order accurate
            inv = 0.5 / delta
            for i in range(n):
                value = (fp[i] - fm[i]) * inv
                jac[i, j] = value if math.isfinite(value) else 0.0
        elif up or down:            # one-sided where the other side is not realizable
            inv = 1.0 / delta if up else -1.0 / delta
            for i in range(n):
                value = ((fp[i] if up else fm[i]) - f0[i]) * inv
                jac[i, j] = value if math.isfinite(value) else 0.0
        else:
            for i in range(n):
                jac[i, j] = 0.0
    for r in range(n_inv):
        p = pivots[r]
        for j in range(n):
            total = 0.0
            for i in range(n):
                if i != p:
                    total += coefs[r, i] * jac[i, j]
            jac[p, j] = -total / coefs[r, p]
    return calls


@nb.njit(cache=True)
def lu_factor(a, piv, n):
    """LU factorisation with partial pivoting of a (n, n) in place; False if singular."""
    for k in range(n):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, n):
            if abs(a[i, k]) > big:
                big = abs(a[i, k])
                p = i
        if not (big > 0.0) or not math.isfinite(big):
            return False
        piv[k] = p
        if p != k:
            for j in range(n):
                tmp = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = tmp
        inv = 1.0 / a[k, k]
        for i in range(k + 1, n):
            a[i, k] *= inv
            factor = a[i, k]
            if factor != 0.0:
                for j in range(k + 1, n):
                    a[i, j] -= factor * a[k, j]
    return True


@nb.njit(cache=True)
def lu_solve(a, piv, b, n):
    """Solve (LU) x = b in place (factors and pivots from ``lu_factor``)."""
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for i in range(n):
        total = b[i]
        for j in range(i):
            total -= a[i, j] * b[j]
        b[i] = total
    for i in range(n - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, n):
            total -= a[i, j] * b[j]
        b[i] = total / a[i, i]


@nb.njit(cache=True)
def spectral_radius(jac, v, w, n):
    """Estimate of the largest |eigenvalue| of jac [1/s] by eight power iterations."""
    for i in range(n):
        v[i] = 1.0 + 0.37 * i
    size = 0.0
    for _ in range(8):
        norm = 0.0
        for i in range(n):
            total = 0.0
            for j in range(n):
                total += jac[i, j] * v[j]
            w[i] = total
            norm += total * total
        norm = math.sqrt(norm)
        vnorm = 0.0
        for i in range(n):
            vnorm += v[i] * v[i]
        vnorm = math.sqrt(vnorm)
        if not (norm > 0.0) or not math.isfinite(norm):
            return 0.0 if norm == 0.0 else math.inf
        size = norm / vnorm
        for i in range(n):
            v[i] = w[i] / norm
    return size


@nb.njit(cache=True, inline="always")
def rodas3_attempt(method, y, h, buf, jac, lu, piv, cell, aux, params, config, work, rtol,
                   atol, n):
    """Attempt one RODAS3 step of size h [s] from y with Jacobian jac (buf[F0] = f(y)).

    The candidate is left in buf[YNEW]. Returns (outcome, error norm, RHS calls) as
    ``explicit.bs3_attempt`` (without the stiffness estimate).
    """
    f0 = buf[F0]
    k1 = buf[KA]
    k2 = buf[KB]
    k3 = buf[KC]
    k4 = buf[KD]
    stage = buf[STAGE]
    y_new = buf[YNEW]
    ft = buf[FTMP]
    diag = 1.0 / (GAMMA * h)
    for i in range(n):
        for j in range(n):
            lu[i, j] = -jac[i, j]
        lu[i, i] += diag
    if not lu_factor(lu, piv, n):
        return REJECT_NOT_FINITE, 0.0, 0
    inv_h = 1.0 / h
    for i in range(n):
        k1[i] = f0[i]
    lu_solve(lu, piv, k1, n)
    for i in range(n):
        k2[i] = f0[i] + 4.0 * inv_h * k1[i]
    lu_solve(lu, piv, k2, n)
    for i in range(n):
        stage[i] = y[i] + 2.0 * k1[i]
    if not method.realizable(stage, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 0
    method.rhs(stage, ft, cell, aux, params, config, work)
    for i in range(n):
        k3[i] = ft[i] + inv_h * (k1[i] - k2[i])
    lu_solve(lu, piv, k3, n)
    for i in range(n):
        stage[i] += k3[i]
    if not method.realizable(stage, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 1
    method.rhs(stage, ft, cell, aux, params, config, work)
    for i in range(n):
        k4[i] = ft[i] + inv_h * (k1[i] - k2[i] - 8.0 / 3.0 * k3[i])
    lu_solve(lu, piv, k4, n)
    err = 0.0
    for i in range(n):
        y_new[i] = stage[i] + k4[i]
        if not (math.isfinite(y_new[i]) and math.isfinite(k4[i])):
            return REJECT_NOT_FINITE, 0.0, 2
        r = abs(k4[i]) / (atol + rtol * max(abs(y[i]), abs(y_new[i])))
        if r > err:
            err = r
    if err > 1.0:
        return REJECT_ERROR, err, 2
    if not method.realizable(y_new, aux, params, config, work):
        return REJECT_REALIZABILITY, 0.0, 2
    return ACCEPT, err, 2
