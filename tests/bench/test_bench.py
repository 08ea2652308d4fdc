"""Benchmark plumbing (pbe_cfd.bench) on tiny configurations: files written, every method
present, errors finite, the analytic reference used where the scene has one, the NumPy/SciPy
baseline computing the same right-hand side. Timings are measured, never asserted."""
import csv
import math

import numpy as np
import pytest

from pbe_cfd import bench, cli
from pbe_cfd.methods.dispatch import WORK_SIZE
from pbe_cfd.methods.qmom.qmom import qmom_rhs
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.runs.simulate import run_well_mixed


def _csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_analytic_moments_solve_the_closed_moment_equations():
    scene = load_scene("study-analytic")
    t = np.linspace(0.0, scene.end_time, 201)
    ref = bench.analytic_moments(scene, t)
    k0 = scene.aggregation.rate
    rate = scene.binder_injection.rate
    pd = bench.model.droplet_mass(scene.binder_injection.droplet_diameter,
                                  scene.material.binder_density)
    from scipy.integrate import solve_ivp

    def rhs(_t, m):      # M00, M10, M01, M20, M11, M02
        return [rate - 0.5 * k0 * m[0] ** 2, rate * pd, rate * pd,
                k0 * m[1] ** 2 + rate * pd * pd, k0 * m[1] * m[2] + rate * pd * pd,
                k0 * m[2] ** 2 + rate * pd * pd]

    names = ("M00", "M10", "M01", "M20", "M11", "M02")
    y0 = [ref[n][0] for n in names]
    scale = np.array([max(abs(ref[n]).max(), 1e-300) for n in names])
    sol = solve_ivp(rhs, (0.0, scene.end_time), y0, t_eval=t, method="DOP853", rtol=1e-12,
                    atol=1e-14 * scale)
    for k, name in enumerate(names):
        assert np.max(np.abs(sol.y[k] - ref[name]) / scale[k]) < 1e-9, name
    # the d43 lattice reproduces the closed-form number density
    lat = bench.smoluchowski_d43(scene, t[::50])
    assert lat is not None
    assert np.max(np.abs(lat["M00"] - ref["M00"][::50]) / ref["M00"][::50]) < 1e-8
    assert lat["lost_mass_share"] < 1e-8
    assert np.all(np.diff(lat["d43_m"]) > 0)


def test_lattice_median_is_the_closed_form_median_of_constant_aggregation(tmp_path):
    """Without injection the constant kernel from monodisperse granules p0 has the closed form
    c_k = N0 (tau/2)^(k-1) / (1 + tau/2)^(k+1), tau = k0 N0 t (Smoluchowski 1916): the mass
    median is the first k whose cumulative mass share sum_(i<=k) i c_i / N0 reaches 1/2."""
    text = (bench.analytic.__file__.rsplit("/", 2)[0] + "/scenes/study-analytic.toml")
    toml = open(text).read()
    head, rest = toml.split("[binder_injection]")
    toml = head + rest[rest.index("[method]"):]
    path = tmp_path / "no-injection.toml"
    path.write_text(toml)
    scene = load_scene(str(path))
    assert scene.binder_injection is None
    times = np.array([1.0, 4.0, 10.0])
    lat = bench.smoluchowski_d43(scene, times)
    n0, k0, p0 = (scene.initial.number_density, scene.aggregation.rate,
                  scene.initial.mean_mass)
    for t, d50 in zip(times, lat["d50_m"]):
        half = 0.5 * k0 * n0 * t
        k, share = 0, 0.0
        while share < 0.5:
            k += 1
            share += k * half ** (k - 1) / (1.0 + half) ** (k + 1)
        want = (6.0 * k * p0 / (math.pi * scene.material.density)) ** (1.0 / 3.0)
        assert d50 == pytest.approx(want, rel=1e-12, abs=0.0), (t, k)
    assert lat["d50_m"][-1] > lat["d50_m"][0]


