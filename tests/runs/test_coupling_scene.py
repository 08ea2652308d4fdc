"""Two-way coupling without OpenFOAM runs: the [coupling] table, the segment schedule, the
carry-over of the bed's population, Wen & Yu's U_mf against an independent solution, the
defluidisation warning, and the exit codes of `couple`."""
import dataclasses
import tomllib
from importlib import resources
from types import SimpleNamespace

import numpy as np
import pytest

from pbe_cfd import cli
from pbe_cfd.physics.fluidisation import minimum_fluidisation_velocity
from pbe_cfd.runs.coupling import (_ends_here, _nears_umf, carry_over, check_times,
                                    two_way_plan)
from pbe_cfd.runs.coupling_output import defluidisation_warnings, umf_of
from pbe_cfd.scene.scene import SceneError, scene_from_dict
from references import wen_yu

AIR = {"gas_density": 1.1586, "gas_viscosity": 1.84e-5}     # the bundled case at 300 K, 1 bar


def transport_data(**coupling):
    text = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-transport.toml").read_text()
    data = tomllib.loads(text)
    if coupling is not None:
        data["coupling"] = coupling
    return data


def test_absent_coupling_is_one_way():
    data = transport_data()
    data.pop("coupling")
    assert scene_from_dict(data, "s.toml").coupling is None


@pytest.mark.parametrize("table, key", [
    ({"interval": 60.0}, "coupling.flow_time"),
    ({"flow_time": 0.5}, "coupling"),
    ({"flow_time": 0.5, "interval": 60.0, "average_from": 0.5}, "coupling.average_from"),
    ({"flow_time": 0.5, "interval": -1.0}, "coupling.interval"),
    ({"flow_time": 0.5, "interval": 60.0, "mesh": "huge"}, "coupling.mesh"),
    ({"flow_time": 0.5, "interval": 60.0, "every": 3}, "coupling.every"),
    ({"flow_time": 0.5, "interval": 60.0, "warn_fraction": 1.5}, "coupling.warn_fraction"),
])
def test_bad_coupling_tables_name_the_key(table, key):
    with pytest.raises(SceneError) as err:
        scene_from_dict(transport_data(**table), "s.toml")
    assert f"[{key}]" in str(err.value)


def test_a_snapshot_cannot_be_continued():
    data = transport_data(flow_time=0.5, interval=60.0)
    data["domain"]["case"] = "bed.vtu"
    with pytest.raises(SceneError, match=r"\[domain.case\].*snapshot"):
        scene_from_dict(data, "s.toml")


def test_the_schedule():
    """A segment ends at the interval, at the relative d32 change, or at the end time."""
    c = scene_from_dict(transport_data(flow_time=0.5, interval=60.0, d32_change=0.1),
                        "s.toml").coupling
    d = 1e-4
    assert not _ends_here(c, 120.0, 175.0, 1.09 * d, d, 600.0)
    assert _ends_here(c, 120.0, 180.0, 1.0 * d, d, 600.0)          # 60 s passed
    assert _ends_here(c, 120.0, 125.0, 1.1 * d, d, 600.0)          # d32 moved by 10%
    assert _ends_here(c, 120.0, 125.0, 0.9 * d, d, 600.0)
    assert _ends_here(c, 590.0, 600.0, d, d, 600.0)                # the end
    only_d = dataclasses.replace(c, interval=None)
    assert not _ends_here(only_d, 0.0, 1e4, 1.05 * d, d, 1e5)


def test_carry_over_conserves_the_bed_and_follows_alpha():
    rng = np.random.default_rng(3)
    states = rng.uniform(0.1, 1.0, (40, 6))
    vol = rng.uniform(1e-6, 2e-6, 40)
    alpha = rng.uniform(0.05, 0.6, 55)
    vol_new = rng.uniform(1e-6, 2e-6, 55)
    new = carry_over(states, vol, alpha, vol_new)
    assert np.allclose(np.sum(new * vol_new[:, None], axis=0),
                       np.sum(states * vol[:, None], axis=0), rtol=1e-13, atol=0.0)
    ratio = new / alpha[:, None]
    assert np.allclose(ratio, ratio[0], rtol=1e-13, atol=0.0)     # the same population per
                                                                 # m3 of solids everywhere


@pytest.mark.parametrize("d", [50e-6, 100.4e-6, 300e-6, 1e-3, 3e-3])
def test_wen_yu_against_the_ergun_quadratic(d):
    """The closed form against the quadratic Wen & Yu solved; their constants' rounding makes
    the closed form at most 1.19e-3 lower (tests/references/wen_yu.py)."""
    ours = minimum_fluidisation_velocity(d, 1021.0, AIR["gas_density"], AIR["gas_viscosity"])
    ref = wen_yu.u_mf(d, 1021.0, AIR["gas_density"], AIR["gas_viscosity"])
    assert ref * (1 - 1.2e-3) <= ours <= ref


def test_the_bundled_powder_is_well_fluidised():
    """100.4 um Avicel: U_mf about 3.3 mm/s, so 0.08 m/s is about 24 U_mf (the case's README)."""
    umf = minimum_fluidisation_velocity(100.4e-6, 1021.0, AIR["gas_density"],
                                        AIR["gas_viscosity"])
    assert 0.08 / umf == pytest.approx(24.0, abs=1.0)


