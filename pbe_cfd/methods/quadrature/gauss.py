"""Gaussian quadrature from moments: Wheeler's algorithm and a tridiagonal eigen-solve.

All functions work on non-dimensional moments (the caller scales masses and number densities);
they never allocate inside the per-cell loop beyond small fixed work arrays passed in.

The quadrature of n nodes reproduces the moments mu_0 .. mu_{2n-1} of a positive measure on
(0, inf). A moment set is *realizable* when the Hankel determinants are positive; the Wheeler
recurrence exposes them as the coefficients b_k > 0. A set on the boundary of the realizable
region (for example a monodisperse population, whose Hankel determinants vanish) yields fewer
nodes; a set outside it also yields fewer nodes, and the caller decides, by re-projecting, whether
the discarded moments were consistent with the reduced quadrature.

Speed (the QMOM right-hand side inverts every call): the Jacobi matrices of 2 and 3 nodes are
solved in closed form -- 2 x 2 by the quadratic formula, 3 x 3 by the trigonometric cubic
formula polished by Newton steps on the characteristic polynomial (the three-term
recurrence), the weights (squared first eigenvector components) from the best-conditioned
cross product of two rows of J - lambda I. Any doubt (non-finite, unordered, or weights not
summing to 1 within CLOSED_FORM_CHECK) falls back to the implicit QL iteration, which also
serves 4 nodes and more.
"""
import math

import numba as nb
import numpy as np

#: Relative size below which a Wheeler coefficient is treated as zero (round-off of the
#: recurrence's subtraction is ~1e-16 of the terms; a genuine distribution whose relative
#: variance is below this acts as monodisperse to every carried moment).
DEGENERACY_TOLERANCE = 1.0e-11
#: A closed-form eigen-solve (2 or 3 nodes) is accepted when its weights sum to 1 within this;
#: otherwise the QL iteration solves the matrix.
CLOSED_FORM_CHECK = 1.0e-10
_THIRD_TURN = 2.0 * math.pi / 3.0


@nb.njit(cache=True, inline="always")
def _hypot(x, y):
    """sqrt(x^2 + y^2) without the cost of math.hypot where no over/underflow can occur."""
    ax = abs(x)
    ay = abs(y)
    big = ax if ax > ay else ay
    if big < 1.0e150 and big > 1.0e-150:
        return math.sqrt(x * x + y * y)
    return math.hypot(x, y)


@nb.njit(cache=True, error_model="numpy")
def tridiagonal_eigen(diagonal, offdiagonal, first_component, n):
    """Eigenvalues and first eigenvector components of a symmetric tridiagonal matrix.

    Implicit QL iteration with Wilkinson-type shifts on the leading n x n block.
    ``diagonal[0:n]`` is overwritten with the eigenvalues, ``offdiagonal[0:n-1]`` (coupling of
    rows k and k+1) is destroyed, ``first_component[0:n]`` receives row 0 of the eigenvector
    matrix (the Golub-Welsch weights are its squares). Dimensionless. Returns False if the
    iteration did not converge (never observed for the small, well-scaled Jacobi matrices here).
    """
    for k in range(n):
        first_component[k] = 0.0
    first_component[0] = 1.0
    if n == 1:
        return True
    offdiagonal[n - 1] = 0.0
    for l in range(n):
        iterations = 0
        while True:
            m = l
            while m < n - 1:
                scale = abs(diagonal[m]) + abs(diagonal[m + 1])
                if abs(offdiagonal[m]) <= 1.0e-16 * scale:
                    break
                m += 1
            if m == l:
                break
            iterations += 1
            if iterations > 60:
                return False
            g = (diagonal[l + 1] - diagonal[l]) / (2.0 * offdiagonal[l])
            r = _hypot(g, 1.0)
            g = diagonal[m] - diagonal[l] + offdiagonal[l] / (g + math.copysign(r, g))
            s = 1.0
            c = 1.0
            p = 0.0
            i = m - 1
            deflated = False
            while i >= l:
                f = s * offdiagonal[i]
                b = c * offdiagonal[i]
                r = _hypot(f, g)
                offdiagonal[i + 1] = r
                if r == 0.0:
                    diagonal[i + 1] -= p
                    offdiagonal[m] = 0.0
                    deflated = True
                    break
                s = f / r
                c = g / r
                g = diagonal[i + 1] - p
                r = (diagonal[i] - g) * s + 2.0 * c * b
                p = s * r
                diagonal[i + 1] = g + p
                g = c * r - b
                f = first_component[i + 1]
                first_component[i + 1] = s * first_component[i] + c * f
                first_component[i] = c * first_component[i] - s * f
                i -= 1
            if deflated:
                continue
            diagonal[l] -= p
            offdiagonal[l] = g
            offdiagonal[m] = 0.0
    return True


