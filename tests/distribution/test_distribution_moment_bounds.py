"""The range of a mass-based percentile over every distribution with given moments
(tests/distribution/psd_moment_bounds.py, docs/results/psd.md "What the carried moments
allow"), against closed forms.

With only M0 = 1 and M1 = 1 (mean mass 1) and atoms on a grid up to P, the largest mass
fraction below xi < 1 is xi (P - 1) / (P - xi) (one atom at xi, one at P: the two-atom extreme
points of the moment problem) and the smallest is 0 (one atom at the mean). The exponential's
own percentiles lie inside the range its first six moments allow.
"""
import math

import numpy as np
import pytest
from scipy import stats

import psd_moment_bounds as B


def test_two_moments_give_the_two_atom_extremes():
    grid = np.geomspace(1e-2, 1e2, 401)
    top = grid[-1]
    for xi in grid[[100, 150, 190]]:                        # 0.1, 0.32, 0.79 mean masses
        lo, hi = B.q3_extremes([1.0, 1.0], xi, grid)
        assert hi == pytest.approx(xi * (top - 1.0) / (top - xi), rel=0, abs=1e-7)  # HiGHS
        assert lo == pytest.approx(0.0, rel=0, abs=1e-7)                           # 1e-7


def test_the_exponential_s_percentiles_lie_in_the_range_its_moments_allow():
    moments = [math.factorial(k) for k in range(6)]         # exponential, mean mass 1 kg
    grid = np.geomspace(1e-3, 1e3, 400)
    rho = 1000.0
    for q in (0.1, 0.5, 0.9):
        lo, hi = B.percentile_range(moments, q, grid, rho)
        exact = (6.0 * stats.gamma.ppf(q, 2) / (math.pi * rho)) ** (1.0 / 3.0)
        assert lo < exact < hi
        assert hi / lo > 1.2                                # six moments do not fix it
