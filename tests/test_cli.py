"""The command line: the default run, bundled scenes, plan, and clear errors on bad input."""
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pbe_cfd.cli import main
from pbe_cfd.output import read_columns_csv
from pbe_cfd.scene import bundled_scenes, load_scene

GOOD = textwrap.dedent("""
    [scene]
    name = "tiny"
    end_time = 2.0
    output_interval = 1.0
    [domain]
    type = "well-mixed"
    solids_fraction = 0.3
    [material]
    density = 1000.0
    [initial]
    distribution = "monodisperse"
    number_density = 1e10
    mean_mass = 1e-9
    [aggregation]
    kernel = "constant"
    rate = 1e-11
    [method]
    name = "qmom"
    nodes = 2
""")


def test_default_run_writes_the_contract(tmp_path):
    out = tmp_path / "out"
    assert main(["run", "--out", str(out)]) == 0
    cols = read_columns_csv(out / "moments.csv")
    names = list(cols)
    assert names[0] == "time_s"
    for required in ("M00", "M10", "M01", "M20", "M11", "M02", "droplet_number_density",
                     "d32_m", "d43_m", "binder_fraction"):
        assert required in names
    assert names[-3:] == ["d32_m", "d43_m", "binder_fraction"]
    assert cols["time_s"][-1] == pytest.approx(600.0)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "qmom"
    assert summary["wall_time_s"] > 0
    assert summary["stats"]["accepted_steps"] > 0
    png = (out / "moments.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    # seed scenario: mass grows at exactly the binder mass rate (1.485e8 droplets of 60 um)
    pd = 1000.0 * np.pi / 6 * (60e-6) ** 3
    t = cols["time_s"]
    assert np.allclose(cols["M10"], cols["M10"][0] + 1.485e8 * pd * t, rtol=1e-12)


def test_every_bundled_scene_validates():
    scenes = bundled_scenes()
    assert "seed-wurster" in scenes
    for name, path in scenes.items():
        scene = load_scene(path)
        assert scene.end_time > 0


def test_plan_lists_computed_and_left_out(capsys):
    assert main(["plan", "seed-wurster"]) == 0
    text = capsys.readouterr().out
    assert "kernel eke" in text and "geometric x physical" in text
    assert "droplets: a population of their own" in text
    assert "QMOM with 2 nodes" in text


def test_plan_of_a_dry_scene_leaves_out_binder(tmp_path, capsys):
    path = tmp_path / "tiny.toml"
    path.write_text(GOOD)
    assert main(["plan", str(path)]) == 0
    text = capsys.readouterr().out
    assert "p (granule mass) only" in text
    assert "binder injection (no [binder_injection] table)" in text
    assert "M01" not in text


BAD = {
    "missing key": (GOOD.replace("end_time = 2.0\n", ""), "scene.end_time", "missing"),
    "unknown key": (GOOD.replace("nodes = 2", "nodes = 2\nnode_count = 3"), "method.node_count",
                    "unknown key"),
    "negative rate": (GOOD.replace("rate = 1e-11", "rate = -1e-11"), "aggregation.rate",
                      "positive"),
    "alpha above max": (GOOD.replace("solids_fraction = 0.3", "solids_fraction = 0.7"),
                        "domain.solids_fraction", "below alpha_max"),
    "not toml": ("this is [not toml", None, "not a valid TOML"),
    "binder needed": (GOOD.replace('rate = 1e-11', 'rate = 1e-11\nefficiency = ["geometric"]')
                      .replace("density = 1000.0", "density = 1000.0\naccessible_binder_slope = 35.1\n"
                               "accessible_binder_centre = 0.129"),
                      "aggregation.efficiency", "depends on binder"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_clear_message_and_no_output(case, tmp_path, capsys):
    text, key, phrase = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert str(path) in err and phrase in err
    if key:
        assert f"[{key}]" in err
    assert not out.exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_console_script_exit_code_for_missing_file(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "run",
                           str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "no such file" in proc.stderr


def test_failed_run_leaves_no_partial_directory(tmp_path, capsys):
    text = GOOD.replace('kernel = "constant"', 'kernel = "product"').replace(
        "rate = 1e-11", "rate = 1e9")       # gels at t = 1/(k0 M2) = 0.1 s < 2 s
    path = tmp_path / "gel.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 1
    assert "gels at" in capsys.readouterr().err
    assert not out.exists()


def test_scenes_lists_bundled(capsys):
    assert main(["scenes"]) == 0
    assert "seed-wurster" in capsys.readouterr().out
