"""The sprayed binder as a solution and the spray schedule (docs/physics.md section 7).

Closed forms: with a constant kernel k0 and droplets injected as ordinary particles at R(t)
(piecewise constant), aggregation conserves mass and binder, so
    M10(t) = M10(0) + p_d I(t),  M01(t) = (1 - s) p_d I(t),  I(t) = int_0^t R,
piecewise linear in t; and M00 obeys dM0/dt = -k0 M0^2 / 2 + R, solved per segment in closed
form (tanh / coth towards sqrt(2 R / k0), the Smoluchowski 1/(1 + k0 M0 t / 2) where R = 0).
"""
import math
import subprocess
import sys

import numpy as np
import pytest

from conftest import make_scene
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs import model
from pbe_cfd.runs.simulate import run_well_mixed
from pbe_cfd.scene import spray
from pbe_cfd.scene.scene import SceneError

K0 = 1.0e-10          # m3/s
N0 = 1.0e10           # 1/m3
P0 = 1.0e-9           # kg
RATE = 2.0e9          # droplets/(m3 s)
D_DROP = 60e-6        # m
SOLIDS = 0.2
END = 10.0

#: relative tolerance of the comparisons: the integrator runs at rtol 1e-11 on the scaled state
#: over ~10^2 steps of local error below rtol each; 1e-8 leaves a factor >10 for their sum
TOL = 1.0e-8


def _m0_segment(m0, rate, t):
    """M0 after t [s] of dM0/dt = -K0 M0^2 / 2 + rate from m0 [1/m3]."""
    if rate == 0.0:
        return m0 / (1.0 + 0.5 * K0 * m0 * t)
    eq = math.sqrt(2.0 * rate / K0)
    g = math.sqrt(0.5 * K0 * rate)
    if m0 < eq:
        return eq * math.tanh(g * t + math.atanh(m0 / eq))
    if m0 == eq:
        return eq
    return eq / math.tanh(g * t + math.atanh(eq / m0))


def _closed_form(inj, times):
    """(M00, M10, M01) [1/m3, kg/m3, kg/m3] at ``times`` for the scene's injection ``inj``."""
    pd = model.droplet_mass(D_DROP, 1000.0)
    segs = spray.segments(inj, END)
    m00 = []
    for t in times:
        m0 = N0
        for t0, t1, rate in segs:
            if t > t0:
                m0 = _m0_segment(m0, rate, min(t, t1) - t0)
        m00.append(m0)
    injected = np.array([spray.injected(inj, t) for t in times])
    return (np.array(m00), N0 * P0 + pd * injected,
            (1.0 - inj.solids_fraction) * pd * injected)


def _scene(method, **injection):
    table = {"droplet_diameter": D_DROP, "solids_fraction": SOLIDS, **injection}
    return make_scene(scene={"end_time": END, "output_interval": 0.5},
                      initial={"mean_mass": P0, "number_density": N0},
                      aggregation={"kernel": "constant", "rate": K0},
                      binder_injection=table,
                      method={"_replace": True, "rtol": 1e-11, "atol": 1e-16, **method})


METHODS = {"qmom": {"name": "qmom", "nodes": 3},
           "cqmom": {"name": "cqmom", "nodes": 2, "binder_nodes": 2},
           "laguerre": {"name": "laguerre", "order": 3},
           "eqmom": {"name": "eqmom", "nodes": 2}}
SCHEDULES = {"start-stop": {"rate": RATE, "start": 2.25, "stop": 6.5},
             "segments": {"schedule": [[1.0, RATE], [3.75, 0.25 * RATE], [5.0, 0.0],
                                       [7.0, RATE]]}}


