"""Resource limits and exit codes known before a run: the number of output times, the Laguerre
ROM's table memory against the machine, --threads within the cores, tolerances that keep the
error control, the product kernel past its gel time; each refused in one line (exit 2) that
names the key and the limit, by `plan` as well as by the runs."""
import dataclasses
import math

import pytest

from pbe_cfd.scene import limits
from pbe_cfd.runs.batch import output_times
from pbe_cfd.cli import main
from pbe_cfd.scene.limits import MAX_OUTPUT_TIMES, output_count
from pbe_cfd.methods.laguerre import tensor as laguerre_tensor
from pbe_cfd.scene.scene import SceneError, load_scene

from conftest import make_scene
from test_data_safety import TINY_RUN

TINY = TINY_RUN           # the smallest well-mixed run (test_data_safety)


def one_line_refusal(capsys, *keys):
    """The command's stderr is one line naming every one of ``keys``, no traceback."""
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    for key in keys:
        assert key in err, (key, err)
    return err


def write(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


# ------------------------------------------------------------------ output times
@pytest.mark.parametrize("verb", ["plan", "run"])
def test_a_billion_output_times_are_refused_before_anything(tmp_path, capsys, verb):
    """output_interval = 1e-9 s over end_time = 20 s asks for 2e10 output times (listing them
    took 23 GB and 190 s before the kernel killed the run): refused from the two numbers."""
    path = write(tmp_path, TINY.replace("end_time = 2.0", "end_time = 20.0")
                 .replace("output_interval = 1.0", "output_interval = 1e-9"))
    argv = [verb, path] + (["--out", str(tmp_path / "o")] if verb == "run" else [])
    assert main(argv) == 2
    err = one_line_refusal(capsys, "scene.output_interval", str(MAX_OUTPUT_TIMES["well-mixed"]))
    assert "2e+10" in err
    assert not (tmp_path / "o").exists()


def test_the_output_limit_is_per_domain_and_inclusive():
    """At the limit a scene loads (and its count is what output_times lists); one output time
    more is refused; an OpenFOAM domain (one .vtu per time) has the lower limit."""
    limit = MAX_OUTPUT_TIMES["well-mixed"]
    scene = make_scene(scene={"end_time": 1.0, "output_interval": 1.0 / (limit - 1)})
    assert output_count(scene.end_time, scene.output_interval) == len(output_times(scene))
    assert len(output_times(scene)) <= limit
    with pytest.raises(SceneError, match="output_interval"):
        make_scene(scene={"end_time": 1.0, "output_interval": 1.0 / limit})
    coupled = dict(domain={"type": "openfoam", "_replace": True},
                   initial={"distribution": "monodisperse", "mean_mass": 1e-9, "_replace": True})
    n_cfd = MAX_OUTPUT_TIMES["openfoam"]
    make_scene(**coupled, scene={"end_time": 1.0, "output_interval": 1.0 / (n_cfd - 1)})
    with pytest.raises(SceneError, match=str(n_cfd)):
        make_scene(**coupled, scene={"end_time": 1.0, "output_interval": 1.0 / n_cfd})


@pytest.mark.parametrize("end,interval", [(10.0, 1.0), (10.0, 3.0), (600.0, 10.0),
                                          (1.0, 0.1), (7.3, 0.7), (20.0, 1e-3)])
def test_output_count_is_the_number_of_output_times(end, interval):
    scene = make_scene(scene={"end_time": end, "output_interval": interval})
    assert output_count(end, interval) == len(output_times(scene))


# ------------------------------------------------------------------ Laguerre table memory
def test_laguerre_tables_of_a_400_x_400_grid_are_refused(tmp_path, capsys):
    """grid_mass = grid_binder = 400: 160,000 wet nodes, one pair-rate matrix alone is
    8 x 160000^2 B = 191 GiB; refused against the machine's memory in plan and run."""
    text = TINY.replace('name = "qmom"\nnodes = 2',
                        'name = "laguerre"\ngrid_mass = 400\ngrid_binder = 400')
    path = write(tmp_path, text)
    for argv in (["plan", path], ["run", path, "--out", str(tmp_path / "o")]):
        assert main(argv) == 2
        one_line_refusal(capsys, "method.grid_mass", "GiB", "of this machine's")
    assert not (tmp_path / "o").exists()


def test_laguerre_table_bytes_bound_the_pair_rate_matrix_and_the_limit_is_the_share():
    """table_bytes is at least the two N x N pair-rate matrices it holds at once; the scene
    is refused exactly when that exceeds MEMORY_SHARE of the machine (memory patched)."""
    base = load_scene("seed-wurster-laguerre").method.options
    for n_p, n_b in ((20, 20), (50, 40), (400, 400)):
        m = dataclasses.replace(base, grid_mass=n_p, grid_binder=n_b)
        assert laguerre_tensor.table_bytes(m) >= 2 * 8 * (n_p * n_b) ** 2
    need = laguerre_tensor.table_bytes(base)
    method = {"name": "laguerre", "_replace": True}
    original = limits.machine_memory
    try:
        limits.machine_memory = lambda: int(need / limits.MEMORY_SHARE) + 8
        make_scene(method=method)                        # fits: accepted
        limits.machine_memory = lambda: int(need / limits.MEMORY_SHARE) - 8
        with pytest.raises(SceneError, match="method.grid_mass"):
            make_scene(method=method)
    finally:
        limits.machine_memory = original


@pytest.mark.slow
def test_laguerre_stop_inside_its_support_does_not_blame_the_support():
    """A ROM cell that stops with none of its mass beyond the support: the hint says the
    support is not the cause instead of "widen the support" (0.0% had left it)."""
    from pbe_cfd.runs import model
    from pbe_cfd.methods.registry import method_of, method_plan
    scene = load_scene("seed-wurster-laguerre")
    arrays = model.pack(scene)
    method = method_of(scene)
    aux = method.aux(scene, arrays, None)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    hint = method.failure_hint(method_plan(scene), arrays, state, aux)
    assert "widen" not in hint and "not the cause" in hint and "0.0%" in hint


# ------------------------------------------------------------------ --threads
@pytest.mark.parametrize("threads", ["0", "-1", "1000"])
def test_threads_outside_the_cores_are_refused(tmp_path, capsys, threads):
    import numba
    cores = numba.config.NUMBA_NUM_THREADS
    out = tmp_path / "o"
    assert main(["couple", "--out", str(out), "--threads", threads]) == 2
    one_line_refusal(capsys, "--threads", f"1 to {cores}", f"got {threads}")
    assert not out.exists()


def test_bench_threads_beyond_the_cores_are_refused(tmp_path, capsys):
    import numba
    too_many = str(numba.config.NUMBA_NUM_THREADS + 1)
    out = tmp_path / "b"
    assert main(["bench", "throughput", "--quick", "--out", str(out),
                 "--threads", f"1,{too_many}"]) == 2
    one_line_refusal(capsys, "--threads", f"got {too_many}")
    assert not out.exists()


def test_scenes_lists_breakage_among_the_effects(capsys):
    assert main(["scenes"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines()
                if x.startswith("fluid-bed-breakage "))
    assert "breakage" in line.split("effects:")[1]


# ------------------------------------------------------------------ tolerances
@pytest.mark.parametrize("key,value,limit", [("atol", "1e300", "at most rtol"),
                                             ("atol", "1e-7", "at most rtol"),
                                             ("rtol", "1e-16", ">= 1e-13"),
                                             ("rtol", "0.5", "<= 0.1")])
def test_tolerances_that_lose_error_control_are_refused(tmp_path, capsys, key, value, limit):
    """atol = 1e300 switched the error control off (the free droplets ended at 0 instead of
    2.9e8): the scaled state starts at order 1, so atol may not exceed rtol; rtol must stay
    above round-off and at most 0.1."""
    path = write(tmp_path, TINY.replace("nodes = 2", f"nodes = 2\n{key} = {value}"))
    assert main(["plan", path]) == 2
    one_line_refusal(capsys, f"method.{key}", limit)


def test_atol_at_its_limit_keeps_the_free_droplets():
    """atol = rtol (the largest accepted): the seed scenario's free droplets at 600 s agree
    with the default atol (1e-14). Band: each accepted step adds at most atol + rtol |y| to
    the scaled state (y the droplets, ~0.01 of the number scale), so the difference is below
    accepted steps x (atol / y + rtol)."""
    from pbe_cfd.runs.simulate import run_well_mixed
    scene = load_scene("seed-wurster")
    ref = run_well_mixed(scene)
    loose = run_well_mixed(scene.with_method(atol=scene.method.rtol))
    y = ref.columns["droplet_number_density"][-1] / ref.columns["M00"][0]
    band = loose.stats["accepted_steps"] * (scene.method.rtol / y + scene.method.rtol)
    got = loose.columns["droplet_number_density"][-1]
    want = ref.columns["droplet_number_density"][-1]
    assert want > 1e8
    assert got == pytest.approx(want, rel=band, abs=0)


# ------------------------------------------------------------------ gel time
@pytest.mark.parametrize("verb", ["plan", "run"])
def test_product_kernel_past_its_gel_time_is_bad_input(tmp_path, capsys, verb):
    """k0 = 1e9 m3/(kg2 s), M20(0) = 1e10 x (1e-9 kg)^2 = 1e-8 kg2/m3 from the monodisperse
    start: t_gel = 1/(k0 M20(0)) = 0.1 s < end_time 2 s (docs/physics.md): exit 2 naming it."""
    path = write(tmp_path, TINY.replace('kernel = "constant"', 'kernel = "product"')
                 .replace("rate = 1e-11", "rate = 1e9"))
    argv = [verb, path] + (["--out", str(tmp_path / "o")] if verb == "run" else [])
    assert main(argv) == 2
    err = one_line_refusal(capsys, "scene.end_time", "t_gel")
    t_gel = 1.0 / (1e9 * 1e10 * 1e-18)
    assert math.isclose(t_gel, 0.1, rel_tol=1e-12, abs_tol=0)
    assert f"= {t_gel:.6g} s" in err
    assert not (tmp_path / "o").exists()


def test_product_kernel_before_its_gel_time_plans(tmp_path, capsys):
    path = write(tmp_path, TINY.replace('kernel = "constant"', 'kernel = "product"')
                 .replace("rate = 1e-11", "rate = 1e8"))             # t_gel = 1 s ... 2 s
    path2 = write(tmp_path, TINY.replace('kernel = "constant"', 'kernel = "product"')
                  .replace("rate = 1e-11", "rate = 4e7"), "ok.toml")  # t_gel = 2.5 s
    assert main(["plan", path]) == 2
    capsys.readouterr()
    assert main(["plan", path2]) == 0
    assert "gel time: 2.5 s" in capsys.readouterr().out