@pytest.mark.slow
def test_accuracy_quick_uses_the_analytic_reference_and_writes_everything(tmp_path, capsys):
    out = tmp_path / "acc"
    code = cli.main(["bench", "accuracy", "study-analytic", "--out", str(out), "--quick"])
    assert code == 0
    for name in ("accuracy.csv", "accuracy.md", "pareto.png", "accuracy.json"):
        assert (out / name).stat().st_size > 0, name
    rows = _csv(out / "accuracy.csv")
    assert {r["method"] for r in rows} == {"qmom", "cqmom", "eqmom", "laguerre", "cnmc"}
    md = (out / "accuracy.md").read_text()
    assert "closed-form moments" in md and "Smoluchowski" in md
    for r in rows:
        # a variant that cannot run is a row saying why (the study is about every method)
        if r["status"] != "ok":
            assert r["status"].startswith("failed: ") and len(r["status"]) > 10
            continue
        for q in bench.QUANTITIES:
            # the closed-form reference gives the moments, the Smoluchowski lattice d43 and d50
            assert math.isfinite(float(r[f"err_{q}"])), (r["method"], r["knob"], q)
        assert float(r["wall_s_median"]) > 0
    assert {r["method"] for r in rows if r["status"] == "ok"} >= {"qmom", "cnmc"}
    # the closure is exact for the constant kernel: QMOM's number and M20 are right to the
    # integrator's tolerance, which a Monte Carlo or an approximate reference could not show
    for r in rows:
        if r["method"] == "qmom" and r["knob"] in ("N=2", "N=3"):
            assert abs(float(r["err_M00"])) < 1e-6
            assert abs(float(r["err_M20"])) < 1e-6
        if r["method"] == "cqmom":          # and CQMOM's every carried moment
            for q in ("M00", "M20", "M11", "M02"):
                assert abs(float(r[f"err_{q}"])) < 1e-6, q
    assert "qmom" in capsys.readouterr().out


@pytest.mark.slow
def test_accuracy_with_a_cnmc_reference_states_its_band(tmp_path):
    variants = [bench.Variant("qmom", "N=2", {"name": "qmom", "nodes": 2}),
                bench.Variant("laguerre", "m=2 coarse consistent",
                              {"name": "laguerre", "order": 2, "consistent": True,
                               "grid_mass": 8, "grid_binder": 8}),
                bench.Variant("cnmc", "300 x 2", {"name": "cnmc", "particles": 300,
                                                  "replicas": 2, "seed": 3})]
    res = bench.accuracy_study("study-seed", tmp_path / "seed", quick=True, repeats=1,
                               variants=variants, reference=(2000, 3), quiet=True)
    assert res["reference"]["kind"] == "cnmc"
    assert set(res["reference"]["band"]) == set(bench.QUANTITIES)
    assert all(math.isfinite(b) for b in res["reference"]["band"].values())
    assert [r["method"] for r in res["rows"]] == ["qmom", "laguerre", "cnmc"]
    for r in res["rows"]:
        assert (r["status"] == "ok" and math.isfinite(r["max_abs_error"])) or (
            r["method"] == "laguerre" and r["status"].startswith("failed: ")), r
    md = (tmp_path / "seed" / "accuracy.md").read_text()
    assert "95% band" in md and "cNMC ensemble of 2000 particles x 3 replicas" in md


def test_a_failing_variant_is_reported_not_fatal(tmp_path):
    bad = bench.Variant("qmom", "N=2 unknown option", {"name": "qmom", "nodes": 2, "no": 1})
    res = bench.accuracy_study("study-analytic", tmp_path / "bad", quick=True, repeats=0,
                               variants=[bad], quiet=True)
    assert res["rows"][0]["status"].startswith("failed")
    assert "failed" in (tmp_path / "bad" / "accuracy.md").read_text()


def test_pareto_front():
    pts = [(1.0, 0.5), (2.0, 0.1), (3.0, 0.2), (0.5, 0.9), (2.0, 0.05)]
    assert sorted(bench.pareto_front(pts)) == [0, 3, 4]


@pytest.mark.parametrize("nodes", [2, 3])
def test_numpy_baseline_computes_the_same_rhs(nodes):
    case = bench.throughput_case("qmom", nodes)
    base = bench.NumpyQMOM(case.arrays.params, case.arrays.config)
    cells = bench.synthetic_cells(20, seed=5)
    states = bench.cell_states(case.trajectory, 20, seed=6)
    work = np.empty(WORK_SIZE)
    for i in range(20):
        expected = np.zeros(states.shape[1])
        qmom_rhs(states[i], expected, cells[i], case.aux, case.arrays.params,
                 case.arrays.config, work)
        got = base.rhs(0.0, states[i], cells[i])
        scale = 1e-12 * np.max(np.abs(expected))
        assert np.max(np.abs(got - expected) / np.maximum(np.abs(expected), scale)) < 1e-8