@pytest.mark.parametrize("schedule", SCHEDULES)
@pytest.mark.parametrize("method", METHODS)
def test_switched_injection_matches_the_closed_form(method, schedule):
    scene = _scene(METHODS[method], **SCHEDULES[schedule])
    res = run_well_mixed(scene)
    t = res.columns["time_s"]
    m00, m10, m01 = _closed_form(scene.binder_injection, t)
    assert np.allclose(res.columns["M10"], m10, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["M01"], m01, rtol=TOL, atol=1e-30)
    assert np.allclose(res.columns["M00"], m00, rtol=TOL, atol=0.0)
    # the schedule does switch: nothing is sprayed in the pauses
    off = [k for k, tk in enumerate(t) if spray.injected(scene.binder_injection, tk) == 0.0]
    assert off and np.all(res.columns["M01"][off] == 0.0)


def test_the_droplet_liquid_is_the_sprayed_mass_less_its_solids():
    scene = _scene(METHODS["qmom"], rate=RATE)
    arrays = model.pack(scene)
    pd = model.droplet_mass(D_DROP, 1000.0)
    assert arrays.params[P.DROPLET_MASS] == pytest.approx(pd, rel=1e-15, abs=0.0)
    assert arrays.params[P.DROPLET_SOLIDS] == SOLIDS
    pure = model.pack(_scene(METHODS["qmom"], rate=RATE, solids_fraction=0.0))
    assert pure.params[P.DROPLET_SOLIDS] == 0.0


@pytest.mark.parametrize("injection, key", [
    ({"rate": -1.0}, "binder_injection.rate"),
    ({"rate": RATE, "solids_fraction": 1.0}, "binder_injection.solids_fraction"),
    ({"rate": RATE, "solids_fraction": -0.1}, "binder_injection.solids_fraction"),
    ({"rate": RATE, "start": 5.0, "stop": 4.0}, "binder_injection.stop"),
    ({"rate": RATE, "start": -1.0}, "binder_injection.start"),
    ({"schedule": [[0.0, RATE], [2.0, -1.0]]}, "binder_injection.schedule"),
    ({"schedule": [[3.0, RATE], [2.0, 0.0]]}, "binder_injection.schedule"),
    ({"schedule": [[0.0, RATE], [0.0, 0.0]]}, "binder_injection.schedule"),
    ({"schedule": [[0.0, RATE, 1.0]]}, "binder_injection.schedule"),
    ({"schedule": []}, "binder_injection.schedule"),
    ({"schedule": [[0.0, RATE]], "rate": RATE}, "binder_injection.rate"),
])
def test_bad_spray_input_names_the_key(injection, key):
    with pytest.raises(SceneError) as err:
        _scene(METHODS["qmom"], **{"solids_fraction": 0.0, **injection})
    assert err.value.key == key


@pytest.mark.parametrize("schedule", SCHEDULES)
def test_the_cnmc_follows_a_spray_schedule(schedule):
    """The cNMC's box sprays at the schedule's rate (``methods.cnmc.spray``): its volume
    follows the mass concentration, so M10 is the closed form to round-off; M00 and M01 lie
    within twice the replicas' 95% band (about 4.7 standard deviations of the mean) plus one
    droplet per box of the injected ones (the box sprays at mean waiting times, so its
    count of injections is early or late by at most one); nothing is sprayed before the first
    start (M01 exactly 0)."""
    particles, replicas = 2000, 8
    scene = _scene({"name": "cnmc", "particles": particles, "replicas": replicas, "seed": 11},
                   **SCHEDULES[schedule])
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    m00, m10, m01 = _closed_form(scene.binder_injection, t)
    assert np.allclose(c["M10"], m10, rtol=1e-12, atol=0.0)
    injected = np.array([spray.injected(scene.binder_injection, tk) for tk in t])
    per_droplet = particles / c["M00"]          # particles of a box per particle per m3
    for name, exact, unit in (("M00", m00, 1.0), ("M01", m01, m01[-1] / injected[-1])):
        half = 0.5 * (c[name + "_hi"] - c[name + "_lo"])
        slack = 2.0 * half + unit / per_droplet
        assert np.all(np.abs(c[name] - exact) <= slack), \
            (name, np.max(np.abs(c[name] - exact) / slack))
    before = injected == 0.0
    assert before[0] and np.all(c["M01"][before & (t < 3.0)] == 0.0)


