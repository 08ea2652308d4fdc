"""Drying (docs/physics.md section 15) in every method that carries it: CQMOM, EQMOM, the
Laguerre ROM and the cNMC, beside QMOM (tests/physics/test_drying.py).

Closed forms: no aggregation, a monodisperse wet population is one point of every quadrature
(one size node, one conditional point, one degenerate gamma kernel; the ROM's drift points,
``methods.laguerre.drying.wet_points``, are one mass node with one liquid point) and a box
of identical particles in the cNMC, so the drift's quadrature is exact and the moments follow
the liquid b(t) of one granule (linear in the constant-rate period, exponential in the falling-rate
period): M_ij = N0 (m_s + b)^i b^j, E = N0 (b0 - b). Tolerance 1e-8 as there (rtol 1e-11
over ~10^2 steps); the cNMC integrates each particle in closed form (skeleton period), so its
moments are exact to round-off of the box sums.
"""
import numpy as np
import pytest

from conftest import make_scene
from test_drying import AIR, N0, P0, RHO_S, TOL, _constant_rate, _liquid, _scene
from pbe_cfd.runs.simulate import run_well_mixed

METHODS = {
    "cqmom": {"name": "cqmom", "nodes": 2, "binder_nodes": 2},
    "eqmom": {"name": "eqmom", "nodes": 2},
    "cnmc": {"name": "cnmc", "particles": 64, "replicas": 2, "seed": 3},
    "laguerre": {"name": "laguerre", "order": 3},
}
BALANCED = METHODS


def _check(res, y0, x_cr, x_eq, rtol):
    c = res.columns
    ms = P0 * (1.0 - y0)
    ec = _constant_rate(P0, y0)
    b = np.array([_liquid(t, y0 * P0, ms, ec, x_cr, x_eq) for t in c["time_s"]])
    p = ms + b
    for name, expected in (("M00", N0 + 0 * b), ("M10", N0 * p), ("M01", N0 * b),
                           ("M20", N0 * p * p), ("M11", N0 * p * b), ("M02", N0 * b * b)):
        if name in c:
            assert np.allclose(c[name], expected, rtol=rtol, atol=0.0), name
    assert np.allclose(c["liquid_evaporated"], N0 * (y0 * P0 - b), rtol=rtol,
                       atol=rtol * N0 * y0 * P0)
    return b


# The Laguerre ROM missed it by 1.5e-7 on M01 after the switch while its drift had one liquid
# point outside the realizability boundary and two inside (a kink the integration's stages
# straddle); with the pair continued smoothly across the boundary (docs/physics.md section 15)
# it holds 1e-8 through both periods. CQMOM's monodisperse binder sits on the same kind of
# boundary (M00 M02 = M01^2) and its drift takes the continued pair too (section 15, "CQMOM's
# drift near a monodisperse binder"): M01 1.4e-10 off at the end. With one conditional point
# outside, each step (rtol 1e-11) left a spurious conditional variance of 7e-12 b^2, which
# grew to 2.3e-8 b^2 once above the one-point threshold; spread over the kink of e at X_cr,
# it raised M01 by half of that, 1.1e-8.


@pytest.mark.parametrize("method", sorted(METHODS))
def test_constant_rate_then_falling_rate_closed_form(method):
    y0, x_cr = 0.2, 0.05                          # X0 = 0.25 > X_cr: both periods
    ec = _constant_rate(P0, y0)
    t_c = (y0 * P0 - x_cr * P0 * (1 - y0)) / ec
    res = run_well_mixed(_scene(y0, 3.0 * t_c, x_cr, method=METHODS[method]))
    # the cNMC's moments are box sums of identical particles: round-off of N additions
    b = _check(res, y0, x_cr, 0.0, 1e-12 if method == "cnmc" else TOL)
    t = res.columns["time_s"]
    assert (t < t_c).sum() >= 5 and (t > t_c).sum() >= 5
    assert np.all(np.diff(b) < 0)


# The ROM's M02 left the constant-rate closed form by 1.15e-8 of its start at 0.9 t_c (the
# Hankel gap the integration opened where its drift switched between one and two liquid points
# on the realizability boundary); with the pair continued smoothly across it, 7e-11
# (docs/physics.md section 15, "The constant-rate closed form's M02, and the smooth
# continuation"). test_constant_rate_period_is_linear holds it to 1e-8.


