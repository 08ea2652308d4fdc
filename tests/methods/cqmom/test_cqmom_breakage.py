"""CQMOM with breakage against the closed forms of tests/methods/test_breakage.py (issue 16).

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
tests/methods/test_breakage.py and tests/methods/cqmom/test_cqmom_analytic.py). M10 and M01 get exactly nothing
from breakage and aggregation: 1e-10 relative (round-off of the scaled sums).

3. power selection S = k p (exponent 1), uniform daughters: dM_k0/dt = k (F(k) - 1) M_(k+1),0
   closes for M00 and M10 only (to 1e-6 against the closed form); the size moments of CQMOM
   follow exactly QMOM's closure with N1 nodes (their sources do not see the binder), computed
   independently in tests/methods/test_breakage.py (a plain-NumPy Gauss rule, scipy); a mixed moment
   of total order k + l < 2 N1 is y0^l times that closure's M_(k+l),0 (every granule keeps
   y0; the size rule reproduces those orders, so the conditional moments stay y0^l).

The size-moment sources are quadratures over the size nodes; a mixed moment's source is the
carried M_kl times the mean selection over the N1 x N2 points weighted by its integrand
(``cqmom_sources._breakage``). Under a constant selection that is s (F(k + l) - 1) M_kl for
every carried moment, whether or not the points reproduce it: with N1 = 2 the carried
M_13 = y0^3 M_40 is exact too (the quadrature sum over the points gave it y0^3 Q_40, Q_40 the
size rule's closure of M_40: 54% off at s t = 2 with uniform daughters, 115% with equal halves).
Where the points do not reproduce a mixed moment, the relative form also keeps it from being
driven below zero (``test_breakage_of_a_state_the_points_do_not_reproduce``: the quadrature sum
took M03 of such a state below zero within 5 ms).
"""
import math

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.methods.cqmom import cqmom as cqmom_core
from pbe_cfd.methods.cqmom import sources as cqmom_sources
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

from test_breakage import (N0, P0, Y0, aggregation_breakage, breakage_scene, carried,
                           constant_selection, equal_F, logistic, moment0, power_selection,
                           qmom_power_closure, uniform_F)

TOL = 1.0e-6         # 100 x rtol (module docstring)
EXACT = 1.0e-10      # M10, M01

CASES = [(2, 2), (3, 2)]


def cqmom(n1, n2):
    return {"name": "cqmom", "nodes": n1, "binder_nodes": n2}


def check_carried(c, n1, exact):
    """Every carried M_kl against the closed form, M_13 of N1 = 2 (order 2 N1, beyond what
    the points reproduce) included (module docstring)."""
    t = c["time_s"]
    names = carried(c)
    assert len(names) == 2 * n1 + n1 * 3                    # N2 = 2: every M_kl reported
    for name in names:
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name


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
    check_carried(c, n1, constant_selection(s, F))
    assert c["M00"][-1] / N0 == pytest.approx(math.exp(s * 20.0 * (F(0) - 1)), rel=TOL, abs=0)
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
    check_carried(c, n1, aggregation_breakage(K, s, 2 * n1 + 1))
    m1 = N0 * P0
    m2s = 3 * K * m1 ** 2 / s
    m2 = m2s + (moment0(2, 0) - m2s) * np.exp(-s * t / 3)
    assert np.max(np.abs(c["M20"] / m2 - 1.0)) < TOL
    assert_exact_mass_and_binder(c)


