"""A kernel compiled once serves the same sources wherever they sit (a checkout, an installed
copy with fresh modification times), and never serves changed sources.

Each run is a fresh process that imports the package from one copy and calls a small cached
kernel (the QL eigen-solver of the quadrature): numba's statistics say whether it compiled or
loaded it, and the eigenvalues of the tridiagonal matrix with diagonal (1, 2, 3) and
off-diagonal 1/2 are checked against the closed form 2 and 2 -+ sqrt(3/2)."""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import json
import numpy as np
import pbe_cfd
from pbe_cfd.methods.quadrature.gauss import tridiagonal_eigen as f
d = np.array([1.0, 2.0, 3.0]); o = np.array([0.5, 0.5, 0.0]); c = np.zeros(3)
assert f(d, o, c, 3)
print(json.dumps({"file": pbe_cfd.__file__, "hits": sum(f.stats.cache_hits.values()),
                  "misses": sum(f.stats.cache_misses.values()), "eigen": sorted(d.tolist())}))
"""

#: The closed form of the eigenvalues; the QL iteration converges to rounding (about 1e-15
#: relative for these well-scaled entries): 1e-12 is three orders looser than rounding.
EXACT = (2.0 - math.sqrt(1.5), 2.0, 2.0 + math.sqrt(1.5))


def _copy(dest: Path) -> Path:
    """The package copied as an installer copies it: new modification times, no bytecode."""
    shutil.copytree(ROOT / "pbe_cfd", dest / "pbe_cfd", copy_function=shutil.copy,
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return dest


def _probe(where: Path, env: dict) -> dict:
    run = subprocess.run([sys.executable, "-c", PROBE], cwd=where, capture_output=True,
                         text=True, env=dict(env, PYTHONPATH=str(where)), timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert Path(out["file"]).resolve().parent == (where / "pbe_cfd").resolve()
    assert out["eigen"] == pytest.approx(EXACT, abs=1e-12)
    return out


def _env(tmp_path: Path, root: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env[root] = str(tmp_path / "cache")
    return env


@pytest.mark.slow
def test_a_kernel_compiled_in_one_copy_loads_in_another_copy_of_the_same_sources(tmp_path):
    """The user's default cache ($XDG_CACHE_HOME/pbe_cfd/numba/<hash>)."""
    env = _env(tmp_path, "XDG_CACHE_HOME")
    checkout = _probe(_copy(tmp_path / "checkout"), env)
    installed = _probe(_copy(tmp_path / "site-packages"), env)
    assert (checkout["misses"], checkout["hits"]) == (1, 0)      # compiled
    assert (installed["misses"], installed["hits"]) == (0, 1)    # loaded, not compiled
    assert installed["eigen"] == checkout["eigen"]               # bitwise the same


@pytest.mark.slow
def test_changed_sources_are_never_served_from_the_cache(tmp_path):
    """A change in another compiled module than the kernel's (whose code a caller could have
    inlined) compiles afresh: numba itself checks only the kernel's own module."""
    changed = "pbe_cfd/physics/kernels.py"
    env = _env(tmp_path, "NUMBA_CACHE_DIR")
    first = _probe(_copy(tmp_path / "one"), env)
    other = _copy(tmp_path / "other")
    with open(other / changed, "a") as fh:
        fh.write("\n# a change\n")
    second = _probe(other, env)
    assert (first["misses"], second["misses"], second["hits"]) == (1, 1, 0)