def _fake_run(scene, diameters, d_end, u_in):
    segs = [SimpleNamespace(index=k, t_start=120.0 * k, t_end=120.0 * (k + 1), diameter=d,
                            d32_end=(diameters[k + 1] if k + 1 < len(diameters) else d_end))
            for k, d in enumerate(diameters)]
    return SimpleNamespace(segments=segs, fluidisation={**AIR, "inlet_velocity": u_in},
                           plan=two_way_plan(scene))


def test_defluidisation_warns_before_the_bed_collapses():
    """Granules growing 100 -> 600 um under an inlet lowered to 0.03 m/s: the first warning
    comes at the first segment whose U_mf reaches warn_fraction x U_in, while U_mf is still
    below U_in (the bed still bubbles); later ones say it is defluidised."""
    scene = scene_from_dict(transport_data(flow_time=0.5, interval=120.0), "s.toml")
    u_in = 0.03
    diameters = [100e-6, 200e-6, 300e-6, 400e-6, 500e-6]
    run = _fake_run(scene, diameters, 600e-6, u_in)
    ref = [wen_yu.u_mf(d, 1021.0, AIR["gas_density"], AIR["gas_viscosity"]) for d in diameters]
    first = next(k for k, u in enumerate(ref) if u >= 0.8 * u_in)
    assert ref[first] < u_in                     # the case warns before collapse
    warnings = defluidisation_warnings(run)
    assert warnings, "no defluidisation warning"
    assert f"at t = {120 * first:g} s" in warnings[0] and "stops bubbling" in warnings[0]
    assert not any(f"at t = {120 * k:g} s" in w for w in warnings for k in range(first))
    assert any("is defluidised" in w for w in warnings)
    assert ref[0] * (1 - 1.2e-3) <= umf_of(run.plan, run.fluidisation, 1e-4) <= ref[0]
    # the bundled inlet (0.08 m/s) and the same granules: no warning below 0.8 x 0.08 m/s
    calm = _fake_run(scene, diameters[:2], 200e-6, 0.08)
    assert defluidisation_warnings(calm) == []


def test_check_times_split_an_output_interval_evenly():
    assert check_times(30.0, 60.0, None) == [60.0]
    assert check_times(30.0, 60.0, 30.0) == [60.0]
    assert check_times(30.0, 60.0, 7.0) == pytest.approx([36.0, 42.0, 48.0, 54.0, 60.0],
                                                         rel=0, abs=1e-12)
    assert check_times(30.0, 60.0, 7.0)[-1] == 60.0       # the output time itself, exactly
    with pytest.raises(SceneError, match=r"\[coupling.check_interval\]"):
        scene_from_dict(transport_data(flow_time=0.5, interval=60.0, check_interval=0.0),
                        "s.toml")


def test_a_segment_ends_where_u_mf_first_nears_the_inlet_velocity():
    """The segment ends (and the CFD re-runs) at the first check where the granules' U_mf
    reaches warn_fraction x U_in, computed from the independent Wen & Yu solution; once the
    CFD's own diameter is past it, the threshold no longer ends segments."""
    scene = scene_from_dict(transport_data(flow_time=0.5, interval=120.0), "s.toml")
    u_in = 0.04
    fluid = {**AIR, "inlet_velocity": u_in}
    ds = np.linspace(100e-6, 600e-6, 501)
    u = np.array([wen_yu.u_mf(d, 1021.0, AIR["gas_density"], AIR["gas_viscosity"])
                  for d in ds])
    k = int(np.argmax(u >= 0.8 * u_in))             # the first diameter past the threshold
    assert 0 < k < ds.size - 1
    d_cfd = 150e-6
    plan = two_way_plan(scene)
    # Wen & Yu of the project and of the reference agree to 1.2e-3 (test above): skip the
    # diameters within that band of the threshold
    below = ds[:k][u[:k] < 0.8 * u_in * (1 - 2.4e-3)]
    above = ds[k:][u[k:] > 0.8 * u_in * (1 + 2.4e-3)]
    assert not any(_nears_umf(plan, fluid, d_cfd, d) for d in below)
    assert all(_nears_umf(plan, fluid, d_cfd, d) for d in above)
    assert not any(_nears_umf(plan, fluid, above[0], d) for d in above)
    assert not _nears_umf(plan, {**AIR, "inlet_velocity": None}, d_cfd, 600e-6)
    c = scene.coupling
    assert _ends_here(c, 0.0, 10.0, d_cfd, d_cfd, 600.0, nears_umf=True)


def test_without_openfoam_couple_exits_2(tmp_path, monkeypatch, capsys):
    path = tmp_path / "s.toml"
    text = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-transport.toml").read_text()
    path.write_text(text + "\n[coupling]\ninterval = 60.0\nflow_time = 0.5\n")
    monkeypatch.setenv("PATH", str(tmp_path))
    code = cli.main(["couple", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "needs OpenFOAM" in err and "not found on PATH" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.coupling").exists()
