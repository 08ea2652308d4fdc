"""docs/results/psd.md, "What the carried moments allow": for each of the 3 misses, the range of
d10, d50 and d90 over every distribution that has exactly the method's carried moments.

A method carries M00..M(K)0 (number moments of the granule mass p, kg^k/m3). Any number density
with those moments is a candidate; its mass-based Q3(xi) = int_0^xi p n(p) dp / M10. On a fine
log grid of masses (atoms w_j >= 0 at p_j), min and max of Q3(xi) subject to
sum_j w_j p_j^k = M_k0 (k = 0..K) are linear programs (scipy's HiGHS). The lowest dq any
such distribution can have is the smallest xi where max Q3(xi) >= q; the highest is the
smallest xi where min Q3(xi) >= q (both found by bisection in ln xi). If the particle list's
percentile lies outside [lowest, highest], no reconstruction of these moments can give it
(the moments forbid it); if inside, the moments allow it but, where the range is wider than
the aim, do not determine it: the miss is then the reconstruction's choice among them.

The grid (atoms between 1e-3 and 1e3 mean masses, 800 and 1600 points) gives an inner
approximation of the range; the two grids are printed side by side to show it has converged.

python tests/distribution/psd_moment_bounds.py      (reads docs/results/psd-reference.json)
"""
import json
import math
import os
import sys

import numpy as np
from scipy.optimize import linprog

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import psd_cases  # noqa: E402

F = (0.1, 0.5, 0.9)
AIM = (0.05, 0.03, 0.05)


def linear_extremes(moments, grid, values):
    """(min, max) of sum_j w_j values_j over atoms w_j >= 0 at the masses ``grid`` with the
    number moments sum_j w_j grid_j^k = moments[k], k = 0..K (any consistent units: masses in
    the grid's, moments in (number) x mass^k); None when the grid cannot match them."""
    moments = np.asarray(moments, float)
    scale = moments[1] / moments[0]                  # mean mass: the unit of the LP
    u = grid / scale
    k = np.arange(moments.size)[:, None]
    a_eq = u[None, :] ** k / (moments / (moments[0] * scale ** np.arange(moments.size)))[:, None]
    b_eq = np.ones(moments.size)
    col = a_eq.max(axis=0)                          # columns scaled to 1 (conditioning)
    a_eq = a_eq / col
    c = np.asarray(values, float) / col             # per number fraction w_j / M0
    norm = np.abs(c).max() or 1.0                   # the objective scaled to 1 (conditioning)
    out = []
    for sign in (1.0, -1.0):
        r = linprog(sign * c / norm, A_eq=a_eq, b_eq=b_eq, bounds=(0, None), method="highs")
        if r.status != 0:
            return None
        out.append(sign * r.fun * norm * moments[0])
    return tuple(out)


def q3_extremes(moments, xi, grid):
    """(min, max) of the mass fraction below mass xi [kg] over atoms on ``grid`` [kg] with the
    number moments ``moments`` [kg^k/m3], k = 0..K; None when the grid cannot match them."""
    found = linear_extremes(moments, grid, np.where(grid <= xi, grid, 0.0))
    return None if found is None else (found[0] / moments[1], found[1] / moments[1])


def percentile_range(moments, q, grid, rho):
    """(lowest, highest) diameter [m] of the mass-based percentile q over the distributions
    with these moments (24 bisections in ln p: to 1e-6)."""
    def diameter(p):
        return (6.0 * p / (math.pi * rho)) ** (1.0 / 3.0)

    def first(pick):
        lo, hi = math.log(grid[0]), math.log(grid[-1])
        for _ in range(24):
            mid = 0.5 * (lo + hi)
            ext = q3_extremes(moments, math.exp(mid), grid)
            if ext is not None and pick(ext) >= q:
                hi = mid
            else:
                lo = mid
        return diameter(math.exp(hi))

    return first(lambda e: e[1]), first(lambda e: e[0])


def carried(case, label):
    """The carried granule moments M00..M(K)0 [kg^k/m3] at the end of the method's run."""
    import psd_methods_run as M
    res = M.run(case, M.METHODS[label])
    c = res.columns
    return [float(c[f"M{k}0"][-1]) for k in range(6) if f"M{k}0" in c], \
        res.scene.material.density


def main():
    ref = json.load(open(os.path.join(HERE, "..", "..", "docs", "results",
                                      "psd-reference.json")))
    misses = [("sum-a1-uniform", "QMOM N=3", 6), ("sum-a1-uniform", "Laguerre m=3", 3),
              ("eke-a1/3-equal", "Laguerre m=3", 3)]
    for case, label, k in misses:
        r = ref[case]
        want = np.array(r["percentiles"])
        moments, rho = carried(case, label)
        moments = moments[:k]
        rows = []
        for points in (800, 1600):
            grid = np.geomspace(1e-3, 1e3, points) * moments[1] / moments[0]
            rows.append([percentile_range(moments, q, grid, rho) for q in F])
        print(f"== {case}, {label}: carried M00..M{k - 1}0 = "
              + ", ".join(f"{m:.5g}" for m in moments)
              + f"; particle list M00, M10, M20 = {r['moments']}")
        for j, q in enumerate(F):
            (lo, hi), (lo2, hi2) = rows[0][j], rows[1][j]
            w = want[j]
            inside = lo2 <= w <= hi2
            best = 0.0 if inside else min(abs(lo2 / w - 1), abs(hi2 / w - 1))
            print(f"  d{int(100 * q)}: particle list {w * 1e6:.2f} um; the moments allow "
                  f"{lo2 * 1e6:.2f} .. {hi2 * 1e6:.2f} um ({100 * (lo2 / w - 1):+.1f} .. "
                  f"{100 * (hi2 / w - 1):+.1f}%; 800 points: {lo * 1e6:.2f} .. "
                  f"{hi * 1e6:.2f}); nearest allowed {100 * best:.2f}% off, aim "
                  f"{100 * AIM[j]:g}%: " + ("allowed" if inside else
                                            ("forbidden" if best > AIM[j] else
                                             "outside, but within the aim")), flush=True)


if __name__ == "__main__":
    main()