def test_rom_drift_of_a_monodisperse_class_is_exact():
    """The ROM's drying RHS at a monodisperse wet state (p0, b0) is one point's drift: dW_ij =
    -N0 e (i p^(i-1) b^j + j p^i b^(j-1)), dE = N0 e, to round-off (1e-13 of each rate: a few
    products of O(1) scaled numbers), e the evaporated entry's rate."""
    from pbe_cfd.methods.entry import WORK_SIZE
    from pbe_cfd.methods.laguerre.rhs import laguerre_rhs
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.runs.problem import problem_of
    problem = problem_of(_scene(0.2, 1.0, 0.05, method=METHODS["laguerre"]))
    batch = CellBatch.for_problem(problem)
    state = problem.states[0].copy()
    names = list(problem.arrays.state_names)
    out = np.zeros(len(state))
    laguerre_rhs(state, out, np.ascontiguousarray(problem.rows[0], float), problem.aux,
                 np.ascontiguousarray(batch.params, float), problem.arrays.config,
                 np.empty(WORK_SIZE))
    w00 = state[names.index("wet_M00")]
    p = state[names.index("wet_M10")] / w00
    b = state[names.index("wet_M01")] / w00
    e = out[names.index("evaporated_liquid")] / w00
    assert e * problem.arrays.number_scale * problem.arrays.mass_scale == pytest.approx(
        N0 * _constant_rate(P0, 0.2), rel=1e-12, abs=0.0)
    for k, name in enumerate(names[:9]):
        i, j = int(name[-2]), int(name[-1])
        expected = -w00 * e * ((i * p ** (i - 1) * b ** j if i else 0.0)
                               + (j * p ** i * b ** (j - 1) if j else 0.0))
        assert out[k] == pytest.approx(expected, rel=1e-13, abs=0.0), name



@pytest.mark.parametrize("y0, x_cr", [(0.2, 0.05), (0.05, 0.2)])   # constant, falling rate
def test_cqmom_drift_is_smooth_across_a_monodisperse_binder(y0, x_cr):
    """CQMOM 2x2's RHS at a monodisperse wet state (on the conditional boundary M00 M02 =
    M01^2) and with M02, M12 moved by -+1e-8 of themselves (an integrator's stage lands
    outside by (h e / 2b)^2 = 1.4e-8 of M02 at rtol 1e-11): every entry is differentiable
    there, its second difference below 1e-3 of its first (round-off: 1e-15 of the rate). With
    one conditional point outside and the nodes of mu3's noise inside, the second difference
    was the first's size: a kink the stages straddle (docs/physics.md section 15, "CQMOM's
    drift near a monodisperse binder")."""
    from pbe_cfd.methods.cqmom.sources import cqmom_rhs
    from pbe_cfd.methods.entry import WORK_SIZE
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.runs.problem import problem_of
    problem = problem_of(_scene(y0, 1.0, x_cr, method=METHODS["cqmom"]))
    params = np.ascontiguousarray(CellBatch.for_problem(problem).params, float)
    names = list(problem.arrays.state_names)

    def rate(g):
        state = problem.states[0].copy()
        for name in ("M02", "M12"):
            state[names.index(name)] *= 1.0 + g
        out = np.zeros(len(state))
        cqmom_rhs(state, out, np.ascontiguousarray(problem.rows[0], float), problem.aux,
                  params, problem.arrays.config, np.empty(WORK_SIZE))
        return out

    below, on, above = rate(-1e-8), rate(0.0), rate(1e-8)
    second = np.abs(above - 2.0 * on + below)
    assert np.all(second <= 1e-3 * np.abs(above - below) + 1e-15 * np.abs(on)), names
    assert on[names.index("evaporated_liquid")] > 0.0

def test_constant_rate_period_is_linear():
    """The Laguerre ROM in the constant-rate period alone (to 0.9 t_c, before the switch to
    the falling rate): the liquid falls linearly, every moment the closed form's to 1e-8 of its
    largest value over the run."""
    y0, x_cr = 0.2, 0.05
    t_c = (y0 * P0 - x_cr * P0 * (1 - y0)) / _constant_rate(P0, y0)
    c = run_well_mixed(_scene(y0, 0.9 * t_c, x_cr, method=METHODS["laguerre"])).columns
    ms = P0 * (1.0 - y0)
    b = y0 * P0 - _constant_rate(P0, y0) * np.asarray(c["time_s"])      # linear in time
    p = ms + b
    # every moment only falls, so the step control's error (rtol 1e-11 of each step's state,
    # ~10^2 steps) is bounded by TOL of the moment's value at t = 0: M02 ends at 0.08 of it
    for name, expected in (("M00", N0 + 0 * b), ("M10", N0 * p), ("M01", N0 * b),
                           ("M20", N0 * p * p), ("M11", N0 * p * b), ("M02", N0 * b * b),
                           ("liquid_evaporated", N0 * (y0 * P0 - b))):
        scale = max(abs(expected[0]), abs(expected[-1]))
        assert np.allclose(c[name], expected, rtol=TOL, atol=TOL * scale), name
    assert b[-1] < 0.5 * b[0]


