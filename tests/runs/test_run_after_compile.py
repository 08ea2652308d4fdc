"""``pbe-cfd compile`` leaves the README's first runs nothing to compile: after it, ``couple``
and ``run`` of the default scenes add no compiled specialisation to any numba function of the
package, the output assembly's included (the method's populations, the size distribution's
node groups). Measured in a fresh process, where every function starts with none: each
compiled or cached signature a run needs is then counted where it is first taken.

Red if a numba function that a run's integration or output assembly calls is left out of
``pbe-cfd compile`` (the run would compile it on a fresh machine: docs/results/first-run.md).
"""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pbe_cfd.runs import model, simulate
from pbe_cfd.runs.problem import problem_of
from pbe_cfd.scene.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import json, sys
from numba.core.registry import CPUDispatcher
from pbe_cfd.cli import main

def signatures():
    seen = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("pbe_cfd") or module is None:
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher):
                f = value.py_func
                seen[f.__module__ + "." + f.__qualname__] = len(value.signatures)
    return seen

out = sys.argv[1]
assert main(["compile", "-j", "1"]) == 0
after_compile = signatures()
assert main(["couple", "--out", out + "/couple"]) == 0
after_couple = signatures()
assert main(["run", "--out", out + "/run"]) == 0
after_run = signatures()
print(json.dumps({"compile": after_compile, "couple": after_couple, "run": after_run}))
"""


#: a bundled scene's ``compile`` then its ``run`` (argv: output directory, scene)
PROBE_SCENE = PROBE.split("out = sys.argv[1]")[0] + """
out, scene = sys.argv[1], sys.argv[2]
assert main(["compile", scene, "-j", "1"]) == 0
after_compile = signatures()
assert main(["run", scene, "--out", out + "/run"]) == 0
print(json.dumps({"compile": after_compile, "run": signatures()}))
"""


def _gained(before: dict, after: dict) -> dict:
    return {k: (before.get(k, 0), n) for k, n in after.items() if n > before.get(k, 0)}


@pytest.mark.slow
def test_couple_and_run_compile_nothing_after_compile(tmp_path):
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                         if p)}
    proc = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=3600, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen["compile"], "no numba function of the package was compiled"
    assert _gained(seen["compile"], seen["couple"]) == {}
    assert _gained(seen["couple"], seen["run"]) == {}


@pytest.mark.slow
def test_a_laguerre_run_from_a_monodisperse_start_compiles_nothing_after_compile(tmp_path):
    """seed-wurster-laguerre starts monodisperse: its start states reach only the one-point
    reconstruction, the run the general gamma fit once the population spreads (19 numba
    functions, 2.6 s of its first run). ``compile`` warms the distribution on a broad
    population too. Red without it."""
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                         if p)}
    proc = subprocess.run([sys.executable, "-c", PROBE_SCENE, str(tmp_path),
                           "seed-wurster-laguerre"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=3600, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen["compile"], "no numba function of the package was compiled"
    assert _gained(seen["compile"], seen["run"]) == {}


def test_warm_outputs_reconstructs_the_row_with_the_most_granules(monkeypatch):
    """A case's first cell may hold no granules (a freeboard cell): the size distribution,
    which has nothing to reconstruct there, is warmed on the start state with the most
    granules (largest M00), so its functions still compile ahead. Red if the first row is
    taken."""
    problem = problem_of(load_scene("seed-wurster"))
    start = np.array(problem.states[0], dtype=np.float64)
    states = np.vstack([0.0 * start, 0.5 * start, start, 0.25 * start])
    problem = dataclasses.replace(problem, states=states)
    seen = []
    monkeypatch.setattr(simulate, "_size_distribution",
                        lambda plan, arrays, rows, aux, pops, columns, notes:
                        seen.append((rows.copy(), float(columns["M00"][0]), len(pops))))
    simulate.warm_outputs(problem)
    assert len(seen) == 1
    rows, m00, n_pops = seen[0]
    assert np.array_equal(rows, states[2:3]) and n_pops == 1
    every = model.moment_outputs(problem.outputs.method_plan, problem.arrays, states,
                                 problem.aux)["M00"]
    assert m00 == max(every) > every[1] > every[3]


@pytest.mark.parametrize("method", [{"name": "qmom", "nodes": 3},
                                    {"name": "laguerre", "order": 3}])
def test_compile_warms_the_distribution_on_a_broad_population(monkeypatch, method):
    """Besides the start state with the most granules (here none: a scene that starts empty,
    its granules made by the spray), the size distribution is warmed on the scene's initial
    population made exponential at the number scale, packed like the start states: M00 =
    the number scale [1/m3], M10 that times the mean mass [kg/m3], M20 = 2 M10^2 / M00 (an
    exponential: the reconstruction's general fit, not the one-point rule of a monodisperse
    start). Red without it (only the empty start is seen)."""
    from conftest import make_scene
    scene = make_scene(initial={"number_density": 0.0, "mean_mass": 2e-9},
                       aggregation={"kernel": "constant", "rate": 1e-12},
                       binder_injection={"rate": 1e11, "droplet_diameter": 60e-6},
                       method=dict(method, _replace=True))
    problem = problem_of(scene)
    seen = []
    monkeypatch.setattr(simulate, "_size_distribution",
                        lambda plan, arrays, rows, aux, pops, columns, notes:
                        seen.append({k: float(columns[k][0]) for k in ("M00", "M10", "M20")}
                                    | {"populations": len(pops)}))
    simulate.warm_outputs(problem, scene)
    assert len(seen) == 2 and seen[0]["M00"] == 0.0          # the empty start, then the broad
    broad = seen[1]
    scale = problem.arrays.number_scale
    assert broad["populations"] == 1
    assert broad["M00"] == pytest.approx(scale, rel=1e-12, abs=0.0)
    assert broad["M10"] == pytest.approx(scale * 2e-9, rel=1e-12, abs=0.0)
    assert broad["M20"] == pytest.approx(2.0 * broad["M10"] ** 2 / broad["M00"], rel=1e-12,
                                         abs=0.0)