@pytest.mark.parametrize("method", ["qmom", "cqmom", "laguerre", "eqmom"])
def test_only_a_method_whose_own_droplets_hold_solids_takes_a_solution(method):
    """Droplets of their own ([aggregation] droplet_factor) with binder solids: EQMOM's
    droplets hold pure liquid and refuse; pure liquid, the other quadratures and the Laguerre
    ROM (its capture tensors at the droplet's (p_d, b_d)) are accepted."""
    def scene(solids):
        return make_scene(scene={"end_time": END, "output_interval": 0.5},
                          initial={"mean_mass": P0, "number_density": N0},
                          aggregation={"kernel": "constant", "rate": K0, "droplet_factor": 1.0},
                          binder_injection={"droplet_diameter": D_DROP, "rate": RATE,
                                            "solids_fraction": solids},
                          method={"_replace": True, **METHODS[method]})
    assert scene(0.0).separate_droplets
    if method == "eqmom":
        with pytest.raises(SceneError) as err:
            scene(SOLIDS)
        assert err.value.key == "binder_injection.solids_fraction"
    else:
        assert scene(SOLIDS).binder_injection.solids_fraction == SOLIDS


def test_a_mass_flow_needs_the_cells_of_a_spray_zone():
    """rate_unit = "kg/s" is a nozzle's flow over a spray zone's cells: a well-mixed scene
    refuses it naming the key; a bad unit is refused naming the choices."""
    for unit, key in (("kg/s", "binder_injection.rate_unit"),
                      ("g/min", "binder_injection.rate_unit")):
        with pytest.raises(SceneError) as err:
            make_scene(binder_injection={"droplet_diameter": D_DROP, "rate": 1e-4,
                                         "rate_unit": unit})
        assert err.value.key == key, err.value
        assert ("openfoam" in str(err.value)) == (unit == "kg/s"), err.value


def test_a_mass_flow_is_spread_over_the_zone_volume():
    """per_volume: F [kg/s] over V [m3] of droplets of mass p_d is F / (p_d V) droplets per m3
    and s, the schedule's rates alike; the zone then receives F p_d V / p_d V = F."""
    from pbe_cfd.scene import spray
    inj = spray.BinderInjection(rate=2e-4, droplet_diameter=D_DROP, rate_unit=spray.MASS_FLOW,
                                schedule=((0.0, 2e-4), (5.0, 1e-4), (8.0, 0.0)))
    pd, volume = 1.2e-10, 3.5e-4
    per = spray.per_volume(inj, volume, pd)
    assert per.rate_unit == spray.PER_VOLUME
    assert per.rate * pd * volume == pytest.approx(2e-4, rel=1e-15, abs=0.0)
    assert [t for t, _ in per.schedule] == [0.0, 5.0, 8.0]
    assert [r * pd * volume for _, r in per.schedule] == pytest.approx([2e-4, 1e-4, 0.0],
                                                                        rel=1e-15, abs=0.0)
    assert spray.per_volume(per, volume, pd) is per          # already per volume
    with pytest.raises(ValueError, match="holds no cell"):
        spray.per_volume(inj, 0.0, pd)


@pytest.mark.slow
def test_plan_lists_the_schedule_and_exit_2_names_the_key(tmp_path):
    good = tmp_path / "spray.toml"
    good.write_text(_toml("rate = 2e9\nstart = 2.0\nstop = 6.0\nsolids_fraction = 0.2"))
    out = subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "plan", str(good)],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "spray schedule (droplets/(m3 s)): 0-2 s: 0; 2-6 s: 2e+09; 6-10 s: 0" in out.stdout
    assert "solids fraction 0.2" in out.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(_toml("schedule = [[4.0, 2e9], [1.0, 0.0]]"))
    out = subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "plan", str(bad)],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert "[binder_injection.schedule]" in out.stderr and "out of order" in out.stderr


