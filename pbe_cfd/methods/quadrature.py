"""Gaussian quadrature from moments: Wheeler's algorithm and a tridiagonal eigen-solve.

All functions work on non-dimensional moments (the caller scales masses and number densities);
they never allocate inside the per-cell loop beyond small fixed work arrays passed in.

The quadrature of n nodes reproduces the moments mu_0 .. mu_{2n-1} of a positive measure on
(0, inf). A moment set is *realizable* when the Hankel determinants are positive; the Wheeler
recurrence exposes them as the coefficients b_k > 0. A set on the boundary of the realizable
region (for example a monodisperse population, whose Hankel determinants vanish) yields fewer
nodes; a set outside it also yields fewer nodes, and the caller decides, by re-projecting, whether
the discarded moments were consistent with the reduced quadrature.
"""
import math

import numba as nb

#: Relative size below which a Wheeler coefficient is treated as zero (round-off of the
#: recurrence's subtraction is ~1e-16 of the terms; a genuine distribution whose relative
#: variance is below this acts as monodisperse to every carried moment).
DEGENERACY_TOLERANCE = 1.0e-11


@nb.njit(cache=True)
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
            r = math.hypot(g, 1.0)
            g = diagonal[m] - diagonal[l] + offdiagonal[l] / (g + math.copysign(r, g))
            s = 1.0
            c = 1.0
            p = 0.0
            i = m - 1
            deflated = False
            while i >= l:
                f = s * offdiagonal[i]
                b = c * offdiagonal[i]
                r = math.hypot(f, g)
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


@nb.njit(cache=True)
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
    base_a = (n_max + 1) * width
    a = work[base_a:base_a + n_max]
    b = work[base_a + n_max:base_a + 2 * n_max]
    diag = work[base_a + 2 * n_max:base_a + 3 * n_max]
    off = work[base_a + 3 * n_max:base_a + 4 * n_max]
    for l in range(width):
        sig[l] = 0.0                      # row k = -1
    scale = 1.0
    for l in range(n_mom):
        sig[width + l] = moments[l] / (m0 * scale)   # row k = 0: normalised moments
        scale *= mean
    a[0] = sig[width + 1] / sig[width + 0]
    b[0] = 0.0
    n_eff = 1
    for k in range(1, n_max):
        row = (k + 1) * width
        prev = k * width
        prev2 = (k - 1) * width
        for l in range(k, n_mom - k):
            sig[row + l] = (sig[prev + l + 1] - a[k - 1] * sig[prev + l]
                            - b[k - 1] * sig[prev2 + l])
        # compare the new diagonal sigma with the size of the terms it was computed from
        terms = (abs(sig[prev + k + 1]) + abs(a[k - 1] * sig[prev + k])
                 + abs(b[k - 1] * sig[prev2 + k]))
        if not (sig[row + k] > DEGENERACY_TOLERANCE * terms) or not math.isfinite(sig[row + k]):
            break
        a[k] = sig[row + k + 1] / sig[row + k] - sig[prev + k] / sig[prev + k - 1]
        b[k] = sig[row + k] / sig[prev + k - 1]
        if not (b[k] > 0.0) or not math.isfinite(a[k]):
            break
        n_eff = k + 1
    # Golub-Welsch; drop nodes while any abscissa is not positive
    while n_eff > 0:
        for k in range(n_eff):
            diag[k] = a[k]
        for k in range(n_eff - 1):
            off[k] = math.sqrt(b[k + 1])
        ok = tridiagonal_eigen(diag, off, weights, n_eff)
        positive = ok
        for k in range(n_eff):
            if not (diag[k] > 0.0) or not math.isfinite(diag[k]):
                positive = False
        if positive:
            for k in range(n_eff):
                nodes[k] = diag[k] * mean
                weights[k] = weights[k] * weights[k] * m0
            return n_eff
        n_eff -= 1
    return 0


@nb.njit(cache=True)
def solve_vandermonde(nodes, rhs, solution, n, work):
    """Solve sum_a nodes[a]^k solution[a] = rhs[k], k < n, by Gaussian elimination with partial
    pivoting on an n x n work block (``work`` length >= n * (n + 1)). Dimensionless.

    Returns False if the nodes are not distinct (a singular system).
    """
    w = n + 1
    for k in range(n):
        for a in range(n):
            work[k * w + a] = nodes[a] ** k
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
