"""Quadrature nodes grouped by mass: the numba kernels of ``reconstruct.node_binder`` (the
groups' binder fraction) and of ``kernel_mixture.of_nodes`` (the distinct size nodes).

Nodes of one row that share a mass p (CQMOM's binder nodes of one size node; the Laguerre
ROM's nodes of one p at every binder fraction) share the mass-mean binder fraction of their
group, sum w b / sum w p over the group's nodes (w taken as 0 where w <= 0 or p <= 0). A
row's nodes come in runs of one mass (the Laguerre ROM lists a mass's binder nodes side by
side): the runs are sorted by mass, not the nodes, and each group's sums are added node by
node in the row's order (as a stable sort and ``np.bincount`` add them).
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _mass_groups(p, lo, hi, first, keys):
    """The groups of equal mass among the nodes p[lo:hi] [kg]: fills first (its runs of one
    mass: run k from first[k] to first[k + 1]) and keys (each run's mass), and returns (runs,
    order) with order the runs sorted by mass, the runs of one mass in the row's order."""
    runs = 0
    for i in range(lo, hi):
        if i == lo or not (p[i] == p[i - 1]):
            first[runs] = i
            keys[runs] = p[i]
            runs += 1
    first[runs] = hi
    # a stable sort: the runs of one mass keep the row's order
    return runs, np.argsort(keys[:runs], kind="mergesort")


@nb.njit(cache=True)
def _group_end(keys, order, k, runs):
    """The end of the group of equal mass that starts at position k of ``order``."""
    end = k + 1
    while end < runs and keys[order[end]] == keys[order[k]]:
        end += 1
    return end


@nb.njit(cache=True)
def size_nodes(w, p, signed, x, wx):
    """Each row's distinct masses [kg] of its nodes with w > 0 (``signed``: w != 0) and p > 0,
    sorted, into x (rows, n), and their summed weights [1/m3] (added in the row's order, as
    ``np.bincount`` adds them) into wx; w [1/m3], p [kg] (rows, n). Returns the masses per
    row (the rest of x and wx is not written)."""
    rows, n = p.shape
    first = np.empty(n + 1, np.int64)
    keys = np.empty(n)
    count = np.zeros(rows, np.int64)
    for r in range(rows):
        runs, order = _mass_groups(p[r], 0, n, first, keys)
        k = 0
        while k < runs:
            end = _group_end(keys, order, k, runs)
            total = 0.0
            used = False
            for q in range(k, end):
                for i in range(first[order[q]], first[order[q] + 1]):
                    if ((w[r, i] != 0.0) if signed else (w[r, i] > 0.0)) and p[r, i] > 0.0:
                        total += w[r, i]
                        used = True
            if used:
                x[r, count[r]] = keys[order[k]]
                wx[r, count[r]] = total
                count[r] += 1
            k = end
    return count


@nb.njit(cache=True)
def binder_of_groups(w, p, b, starts, distinct, x, y):
    """Fills x (rows, n) with each row's node masses [kg] of w > 0 and 0 < p < inf sorted,
    then +inf, and y (rows, n) with the mass-mean binder fraction [-] of the group of nodes
    of that mass (0 for a group without mass; 0 after the finite masses). w [1/m3], p [kg],
    b [kg] (N,) the nodes of every row, row r's from starts[r] to starts[r + 1]; with
    ``distinct`` each mass once, x and y filled only up to the most finite masses of a row
    (the part kept). Returns that number."""
    rows = starts.size - 1
    longest = 0
    for r in range(rows):
        longest = max(longest, starts[r + 1] - starts[r])
    first = np.empty(longest + 1, np.int64)        # the row's runs of one mass
    keys = np.empty(longest)
    count = np.zeros(rows, np.int64)
    for r in range(rows):
        runs, order = _mass_groups(p, starts[r], starts[r + 1], first, keys)
        k = 0
        out = 0
        while k < runs:
            end = _group_end(keys, order, k, runs)
            mass = 0.0
            binder = 0.0
            valid = 0
            for q in range(k, end):
                for i in range(first[order[q]], first[order[q] + 1]):
                    ok = w[i] > 0.0 and p[i] > 0.0
                    wv = w[i] if ok else 0.0
                    mass += wv * p[i]
                    binder += wv * b[i]
                    if ok and p[i] < np.inf:
                        valid += 1
            value = binder / mass if mass > 0.0 else 0.0
            for _ in range(min(valid, 1) if distinct else valid):
                x[r, out] = keys[order[k]]
                y[r, out] = value
                out += 1
            k = end
        count[r] = out
    widest = count.max() if rows > 0 else 0
    for r in range(rows):                           # the tails, up to what is kept
        for s in range(count[r], widest if distinct else x.shape[1]):
            x[r, s] = np.inf
            y[r, s] = 0.0
    return widest
