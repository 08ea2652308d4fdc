"""QMOM + realizable RK3(2) against the analytic moment solutions of docs/physics.md section 10.

These moment systems close exactly under N-node quadrature (M0, M1, M2 for the constant, sum
and product kernels; M11 for the two-component constant kernel), so the error measured is the
time integrator's. The integrator bounds each step's embedded error estimate by rtol = 1e-8 of
the state; the propagated third-order solution's own local error is smaller, and over the ~1e3
steps of these runs the global error stays below 100 rtol = 1e-6, the bound required here.
"""
import math

import numpy as np
import pytest

from pbe_cfd.methods.dispatch import WORK_SIZE
from pbe_cfd.methods.qmom.qmom import qmom_realizable
from pbe_cfd.runs.model import pack
from pbe_cfd.scene.scene import SceneError
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

N0 = 1.0e10      # 1/m3
P0 = 1.0e-9      # kg
TOL = 1.0e-6     # 100 x the default rtol (module docstring)


def _moments0(dist):
    factor = 1.0 if dist == "monodisperse" else 2.0      # exponential: M2 = 2 N0 p0^2
    return N0, N0 * P0, factor * N0 * P0 ** 2


def _run(kernel, rate, dist, end, nodes, **extra):
    tables = {"scene": {"end_time": end, "output_interval": end / 20},
              "initial": {"distribution": dist},
              "aggregation": {"kernel": kernel, "rate": rate},
              "method": {"nodes": nodes}}
    tables.update(extra)
    scene = make_scene(**tables)
    return scene, run_well_mixed(scene)


def _rel(a, b):
    return np.max(np.abs(a - b) / np.abs(b))


@pytest.mark.parametrize("dist", ["monodisperse", "exponential"])
@pytest.mark.parametrize("nodes", [2, 3])
def test_constant_kernel(dist, nodes):
    k0 = 1.0e-10                       # tau = k0 N0 t = 10 at t = 10 s
    _, res = _run("constant", k0, dist, 10.0, nodes)
    c = res.columns
    t = c["time_s"]
    m0, m1, m2 = _moments0(dist)
    tau = k0 * N0 * t
    assert tau[-1] == pytest.approx(10.0, rel=1e-12, abs=0)
    assert _rel(c["M00"], 2 * N0 / (2 + tau)) < TOL
    assert _rel(c["M20"], m2 + k0 * m1 ** 2 * t) < TOL
    assert _rel(c["M10"], m1) < 1e-12


@pytest.mark.parametrize("dist", ["monodisperse", "exponential"])
@pytest.mark.parametrize("nodes", [2, 3])
def test_sum_kernel(dist, nodes):
    k0 = 1.0                           # m3/(kg s): k0 M1 = 10/s ... tau = k0 M1 t
    m0, m1, m2 = _moments0(dist)
    end = 10.0 / (k0 * m1)             # tau = 10
    _, res = _run("sum", k0, dist, end, nodes)
    c = res.columns
    t = c["time_s"]
    assert _rel(c["M00"], N0 * np.exp(-k0 * m1 * t)) < TOL
    assert _rel(c["M20"], m2 * np.exp(2 * k0 * m1 * t)) < TOL
    assert c["M20"][-1] / c["M20"][0] > 1e8          # a hard growth: e^20
    assert _rel(c["M10"], m1) < 1e-12


@pytest.mark.parametrize("dist", ["monodisperse", "exponential"])
@pytest.mark.parametrize("nodes", [2, 3])
def test_product_kernel_before_gelation(dist, nodes):
    m0, m1, m2 = _moments0(dist)
    k0 = 1.0e8                         # m3/(kg2 s)
    t_gel = 1.0 / (k0 * m2)
    _, res = _run("product", k0, dist, 0.8 * t_gel, nodes)
    c = res.columns
    t = c["time_s"]
    assert _rel(c["M00"], N0 - k0 * m1 ** 2 * t / 2) < TOL
    assert _rel(c["M20"], m2 / (1 - k0 * m2 * t)) < TOL


