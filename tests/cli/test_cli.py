"""The command line: the default run, bundled scenes, plan, and clear errors on bad input."""
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pbe_cfd.cli import main
from pbe_cfd.io.output import read_columns_csv
from pbe_cfd.scene.scene import bundled_scenes, load_scene

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
    # the size-distribution columns come after the earlier ones (an additive contract)
    assert names[-7:] == ["d32_m", "d43_m", "binder_fraction", "d10_m", "d50_m", "d90_m", "span"]
    assert (out / "psd.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    psd = read_columns_csv(out / "psd.csv")
    assert list(psd) == ["time_s", "d_m", "Q3", "q3_per_ln_d", "binder_fraction"]
    labels = json.loads((out / "columns.json").read_text())
    assert labels["moments.csv"]["M02"].startswith("reconstructed")
    assert labels["moments.csv"]["M20"].startswith("carried")
    assert cols["time_s"][-1] == pytest.approx(600.0, rel=1e-12, abs=0)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "qmom"
    assert summary["wall_time_s"] > 0
    assert summary["stats"]["accepted_steps"] > 0
    png = (out / "moments.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    # seed scenario: mass grows at exactly the binder mass rate (1.485e8 droplets of 60 um)
    pd = 1000.0 * np.pi / 6 * (60e-6) ** 3
    t = cols["time_s"]
    assert np.allclose(cols["M10"], cols["M10"][0] + 1.485e8 * pd * t, rtol=1e-12, atol=0)


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


def test_plan_notes_qmoms_one_binder_value_where_the_efficiency_reads_it(capsys):
    """QMOM holds one binder value per size node: its plan says so where an efficiency factor
    reads the binder (seed-wurster: geometric x physical), not where none does
    (constant-kernel: no efficiency, no binder) and not for CQMOM, which carries a binder
    spread per size node."""
    note = "one binder value per size node, and the efficiency reads the binder"
    texts = {}
    for name in ("seed-wurster", "constant-kernel", "seed-wurster-cqmom"):
        assert main(["plan", name]) == 0
        texts[name] = capsys.readouterr().out
    assert note in texts["seed-wurster"]
    assert note not in texts["constant-kernel"]
    assert note not in texts["seed-wurster-cqmom"]


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
    assert main(["run", str(path), "--out", str(out)]) == 2   # bad input, refused before
    assert "gels at" in capsys.readouterr().err
    assert not out.exists()


def test_scenes_lists_bundled(capsys):
    assert main(["scenes"]) == 0
    assert "seed-wurster" in capsys.readouterr().out


def test_scenes_lists_every_effect_table_of_each_scene(capsys):
    """Each bundled scene's line names exactly the effect tables its TOML file has (read here
    with tomllib, not through the scene loader): drying and two-way coupling included."""
    import tomllib
    effect_tables = ("aggregation", "binder_injection", "breakage", "drying", "transport",
                     "coupling")
    assert main(["scenes"]) == 0
    lines = {ln.split()[0]: ln for ln in capsys.readouterr().out.splitlines() if ln.strip()}
    seen = set()
    for name, path in bundled_scenes().items():
        tables = tomllib.loads(path.read_text())
        listed = lines[name].split("effects: ")[1]
        named = set() if listed == "none" else set(listed.split(", "))
        assert named == {t for t in effect_tables if t in tables}, name
        seen |= named
    assert "drying" in seen


# ---------------------------------------------------------------------------- bad input
@pytest.fixture(scope="module")
def coupled_run(tmp_path_factory):
    """A 2 s coupled run of the bundled bed (outputs at 0, 1, 2 s)."""
    from test_data_safety import tiny_couple_text
    root = tmp_path_factory.mktemp("coupled")
    (root / "tiny-couple.toml").write_text(tiny_couple_text())
    assert main(["couple", str(root / "tiny-couple.toml"), "--out", str(root / "c")]) == 0
    return root / "c"


@pytest.mark.slow
def test_couple_leaves_no_drawing_process_behind(coupled_run):
    """The drawing processes live as long as the command: a caller that goes on (a test, a
    notebook) must not inherit them."""
    from pbe_cfd.viz import figure_pool
    assert (coupled_run / "png" / "bed_moments.png").stat().st_size > 0
    assert not figure_pool.drawing_elsewhere()


def test_render_draws_the_nearest_written_time_and_says_which(coupled_run, capsys):
    capsys.readouterr()
    assert main(["render", str(coupled_run), "--fields", "M00", "--times", "7"]) == 2
    err = capsys.readouterr().err                # t = 2 s was drawn by couple: --overwrite
    assert "t = 7 s is not an output time; drawing the nearest written one, t = 2 s" in err
    assert main(["render", str(coupled_run), "--fields", "M00", "--times", "0.6"]) == 0
    out, err = capsys.readouterr()
    assert "nearest written one, t = 1 s" in err
    assert out.strip().endswith("M00_t1s.png")
    assert (coupled_run / "png" / "M00_t1s.png").is_file()


@pytest.mark.parametrize("argv,phrase", [
    (["render", "{c}", "--fields", "nosuchfield"], "no field nosuchfield in"),
    (["render", "{c}", "--times", "nan"], "--times nan: expected a time in s"),
    (["render", "{c}/vtk/pbe_00000.vtu"], "no such directory"),
    (["compare", "{c}", "--out", "{tmp}/x.txt"], "expected a figure file ending in .png"),
    (["compare", "{c}/summary.json", "--out", "{tmp}/x.png"], "not a table of numbers"),
    (["compare", "{tmp}", "--out", "{tmp}/x.png"], "neither moments.csv"),
    (["couple", "--foam-fields", "--out", "{tmp}/o"], "a snapshot, which has no OpenFOAM case"),
])
def test_bad_command_input_is_one_line_exit_2(coupled_run, tmp_path, capsys, argv, phrase):
    argv = [a.format(c=coupled_run, tmp=tmp_path) for a in argv]
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("pbe-cfd: error: ") and len(err.strip().splitlines()) == 1, err
    assert phrase in err, err
    assert not (tmp_path / "o").exists() and not (tmp_path / "x.png").exists()


def test_case_run_into_a_non_empty_directory_is_refused(tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    assert main(["case", "run", "--dir", str(tmp_path / "mine")]) == 2
    err = capsys.readouterr().err
    assert "not written by pbe-cfd" in err and len(err.strip().splitlines()) == 1
    assert [p.name for p in (tmp_path / "mine").iterdir()] == ["notes.txt"]


@pytest.mark.slow
def test_compare_of_a_coupled_run_uses_its_bed_moments(coupled_run, tmp_path, capsys):
    assert main(["run", "--out", str(tmp_path / "r")]) == 0
    assert main(["compare", str(tmp_path / "r"), str(coupled_run),
                 "--out", str(tmp_path / "cmp.png")]) == 0
    assert (tmp_path / "cmp.png").read_bytes()[:4] == b"\x89PNG"


def test_compare_draws_the_cnmc_band_under_its_mean_and_a_deviation_panel():
    from matplotlib.collections import PolyCollection

    from pbe_cfd.viz.plotting import BAND_ALPHA, trajectories_figure
    t = np.linspace(0, 600, 61)
    mean = 3.3e10 * np.exp(-t / 800)
    cnmc = {"time_s": t, "M00": mean, "M00_lo": mean * 0.996, "M00_hi": mean * 1.004}
    qmom = {"time_s": t, "M00": mean * (1 + 0.05 * np.sin(t / 200))}
    fig = trajectories_figure([("cnmc", cnmc), ("qmom", qmom)], common_only=True)
    top, dev = fig.axes[0], fig.axes[1]
    (band,) = [c for c in top.collections if isinstance(c, PolyCollection)]
    assert band.get_alpha() == BAND_ALPHA
    mean_line = [ln for ln in top.get_lines() if ln.get_label() == "cnmc mean"][0]
    assert mean_line.get_zorder() > band.get_zorder()        # the mean is drawn on top
    # below: deviation from the cNMC mean in %, the band +-0.4 % around zero
    (dev_band,) = [c for c in dev.collections if isinstance(c, PolyCollection)]
    ys = dev_band.get_paths()[0].vertices[:, 1]
    assert np.nanmax(ys) == pytest.approx(0.4, rel=1e-12, abs=0) and np.nanmin(ys) == pytest.approx(-0.4, rel=1e-12, abs=0)
    (q,) = [ln for ln in dev.get_lines() if np.size(ln.get_xdata()) == t.size]
    np.testing.assert_allclose(q.get_ydata(), 5 * np.sin(t / 200), atol=1e-9)
    assert "%" in dev.get_ylabel()


def test_bench_failure_status_keeps_the_whole_reason():
    from pbe_cfd.bench import failure_status
    path = "/a/long/path/to/scenes/" + "x" * 200 + "/fluid-bed.toml"
    exc = RuntimeError(f"{path}: cell 12 (alpha 0.5) stopped at t = 1 s:\n  the population "
                       "left the support; 3 cell(s) affected")
    text = failure_status(exc)
    assert text.startswith("failed: " + path) and text.endswith("3 cell(s) affected")
    assert "\n" not in text and "left the support" in text


# ---------------------------------------------------------------------------- first run
@pytest.mark.slow
def test_the_compile_is_said_while_it_runs_and_reported_apart(tmp_path, capsys, monkeypatch):
    """A slow kernel compile (a first run) is announced while it runs, and its time is kept
    out of the run time in the printed summary and in summary.json."""
    import time

    from pbe_cfd.runs import simulate
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.util.progress import COMPILING
    original = CellBatch.compile
    clock = {"offset": 0.0}                   # the run's clock; a compile moves it 1000 s on

    class Clock:
        @staticmethod
        def perf_counter():
            return time.perf_counter() + clock["offset"]

    def slow_compile(self):
        seconds = original(self)
        time.sleep(0.8)                       # long enough to be announced
        clock["offset"] += 1000.0             # stands in for numba compiling for 1000 s
        self.compiled_now = True
        return seconds + 0.8 + 1000.0

    monkeypatch.setattr(CellBatch, "compile", slow_compile)
    monkeypatch.setattr(simulate, "_time", Clock)
    monkeypatch.setattr("pbe_cfd.util.progress.NOTICE_AFTER_S", 0.3)
    path = tmp_path / "tiny.toml"
    path.write_text(GOOD)
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert COMPILING in err                   # said while compiling (stderr: not a terminal)
    assert "s compiling kernels, first run only" in out
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["compile_time_s"] >= 1000.0 and summary["kernels_compiled"] is True
    assert summary["wall_time_s"] < 100.0     # the run alone, without the compile


def test_the_compile_notice_names_the_kernel_and_the_last_compile_here(tmp_path, monkeypatch):
    """The notice of a compile names the kernel (method and integrator) and says roughly how
    long it takes: the figure measured for a first compile where this machine has none on
    record, else the CPU time of the last compile here, which a compile records."""
    import time

    from pbe_cfd.methods.registry import method_of
    from pbe_cfd.runs import model
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.util import progress
    monkeypatch.setenv("PBE_CFD_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "tiny.toml"
    path.write_text(GOOD)
    scene = load_scene(path)
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    batch = CellBatch.for_scene(scene, arrays, aux, model.well_mixed_cell(scene),
                                state[None, :].copy())
    name = batch.kernel_name()
    assert name == f"the {scene.method.name} kernel with the {scene.method.integrator} integrator"
    assert progress.compile_text(name) == (f"{progress.COMPILING}: {name}, "
                                           f"{progress.FIRST_COMPILE_HINT}")
    said = []

    clock = {"cpu": 100.0}

    class Clock:                               # the batch's clock: CPU seconds
        perf_counter = staticmethod(time.perf_counter)

        @staticmethod
        def process_time():
            return clock["cpu"]

    def compiled(self):
        self.compiled_now = True               # numba compiling for 42.4 s of CPU, in
        clock["cpu"] += 42.4                   # 1000 s of wall time on a loaded machine
        return 1000.0

    monkeypatch.setattr(CellBatch, "compile", compiled)
    monkeypatch.setattr("pbe_cfd.runs.batch._time", Clock)
    monkeypatch.setattr("pbe_cfd.util.progress.NOTICE_AFTER_S", 1e-3)
    progress_calls = type("P", (), {"notice": lambda self, text: said.append(text)})()
    assert batch.compile_announced(progress_calls, extra=lambda: (time.sleep(0.05), 0.0)[1]) \
        == pytest.approx(1000.0, abs=1e-12)
    assert said == [f"{progress.COMPILING}: {name}, {progress.FIRST_COMPILE_HINT}"]
    assert progress.compile_text(name) == (f"{progress.COMPILING}: {name}, about 42 s of "
                                           "CPU time (the last compile on this machine)")


def test_a_warm_run_says_nothing_and_compile_leaves_nothing_to_compile(tmp_path, capsys):
    """After ``CellBatch.compile`` the run itself compiles nothing (so the run time holds no
    compile), and a run whose kernels are cached is not announced as compiling."""
    from pbe_cfd import integrate
    from pbe_cfd.runs import model
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.methods.registry import method_of
    from pbe_cfd.util.progress import COMPILING
    path = tmp_path / "tiny.toml"
    path.write_text(GOOD)
    scene = load_scene(path)
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    batch = CellBatch.for_scene(scene, arrays, aux, model.well_mixed_cell(scene),
                                state[None, :].copy())
    batch.compile()
    before = dict(integrate.integrate_cells_kernel.overloads)
    batch.step(0.0, 1.0)
    assert dict(integrate.integrate_cells_kernel.overloads) == before
    assert batch.stats()["accepted_steps"] > 0
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert COMPILING not in err and "first run only" not in out
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["kernels_compiled"] is False and summary["compile_time_s"] < 0.5


def test_coupled_summary_keeps_compile_and_run_apart(coupled_run):
    summary = json.loads((coupled_run / "summary.json").read_text())
    assert summary["compile_time_s"] >= 0 and isinstance(summary["kernels_compiled"], bool)
    st = summary["stats"]
    assert st["cell_steps_per_second"] == pytest.approx(st["accepted_steps"]
                                                         / summary["wall_time_s"], rel=1e-12, abs=0)


def test_a_library_warning_of_a_run_is_one_line_and_kept_in_the_summary(tmp_path, capsys,
                                                                         monkeypatch):
    """A Python warning raised inside a well-mixed run (numpy, scipy, meshio ...) is printed
    as one ``warning:`` line and listed in summary.json, never as a raw warning with its
    source line."""
    from pbe_cfd.runs import simulate
    real = simulate.run_well_mixed

    def warning_run(scene, **kwargs):
        import warnings
        warnings.warn("a library's first line\nits second line", UserWarning)
        return real(scene, **kwargs)

    monkeypatch.setattr(simulate, "run_well_mixed", warning_run)
    scene = tmp_path / "tiny.toml"
    scene.write_text(GOOD)
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert err.count("warning: a library's first line") == 1
    assert "UserWarning" not in err and "its second line" not in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert "a library's first line" in summary["warnings"]



def test_every_bed_column_says_what_it_is(coupled_run):
    """columns.json gives every bed_moments.csv column a meaning after its prefix (the bed
    totals bed_mass_kg, bed_binder_mass_kg included), never a bare "bed (...): "."""
    labels = json.loads((coupled_run / "columns.json").read_text())["bed_moments.csv"]
    for name, text in labels.items():
        assert text.split(": ", 1)[-1].strip(), (name, text)
    assert "sum over the cells of M10 times the cell volume" in labels["bed_mass_kg"]


def test_a_cnmc_replica_that_stops_is_one_line_exit_1(tmp_path, monkeypatch, capsys):
    """A cNMC replica that cannot finish (here its box reports a rate above its majorant)
    ends the run with exit 1 and one line naming the scene, the replica and why, no
    traceback and no output."""
    from pbe_cfd.methods.cnmc import ensemble
    real = ensemble.run_box_with_sizes

    def one_violation(*args):
        out = real(*args)
        return (out[0], out[1], out[2], 1) + tuple(out[4:])
    monkeypatch.setattr(ensemble, "run_box_with_sizes", one_violation)
    scene = tmp_path / "tiny.toml"
    text = GOOD.replace('name = "qmom"\nnodes = 2', 'name = "cnmc"\nparticles = 50\nreplicas = 2')
    assert "cnmc" in text
    scene.write_text(text)
    code = main(["run", str(scene), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and "tiny.toml" in err[0] and "cNMC replica 0" in err[0]
    assert "majorant" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "out").exists()
