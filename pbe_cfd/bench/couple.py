"""The coupling study: cell-steps per second of ``run_coupled`` on the bundled bed and on its
cells replicated (``pbe-cfd bench couple``)."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numba as nb
import numpy as np

from ..methods.qmom import ENTRY as QMOM
from ..runs.couple import run_coupled
from ..runs.domain import Domain, load_domain
from ..scene.scene import load_scene
from .common import (_git_describe, _machine_line, _say, _write_simple, failure_status,
                     machine_info)


def replicated_domain(domain, copies):
    """The domain's cells repeated ``copies`` times (a larger mesh with the same fields)."""
    cells = domain.cells
    n = len(cells.alpha) * copies
    big = dataclasses.replace(
        cells, alpha=np.tile(cells.alpha, copies), theta=np.tile(cells.theta, copies),
        cell_volume=np.tile(cells.cell_volume, copies),
        cell_centre=np.tile(cells.cell_centre, (copies, 1)),
        vtk_cell_id=np.arange(n, dtype=np.int64))
    return Domain(cells=big, flux=None, description=f"{domain.description} x {copies}")


def couple_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Cell-steps per second of ``run_coupled`` on the bundled small bed (900 cells) and on its
    cells replicated 4 times (3600 cells, standing in for the full mesh, whose snapshot is not
    bundled), threads 1 and 2: the fluid-bed scene with QMOM, and the fluid-bed-laguerre scene
    (the same bed, dry start, no droplets at t = 0) with the Laguerre ROM."""
    end, interval = (2.0, 1.0) if quick else (10.0, 5.0)
    base = dataclasses.replace(load_scene("fluid-bed"), end_time=end, output_interval=interval)
    laguerre = dataclasses.replace(load_scene("fluid-bed-laguerre"), end_time=end,
                                   output_interval=interval)
    small = load_domain(base)
    domains = [("small (900 cells)", small)]
    if not quick:
        domains.append(("small x 4 (3600 cells)", replicated_domain(small, 4)))
    methods = [("QMOM N = 2", base.with_method(name=QMOM.name, nodes=2))]
    if not quick:
        methods += [("QMOM N = 3", base.with_method(name=QMOM.name, nodes=3)),
                    ("Laguerre m = 3 (fluid-bed-laguerre)", laguerre)]
    rows = []
    for mlabel, scene in methods:
        for dlabel, dom in domains:
            try:
                run_coupled(dataclasses.replace(scene, end_time=interval), dom, threads=1)
            except Exception as exc:  # noqa: BLE001 - a failing method is a result
                rows.append({"method": mlabel, "domain": dlabel, "threads": 0,
                             "active_cells": 0, "wall_s": float("nan"), "accepted_steps": 0,
                             "cell_steps_per_s": float("nan"), "rhs_calls": 0,
                             "status": failure_status(exc)})
                _say(quiet, f"  couple {mlabel} {dlabel}: failed: {exc}")
                continue
            for th in (1, 2):
                if th > nb.config.NUMBA_NUM_THREADS:
                    continue
                t0 = time.perf_counter()
                res = run_coupled(scene, dom, threads=th)
                wall = time.perf_counter() - t0
                st = res.stats
                rows.append({"method": mlabel, "domain": dlabel, "threads": th,
                             "active_cells": st["active_cells"], "wall_s": wall,
                             "accepted_steps": st["accepted_steps"],
                             "cell_steps_per_s": st["accepted_steps"] / wall,
                             "rhs_calls": st["rhs_calls"], "status": "ok"})
                _say(quiet, f"  couple {mlabel} {dlabel} {th} thr: {wall:.2f} s, "
                     f"{st['accepted_steps'] / wall:.3g} cell-steps/s")
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows,
              "end_time_s": end}
    lines = ["| method | domain | active cells | threads | wall [s] | cell-steps/s | "
             "RHS calls/s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['method']} | {r['domain']} | - | - | - | "
                         f"{r['status'].replace('|', '/')} | - |")
            continue
        lines.append(f"| {r['method']} | {r['domain']} | {r['active_cells']} | {r['threads']} | "
                     f"{r['wall_s']:.3g} | {r['cell_steps_per_s']:.3g} | "
                     f"{r['rhs_calls'] / r['wall_s']:.3g} |")
    lines += ["", f"fluid-bed scenes to t = {end:g} s (whole run_coupled after a first run that "
              "compiles and builds the Laguerre tensors: set-up, solve, output fields). "
              "Machine: " + _machine_line(result["machine"]) + "."]
    _write_simple(Path(out_dir), "couple", rows, "\n".join(lines) + "\n", result)
    return result