@nb.njit(cache=True, inline="always")
def _first_weight2(lam, a0, a1, e):
    """Squared first component of the unit eigenvector of [[a0, e], [e, a1]] for lam, from the
    larger of the two vectors orthogonal to a row of J - lam I."""
    u0 = e                       # orthogonal to row 0: (e, lam - a0)
    u1 = lam - a0
    v0 = lam - a1                # orthogonal to row 1: (lam - a1, e)
    v1 = e
    nu = u0 * u0 + u1 * u1
    nv = v0 * v0 + v1 * v1
    if nu >= nv:
        return u0 * u0 / nu
    return v0 * v0 / nv


@nb.njit(cache=True, error_model="numpy")
def jacobi2(a0, a1, b1, nodes, weights):
    """Closed-form Gauss rule of the 2 x 2 Jacobi matrix [[a0, sqrt(b1)], [sqrt(b1), a1]]:
    eigenvalues into nodes[0:2], squared first eigenvector components into weights[0:2].
    The eigenvalue of smaller modulus comes from the determinant (no cancellation). Returns
    False if the result fails the checks (the caller then uses the QL iteration)."""
    e = math.sqrt(b1)
    m = 0.5 * (a0 + a1)
    d = 0.5 * (a0 - a1)
    r = math.sqrt(d * d + b1)
    big = m + math.copysign(r, m)
    if big == 0.0:
        return False
    small = (a0 * a1 - b1) / big
    w0 = _first_weight2(big, a0, a1, e)
    w1 = _first_weight2(small, a0, a1, e)
    total = w0 + w1
    if not (abs(total - 1.0) <= CLOSED_FORM_CHECK) or not math.isfinite(small):
        return False
    nodes[0] = big
    nodes[1] = small
    weights[0] = w0 / total
    weights[1] = w1 / total
    return True


@nb.njit(cache=True, inline="always")
def _newton3(lam, a0, a1, a2, b1, b2, scale):
    """Newton steps on det(lam I - J) of the 3 x 3 Jacobi matrix (three-term recurrence): a
    second step only where the first moved lam by more than 1e-9 of ``scale`` (the spread of
    the eigenvalues; the trigonometric formula loses digits only for near-double roots)."""
    for it in range(2):
        p1 = lam - a0
        p2 = (lam - a1) * p1 - b1
        p3 = (lam - a2) * p2 - b2 * p1
        d2 = p1 + (lam - a1)
        d3 = p2 + (lam - a2) * d2 - b2
        if d3 == 0.0 or p3 == 0.0:
            break
        step = p3 / d3
        lam -= step
        if abs(step) <= 1.0e-9 * scale:
            break
    return lam


@nb.njit(cache=True, inline="always")
def _first_weight3(lam, a0, a1, a2, e1, e2):
    """Squared first component of the unit eigenvector of the 3 x 3 Jacobi matrix for lam: the
    largest of the three cross products of rows of J - lam I (all parallel to the vector)."""
    d0 = a0 - lam
    d1 = a1 - lam
    d2 = a2 - lam
    u0 = e1 * e2                 # row 0 x row 1
    u1 = -d0 * e2
    u2 = d0 * d1 - e1 * e1
    v0 = d1 * d2 - e2 * e2       # row 1 x row 2
    v1 = -e1 * d2
    v2 = e1 * e2
    w0 = e1 * d2                 # row 0 x row 2
    w1 = -d0 * d2
    w2 = d0 * e2
    nu = u0 * u0 + u1 * u1 + u2 * u2
    nv = v0 * v0 + v1 * v1 + v2 * v2
    nw = w0 * w0 + w1 * w1 + w2 * w2
    if nu >= nv and nu >= nw:
        return u0 * u0 / nu
    if nv >= nw:
        return v0 * v0 / nv
    return w0 * w0 / nw


