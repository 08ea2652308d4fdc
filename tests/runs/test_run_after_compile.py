"""``pbe-cfd compile`` leaves the README's first runs nothing to compile: after it, ``couple``
and ``run`` of the default scenes add no compiled specialisation to any numba function of the
package, the output assembly's included (the method's populations, the size distribution's
node groups). Measured in a fresh process, where every function starts with none: each
compiled or cached signature a run needs is then counted where it is first taken.

Red if a numba function that a run's integration or output assembly calls is left out of
``pbe-cfd compile`` (the run would compile it on a fresh machine: docs/results/first-run.md).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

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
