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
           "laguerre": {"name": "laguerre", "order": 3}}
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


def test_the_cnmc_refuses_a_schedule_it_cannot_run():
    with pytest.raises(SceneError) as err:
        _scene({"name": "cnmc"}, rate=RATE, stop=5.0)
    assert err.value.key == "binder_injection.schedule"


@pytest.mark.parametrize("method", ["qmom", "cqmom", "laguerre"])
def test_only_a_method_whose_own_droplets_hold_solids_takes_a_solution(method):
    """Droplets of their own ([aggregation] droplet_factor) with binder solids: the Laguerre
    ROM's capture tensors hold pure-liquid droplets (b = p_d) and refuse; pure liquid, and the
    quadratures, are accepted."""
    def scene(solids):
        return make_scene(scene={"end_time": END, "output_interval": 0.5},
                          initial={"mean_mass": P0, "number_density": N0},
                          aggregation={"kernel": "constant", "rate": K0, "droplet_factor": 1.0},
                          binder_injection={"droplet_diameter": D_DROP, "rate": RATE,
                                            "solids_fraction": solids},
                          method={"_replace": True, **METHODS[method]})
    assert scene(0.0).separate_droplets
    if method == "laguerre":
        with pytest.raises(SceneError) as err:
            scene(SOLIDS)
        assert err.value.key == "binder_injection.solids_fraction"
    else:
        assert scene(SOLIDS).binder_injection.solids_fraction == SOLIDS


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
