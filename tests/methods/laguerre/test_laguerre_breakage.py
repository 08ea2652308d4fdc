"""Breakage in the Laguerre ROM (methods.laguerre_breakage) against the closed forms of
tests/methods/test_breakage.py (issue 16; docs/physics.md section 8).

The Laguerre ROM's breakage term is linear, dM_a/dt = F_cell sum_k L[k, a] M_k, with
L[k, a] = int_S S_unit (F(i + j) - 1) p^i b^j phi~_k. With the consistent reconstruction
(int_S p^i b^j phi~_k = delta_ak on the support S) it is exact whenever the integrand is a
carried monomial:
- constant selection: L = diag(F - 1), every carried moment closes (problem 1);
- constant aggregation + constant selection: the constant kernel's tensors are exact too
  (tests/methods/laguerre/test_laguerre.py), so problem 3 closes on every carried moment;
- power selection S = k p: the source of M_ij needs M_(i+1),j, carried for i < m - 1; the
  top row i = m - 1 is the reconstruction's closure, so M00, M10 and M01 (sources k M10, 0, 0)
  close exactly and the rest carry the closure error.
Tolerance where the system closes: the integrator's, 100 rtol = 1e-6 (rtol 1e-8; the bound of
tests/methods/qmom/test_qmom_analytic.py), plus the reconstruction's round-off, 100 eps cond(G) of the wet
weight slices (at most ~1e-9 here, printed by the aux). M10 and M01 exact to 1e-10 (their rows
of L are exactly zero: F(1) = 1).
"""
import math

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.methods.laguerre import rhs as L
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.methods.laguerre.layout import (AUX_COND_DRY, AUX_COND_G, AUX_NWC, AUX_NWD,
                                             AUX_OFF_BREAK)
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene
from test_breakage import (EXACT, N0, P0, TOL, Y0, aggregation_breakage,
                           assert_exact_mass_and_binder, breakage_scene, carried,
                           constant_selection, equal_F, logistic, moment0, power_selection,
                           uniform_F)

ORDERS = [3, 4]


def laguerre(order):
    """The ROM with the seed's fixed support, whose consistent reconstruction makes the
    tensors exact as above (the following support's breakage:
    tests/methods/laguerre/test_laguerre_following.py)."""
    return {"name": "laguerre", "order": order, "following_support": False}


def max_rel(c, exact, names):
    t = c["time_s"]
    return {n: float(np.max(np.abs(c[n] / exact(int(n[1]), int(n[2]), t) - 1.0)))
            for n in names}


def aux_of(scene):
    arrays = model.pack(scene)
    return LT.aux_for_scene(scene, arrays), arrays


# ---------------------------------------------------------------------------- the block
@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("daughters", ["uniform", "equal"])
@pytest.mark.slow
def test_block_mass_and_binder_rows_exactly_zero_and_constant_selection_diagonal(order,
                                                                                daughters):
    scene = breakage_scene(laguerre(order), {"selection": "constant", "rate": 0.1,
                                             "daughters": daughters}, 1.0)
    aux, _ = aux_of(scene)
    K = order * order
    nw = int(aux[AUX_NWC]) * int(aux[AUX_NWD])
    o = int(aux[AUX_OFF_BREAK])
    assert o > 0
    wet = aux[o:o + nw * K * K].reshape(nw, K, K)          # [w, k, a]
    dry = aux[o + nw * K * K:o + nw * K * K + order * order].reshape(order, order)
    F = uniform_F if daughters == "uniform" else equal_F
    gains = np.array([F(i + j) - 1.0 for i in range(order) for j in range(order)])
    # mass (1, 0) and binder (0, 1) columns: exactly zero, every weight slice
    assert np.all(wet[:, :, order] == 0.0) and np.all(wet[:, :, 1] == 0.0)
    assert np.all(dry[:, 1] == 0.0)
    # constant selection, consistent reconstruction: L = diag(F - 1) to its round-off
    tol = 100 * np.finfo(float).eps * max(aux[AUX_COND_G], aux[AUX_COND_DRY])
    for w in range(nw):
        assert np.max(np.abs(wet[w] - np.diag(gains))) < tol, w
    assert np.max(np.abs(dry - np.diag([F(k) - 1.0 for k in range(order)]))) < tol