@pytest.mark.parametrize("method", sorted(METHODS))
def test_falling_rate_is_first_order_and_dry_stays_dry(method):
    y0, x_cr, x_eq = 0.05, 0.2, 0.01              # falling from the start
    ms = P0 * (1 - y0)
    tau = (x_cr - x_eq) * ms / _constant_rate(P0, y0)
    res = run_well_mixed(_scene(y0, 8.0 * tau, x_cr, x_eq, method=METHODS[method]))
    b = _check(res, y0, x_cr, x_eq, 1e-12 if method == "cnmc" else TOL)
    assert np.all(b >= x_eq * ms) and np.all(res.columns["M01"] >= N0 * x_eq * ms * (1 - TOL))


def _spray_dry(method):
    """Spray a solution (s = 0.1) for 20 s, dry for 2 s, constant-kernel aggregation, droplets
    as ordinary particles (the scene of tests/physics/test_drying.py's balance test)."""
    return make_scene(scene={"end_time": 22.0, "output_interval": 0.5},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": 0.02},
                      aggregation={"kernel": "constant", "rate": 2.0e-11},
                      binder_injection={"rate": 8.8e7, "droplet_diameter": 60e-6,
                                        "solids_fraction": 0.1, "start": 0.0, "stop": 20.0},
                      drying={**AIR, "critical_moisture": 0.05},
                      method={"_replace": True, "rtol": 1e-8, **BALANCED[method]})


@pytest.mark.parametrize("method", ["cqmom", "laguerre"])
def test_liquid_and_binder_solids_balance(method):
    """Sprayed liquid = held + evaporated to 1e-8, the binder solids M10 - M01 = s p_d I(t)
    (plus their start) to 1e-10: the invariants M10 + E and M01 + E have state-free
    derivatives (the spray), kept by the integrator to round-off."""
    c = run_well_mixed(_spray_dry(method)).columns
    total = c["M01"][0] + c["liquid_sprayed"]
    assert np.allclose(c["M01"] + c["liquid_evaporated"], total, rtol=1e-8, atol=0.0)
    solids = (c["M10"] - c["M01"]) - (c["M10"][0] - c["M01"][0])
    expected = c["liquid_sprayed"] * 0.1 / 0.9
    assert np.allclose(solids, expected, rtol=1e-10, atol=1e-10 * expected[-1])
    after = (c["time_s"] >= 20.0) & (c["M01"] > 1e-6 * c["M01"].max())
    assert c["liquid_evaporated"][-1] > 0.5 * c["liquid_sprayed"][-1]
    assert after.sum() >= 2 and np.all(np.diff(c["M01"][after]) < 0)
    assert np.all(c["M01"] >= 0)


# ---- against the independent cNMC with drying and aggregation ---------------------------------
#: the spray-then-dry scene (fixed before any method was run on it): the granules start wet
#: (y0 = 0.1, X = 0.11 < X_cr = 0.2: falling rate, tau = X_cr m_s / e_c = 5.8 s in air at
#: 30 C, humidity 0.022), a solution (s = 0.1) is sprayed for 20 s, then the bed dries for 10 s;
#: constant kernel k0 N0 = 0.2 1/s, droplets (60 um) as ordinary particles
SPRAY_DRY = dict(end=30.0, air={"air_temperature": 303.15, "air_humidity": 0.022,
                                "slip_velocity": 0.1, "critical_moisture": 0.2},
                 k0=2.0e-11, y0=0.1, rate=8.8e7, d_drop=60e-6, solids=0.1, stop=20.0)
#: reference ensemble: N particles x R replicas, seed (fixed before looking)
REF_PARTICLES, REF_REPLICAS, REF_SEED = 2000, 8, 2026
COMPARED = {"qmom": {"name": "qmom", "nodes": 3},
            "cqmom": {"name": "cqmom", "nodes": 3, "binder_nodes": 2},
            "laguerre": {"name": "laguerre", "order": 3, "support_mass": 8e-8,
                         "grid_mass": 80}}


