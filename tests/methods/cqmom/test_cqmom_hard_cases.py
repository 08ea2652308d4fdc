"""The hard-case suite (tests/methods/test_hard_cases.py) for CQMOM: degenerate starts, empty cells,
extreme injection, huge growth, gelation, extreme cells in one mesh, random scenes; and the same
with breakage (a monodisperse start breaking, the number multiplied by 1e8, dry granules breaking
while binder arrives, steep power selection on the seed scenario, collisional selection in the
extreme cells, random scenes with breakage).

Invariants asserted wherever they apply: finite values; every stored state realizable (by the
Hankel test of tests/error_bounds.py, written there, and by the package's own test); M10 and
M01 conserved to 1e-10 without injection and growing at exactly the injected rate with it;
M00 non-increasing under pure aggregation; every point's binder within [0, its mass]. The
random scenes and the steep breakage follow a run at 100 times tighter rtol to the error bound
of tests/error_bounds.py (trajectories, not only invariants).
"""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pbe_cfd import integrate
from pbe_cfd.runs import model
from pbe_cfd.io.openfoam import load_snapshot
from pbe_cfd.runs.couple import Domain, run_coupled
from pbe_cfd.methods.cqmom import cqmom
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.scene.scene import Breakage, load_scene
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene
from error_bounds import assert_close_to_reference, hankel_realizable, size_moments

SEED_RATE = 1.485e8          # droplets/(m3 s), seed 000
PD = droplet_mass(60e-6, 1000.0)


def method(n1, n2):
    return {"name": "cqmom", "nodes": n1, "binder_nodes": n2, "_replace": True}


def states_of(scene, columns):
    """Scaled CQMOM states of every output row, rebuilt from the SI columns (free droplets,
    which the columns include, taken out again)."""
    arrays = model.pack(scene)
    names = arrays.state_names
    rows = []
    nd = columns.get("droplet_number_density", np.zeros_like(columns["time_s"]))
    for r in range(len(columns["time_s"])):
        row = []
        for s in names:
            if s == "droplet_number_density":
                row.append(nd[r] / arrays.number_scale)
                continue
            i, j = int(s[1]), int(s[2])
            value = columns[s][r] - nd[r] * arrays.droplet_mass ** (i + j)
            row.append(value / (arrays.number_scale * arrays.mass_scale ** (i + j)))
        rows.append(np.array(row))
    return arrays, rows


def assert_follows_tight_run(scene, columns):
    """The trajectory against the same scene at 100 times tighter rtol, every carried size
    moment and M11 within the error bound of tests/error_bounds.py."""
    tight = dataclasses.replace(scene, method=dataclasses.replace(
        scene.method, rtol=scene.method.rtol / 100, atol=scene.method.atol / 100))
    ref = run_well_mixed(tight).columns
    names = [f"M{k}0" for k in range(2 * scene.method.options.nodes)]
    if "M11" in columns:
        names.append("M11")
    assert_close_to_reference(columns, ref, scene.method.rtol, names)


def assert_invariants(scene, columns, injected_mass_rate=0.0, pure_aggregation=False):
    t = columns["time_s"]
    for name, values in columns.items():
        assert np.all(np.isfinite(values)), name
    expected = columns["M10"][0] + injected_mass_rate * t
    assert np.max(np.abs(columns["M10"] - expected) / expected) < 1e-10
    if "M01" in columns:
        expected = columns["M01"][0] + injected_mass_rate * t
        if expected[-1] > 0:
            scale = np.maximum(expected, 1e-300)
            assert np.max(np.abs(columns["M01"] - expected) / scale) < 1e-10
    if pure_aggregation:
        assert np.all(np.diff(columns["M00"]) <= 0.0)
    # independent of the package's realizability test: the size moments (free droplets
    # included, a positive measure too) pass the Hankel test, and the binder moments keep
    # 0 <= M_k1 <= M_(k+1)0 (every particle's binder within its mass)
    n1 = scene.method.options.nodes
    for r in range(len(t)):
        assert hankel_realizable(size_moments(columns, r, 2 * n1)), r
        for k in range(n1):
            if f"M{k}1" in columns and f"M{k + 1}0" in columns:
                assert -1e-12 * columns[f"M{k + 1}0"][r] <= columns[f"M{k}1"][r] \
                    <= columns[f"M{k + 1}0"][r] * (1 + 1e-12), (k, r)
    arrays, rows = states_of(scene, columns)
    work = np.zeros(cqmom.work_size(int(arrays.config[P.ORDER]),
                                    int(arrays.config[P.BINDER_NODES])))
    for state in rows:
        # output columns round-trip through SI: allow the round-off of that conversion
        assert cqmom.cqmom_realizable(state, np.zeros(1), arrays.params, arrays.config, work) \
            or np.all(np.abs(state) < 1e-300)
        x, w, b = cqmom.quadrature_of(state, arrays.config)
        assert np.all(np.isfinite(x)) and np.all(w >= 0) and np.all((b >= 0) & (b <= x))


