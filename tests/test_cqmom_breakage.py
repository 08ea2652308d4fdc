"""CQMOM with breakage against the closed forms of tests/test_breakage.py (issue 16).

Problems (N0 granules per m3 of an exponential start, binder fraction y0 = 0.25 on every
granule, so M_kl = y0^l M_(k+l),0 for all t):

1. constant selection s, uniform daughters / equal halves: every moment decays or grows on
   its own, M_kl(t) = M_kl(0) exp(s t (F(k + l) - 1));
2. constant aggregation K with constant selection s, uniform daughters: M0 the logistic to
   2 s / K, the higher moments from the closed hierarchy in n = k + l (scipy, rtol 1e-12).

Both close exactly under CQMOM: the breakage source of a carried M_kl is s (F(k+l) - 1) M_kl
(the size rule reproduces M_k0, k < 2 N1, the Vandermonde solve M_kl, k < N1), and the
constant kernel's gains are polynomials in carried moments of total order below k + l. What
remains is the integrator's error: each step's local error estimate below rtol = 1e-8 of the
state, the global error over these few hundred steps below 100 rtol = 1e-6 (the bound of
tests/test_breakage.py and tests/test_cqmom_analytic.py). M10 and M01 get exactly nothing
from breakage and aggregation: 1e-10 relative (round-off of the scaled sums).

With N1 = 2 the carried M_13 = y0^3 M_40 is a moment the size quadrature does not reproduce,
so its node sits off the points of the inversion: the test checks it all the same (the source
uses the carried conditional moments, not the points' moments).
"""
import math

import numpy as np
import pytest

from pbe_cfd.simulate import run_well_mixed

from test_breakage import (N0, P0, Y0, aggregation_breakage, breakage_scene, carried,
                           constant_selection, equal_F, logistic, moment0, uniform_F)

TOL = 1.0e-6         # 100 x rtol (module docstring)
EXACT = 1.0e-10      # M10, M01

CASES = [(2, 2), (3, 2)]


def cqmom(n1, n2):
    return {"name": "cqmom", "nodes": n1, "binder_nodes": n2}


def assert_exact_mass_and_binder(c):
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M01"] / (Y0 * N0 * P0) - 1.0)) < EXACT


@pytest.mark.parametrize("daughters,F", [("uniform", uniform_F), ("equal", equal_F)])
@pytest.mark.parametrize("n1,n2", CASES)
def test_cqmom_constant_selection(daughters, F, n1, n2):
    s = 0.1
    scene = breakage_scene(cqmom(n1, n2),
                           {"selection": "constant", "rate": s, "daughters": daughters}, 20.0)
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    exact = constant_selection(s, F)
    names = carried(c)
    assert len(names) == 2 * n1 + n1 * (2 * n2 - 1)          # every carried M_kl is reported
    for name in names:
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name
    assert c["M00"][-1] / N0 == pytest.approx(math.exp(s * 20.0 * (F(0) - 1)), rel=TOL)
    assert_exact_mass_and_binder(c)
    assert np.max(np.abs(c["binder_fraction"] - Y0)) < EXACT


@pytest.mark.parametrize("n1,n2", CASES)
def test_cqmom_constant_aggregation_with_constant_breakage(n1, n2):
    K, s = 1.0e-10, 0.25            # K N0 = 1 /s; M0 -> 2 s / K = N0 / 2
    scene = breakage_scene(cqmom(n1, n2), {"selection": "constant", "rate": s}, 20.0,
                           aggregation={"kernel": "constant", "rate": K})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    assert np.max(np.abs(c["M00"] / logistic(K, s, t) - 1.0)) < TOL
    names = carried(c)
    exact = aggregation_breakage(K, s, max(int(v[1]) + int(v[2]) for v in names))
    for name in names:
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name
    m1 = N0 * P0
    m2s = 3 * K * m1 ** 2 / s
    m2 = m2s + (moment0(2, 0) - m2s) * np.exp(-s * t / 3)
    assert np.max(np.abs(c["M20"] / m2 - 1.0)) < TOL
    assert_exact_mass_and_binder(c)