@nb.njit(cache=True, error_model="numpy")
def jacobi3(a0, a1, a2, b1, b2, nodes, weights):
    """Closed-form Gauss rule of the 3 x 3 Jacobi matrix with diagonal (a0, a1, a2) and squared
    off-diagonals (b1, b2): trigonometric cubic formula on J - q I (q the mean eigenvalue),
    polished by Newton on the characteristic polynomial; weights from cross products.
    Returns False if the eigenvalues are not finite and strictly ordered or the weights do not
    sum to 1 within CLOSED_FORM_CHECK (the caller then uses the QL iteration)."""
    e1 = math.sqrt(b1)
    e2 = math.sqrt(b2)
    q = (a0 + a1 + a2) / 3.0
    s0 = a0 - q
    s1 = a1 - q
    s2 = a2 - q
    p = math.sqrt((s0 * s0 + s1 * s1 + s2 * s2 + 2.0 * (b1 + b2)) / 6.0)
    if not (p > 0.0) or not math.isfinite(p):
        return False
    det = s0 * (s1 * s2 - b2) - b1 * s2
    r = det / (2.0 * p * p * p)
    if r > 1.0:
        r = 1.0
    elif r < -1.0:
        r = -1.0
    phi = math.acos(r) / 3.0
    l0 = q + 2.0 * p * math.cos(phi)
    l2 = q + 2.0 * p * math.cos(phi + _THIRD_TURN)
    l1 = 3.0 * q - l0 - l2
    l0 = _newton3(l0, a0, a1, a2, b1, b2, p)
    l1 = _newton3(l1, a0, a1, a2, b1, b2, p)
    l2 = _newton3(l2, a0, a1, a2, b1, b2, p)
    if not (l0 > l1 and l1 > l2) or not math.isfinite(l0) or not math.isfinite(l2):
        return False
    w0 = _first_weight3(l0, a0, a1, a2, e1, e2)
    w1 = _first_weight3(l1, a0, a1, a2, e1, e2)
    w2 = _first_weight3(l2, a0, a1, a2, e1, e2)
    total = w0 + w1 + w2
    if not (abs(total - 1.0) <= CLOSED_FORM_CHECK):
        return False
    nodes[0] = l0
    nodes[1] = l1
    nodes[2] = l2
    weights[0] = w0 / total
    weights[1] = w1 / total
    weights[2] = w2 / total
    return True


@nb.njit(cache=True, error_model="numpy")
def wheeler_nodes(moments, n_max, nodes, weights, work):
    """Gauss quadrature of at most n_max nodes from the moments mu_0 .. mu_{2 n_max - 1}.

    ``moments`` are non-dimensional moments of a measure on (0, inf); ``nodes`` and ``weights``
    (length >= n_max) receive abscissas and weights in the same units; ``work`` is a float work
    array of length >= (2 n_max + 1) * (2 n_max + 1) + 4 n_max. Moments are normalised by mu_0
    and the mean before the recurrence, so any overall scale is harmless.

    Returns the number of nodes n_eff (0 for an empty or invalid set). The node count drops
    below n_max where a Wheeler coefficient b_k is not positive beyond round-off (a degenerate or
    a non-realizable set) or where a node would not be positive; whether the dropped moments were
    consistent is for the caller to judge by re-projecting.
    """
    m0 = moments[0]
    if not (m0 > 0.0) or not math.isfinite(m0):
        return 0
    mean = moments[1] / m0
    if not (mean > 0.0) or not math.isfinite(mean):
        return 0
    n_mom = 2 * n_max
    width = n_mom + 1
    # work layout: sigma rows k = -1 .. n_max-1 (n_max + 1 rows of width), then a, b, diag, off
    sig = work
    ia = (n_max + 1) * width          # a[k] = work[ia + k]
    ib = ia + n_max                   # b[k] = work[ib + k]
    for l in range(width):
        sig[l] = 0.0                      # row k = -1
    scale = 1.0
    for l in range(n_mom):
        sig[width + l] = moments[l] / (m0 * scale)   # row k = 0: normalised moments
        scale *= mean
    work[ia] = sig[width + 1] / sig[width + 0]
    work[ib] = 0.0
    n_eff = np.int64(1)      # not a literal: tridiagonal_eigen compiles once
    for k in range(1, n_max):
        row = (k + 1) * width
        prev = k * width
        prev2 = (k - 1) * width
        ak = work[ia + k - 1]
        bk = work[ib + k - 1]
        for l in range(k, n_mom - k):
            sig[row + l] = sig[prev + l + 1] - ak * sig[prev + l] - bk * sig[prev2 + l]
        # compare the new diagonal sigma with the size of the terms it was computed from
        terms = (abs(sig[prev + k + 1]) + abs(ak * sig[prev + k])
                 + abs(bk * sig[prev2 + k]))
        if not (sig[row + k] > DEGENERACY_TOLERANCE * terms) or not math.isfinite(sig[row + k]):
            break
        a_new = sig[row + k + 1] / sig[row + k] - sig[prev + k] / sig[prev + k - 1]
        b_new = sig[row + k] / sig[prev + k - 1]
        if not (b_new > 0.0) or not math.isfinite(a_new):
            break
        work[ia + k] = a_new
        work[ib + k] = b_new
        n_eff = k + 1
    # Golub-Welsch; drop nodes while any abscissa is not positive
    idiag = ib + n_max
    ioff = idiag + n_max
    while n_eff > 0:
        ok = False
        if n_eff == 1:
            nodes[0] = work[ia]
            weights[0] = 1.0
            ok = True
        elif n_eff == 2:
            ok = jacobi2(work[ia], work[ia + 1], work[ib + 1], nodes, weights)
        elif n_eff == 3:
            ok = jacobi3(work[ia], work[ia + 1], work[ia + 2], work[ib + 1], work[ib + 2],
                         nodes, weights)
        if not ok:
            diag = work[idiag:idiag + n_max]
            off = work[ioff:ioff + n_max]
            for k in range(n_eff):
                diag[k] = work[ia + k]
            for k in range(n_eff - 1):
                off[k] = math.sqrt(work[ib + k + 1])
            ok = tridiagonal_eigen(diag, off, weights, n_eff)
            for k in range(n_eff):
                nodes[k] = diag[k]
                weights[k] = weights[k] * weights[k]
        positive = ok
        for k in range(n_eff):
            if not (nodes[k] > 0.0) or not math.isfinite(nodes[k]):
                positive = False
        if positive:
            for k in range(n_eff):
                nodes[k] = nodes[k] * mean
                weights[k] = weights[k] * m0
            return n_eff
        n_eff -= 1
    return 0


