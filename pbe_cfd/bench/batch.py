"""The batch study (``pbe-cfd bench batch``): what a whole batch costs and what its lag does.

In one process, after a warm-up run of each scene's first output interval (the kernels compile
or load; the QMOM scenes run the same kernel), interleaved over ``repeats`` rounds:
``fluid-bed-transport`` and ``fluid-bed-batch`` to the same process time (the batch's), the
batch at half its ``air_interval`` (the lag of the bed's humidity, docs/physics.md
section 15), and the batch with CQMOM 2 x 2 in place of QMOM N = 2. Per run: the run's wall
time (``run_coupled``'s, without the compile), its solve phase, accepted cell-steps per second
of wall time, RHS calls; per batch run its end-of-spray and end moisture and d50. The ratio
to fluid-bed-transport is of the medians of the same round set.
"""
from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path

import numpy as np

from ..methods.cqmom import ENTRY as CQMOM
from ..scene.scene import load_scene
from .common import _git_describe, _machine_line, _say, _write_simple, machine_info

#: the variants: (label, scene name, air_interval factor or None, [method] keys replaced)
VARIANTS = (("fluid-bed-transport", "fluid-bed-transport", None, {}),
            ("fluid-bed-batch", "fluid-bed-batch", 1.0, {}),
            ("fluid-bed-batch, air_interval / 2", "fluid-bed-batch", 0.5, {}),
            ("fluid-bed-batch, CQMOM 2 x 2", "fluid-bed-batch", 1.0,
             {"name": CQMOM.name, "nodes": 2, "binder_nodes": 2}))


def _scene(name, factor, end, interval, method=None):
    scene = load_scene(name)
    scene = dataclasses.replace(scene, end_time=end, output_interval=interval)
    if method:
        scene = scene.with_method(**method)
    if factor is not None and factor != 1.0:
        scene = dataclasses.replace(scene, drying=dataclasses.replace(
            scene.drying, air_interval=scene.drying.air_interval * factor))
    return scene


def _at(bed, column, t):
    """The bed column at the output time nearest t [s]."""
    k = int(np.argmin(np.abs(bed["time_s"] - t)))
    return float(bed[column][k]) if column in bed else float("nan")


def batch_rows(quick=False, repeats=1, quiet=False) -> tuple[list, dict]:
    """(rows, the runs' bed columns by label): one row per variant with the medians over
    ``repeats`` rounds (quick: 20 s of process time, spraying to 12 s)."""
    from ..runs.couple import run_coupled
    from ..runs.domain import load_domain
    batch = load_scene("fluid-bed-batch")
    end, interval = (20.0, 4.0) if quick else (batch.end_time, batch.output_interval)
    stop = batch.binder_injection.schedule[-1][0]
    if quick:
        stop = 12.0
    scenes = {}
    for label, name, factor, method in VARIANTS:
        sc = _scene(name, factor, end, interval, method)
        if quick and sc.drying is not None:
            inj = sc.binder_injection
            sc = dataclasses.replace(sc, binder_injection=dataclasses.replace(
                inj, schedule=((0.0, inj.rate), (stop, 0.0))))
        scenes[label] = sc
    domain = load_domain(batch, need_flux=True)
    for label, sc in scenes.items():               # compile or load; not measured
        run_coupled(dataclasses.replace(sc, end_time=interval), domain)
    runs = {label: [] for label in scenes}
    beds = {}
    for r in range(repeats):
        for label, sc in scenes.items():
            t0 = time.perf_counter()
            res = run_coupled(sc, domain)
            whole = time.perf_counter() - t0
            runs[label].append((res.wall_time_s, res.phases["solve_s"], whole, res.stats))
            beds[label] = res.bed_columns
            _say(quiet, f"  batch round {r + 1}/{repeats} {label}: {res.wall_time_s:.1f} s, "
                 f"{res.stats['accepted_steps'] / res.wall_time_s:.3g} cell-steps/s")
    rows = []
    base = statistics.median(w for w, _, _, _ in runs[VARIANTS[0][0]])
    for label, rec in runs.items():
        wall = statistics.median(w for w, _, _, _ in rec)
        steps = statistics.median(s["accepted_steps"] for _, _, _, s in rec)
        bed = beds[label]
        rows.append({"variant": label, "process_time_s": end, "repeats": len(rec),
                     "wall_s": wall, "solve_s": statistics.median(s for _, s, _, _ in rec),
                     "wall_ratio": wall / base, "accepted_steps": steps,
                     "cell_steps_per_s": steps / wall,
                     "rhs_calls": statistics.median(s["rhs_calls"] for _, _, _, s in rec),
                     "moisture_end_of_spray": _at(bed, "moisture_content", stop),
                     "moisture_end": _at(bed, "moisture_content", end),
                     "d50_end_of_spray_m": _at(bed, "d50_m", stop),
                     "d50_end_m": _at(bed, "d50_m", end)})
    return rows, beds


def batch_study(out_dir, quick=False, quiet=False, repeats=None) -> dict:
    """Run ``batch_rows`` (3 rounds quick, 1 otherwise) and write batch.csv/.md/.json."""
    info = machine_info()
    repeats = repeats or (3 if quick else 1)
    rows, _ = batch_rows(quick=quick, repeats=repeats, quiet=quiet)
    lines = ["| variant | process time [s] | wall [s] (x transport) | solve [s] | "
             "cell-steps/s | RHS calls | moisture end of spray / end [-] | d50 end of spray "
             "/ end [um] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        moist = (f"{r['moisture_end_of_spray']:.4g} / {r['moisture_end']:.4g}"
                 if np.isfinite(r["moisture_end"]) else "-")
        lines.append(f"| {r['variant']} | {r['process_time_s']:g} | {r['wall_s']:.4g} "
                     f"({r['wall_ratio']:.2f}) | {r['solve_s']:.4g} | "
                     f"{r['cell_steps_per_s']:.3g} | {r['rhs_calls']:.4g} | {moist} | "
                     f"{r['d50_end_of_spray_m'] * 1e6:.1f} / {r['d50_end_m'] * 1e6:.1f} |")
    lines += ["", f"Medians of {repeats} interleaved round(s) in one process after a warm-up "
              "run of each variant (run_coupled's wall time without the compile). Machine: "
              + _machine_line(info) + "."]
    result = {"machine": info, "commit": _git_describe(), "rows": rows, "quick": quick}
    _write_simple(Path(out_dir), "batch", rows, "\n".join(lines) + "\n", result)
    return result
