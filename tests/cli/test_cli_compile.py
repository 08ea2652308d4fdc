"""``pbe-cfd compile`` compiles exactly the kernels the README's first run uses: after it, in
the same fresh process, ``pbe-cfd run`` and ``pbe-cfd couple`` add no signature to the
integration kernel (a kernel of another type, integrator or method would be a new one)."""
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
from pbe_cfd.cli import main
from pbe_cfd.integrate import integrate_cells_kernel as kernel
out = sys.argv[1]
assert main(["compile"]) == 0
compiled = sorted(str(s) for s in kernel.signatures)
assert main(["run", "--out", out + "/run"]) == 0
assert main(["couple", "--out", out + "/couple"]) == 0
print(json.dumps({"compiled": compiled, "after": sorted(str(s) for s in kernel.signatures)}))
"""


@pytest.mark.slow
def test_compile_builds_the_one_kernel_that_run_and_couple_then_use(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)}   # this checkout's code
    proc = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=1800, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert len(seen["compiled"]) == 1
    assert seen["after"] == seen["compiled"]
    for name in ("seed-wurster", "fluid-bed"):
        assert f"{name}: " in proc.stdout and "the qmom kernel with the auto integrator" in \
            proc.stdout
    for sub in ("run", "couple"):
        summary = json.loads((tmp_path / sub / "summary.json").read_text())
        assert summary["kernels_compiled"] is False


def test_the_command_line_parser_leaves_the_bench_unimported():
    """Every command builds the whole parser; the bench's study list is read only for help or
    an error, so a `run` or `couple` does not import the benchmarks (and the Laguerre tensors
    they import) before it starts."""
    code = ("import sys; from pbe_cfd.cli import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules if m.startswith('pbe_cfd.bench')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.strip() == "[]"
    usage = subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "bench", "nosuch"],
                           capture_output=True, text=True,
                           cwd=Path(__file__).resolve().parents[2])
    assert usage.returncode == 2 and "'accuracy'" in usage.stderr