@pytest.mark.slow
def test_throughput_tiny(tmp_path):
    res = bench.throughput_study(tmp_path / "tp", quick=True, cells=(40, 80), threads=(1,),
                                 methods=(("qmom", 2), ("laguerre", 2), ("qmom", 3),
                                          ("cqmom", (2, 2))), interval=0.05, quiet=True)
    for name in ("throughput.csv", "throughput.md", "throughput.png", "machine.json"):
        assert (tmp_path / "tp" / name).stat().st_size > 0, name
    labels = {r["label"] for r in res["rows"]}
    assert labels == {"QMOM N = 2", "Laguerre m = 2", "QMOM N = 3", "CQMOM N1 x N2 = 2 x 2"}
    for r in res["rows"]:
        for key in ("rhs_per_s", "cell_steps_per_s", "ceiling_per_s", "share_of_ceiling"):
            assert math.isfinite(r[key]) and r[key] > 0, (r["label"], key)
        assert r["failed_cells"] == 0
    base = res["baseline"]
    assert base["rhs_per_s"] > 0 and base["cell_steps_per_s"] > 0
    md = (tmp_path / "tp" / "throughput.md").read_text()
    assert "NumPy/SciPy" in md and "speed-up" in md
    assert "CQMOM against QMOM N = 3" in md
    # a breakdown per QMOM and Laguerre method, its parts timed (finite, not negative)
    assert [b["label"] for b in res["breakdown"]] == ["QMOM N = 2", "Laguerre m = 2",
                                                      "QMOM N = 3"]
    for b in res["breakdown"]:
        parts = b["parts"]
        assert all(ns >= 0 and math.isfinite(ns) for ns in parts.values()), b
        assert "pair rates" in parts if b["label"].startswith("QMOM") else len(parts) >= 2
        assert b["full_ns"] > 0 and f"*{b['label']}*" in md
    rows = _csv(tmp_path / "tp" / "throughput.csv")
    assert rows[-1]["method"] == "numpy-scipy-qmom"


@pytest.mark.slow
def test_cnmc_laguerre_couple_studies_write_their_tables(tmp_path):
    out = tmp_path / "misc"
    bench.cnmc_study(out, quick=True, quiet=True)
    bench.laguerre_study(out, quick=True, quiet=True)
    bench.couple_study(out, quick=True, quiet=True)
    for name in ("cnmc", "laguerre", "couple"):
        rows = _csv(out / f"{name}.csv")
        assert rows, name
        assert (out / f"{name}.md").read_text().count("|") > 10
    for r in _csv(out / "couple.csv"):
        assert float(r["cell_steps_per_s"]) > 0


def test_replicated_domain_runs_like_the_original():
    from pbe_cfd.runs.domain import load_domain
    scene = load_scene("fluid-bed")
    dom = load_domain(scene)
    big = bench.replicated_domain(dom, 3)
    assert len(big.cells.alpha) == 3 * len(dom.cells.alpha)
    assert np.array_equal(big.cells.theta[len(dom.cells.alpha):2 * len(dom.cells.alpha)],
                          dom.cells.theta)


def test_study_scenes_are_bundled_and_run():
    for name in ("study-analytic", "study-seed", "study-ktgf"):
        scene = load_scene(name)
        assert scene.domain.type == "well-mixed"
    assert bench.analytic_applicable(load_scene("study-analytic"))
    assert not bench.analytic_applicable(load_scene("study-seed"))
    ktgf = load_scene("study-ktgf")
    assert ktgf.aggregation.kernel == "ktgf"
    assert set(ktgf.aggregation.efficiency) == {"geometric", "physical"}
    res = run_well_mixed(ktgf.with_method(name="qmom", nodes=2))
    assert np.all(np.isfinite(res.columns["M00"]))


def test_bench_method_and_count_lists_are_checked():
    from pbe_cfd.cli_bench import int_list as _int_list, method_list as _method_list
    assert _method_list("qmom:3, laguerre:2,cqmom:3x2") == (("qmom", 3), ("laguerre", 2),
                                                            ("cqmom", (3, 2)))
    assert _int_list("1,2") == (1, 2)
    import argparse
    for bad in ("qmom", "fancy:3", "cqmom:3", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            _method_list(bad)
    for bad in ("0", "a,b", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            _int_list(bad)
