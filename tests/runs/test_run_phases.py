"""Whole-run accounting of a coupled run: the phases in summary.json, and the array-at-once
output assembly giving the very numbers of the row-by-row one."""
import dataclasses
import json
import time

import numpy as np
import pytest

from pbe_cfd.methods.registry import method_plan
from pbe_cfd.runs import model
from pbe_cfd.runs.couple import run_coupled, write_coupled
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene


def short_fluid_bed(end=10.0, interval=5.0, **method):
    scene = load_scene("fluid-bed")
    scene = dataclasses.replace(scene, end_time=end, output_interval=interval)
    return scene.with_method(**method) if method else scene


@pytest.fixture(scope="module")
def coupled():
    scene = short_fluid_bed()
    domain = load_domain(scene)
    t0 = time.perf_counter()
    res = run_coupled(scene, domain)
    return scene, domain, res, time.perf_counter() - t0


def test_phases_cover_the_run_and_reach_summary_json(tmp_path, coupled):
    """Every phase is a wall time >= 0 and all of them fit in the call's own wall time; the
    phases of the caller, of the run and of the writing all land in summary.json."""
    scene, domain, res, outer_s = coupled
    ph = res.phases
    assert set(ph) == {"setup_s", "compile_s", "solve_s", "assemble_s"}
    assert all(v >= 0.0 for v in ph.values())
    assert ph["compile_s"] == res.compile_time_s
    # the phases are disjoint parts of the call: together they fit inside the wall time
    # measured around run_coupled by this test's own clock, and the solve is not empty
    assert sum(ph.values()) <= outer_s
    assert ph["solve_s"] > 0.0
    phases = write_coupled(tmp_path, domain, res, render=False,
                           phases={"startup_s": 0.5, "read_s": 0.25})
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["phases"]["startup_s"] == 0.5 and summary["phases"]["read_s"] == 0.25
    assert summary["phases"]["solve_s"] == ph["solve_s"]
    assert summary["phases"]["write_s"] > 0.0 and "render_s" not in summary["phases"]
    assert phases["write_s"] >= summary["phases"]["write_s"]


@pytest.mark.parametrize("method", [{}, {"name": "cqmom", "nodes": 2, "binder_nodes": 2}])
def test_array_outputs_equal_the_row_by_row_outputs_bitwise(coupled, method):
    """model.moment_outputs assembles all cells at once; the row-by-row path (kept for
    populations of different sizes) does the same arithmetic per cell: equal to the last bit,
    cells with and without free droplets alike."""
    scene, domain, res, _ = coupled
    if method:
        scene = short_fluid_bed(**method)
        res = run_coupled(scene, domain)
    active = res.cell_fields[-1]["active"] > 0
    arrays = model.pack(scene)
    # the coupled states are scaled by the run's own scales: rebuild them from the SI output
    names = arrays.state_names
    states = np.zeros((int(active.sum()), len(names)))
    for k, name in enumerate(names):
        if name.startswith("M") and name in res.cell_fields[-1]:
            states[:, k] = res.cell_fields[-1][name][active] / (
                arrays.number_scale * arrays.mass_scale ** (int(name[1]) + int(name[2])))
    if scene.separate_droplets:
        states[:, -1] = res.cell_fields[-1]["droplet_number_density"][active] / \
            arrays.number_scale
    assert np.any(states[:, -1] > 0) and np.any(states[:, -1] == 0)   # both branches
    entry = model.method_of(scene)
    aux = entry.aux(scene, arrays, None)
    populations = []
    fast = model.moment_outputs(method_plan(scene), arrays, states, aux,
                                populations=populations)
    slow = {c: np.zeros(states.shape[0]) for c in fast}
    nd = states[:, -1] * arrays.number_scale
    cols = [c for c in fast if c.startswith("M")]
    model._outputs_by_row(slow, populations, states, list(names), cols, nd,
                          *model.droplet_points(arrays, states, nd),
                          arrays.number_scale, arrays.mass_scale,
                          scene.material.density)
    for c in cols + ["d32_m", "d43_m"]:
        np.testing.assert_array_equal(fast[c], slow[c], err_msg=c)
    assert np.all(fast["d43_m"] > 0)


def test_thread_scaling_is_the_ratio_of_the_same_runs_rates():
    """Hand values: 2 threads at 1.8x the RHS rate, 2x the ceiling, 1.5x the steps; rows of
    other cells or methods do not enter; a method measured on one thread count has none."""
    from pbe_cfd.bench.throughput import thread_scaling, thread_scaling_markdown
    rows = [{"label": "QMOM N = 3", "cells": 1000, "threads": 1, "rhs_per_s_median": 2.0e6,
             "ceiling_per_s": 1.0e7, "cell_steps_per_s": 4.0e5},
            {"label": "QMOM N = 3", "cells": 1000, "threads": 2, "rhs_per_s_median": 3.6e6,
             "ceiling_per_s": 2.0e7, "cell_steps_per_s": 6.0e5},
            {"label": "QMOM N = 3", "cells": 10, "threads": 2, "rhs_per_s_median": 9.9e9,
             "ceiling_per_s": 9.9e9, "cell_steps_per_s": 9.9e9},
            {"label": "Laguerre m = 3", "cells": 1000, "threads": 1, "rhs_per_s_median": 1e6,
             "ceiling_per_s": 2e6, "cell_steps_per_s": 2e5}]
    sc = thread_scaling(rows, "QMOM N = 3", 1000)
    assert sc == pytest.approx({"rhs_per_s_median": 1.8, "ceiling_per_s": 2.0,
                                "cell_steps_per_s": 1.5}, rel=1e-12, abs=0)
    assert thread_scaling(rows, "Laguerre m = 3", 1000) == {}
    table = "\n".join(thread_scaling_markdown(rows, ["QMOM N = 3", "Laguerre m = 3"], 1000,
                                              [1, 2]))
    assert "| QMOM N = 3 | 1.80x | 2.00x | 1.50x |" in table
    assert "| Laguerre m = 3 | - | - | - |" in table