@nb.njit(cache=True, error_model="numpy")
def solve_vandermonde(nodes, rhs, solution, n, work):
    """Solve sum_a nodes[a]^k solution[a] = rhs[k], k < n. Dimensionless.

    n <= 3 in closed form (Lagrange basis polynomials), larger n by Gaussian elimination with
    partial pivoting on an n x n work block (``work`` length >= n * (n + 1)).
    Returns False if the nodes are not distinct (a singular system).
    """
    if n == 1:
        solution[0] = rhs[0]
        return True
    if n == 2:
        x0 = nodes[0]
        x1 = nodes[1]
        if x0 == x1:
            return False
        solution[0] = (rhs[1] - x1 * rhs[0]) / (x0 - x1)
        solution[1] = (rhs[1] - x0 * rhs[0]) / (x1 - x0)
        return True
    if n == 3:
        x0 = nodes[0]
        x1 = nodes[1]
        x2 = nodes[2]
        if x0 == x1 or x0 == x2 or x1 == x2:
            return False
        solution[0] = (rhs[2] - (x1 + x2) * rhs[1] + x1 * x2 * rhs[0]) / ((x0 - x1) * (x0 - x2))
        solution[1] = (rhs[2] - (x0 + x2) * rhs[1] + x0 * x2 * rhs[0]) / ((x1 - x0) * (x1 - x2))
        solution[2] = (rhs[2] - (x0 + x1) * rhs[1] + x0 * x1 * rhs[0]) / ((x2 - x0) * (x2 - x1))
        return True
    w = n + 1
    for a in range(n):
        value = 1.0
        for k in range(n):
            work[k * w + a] = value
            value *= nodes[a]
    for k in range(n):
        work[k * w + n] = rhs[k]
    for col in range(n):
        pivot = col
        big = abs(work[col * w + col])
        for r in range(col + 1, n):
            if abs(work[r * w + col]) > big:
                big = abs(work[r * w + col])
                pivot = r
        if big == 0.0:
            return False
        if pivot != col:
            for c in range(w):
                tmp = work[col * w + c]
                work[col * w + c] = work[pivot * w + c]
                work[pivot * w + c] = tmp
        for r in range(col + 1, n):
            factor = work[r * w + col] / work[col * w + col]
            if factor != 0.0:
                for c in range(col, w):
                    work[r * w + c] -= factor * work[col * w + c]
    for r in range(n - 1, -1, -1):
        acc = work[r * w + n]
        for c in range(r + 1, n):
            acc -= work[r * w + c] * solution[c]
        solution[r] = acc / work[r * w + r]
    return True