@pytest.mark.slow
def test_no_breakage_table_no_block():
    scene = make_scene(method={"name": "laguerre", "order": 3, "_replace": True})
    aux, _ = aux_of(scene)
    assert aux[AUX_OFF_BREAK] == 0


# ---------------------------------------------------------------------------- closed forms
@pytest.mark.slow
@pytest.mark.parametrize("daughters,F", [("uniform", uniform_F), ("equal", equal_F)])
@pytest.mark.parametrize("order", ORDERS)
def test_constant_selection(order, daughters, F):
    s = 0.1
    scene = breakage_scene(laguerre(order), {"selection": "constant", "rate": s,
                                             "daughters": daughters}, 20.0)
    c = run_well_mixed(scene).columns
    errs = max_rel(c, constant_selection(s, F), carried(c))
    assert max(errs.values()) < TOL, errs
    assert c["M00"][-1] / N0 == pytest.approx(math.exp(s * 20.0 * (F(0) - 1)), rel=TOL, abs=0)
    assert_exact_mass_and_binder(c)


@pytest.mark.parametrize("order", ORDERS)
def test_constant_selection_dry_class(order):
    """No binder anywhere: every granule in the dry class (its own univariate basis)."""
    s = 0.1
    scene = make_scene(scene={"end_time": 20.0, "output_interval": 2.0},
                       initial={"distribution": "exponential", "binder_fraction": 0.0},
                       breakage={"selection": "constant", "rate": s, "daughters": "uniform"},
                       method={"name": "laguerre", "order": order, "_replace": True})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    for k in range(order):
        exact = N0 * P0 ** k * math.factorial(k) * np.exp(s * t * (uniform_F(k) - 1.0))
        assert np.max(np.abs(c[f"M{k}0"] / exact - 1.0)) < TOL, k
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.slow
def test_power_selection(order):
    """S = k p, exponential start: M00, M10, M01 close (module doc); the closure-carrying
    moments are reported in docs/results/breakage.md (its Laguerre rows)."""
    s0 = 0.1                         # k v0 t = 1 at 10 s: M00 doubles
    scene = breakage_scene(laguerre(order), {"selection": "power", "rate": s0,
                                             "exponent": 1.0}, 10.0)
    c = run_well_mixed(scene).columns
    errs = max_rel(c, power_selection(s0 / P0), ("M00", "M10", "M01"))
    assert max(errs.values()) < TOL, errs
    assert c["M00"][-1] == pytest.approx(2 * N0, rel=TOL, abs=0)
    assert_exact_mass_and_binder(c)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.slow
def test_constant_aggregation_with_constant_breakage(order):
    K, s = 1.0e-10, 0.25             # K N0 = 1 /s; M0 -> 2 s / K = N0 / 2
    scene = breakage_scene(laguerre(order), {"selection": "constant", "rate": s}, 20.0,
                           aggregation={"kernel": "constant", "rate": K})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    assert np.max(np.abs(c["M00"] / logistic(K, s, t) - 1.0)) < TOL
    errs = max_rel(c, aggregation_breakage(K, s, 2 * order - 2), carried(c))
    assert max(errs.values()) < TOL, errs
    m1 = N0 * P0
    m2s = 3 * K * m1 ** 2 / s
    m2 = m2s + (2 * N0 * P0 ** 2 - m2s) * np.exp(-s * t / 3)
    assert np.max(np.abs(c["M20"] / m2 - 1.0)) < TOL
    assert_exact_mass_and_binder(c)


