"""The bounded per-node binder solve of a quadrature: given N size nodes p_a with weights w_a
(non-dimensional masses and numbers, see ``methods.qmom``) and the binder moments
M_k1 = sum_a w_a p_a^k b_a, k < N, one binder mass b_a per node with 0 <= b_a <= p_a.
Shared by QMOM and the conditional quadrature (CQMOM); ``binder_within_mass`` is the bound
every binder moment set of real particles keeps (QMOM, EQMOM)."""
import numba as nb
import numpy as np

from .gauss import solve_vandermonde


@nb.njit(cache=True, inline="always")
def binder_within_mass(state, first, count, tolerance):
    """True if 0 <= M_k1 <= M_(k+1)0 (1 + tolerance) for k < count, which b <= p in every
    particle implies: M_k1 at state[first + k], M_(k+1)0 at state[k + 1] (one cell's scaled
    state)."""
    for k in range(count):
        mk1 = state[first + k]
        if mk1 < 0.0 or mk1 > state[k + 1] * (1.0 + tolerance):
            return False
    return True


@nb.njit(cache=True, inline="always")
def _binder_unbounded(state, n_max, n, nodes, weights, binder, mean):
    """The first pass of ``solve_node_binder`` for n <= 3 free nodes in scalars (the same
    arithmetic as ``solve_vandermonde``'s closed forms): if every node's binder lies within
    [0, p_a], store it and return True; otherwise store nothing and return False."""
    i0 = 2 * n_max
    if n == 1:
        v0 = state[i0] / weights[0]
        if v0 < 0.0 or v0 > nodes[0]:
            return False
        binder[0] = v0
        return True
    x0 = nodes[0] / mean
    x1 = nodes[1] / mean
    r0 = state[i0]
    r1 = state[i0 + 1] / mean
    if n == 2:
        if x0 == x1:
            return False
        v0 = (r1 - x1 * r0) / (x0 - x1) / weights[0]
        v1 = (r1 - x0 * r0) / (x1 - x0) / weights[1]
        if v0 < 0.0 or v0 > nodes[0] or v1 < 0.0 or v1 > nodes[1]:
            return False
        binder[0] = v0
        binder[1] = v1
        return True
    x2 = nodes[2] / mean
    r2 = state[i0 + 2] / (mean * mean)
    if x0 == x1 or x0 == x2 or x1 == x2:
        return False
    v0 = (r2 - (x1 + x2) * r1 + x1 * x2 * r0) / ((x0 - x1) * (x0 - x2)) / weights[0]
    v1 = (r2 - (x0 + x2) * r1 + x0 * x2 * r0) / ((x1 - x0) * (x1 - x2)) / weights[1]
    v2 = (r2 - (x0 + x1) * r1 + x0 * x1 * r0) / ((x2 - x0) * (x2 - x1)) / weights[2]
    if (v0 < 0.0 or v0 > nodes[0] or v1 < 0.0 or v1 > nodes[1] or v2 < 0.0
            or v2 > nodes[2]):
        return False
    binder[0] = v0
    binder[1] = v1
    binder[2] = v2
    return True


@nb.njit(cache=True, error_model="numpy")
def solve_node_binder(state, n_max, n, nodes, weights, binder, work):
    """Binder per node from the conditional moments M_k1 with 0 <= b_a <= p_a enforced.

    Active set: solve the Vandermonde system of the free nodes with the first n_free binder
    moments (less what the bounded nodes hold); a node whose binder leaves [0, p_a] is put on
    that bound and the rest solved again. Nodes of tiny weight are where the system is
    ill-conditioned; bounding them keeps every node's binder physical and the binder moments
    consistent with the size moments (a pure-binder population stays pure binder).
    Returns the number of bounded nodes.
    """
    mean = state[1] / state[0]
    if n <= 3 and _binder_unbounded(state, n_max, n, nodes, weights, binder, mean):
        return 0
    fixed = work[0:n_max]
    rhs = work[n_max:2 * n_max]
    sol = work[2 * n_max:3 * n_max]
    scaled = work[3 * n_max:4 * n_max]
    index = work[4 * n_max:5 * n_max]
    solve_work = work[5 * n_max:]
    for a in range(n):
        fixed[a] = 0.0
        binder[a] = 0.0
    n_fixed = 0
    any_fixed = False
    for _ in range(n + 1):
        n_free = np.int64(0)     # not a literal: solve_vandermonde compiles once
        for a in range(n):
            if fixed[a] == 0.0:
                index[n_free] = a
                scaled[n_free] = nodes[a] / mean
                n_free += 1
        if n_free == 0:
            break
        mean_k = 1.0
        for k in range(n_free):
            value = state[2 * n_max + k]
            if any_fixed:
                for a in range(n):
                    if fixed[a] != 0.0:
                        value -= weights[a] * nodes[a] ** k * binder[a]
            rhs[k] = value / mean_k
            mean_k *= mean
        if not solve_vandermonde(scaled, rhs, sol, n_free, solve_work):
            # coincident free nodes: share the remaining binder in proportion to mass
            total = 0.0
            for f in range(n_free):
                a = int(index[f])
                total += weights[a] * nodes[a]
            for f in range(n_free):
                a = int(index[f])
                binder[a] = min(max(rhs[0] / total, 0.0), 1.0) * nodes[a] if total > 0 else 0.0
            break
        violated = False
        for f in range(n_free):
            a = int(index[f])
            value = sol[f] / weights[a]
            if value < 0.0:
                binder[a] = 0.0
                fixed[a] = 1.0
                violated = True
            elif value > nodes[a]:
                binder[a] = nodes[a]
                fixed[a] = 1.0
                violated = True
            else:
                binder[a] = value
        if not violated:
            break
        any_fixed = True
    for a in range(n):
        if fixed[a] != 0.0:
            n_fixed += 1
    return n_fixed