def _toml(injection):
    return f"""[scene]
end_time = 10.0
output_interval = 1.0
[domain]
type = "well-mixed"
[material]
density = 1000.0
binder_density = 1000.0
[initial]
distribution = "monodisperse"
number_density = 1e10
mean_mass = 1e-9
[binder_injection]
droplet_diameter = 60e-6
{injection}
[method]
name = "qmom"
"""


def _captured_hierarchy(factor, y0, times):
    """The constant kernel's closed moment hierarchy with droplets of their own (mass p_d,
    liquid b_d = (1 - s) p_d) sprayed at RATE and captured at factor k0 per granule, from an
    exponential start of binder fraction y0: granule M00, M10, M01, M20, M11, M02 and n_d at
    ``times`` (solve_ivp, rtol 1e-13; an independent reference: only the hierarchy)."""
    from scipy.integrate import solve_ivp
    pd = model.droplet_mass(D_DROP, 1000.0)
    bd = (1.0 - SOLIDS) * pd
    kc = factor * K0

    def rates(t, y):
        n, m10, m01, m20, m11, m02, nd = y
        c = kc * nd
        return [-0.5 * K0 * n * n, c * pd * n, c * bd * n,
                K0 * m10 * m10 + c * (2 * pd * m10 + pd * pd * n),
                K0 * m10 * m01 + c * (pd * m01 + bd * m10 + pd * bd * n),
                K0 * m01 * m01 + c * (2 * bd * m01 + bd * bd * n),
                RATE - c * n]
    y0v = [N0, N0 * P0, y0 * N0 * P0, 2 * N0 * P0 ** 2, 2 * y0 * N0 * P0 ** 2,
           2 * y0 ** 2 * N0 * P0 ** 2, 0.0]
    scale = N0 * np.array([1.0, P0, P0, P0 ** 2, P0 ** 2, P0 ** 2, 1.0])
    sol = solve_ivp(rates, (0.0, times[-1]), y0v, t_eval=times, rtol=1e-13,
                    atol=1e-16 * scale, method="DOP853")
    assert sol.success, sol.message
    return sol.y, pd, bd


@pytest.mark.parametrize("y0", [0.1, 0.0], ids=["wet-start", "dry-start"])
def test_laguerre_captures_solution_droplets_of_their_own_exactly(y0):
    """The Laguerre ROM with droplets of their own carrying binder solids (s = SOLIDS):
    granules aggregate (constant kernel) and capture droplets at 2 k0 each, every carried
    moment of the population (free droplets at (p_d, b_d) included, as the output columns)
    and n_d follow the closed hierarchy to TOL, from a wet start (the wet class's capture
    tensors) and a dry one (the dry class's, its captures handed to the wet class). With the
    capture at b_d = p_d (pure liquid) M01 fails."""
    factor = 2.0
    scene = make_scene(scene={"end_time": END, "output_interval": 0.5},
                       initial={"mean_mass": P0, "number_density": N0, "binder_fraction": y0,
                                "distribution": "exponential"},
                       aggregation={"kernel": "constant", "rate": K0, "droplet_factor": factor},
                       binder_injection={"droplet_diameter": D_DROP, "rate": RATE,
                                         "solids_fraction": SOLIDS},
                       method={"_replace": True, "rtol": 1e-11, "atol": 1e-16,
                               **METHODS["laguerre"]})
    c = run_well_mixed(scene).columns
    t = np.asarray(c["time_s"])
    (n, m10, m01, m20, m11, m02, nd), pd, bd = _captured_hierarchy(factor, y0, t)
    assert np.allclose(c["droplet_number_density"], nd, rtol=TOL, atol=TOL * nd.max())
    for name, granule, (i, j) in (("M00", n, (0, 0)), ("M10", m10, (1, 0)),
                                  ("M01", m01, (0, 1)), ("M20", m20, (2, 0)),
                                  ("M11", m11, (1, 1)), ("M02", m02, (0, 2))):
        expected = granule + nd * pd ** i * bd ** j
        assert np.allclose(c[name], expected, rtol=TOL, atol=0.0), name