def test_product_kernel_past_gelation_is_refused():
    m2 = N0 * P0 ** 2
    k0 = 1.0e8
    scene = make_scene(scene={"end_time": 1.2 / (k0 * m2), "output_interval": 0.1 / (k0 * m2)},
                       aggregation={"kernel": "product", "rate": k0})
    # bad input known before the run (exit 2), SceneError naming end_time and t_gel
    with pytest.raises(SceneError, match="gels at t_gel"):
        run_well_mixed(scene)


@pytest.mark.parametrize("nodes", [2, 3])
def test_two_component_constant_kernel(nodes):
    k0 = 1.0e-10
    _, res = _run("constant", k0, "exponential", 10.0, nodes,
                  initial={"distribution": "exponential", "binder_fraction": 0.25})
    c = res.columns
    t = c["time_s"]
    m10, m01 = c["M10"][0], c["M01"][0]
    assert m01 == pytest.approx(0.25 * N0 * P0, rel=1e-12, abs=0)
    assert _rel(c["M00"], 2 * N0 / (2 + k0 * N0 * t)) < TOL
    assert _rel(c["M11"], c["M11"][0] + k0 * m10 * m01 * t) < TOL
    assert _rel(c["M20"], c["M20"][0] + k0 * m10 ** 2 * t) < TOL
    assert _rel(c["M01"], m01) < 1e-12
    # every granule has y = 0.25 and aggregation keeps it: the binder fraction stays exact
    assert np.max(np.abs(c["binder_fraction"] - 0.25)) < 1e-12


def test_injection_adds_mass_at_the_injected_rate():
    """Droplets as ordinary particles: M10 and M01 grow by rate p_d exactly."""
    rate, d = 1.0e8, 60e-6
    scene = make_scene(scene={"end_time": 100.0, "output_interval": 10.0},
                       aggregation={"kernel": "constant", "rate": 1e-11},
                       binder_injection={"rate": rate, "droplet_diameter": d})
    res = run_well_mixed(scene)
    c = res.columns
    pd = 1000.0 * math.pi / 6 * d ** 3
    t = c["time_s"]
    assert _rel(c["M10"], c["M10"][0] + rate * pd * t) < 1e-12
    assert _rel(c["M01"][1:], rate * pd * t[1:]) < 1e-12


def test_injection_with_separate_droplets_conserves_total_mass_rate():
    rate, d = 1.0e8, 60e-6
    scene = make_scene(scene={"end_time": 100.0, "output_interval": 10.0},
                       material={"accessible_binder_slope": 35.1,
                                 "accessible_binder_centre": 0.129},
                       initial={"droplet_number_density": 1e9},
                       aggregation={"kernel": "constant", "rate": 1e-11,
                                    "efficiency": ["geometric"], "droplet_factor": 100.0},
                       binder_injection={"rate": rate, "droplet_diameter": d})
    res = run_well_mixed(scene)
    c = res.columns
    pd = 1000.0 * math.pi / 6 * d ** 3
    t = c["time_s"]
    assert "droplet_number_density" in c
    assert _rel(c["M10"], c["M10"][0] + rate * pd * t) < 1e-12
    assert _rel(c["M01"], c["M01"][0] + rate * pd * t) < 1e-12
    # droplets are captured far faster than they arrive: their number falls from the start
    assert c["droplet_number_density"][1] < c["droplet_number_density"][0]


@pytest.mark.parametrize("kernel,rate", [("constant", 1e-10), ("sum", 1.0), ("eke", 1e-11)])
def test_stored_states_realizable_and_number_never_increases(kernel, rate):
    scene = make_scene(scene={"end_time": 5.0, "output_interval": 0.25},
                       initial={"binder_fraction": 0.1},
                       aggregation={"kernel": kernel, "rate": rate})
    res = run_well_mixed(scene)
    c = res.columns
    assert np.all(np.diff(c["M00"]) <= 0.0)
    arrays = pack(scene)
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    for r in range(len(c["time_s"])):
        state = np.array([c[n][r] / (n_ref * p_ref ** (int(n[1]) + int(n[2])))
                          if n in c else np.nan for n in arrays.state_names])
        if np.any(np.isnan(state)):
            continue     # moments beyond the output set are checked inside the integrator
        assert qmom_realizable(state, np.zeros(1), arrays.params, arrays.config,
                               np.zeros(WORK_SIZE))
    assert res.stats["accepted_steps"] > 0