# ------------------------------------------------------------------ degenerate starts
@pytest.mark.parametrize("n1", [1, 2, 3, 4])
@pytest.mark.parametrize("n2", [1, 2, 3])
def test_monodisperse_start_with_every_node_count(n1, n2):
    """Zero Hankel determinants and a single binder fraction at t = 0: one point whatever
    N1 and N2 are; the analytic M00 holds."""
    scene = make_scene(scene={"end_time": 5.0, "output_interval": 0.5},
                       initial={"binder_fraction": 0.2},
                       aggregation={"kernel": "constant", "rate": 1e-10}, method=method(n1, n2))
    res = run_well_mixed(scene)
    c = res.columns
    assert_invariants(scene, c, pure_aggregation=True)
    tau = 1e-10 * 1e10 * c["time_s"]
    assert np.max(np.abs(c["M00"] / (2e10 / (2 + tau)) - 1)) < 1e-6
    assert np.max(np.abs(c["binder_fraction"] - 0.2)) < 1e-12


def test_dry_start_receiving_binder():
    """Binder-free granules met by droplets: every conditional set starts degenerate (y = 0)
    and the first wet granules appear as atoms beside the dry ones."""
    scene = make_scene(scene={"end_time": 20.0, "output_interval": 2.0},
                       material={"accessible_binder_slope": 35.1,
                                 "accessible_binder_centre": 0.129},
                       initial={"droplet_number_density": 1e9},
                       aggregation={"kernel": "constant", "rate": 1e-11,
                                    "efficiency": ["geometric"], "droplet_factor": 100.0},
                       binder_injection={"rate": 1e8, "droplet_diameter": 60e-6},
                       method=method(2, 2))
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=1e8 * PD)
    arrays, rows = states_of(scene, res.columns)
    x, w, b = cqmom.quadrature_of(rows[1], arrays.config)
    # dry (y ~ 0) and wet (a captured droplet: y ~ p_d / (p0 + p_d) = 0.1) points side by side
    assert np.any(b / x < 0.01) and np.any(b / x > 0.05)


def test_all_zero_moments_and_an_empty_cell_filled_by_injection():
    scene = make_scene(scene={"end_time": 10.0, "output_interval": 1.0},
                       initial={"number_density": 0.0},
                       aggregation={"kernel": "constant", "rate": 1e-12},
                       binder_injection={"rate": SEED_RATE, "droplet_diameter": 60e-6},
                       method=method(3, 2))
    res = run_well_mixed(scene)
    c = res.columns
    assert c["M00"][0] == 0.0 and c["M10"][0] == 0.0
    t = c["time_s"]
    assert np.max(np.abs(c["M10"][1:] - SEED_RATE * PD * t[1:]) / (SEED_RATE * PD * t[1:])) \
        < 1e-10
    assert np.all(np.isfinite(c["d43_m"]))
    # only droplets (pure binder) exist: every point has b = p
    assert c["binder_fraction"][-1] == pytest.approx(1.0, rel=1e-12, abs=0)
    assert c["M02"][-1] == pytest.approx(c["M20"][-1], rel=1e-10, abs=0)


