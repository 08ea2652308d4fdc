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
