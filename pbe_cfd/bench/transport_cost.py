"""What transport costs, before and after a change, in one run (a part of
``pbe-cfd bench integrators DIR``).

The bundled ``fluid-bed-transport`` scene and the same scene without ``[transport]``, each
run as a whole process (``python -m pbe_cfd.cli couple``: read, solve, VTK, CSV and PNGs
written) by two source trees: the baseline tree DIR (a checkout of another commit, put first
on PYTHONPATH) and this one. The runs alternate tree by tree and scene by scene, ``repeats``
rounds, so a change of the machine's load hits all four alike. Per run: wall [s] and CPU [s]
(user + system of the process and its children) of the process, and the solve phase [s] of
its ``summary.json`` (first step to last: compile and outputs excluded). Medians, and per tree
the ratios with / without transport.
"""
from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..runs.executor import SerialExecutor
from .common import _say

SCENES = ("with [transport]", "without [transport]")


def check_baseline(path) -> Path:
    """The baseline tree as a Path; ValueError naming what is missing if DIR holds no
    pbe_cfd package."""
    root = Path(path)
    if not (root / "pbe_cfd" / "__init__.py").is_file():
        raise ValueError(f"bench integrators {path}: expected a source tree holding "
                         "pbe_cfd/__init__.py (a checkout of another commit)")
    return root


def refusal(path):
    """None if ``path`` is a source tree holding pbe_cfd/, else the one-line error."""
    try:
        check_baseline(path)
    except ValueError as exc:
        return str(exc)
    return None


def _one_process(tree, scene_path, out_dir) -> dict:
    """Wall [s], CPU [s] and solve phase [s] of one ``couple`` process of ``tree`` (None:
    this tree, as imported)."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(tree)] + [p for p in env.get(
            "PYTHONPATH", "").split(os.pathsep) if p])
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "couple", str(scene_path), "--out",
                    str(out_dir), "--overwrite"], check=True, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    summary = json.loads((Path(out_dir) / "summary.json").read_text())
    return {"wall_s": wall,
            "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "solve_s": float(summary["phases"]["solve_s"])}


def before_after_rows(baseline, scene_paths, repeats, quiet=False) -> list:
    """One row per (tree, scene): medians of wall, CPU and solve phase over ``repeats``
    alternating rounds after one warm-up round (kernels loaded from each tree's cache).
    ``scene_paths``: {label: path} for the two SCENES."""
    trees = (("baseline", check_baseline(baseline)), ("this tree", None))
    runs = {(t, s): [] for t, _ in trees for s in SCENES}
    with tempfile.TemporaryDirectory() as tmp:
        for rnd in range(repeats + 1):
            for t, tree in trees:
                for s in SCENES:
                    res = _one_process(tree, scene_paths[s], Path(tmp) / "out")
                    if rnd > 0:
                        runs[(t, s)].append(res)
                    _say(quiet, f"  {t}, {s}{' (warm-up)' if rnd == 0 else ''}: "
                         f"{res['wall_s']:.3g} s wall, {res['cpu_s']:.3g} s CPU, solve "
                         f"{res['solve_s']:.3g} s")
    rows = []
    for (t, s), got in runs.items():
        rows.append({"tree": t, "scene": s, "repeats": len(got),
                     **{k: statistics.median(r[k] for r in got)
                        for k in ("wall_s", "cpu_s", "solve_s")},
                     "solve_all_s": [round(r["solve_s"], 4) for r in got]})
    return rows


def before_after_markdown(rows, baseline_label) -> list:
    """The table and the ratios (Markdown lines)."""
    lines = ["", f"Before ({baseline_label}) and after (this tree), whole `couple` processes "
             "alternating in one run; medians:", "",
             "| tree | scene | process wall [s] | process CPU [s] | solve phase [s] |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['tree']} | {r['scene']} | {r['wall_s']:.3g} | {r['cpu_s']:.3g} | "
                     f"{r['solve_s']:.3g} |")
    lines.append("")
    for tree in dict.fromkeys(r["tree"] for r in rows):
        a = next(r for r in rows if r["tree"] == tree and r["scene"] == SCENES[0])
        b = next(r for r in rows if r["tree"] == tree and r["scene"] == SCENES[1])
        lines.append(f"- {tree}: with / without transport: solve phase "
                     f"{a['solve_s'] / b['solve_s']:.2f}, process wall "
                     f"{a['wall_s'] / b['wall_s']:.2f}, process CPU "
                     f"{a['cpu_s'] / b['cpu_s']:.2f}")
    return lines


# ---------------------------------------------------------------------------- where it goes
class CountingExecutor(SerialExecutor):
    """The serial executor, keeping each cell's integration counters and its spray flag when
    the run ends (``run_coupled(..., executor=CountingExecutor())``)."""

    def __init__(self):
        self.counts = None            # (n_cells, N_STATS) counters of the run
        self.spray = None             # (n_cells,) bool: the cell is sprayed (injection > 0)

    def run(self, batch, times, transport=None, progress=None) -> list:
        """``SerialExecutor.run``, then the batch's counters and spray flags kept."""
        from ..physics import parameters as P
        history = super().run(batch, times, transport, progress)
        self.counts = batch.stats_counts.copy()
        self.spray = batch.rows[:, P.INJECTION] > 0.0
        return history


def per_cell_split_step(counts, spray, end_time: float, split_step: float) -> dict:
    """RHS calls and accepted steps per cell and per split step [-] of the spray cells and of
    the other cells: counters ``counts`` (n_cells, N_STATS) of a run to ``end_time`` [s],
    ``spray`` (n_cells,) bool, ``split_step`` [s] (for a run without transport the same
    length of scene time, so the two runs compare per unit time)."""
    from .. import integrate
    parts = end_time / split_step
    out = {"split_steps": parts}
    for label, mask in (("spray", spray), ("other", ~spray)):
        n = int(np.count_nonzero(mask))
        out[f"{label}_cells"] = n
        for key, slot in (("rhs", integrate.RHS_CALLS), ("steps", integrate.ACCEPTED)):
            total = float(counts[mask, slot].sum())
            out[f"{label}_{key}_per_cell_split_step"] = total / (n * parts) if n else 0.0
    return out


def per_cell_markdown(rows) -> list:
    """The per-cell table of the rows carrying ``per_cell`` (Markdown lines)."""
    have = [r for r in rows if r.get("per_cell")]
    if not have:
        return []
    lines = ["", "Where the source integration goes (the first run of each scene): per cell and "
             "per split step (without transport: per the same length of scene time), the "
             "spray-zone cells and the other active cells:", "",
             "| scene | split step [s] | spray cells | RHS / cell / split step (spray) | steps "
             "(spray) | other cells | RHS / cell / split step (other) | steps (other) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in have:
        p = r["per_cell"]
        lines.append(f"| {r['scene']} | {p['split_step_s']:g} | {p['spray_cells']} | "
                     f"{p['spray_rhs_per_cell_split_step']:.3g} | "
                     f"{p['spray_steps_per_cell_split_step']:.3g} | {p['other_cells']} | "
                     f"{p['other_rhs_per_cell_split_step']:.3g} | "
                     f"{p['other_steps_per_cell_split_step']:.3g} |")
    return lines