def test_injection_a_thousand_times_the_seed_rate():
    scene = load_scene("seed-wurster")
    scene = dataclasses.replace(scene, end_time=60.0, output_interval=5.0,
                                binder_injection=dataclasses.replace(scene.binder_injection,
                                                                     rate=1e3 * SEED_RATE))
    scene = scene.with_method(name="cqmom", nodes=3, binder_nodes=2)
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=1e3 * SEED_RATE * PD)
    assert res.columns["binder_fraction"][-1] > 0.5


# ------------------------------------------------------------------ huge growth, gelation
@pytest.mark.parametrize("n1", [2, 3])
def test_second_moment_grows_by_1e8_without_losing_the_number(n1):
    k0 = 1.0
    m1 = 1e10 * 1e-9
    end = 10.0 / (k0 * m1)                     # tau = 10: M20 grows by e^20 = 4.9e8
    scene = make_scene(scene={"end_time": end, "output_interval": end / 10},
                       initial={"distribution": "exponential", "binder_fraction": 0.1},
                       aggregation={"kernel": "sum", "rate": k0}, method=method(n1, 2))
    res = run_well_mixed(scene)
    c = res.columns
    assert c["M20"][-1] / c["M20"][0] > 1e8
    assert_invariants(scene, c, pure_aggregation=True)
    exact = 1e10 * np.exp(-k0 * m1 * c["time_s"])
    assert np.max(np.abs(c["M00"] / exact - 1)) < 1e-6


def test_product_kernel_close_to_gelation():
    m2 = 1e10 * 1e-18
    k0 = 1e8
    t_gel = 1.0 / (k0 * m2)
    scene = make_scene(scene={"end_time": 0.95 * t_gel, "output_interval": 0.05 * t_gel},
                       initial={"binder_fraction": 0.3},
                       aggregation={"kernel": "product", "rate": k0}, method=method(3, 2))
    res = run_well_mixed(scene)
    c = res.columns
    exact = m2 / (1 - k0 * m2 * c["time_s"])
    assert np.max(np.abs(c["M20"] / exact - 1)) < 1e-5
    assert_invariants(scene, c, pure_aggregation=True)


# ------------------------------------------------------------------ extreme cells in one mesh
def extreme_mesh():
    """Six cells of the bundled mesh with alpha = 0, alpha_max - 1e-6, Theta = 0, Theta = 1,
    and two ordinary cells, side by side (as in test_hard_cases)."""
    cells = load_snapshot()
    pick = np.arange(6)
    alpha = np.array([0.0, 0.62 - 1e-6, 0.4, 0.4, 0.45, 0.3])
    theta = np.array([1e-4, 1e-4, 0.0, 1.0, 1e-4, 5e-5])
    return dataclasses.replace(cells, alpha=alpha, theta=theta,
                               cell_volume=cells.cell_volume[pick].copy(),
                               cell_centre=cells.cell_centre[pick].copy(),
                               vtk_cell_id=np.arange(6))


def _extreme_cells_run(scene_name):
    """CQMOM 2 x 2 on ``extreme_mesh`` for 20 s with droplets sprayed everywhere: the first
    and last cell fields, checked finite, the empty cell untouched, and mass and binder growing
    at exactly the injected rate in the others."""
    scene = load_scene(scene_name)
    scene = dataclasses.replace(scene, end_time=20.0, output_interval=5.0,
                                binder_injection=dataclasses.replace(scene.binder_injection,
                                                                     zone=None),
                                domain=dataclasses.replace(scene.domain,
                                                           alpha_min_friction=0.5))
    scene = scene.with_method(name="cqmom", nodes=2, binder_nodes=2)
    res = run_coupled(scene, Domain(cells=extreme_mesh(), flux=None, description="extreme"))
    first, last = res.cell_fields[0], res.cell_fields[-1]
    assert last["M00"][0] == 0.0                       # alpha = 0: no granules, untouched
    for name, values in last.items():
        assert np.all(np.isfinite(values)), name
    t = res.times[-1]
    for c in range(1, 6):
        assert last["M10"][c] == pytest.approx(first["M10"][c] + 2.0e10 * PD * t, rel=1e-10, abs=0)
        assert last["M01"][c] == pytest.approx(first["M01"][c] + 2.0e10 * PD * t, rel=1e-10, abs=0)
    return first, last