def _spray_dry_scene(method):
    s = SPRAY_DRY
    return make_scene(scene={"end_time": s["end"], "output_interval": 1.0},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": s["y0"]},
                      aggregation={"kernel": "constant", "rate": s["k0"]},
                      binder_injection={"rate": s["rate"], "droplet_diameter": s["d_drop"],
                                        "solids_fraction": s["solids"], "start": 0.0,
                                        "stop": s["stop"]},
                      drying=s["air"],
                      method={"_replace": True, "rtol": 1e-8, **method})


def _reference(stop):
    """(times [s], mean, 95% half-width) of the reference's NAMES over the scene, the spray
    stopping at ``stop`` [s]."""
    import math

    from references import cnmc_drying
    from pbe_cfd.physics import drying
    s = SPRAY_DRY
    air = s["air"]
    rho, mu, diffusivity, _, driving = drying.gas_state(air["air_temperature"],
                                                        air["air_humidity"], 101325.0)
    case = dict(gas=dict(rho=rho, mu=mu, diffusivity=diffusivity, driving=driving),
                slip=air["slip_velocity"], rho_s=RHO_S, rho_l=1000.0,
                x_cr=air["critical_moisture"], x_eq=0.0, k0=s["k0"], n0=N0, p0=P0, y0=s["y0"],
                droplet_mass=1000.0 * math.pi / 6.0 * s["d_drop"] ** 3,
                solids_fraction=s["solids"], rate=s["rate"], start=0.0, stop=stop)
    times = np.arange(0.0, s["end"] + 0.5, 1.0)
    mean, half = cnmc_drying.ensemble(case, REF_PARTICLES, REF_REPLICAS, REF_SEED, times)
    return times, dict(zip(cnmc_drying.NAMES, mean.T)), dict(zip(cnmc_drying.NAMES, half.T))


@pytest.fixture(scope="module")
def reference():
    """The reference over the spray-then-dry scene (the spray stops at SPRAY_DRY["stop"])."""
    return _reference(SPRAY_DRY["stop"])


@pytest.mark.slow
@pytest.mark.study
@pytest.mark.parametrize("method", sorted(COMPARED))
def test_spray_then_dry_against_the_independent_cnmc(method, reference):
    """Every carried moment (that the reference has: M_ij, i < 6, j < 4) and the evaporated
    liquid within 3% of the reference's mean plus its 95% band, at every output time.

    Measured (reference 2000 particles x 4 replicas, seed 2026): QMOM N = 3 and CQMOM 3 x 2
    hold M00 .. M50 and E, but M01 runs 4-7% below the reference from t ~ 10 s on (band
    0.8-1.8%), with more nodes further (QMOM N = 4: -8%, CQMOM 4 x 2: -10% at 20 s); without
    aggregation the same scene agrees to 1% (QMOM N = 3, 4) with the reference and with the
    semi-analytic sum over injection times. Red, reported; not tuned.

    The cause is the closure of the drift, not the physics: the project's cNMC agrees with the
    reference on the same scene (``test_cnmc_with_drying_and_aggregation_matches_the_reference``),
    and the QMOM quadrature of the reference's own box overestimates its evaporation rate by
    3-7% (N = 3) and 6-22% (N = 4) from 3 to 20 s (scripts/drying_closure.py; docs/physics.md
    section 15, "Closure of the drift")."""
    times, mean, half = reference
    c = run_well_mixed(_spray_dry_scene(COMPARED[method])).columns
    assert np.allclose(c["time_s"], times, rtol=0.0, atol=1e-9)
    carried = _carried(method)
    worst = {}
    for name in carried + ["liquid_evaporated"]:
        dev = np.abs(c[name] - mean[name])
        worst[name] = float(np.max(dev / np.abs(mean[name])))
        assert np.all(dev <= 0.03 * np.abs(mean[name]) + half[name]), (name, worst[name])