@pytest.mark.parametrize("n1,n2", CASES)
def test_cqmom_power_selection(n1, n2):
    s0 = 0.1                        # S = s0 p / p0: k v0 = 0.1 /s, k v0 t = 1 at 10 s
    scene = breakage_scene(cqmom(n1, n2), {"selection": "power", "rate": s0, "exponent": 1.0},
                           10.0)
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    exact = power_selection(s0 / P0)
    assert np.max(np.abs(c["M00"] / exact(0, 0, t) - 1.0)) < TOL
    assert c["M00"][-1] == pytest.approx(2 * N0, rel=TOL, abs=0)      # (1 + k v0 t) = 2
    closure = qmom_power_closure(s0 / P0, n1, t)
    checked = 0
    for name in carried(c):
        k, l = int(name[1]), int(name[2])
        if 2 <= k + l < 2 * n1:
            assert np.max(np.abs(c[name] / (Y0 ** l * closure[k + l]) - 1.0)) < TOL, name
            checked += 1
    assert checked >= 4
    assert_exact_mass_and_binder(c)


#: A CQMOM N1 = N2 = 2 state (scaled; M00 M10 M20 M30, M01 M11, M02 M12, M03 M13, droplets)
#: that the bundled bed's collisional breakage reached in a cell at alpha 0.4, Theta = 1 m2/s2
#: with droplets sprayed in: dry fragments (the small node's binder on its bound 0) beside
#: granules holding the binder; the Vandermonde shares of the large node are far from
#: realizable (its points hold 650 times the carried M03).
UNREPRESENTED = np.array([1.437708, 1.00342, 0.883838, 0.84558, 0.00342, 0.006577, 0.000567,
                          0.002581, 3.0e-06, 0.001419, 6.6e-05])


@pytest.mark.parametrize("selection,daughters", [("constant", "uniform"), ("constant", "equal"),
                                                 ("power", "uniform")])
def test_breakage_of_a_state_the_points_do_not_reproduce(selection, daughters):
    """At a state whose points do not reproduce its mixed moments, the breakage source of each
    carried M_kl (k + l >= 2) is (F(k + l) - 1) M_kl times a selection rate between the
    smallest and the largest at the size nodes (exactly s for a constant selection), so no
    mixed moment decays faster than the largest selection allows, and M10, M01 get nothing."""
    s0 = 0.7
    scene = make_scene(initial={"binder_fraction": 0.1},
                       aggregation={"kernel": "constant", "rate": 1e-10,
                                    "droplet_factor": 100.0},
                       binder_injection={"rate": 1e8, "droplet_diameter": 60e-6},
                       breakage={"selection": selection, "rate": s0, "daughters": daughters},
                       method=dict(cqmom(2, 2), _replace=True))
    arrays = model.pack(scene)
    names = arrays.state_names
    assert names == ["M00", "M10", "M20", "M30", "M01", "M11", "M02", "M12", "M03", "M13",
                     "droplet_number_density"]
    config = arrays.config
    work = np.zeros(cqmom_core.work_size(2, 2))
    n = cqmom_core.invert(UNREPRESENTED, config, work)
    assert n == 2
    assert cqmom_core.representation_error(UNREPRESENTED, config, work) > 1e-3
    x = work[0:2] * arrays.mass_scale
    rates = s0 * (x / scene.initial.mean_mass if selection == "power" else np.ones(2))
    out = np.zeros_like(UNREPRESENTED)
    cell = model.well_mixed_cell(scene)[0]
    cell[P.INJECTION] = 0.0
    only_breakage = arrays.params.copy()
    only_breakage[P.RATE] = 0.0
    cqmom_sources.cqmom_rhs(UNREPRESENTED, out, cell, np.zeros(1), only_breakage, config, work)
    F = uniform_F if daughters == "uniform" else equal_F
    assert out[1] == 0.0 and out[4] == 0.0
    for i, name in enumerate(names[:-1]):
        k, l = int(name[1]), int(name[2])
        if l == 0 or k + l < 2:
            continue
        relative = out[i] / ((F(k + l) - 1.0) * UNREPRESENTED[i])
        if selection == "constant":
            assert relative == pytest.approx(s0, rel=1e-12, abs=0), name
        else:
            assert rates.min() * (1 - 1e-12) <= relative <= rates.max() * (1 + 1e-12), name