@pytest.mark.slow
@pytest.mark.parametrize("order", ORDERS)
def test_power_selection_rows_below_the_top_are_exact(order):
    """S = k p at the exponential start: the RHS of every moment (i, j) with i < m - 1 is
    k (F(i + j) - 1) M_(i+1),j of carried moments, to the reconstruction's round-off (100 eps
    cond(G), module doc); the top row i = m - 1 is the closure (reported, not asserted)."""
    s0 = 0.1
    scene = breakage_scene(laguerre(order), {"selection": "power", "rate": s0,
                                             "exponent": 1.0}, 10.0)
    aux, arrays = aux_of(scene)
    state = LT.scene_initial_state(scene, arrays, moment0)
    out = np.zeros_like(state)
    L.laguerre_rhs(state, out, np.zeros(P.N_CELL), aux, arrays.params, arrays.config)
    nref, pref = arrays.params[P.NUMBER_SCALE], arrays.params[P.MASS_SCALE]
    k = s0 / P0
    tol = 100 * np.finfo(float).eps * aux[AUX_COND_G]
    for i in range(order - 1):
        for j in range(order):
            exact = k * (uniform_F(i + j) - 1.0) * moment0(i + 1, j)
            got = out[i * order + j] * nref * pref ** (i + j)
            assert abs(got - exact) <= tol * k * moment0(i + 1, j), (i, j, got, exact)
    assert np.all(out[order * order:] == 0.0)           # no dry class: nothing there


@pytest.mark.parametrize("binder_fraction", [Y0, 0.0], ids=["wet", "dry"])
@pytest.mark.slow
def test_collisional_selection_per_cell(binder_fraction):
    """Collisional selection with exponent 1: dM00/dt = S_cell M10 / p_ref exactly (F(0) - 1 =
    1; int p phi~_k = delta with the consistent reconstruction), S_cell = s0 g0(alpha)
    sqrt(Theta / Theta_ref) from each cell's own row (g0 written out here: Sinclair-Jackson at
    min(alpha, alpha_min_friction)), 0 where the Stokes deformation gate is shut (St_def =
    rho u0^2 / (2 Y) <= 0.2 at Y = 1000 Pa, rho = 1000 kg/m3); mass and binder rates 0.0.
    Tolerance: 100 eps cond(G) (module doc)."""
    scene = make_scene(domain={"type": "well-mixed", "solids_fraction": 0.3,
                               "granular_temperature": 0.05, "alpha_max": 0.62,
                               "alpha_min_friction": 0.5},
                       initial={"distribution": "exponential",
                                "binder_fraction": binder_fraction},
                       breakage={"selection": "collisional", "rate": 0.05, "exponent": 1.0,
                                 "reference_granular_temperature": 0.01,
                                 "yield_strength": 1000.0, "critical_deformation_number": 0.2},
                       method={"name": "laguerre", "order": 3, "_replace": True})
    aux, arrays = aux_of(scene)
    y = binder_fraction
    state = LT.scene_initial_state(
        scene, arrays, lambda i, j: N0 * P0 ** (i + j) * math.factorial(i + j) * y ** j)
    m, K = 3, 9
    first = K if binder_fraction == 0.0 else 0            # the class the granules are in
    nref = arrays.params[P.NUMBER_SCALE]
    m10 = N0 * P0                                          # kg/m3
    tol = 100 * np.finfo(float).eps * max(aux[AUX_COND_G], aux[AUX_COND_DRY])
    for alpha, theta in ((0.31, 0.09), (0.55, 0.09), (0.55, 0.04)):
        u0 = 4.0 * math.sqrt(theta / math.pi)
        cell = np.array([alpha, theta, u0, 0.0])
        out = np.zeros_like(state)
        L.laguerre_rhs(state, out, cell, aux, arrays.params, arrays.config)
        g0 = 1.0 / (1.0 - (min(alpha, 0.5) / 0.62) ** (1.0 / 3.0))
        gate = 1000.0 * u0 ** 2 / (2.0 * 1000.0) > 0.2
        expected = 0.05 * g0 * math.sqrt(theta / 0.01) * m10 / P0 if gate else 0.0
        assert out[first] * nref == pytest.approx(expected, rel=tol, abs=0.0), (alpha, theta)
        mass_row = first + (m if first == 0 else 1)
        assert out[mass_row] == 0.0
        if first == 0:
            assert out[1] == 0.0