@pytest.mark.slow
@pytest.mark.study
def test_cnmc_with_drying_and_aggregation_matches_the_reference():
    """The project's cNMC (per-particle drying, ``physics.drying.advance_liquid``) against the
    independent cNMC on the scene above with the spray on throughout (the project's cNMC sprays
    at one constant rate): M00, M10, M01, M20, M11, M02 and the evaporated liquid within the
    issue's 3% of the reference's mean plus both ensembles' 95% half-widths (two independent
    means: their difference is within the root sum of squares of the halves, which the sum
    bounds). Both are the same model, so only their scatter may separate them; the moment
    methods' M01 gap is then the closure of the drift."""
    times, mean, half = _reference(2.0 * SPRAY_DRY["end"])
    s = SPRAY_DRY
    scene = make_scene(scene={"end_time": s["end"], "output_interval": 1.0},
                       material={"density": RHO_S, "binder_density": 1000.0},
                       initial={"mean_mass": P0, "number_density": N0,
                                "binder_fraction": s["y0"]},
                       aggregation={"kernel": "constant", "rate": s["k0"]},
                       binder_injection={"rate": s["rate"], "droplet_diameter": s["d_drop"],
                                         "solids_fraction": s["solids"]},
                       drying=s["air"],
                       method={"_replace": True, "name": "cnmc", "particles": REF_PARTICLES,
                               "replicas": 4, "seed": 5})
    c = run_well_mixed(scene).columns
    assert np.allclose(c["time_s"], times, rtol=0.0, atol=1e-9)
    for name in ("M00", "M10", "M01", "M20", "M11", "M02", "liquid_evaporated"):
        own_half = 0.5 * (c[name + "_hi"] - c[name + "_lo"])
        dev = np.abs(c[name] - mean[name])
        assert np.all(dev <= 0.03 * np.abs(mean[name]) + half[name] + own_half), \
            (name, float(np.max(dev / np.abs(mean[name]))))
    assert c["liquid_evaporated"][-1] > 0.5 * c["M01"][0]


def _carried(method):
    """The moments the method carries that the reference computes."""
    scene = _spray_dry_scene(COMPARED[method])
    from pbe_cfd.methods.registry import METHOD_REGISTRY
    entry = next(m for m in METHOD_REGISTRY if m.name == method)
    names = [n.replace("wet_", "") for n in entry.state_names(scene)]
    return [n for n in names if len(n) == 3 and n[0] == "M" and int(n[1]) < 6 and int(n[2]) < 4]


@pytest.mark.slow
@pytest.mark.parametrize("schedule", ["start-stop", "segments"])
def test_eqmom_switched_injection_of_a_solution_matches_the_closed_form(schedule):
    """EQMOM's droplets as ordinary particles carry the solution's liquid (1 - s) p_d, not
    p_d: M01 = (1 - s) p_d I(t), piecewise linear (tests/methods/test_spray.py's closed
    forms, the drying scenes' sprayed solution)."""
    import test_spray as S
    scene = S._scene({"name": "eqmom", "nodes": 2}, **S.SCHEDULES[schedule])
    res = run_well_mixed(scene)
    m00, m10, m01 = S._closed_form(scene.binder_injection, res.columns["time_s"])
    assert np.allclose(res.columns["M10"], m10, rtol=S.TOL, atol=0.0)
    assert np.allclose(res.columns["M01"], m01, rtol=S.TOL, atol=1e-30)
    assert np.allclose(res.columns["M00"], m00, rtol=S.TOL, atol=0.0)


def test_a_batch_cell_dries_its_last_liquid_to_the_end():
    """One well-mixed cell of fluid-bed-batch for its whole batch (scripts/
    qmom-liquid-trace-cell.toml: QMOM N = 3, default tolerances, 20 min of spray, 10 of
    drying). Once the granules' liquid is below the absolute tolerance, M01, M11 and M21 are
    no longer held to one another and the per-node liquid solved from them has mixed signs;
    clipped, it evaporated more than M01 carries and drove M01 negative (the cell stopped at
    1218.79 s at its step floor). The drift now dries the liquid the state carries: the run
    ends, the liquid balance holds (sprayed = on granules + in droplets + evaporated, 1e-8 of
    the sprayed), and the granules' liquid falls at every output after the spray to below
    1e-12 of its value when the spray stopped."""
    from pathlib import Path

    from pbe_cfd.scene.scene import load_scene
    path = Path(__file__).resolve().parents[2] / "scripts" / "qmom-liquid-trace-cell.toml"
    c = run_well_mixed(load_scene(path)).columns
    t = c["time_s"]
    assert t[-1] == 1800.0
    held = c["liquid_granules"] + c["liquid_droplets"] + c["liquid_evaporated"]
    assert np.allclose(held, c["liquid_sprayed"], rtol=0.0, atol=1e-8 * c["liquid_sprayed"][-1])
    after = t >= 1200.0
    liquid = c["liquid_granules"][after]
    assert np.all(np.diff(liquid) <= 0.0)
    assert liquid[-1] <= 1e-12 * liquid[0]
