"""The kernel's call tree compiled in stages (``integrate.warmup``, ``pbe-cfd compile -j``).

A staged function compiled in a helper process serves the kernel only if its staged argument
types are those of its call site; otherwise the kernel compiles it again (time lost, never a
wrong result). The fast test checks that such a mismatch is seen; the study test compiles
the README's kernel in two processes on an empty cache and checks that the kernel then
compiled none of the staged functions again, and that the helpers compiled every one."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba as nb
import numpy as np
import pytest
from numba import typeof
from numba.core import types

from pbe_cfd.integrate.warmup import cache_misses, compile_group, recompiled

ROOT = Path(__file__).resolve().parents[2]


@nb.njit
def _leaf(x, n):
    return x[0] * n


@nb.njit
def _caller(x):
    return _leaf(x, x.shape[0])        # n: int64


def test_a_staged_signature_unlike_its_call_site_is_reported_recompiled():
    vec = typeof(np.zeros(3))
    wrong = [[[("_leaf", _leaf, (vec, types.float64))]]]       # the call site passes int64
    compile_group(wrong[0][0])
    before = cache_misses(wrong)
    _caller.compile((vec,))
    assert recompiled(wrong, before) == ["_leaf"]
    right = [[[("_leaf", _leaf, (vec, types.int64))]]]
    assert compile_group(right[0][0]) == []         # compiled already, by the caller
    before = cache_misses(right)
    _caller(np.ones(3))
    assert recompiled(right, before) == []


PROBE = """
import sys
from pbe_cfd.cli import main
sys.exit(main(["compile", "-j", "2", "seed-wurster"]))
"""


@pytest.mark.study
def test_two_process_compile_leaves_the_kernel_no_staged_function_to_compile(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
           "PBE_CFD_CACHE": str(tmp_path / "pbe_cfd"),
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                         if p)}
    proc = subprocess.run([sys.executable, "-c", PROBE], cwd=tmp_path, capture_output=True,
                          text=True, timeout=3600, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "compiled again" not in proc.stdout, proc.stdout
    from pbe_cfd.runs.precompile import _prepared, _stages_of
    from pbe_cfd.scene.scene import load_scene
    _problem, batch, _extra = _prepared(load_scene("seed-wurster"))
    staged = sum(len(group) for stage in _stages_of(batch) for group in stage)
    assert f"{staged} functions of it in 2 processes" in proc.stdout, proc.stdout