def test_extreme_cells_next_to_ordinary_ones():
    _extreme_cells_run("fluid-bed")


# ------------------------------------------------------------------ random scenes
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kernel=st.sampled_from(["constant", "sum", "eke"]),
       n1=st.integers(1, 4), n2=st.integers(1, 3),
       dist=st.sampled_from(["monodisperse", "exponential"]),
       binder=st.floats(0.0, 0.5), inject=st.booleans(), tau=st.floats(0.1, 5.0))
@pytest.mark.slow
def test_random_scenes_in_the_validated_range_run_to_the_end(kernel, n1, n2, dist, binder,
                                                             inject, tau):
    n0, p0 = 1e10, 1e-9
    rate = {"constant": tau / (n0 * 10.0), "sum": tau / (n0 * p0 * 10.0),
            "eke": tau / (n0 * 10.0 * 6.0)}[kernel]
    tables = dict(scene={"end_time": 10.0, "output_interval": 2.0},
                  initial={"distribution": dist, "binder_fraction": binder},
                  aggregation={"kernel": kernel, "rate": rate}, method=method(n1, n2))
    if inject:
        tables["binder_injection"] = {"rate": 1e8, "droplet_diameter": 60e-6}
    if binder == 0.0 and not inject:
        tables["initial"]["binder_fraction"] = 0.01
    scene = make_scene(**tables)
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=1e8 * PD if inject else 0.0,
                      pure_aggregation=not inject)
    assert_follows_tight_run(scene, res.columns)


def test_step_floor_reports_the_time_reached():
    scene = make_scene(scene={"end_time": 1.0, "output_interval": 1.0},
                       initial={"distribution": "exponential", "binder_fraction": 0.2},
                       aggregation={"kernel": "constant", "rate": 1e-10}, method=method(2, 2))
    arrays = model.pack(scene)
    arrays.params[P.STEP_FLOOR] = 0.5             # impossible to respect with rtol 1e-8
    state = model.initial_moments(scene, arrays, arrays.state_names)[None, :].copy()
    status = np.zeros(1, dtype=np.int64)
    reached = np.zeros(1)
    integrate.integrate_cells(state, model.well_mixed_cell(scene), np.zeros(1), arrays.params,
                              arrays.config, 0.0, 1.0, np.array([0.4]), 1e-8, 1e-14, 1000,
                              np.zeros((1, integrate.N_STATS), dtype=np.int64), status, reached)
    assert status[0] == integrate.STEP_BELOW_FLOOR
    assert 0.0 <= reached[0] < 1.0
    assert np.all(np.isfinite(state))


# ------------------------------------------------------------------ breakage
def constant_breakage(rate, daughters="uniform"):
    return {"selection": "constant", "rate": rate, "daughters": daughters}


@pytest.mark.parametrize("n1", [1, 2, 3, 4])
@pytest.mark.parametrize("n2", [1, 2, 3])
def test_monodisperse_start_breaking_with_every_node_count(n1, n2):
    """A single atom (zero Hankel determinants, one binder fraction) that breakage spreads from
    the first step, no aggregation: constant selection s, uniform daughters (F(k) = 2/(k + 1)),
    so M00 = N0 exp(s t) (F(0) = 2) and the binder fraction stays 0.2 on every daughter; after
    s t = 5 the number has grown 150-fold."""
    s = 0.5
    scene = make_scene(scene={"end_time": 10.0, "output_interval": 1.0},
                       initial={"binder_fraction": 0.2}, breakage=constant_breakage(s),
                       method=method(n1, n2))
    c = run_well_mixed(scene).columns
    assert_invariants(scene, c)
    t = c["time_s"]
    assert np.max(np.abs(c["M00"] / (1e10 * np.exp(s * t)) - 1)) < 1e-6
    assert np.max(np.abs(c["binder_fraction"] - 0.2)) < 1e-12


