"""Mass-based percentiles and diameter grids of cumulative size distributions.

A distribution here is anything with ``cdf(d)``: the mass (volume) fraction Q3 of the granules
with diameter below d [m], one row per time or cell (shape (rows, len(d))), non-decreasing in
d. Percentiles are found by bisection in ln d, so a step (a monodisperse population) is found
exactly as well as a smooth cumulative.
"""
from __future__ import annotations

import math

import numpy as np

#: mass fractions of the reported percentiles d10, d50, d90
FRACTIONS = (0.1, 0.5, 0.9)
#: bisection halvings of ln(d_hi / d_lo): 2^-60 of a 20-decade bracket is 4e-17 in ln d
BISECTIONS = 60
#: the widest diameter bracket searched [m]: 1 nm to 10 m
D_SEARCH = (1.0e-9, 10.0)


class DistributionError(ValueError):
    """A percentile or a grid that the distribution cannot support (one-line message)."""


def check_fractions(fractions) -> np.ndarray:
    """The mass fractions as an array; DistributionError unless every one is in (0, 1)."""
    f = np.atleast_1d(np.asarray(fractions, dtype=float))
    bad = f[~((f > 0.0) & (f < 1.0))]
    if bad.size:
        raise DistributionError(f"percentile at mass fraction {bad[0]:g}: expected a fraction "
                                "strictly between 0 and 1 (Q3 reaches 0 and 1 only at the "
                                "ends of the distribution)")
    return f


def bisect_quantiles(cdf, fractions, rows: int, lo=D_SEARCH[0], hi=D_SEARCH[1],
                     halvings: int = BISECTIONS) -> np.ndarray:
    """Diameters [m] (shape (rows, len(fractions))) where each row's cumulative first reaches
    each mass fraction: the smallest d with Q3(d) >= x, to 2^-BISECTIONS of the bracket
    [lo, hi] [m] in ln d. ``cdf(d)`` takes diameters of shape (rows, k) (each row at its
    own) and returns Q3 of the same shape; lo, hi [m] scalars or (rows, len(fractions)).
    Rows whose Q3 never reaches x inside the bracket get NaN (the caller names them)."""
    f = check_fractions(fractions)
    a = np.broadcast_to(np.log(lo), (rows, f.size)).astype(float)
    b = np.broadcast_to(np.log(hi), (rows, f.size)).astype(float)
    target = np.broadcast_to(f, (rows, f.size))
    top = cdf(np.exp(b))
    for _ in range(int(halvings)):
        mid = 0.5 * (a + b)
        above = cdf(np.exp(mid)) >= target
        b = np.where(above, mid, b)
        a = np.where(above, a, mid)
    return np.where(top >= target, np.exp(b), np.nan)


def log_grid(d_lo: float, d_hi: float, points: int) -> np.ndarray:
    """``points`` log-spaced diameters [m] from d_lo to d_hi; DistributionError for a grid
    that is not a positive, increasing range of at least 2 points."""
    if not (math.isfinite(d_lo) and math.isfinite(d_hi) and 0.0 < d_lo < d_hi):
        raise DistributionError(f"diameter grid [{d_lo:g}, {d_hi:g}] m: expected "
                                "0 < d_min < d_max (finite)")
    if int(points) < 2:
        raise DistributionError(f"diameter grid of {points} points: expected at least 2")
    return np.geomspace(d_lo, d_hi, int(points))


def check_grid_covers(q3_lo: np.ndarray, q3_hi: np.ndarray, grid, what: str,
                      share: float = 1.0e-3) -> str | None:
    """A note (or None) when more than ``share`` of some row's mass lies outside the grid
    [m]: q3_lo/q3_hi the rows' Q3 at the grid's first and last point."""
    below = float(np.max(q3_lo, initial=0.0))
    above = float(np.max(1.0 - q3_hi, initial=0.0))
    if below > share or above > share:
        return (f"{what}: the diameter grid {grid[0]:.3g}..{grid[-1]:.3g} m leaves "
                f"{100 * below:.2g}% of the mass below and {100 * above:.2g}% above it")
    return None


def interpolated_cdf(edges_log_d: np.ndarray, cumulative: np.ndarray, d) -> np.ndarray:
    """Q3 at diameters d [m] (shape (k,) for every row, or (rows, k)) of rows given by their
    cumulative (rows, n) at ln-diameters ``edges_log_d`` (n,), linear in ln d between them
    (a density constant per ln d in each class), 0 below the first edge and the row's last
    value above the last."""
    rows = cumulative.shape[0]
    x = np.log(np.broadcast_to(np.asarray(d, dtype=float), (rows,) + np.shape(d)[-1:]))
    out = np.empty(x.shape)
    for r in range(rows):
        out[r] = np.interp(x[r], edges_log_d, cumulative[r], left=0.0, right=cumulative[r, -1])
    return out