@pytest.mark.parametrize("n1", [2, 3])
def test_breakage_multiplies_the_number_by_1e8(n1):
    """Constant selection with s t = ln(1e8): the mean granule mass falls from 1e-9 to 1e-17 kg
    (the scaled nodes span eight decades below their start). Every carried moment of total
    order below 2 N1 follows M_kl(0) exp(s t (F(k + l) - 1)) (tests/methods/cqmom/test_cqmom_breakage.py);
    checked here for M00 and M20 (M20 falls by exp(-s t / 3): 2e-3)."""
    s = 1.0
    end = math.log(1e8) / s
    scene = make_scene(scene={"end_time": end, "output_interval": end / 10},
                       initial={"distribution": "exponential", "binder_fraction": 0.3},
                       breakage=constant_breakage(s), method=method(n1, 2))
    c = run_well_mixed(scene).columns
    assert c["M00"][-1] / c["M00"][0] == pytest.approx(1e8, rel=1e-6, abs=0)
    assert_invariants(scene, c)
    t = c["time_s"]
    assert np.max(np.abs(c["M20"] / (c["M20"][0] * np.exp(-s * t / 3.0)) - 1)) < 1e-6


def test_dry_granules_breaking_while_binder_arrives():
    """Dry granules (every conditional set an atom on y = 0) met by droplets while they break
    into equal halves (dry daughters stay dry): dry and wet points side by side, finite,
    realizable, mass and binder growing at exactly the injected rate."""
    scene = make_scene(scene={"end_time": 20.0, "output_interval": 2.0},
                       material={"accessible_binder_slope": 35.1,
                                 "accessible_binder_centre": 0.129},
                       initial={"droplet_number_density": 1e9},
                       aggregation={"kernel": "constant", "rate": 1e-11,
                                    "efficiency": ["geometric"], "droplet_factor": 100.0},
                       binder_injection={"rate": 1e8, "droplet_diameter": 60e-6},
                       breakage=constant_breakage(0.2, "equal"), method=method(3, 2))
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=1e8 * PD)
    arrays, rows = states_of(scene, res.columns)
    x, w, b = cqmom.quadrature_of(rows[-1], arrays.config)
    assert np.any(b / x < 0.01) and np.any(b / x > 0.05)


# 3x3 slides along St = St* (108,521 of 142,864 accepted steps cross a switch at rtol 1e-8),
# and its runs at rtol 1e-10 and 1e-12 stall while sliding and continue with the smooth
# fallback switch (smooth_stokes_cells = 1): the reference is then another model, and the
# default run differs from it by 4.6e-4 on M00 (against a bound of 2.2e-7). Measured with
# the blanket sliding exemption, before the sliding pair was told apart; strict, so a
# sliding mode that lets the tight run finish sharp shows.
SLIDING_REFERENCE = pytest.mark.xfail(strict=True, reason="the 3x3 tight reference stalls "
                                      "while sliding and is smoothed (see above)")


# 2x2, 3x2: a crossing step within 8 steps of any pair's switch is kept unlocated, so the
# switch of a second point of the same size node, shortly after the first, goes unlocated
# (2x2 at rtol 1e-8: 6 steps across a switch): M00 5.06e-7 against a bound of 2.19e-7 (2x2),
# 7.10e-7 against 2.24e-7 (3x2). Telling the sliding pair apart (keep unlocated only a pair
# that switched within the last 8 steps itself) makes both pass, but then the QMOM hard case
# of tests/physics/test_stokes_jump.py stalls while sliding and is smoothed; strict, so a
# sliding mode that serves both shows.
SWITCH_DEFECT = pytest.mark.xfail(strict=True, reason="CQMOM keeps a second point's switch "
                                  "unlocated after the first (see above)")


@pytest.mark.parametrize("n1,n2", [pytest.param(2, 2, marks=SWITCH_DEFECT),
                                   pytest.param(3, 2, marks=SWITCH_DEFECT),
                                   pytest.param(3, 3, marks=[SLIDING_REFERENCE, pytest.mark.slow])])
def test_steep_power_breakage_on_the_seed_scenario(n1, n2):
    """The seed scenario (eke kernel, geometric and physical efficiency, droplets a population
    of their own, injection) with a steep power selection S = 0.05 (p / p0)^3 1/s and uniform
    daughters: large granules break as fast as they form; 120 s."""
    scene = load_scene("seed-wurster")
    breakage = Breakage(selection="power", rate=0.05, daughters="uniform", exponent=3.0)
    scene = dataclasses.replace(scene, end_time=120.0, output_interval=10.0, breakage=breakage)
    scene = scene.with_method(name="cqmom", nodes=n1, binder_nodes=n2)
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=SEED_RATE * PD)
    assert_follows_tight_run(scene, res.columns)


def test_collisional_breakage_in_extreme_cells_next_to_ordinary_ones():
    """The bundled bed's collisional breakage (S = s0 g0 sqrt(Theta / Theta_ref) p / p_ref)
    in the extreme cells of ``extreme_mesh`` (alpha = 0, next to packing, Theta = 0,
    Theta = 1 m2/s2: 100 times Theta_ref), with aggregation and droplets sprayed everywhere:
    finite, mass and binder growing at exactly the injected rate; a cell without motion
    (Theta = 0) neither aggregates nor breaks."""
    first, last = _extreme_cells_run("fluid-bed-breakage")
    for c in range(1, 6):
        assert last["M20"][c] * last["M00"][c] >= last["M10"][c] ** 2 * (1 - 1e-12)
        assert 0.0 <= last["M01"][c] <= last["M10"][c]
    nd_first = first.get("droplet_number_density", np.zeros(6))
    nd_last = last.get("droplet_number_density", np.zeros(6))
    assert last["M00"][2] - nd_last[2] == pytest.approx(first["M00"][2] - nd_first[2],
                                                        rel=1e-12, abs=0)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kernel=st.sampled_from(["constant", "sum", "eke"]),
       n1=st.integers(1, 4), n2=st.integers(1, 3),
       dist=st.sampled_from(["monodisperse", "exponential"]),
       binder=st.floats(0.0, 0.5), inject=st.booleans(), tau=st.floats(0.1, 5.0),
       selection=st.sampled_from(["constant", "power"]),
       daughters=st.sampled_from(["uniform", "equal"]), st_break=st.floats(0.1, 5.0))
def test_random_scenes_with_breakage_run_to_the_end(kernel, n1, n2, dist, binder, inject, tau,
                                                    selection, daughters, st_break):
    """Random scenes of the validated range with breakage (selection, daughters, s0 t up to 5)
    on top of aggregation: finite, realizable, mass and binder exact."""
    n0, p0 = 1e10, 1e-9
    rate = {"constant": tau / (n0 * 10.0), "sum": tau / (n0 * p0 * 10.0),
            "eke": tau / (n0 * 10.0 * 6.0)}[kernel]
    breakage = {"selection": selection, "rate": st_break / 10.0, "daughters": daughters}
    tables = dict(scene={"end_time": 10.0, "output_interval": 2.0},
                  initial={"distribution": dist, "binder_fraction": binder},
                  aggregation={"kernel": kernel, "rate": rate}, breakage=breakage,
                  method=method(n1, n2))
    if inject:
        tables["binder_injection"] = {"rate": 1e8, "droplet_diameter": 60e-6}
    if binder == 0.0 and not inject:
        tables["initial"]["binder_fraction"] = 0.01
    scene = make_scene(**tables)
    res = run_well_mixed(scene)
    assert_invariants(scene, res.columns, injected_mass_rate=1e8 * PD if inject else 0.0)
    assert_follows_tight_run(scene, res.columns)
