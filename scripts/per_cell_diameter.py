"""Does a per-cell particle diameter pay in two-way coupling? Two measurements on a finished
two-way run (``pbe-cfd couple SCENE --out OUT`` with ``[coupling]``):

1. ``spread OUT``: the spread of the granules' d32 between cells at every output time, from the
   run's VTK series: mass-weighted 10/50/90th percentiles of the cell d32 [m] (weights: granule
   mass per cell, M10 x cell volume) and the ratio d32(p90) / d32(p10).
2. ``bracket SCENE CASE TIME D...``: the CFD re-run of one segment from the flow state of CASE at
   written time TIME, once per constant diameter D [m] (for example the cells' p10, the bed d32
   and p90), with the scene's ``[coupling]`` flow time and averaging window; prints the bed
   state of each (mean alpha of the active cells, bed height, Theta percentiles, spray cells),
   as ``segments.csv`` does. A per-cell diameter field lies between the cells' p10 and p90, so
   the bed states at those two uniform diameters bound what a per-cell diameter can move
   (for the bed-averaged statistics; not for segregation, which needs more than one
   particle phase).

    python scripts/per_cell_diameter.py spread OUT
    python scripts/per_cell_diameter.py bracket SCENE CASE TIME D1 D2 ... --work DIR
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _weighted_quantiles(values, weights, qs):
    order = np.argsort(values)
    v, w = values[order], weights[order]
    c = np.cumsum(w) - 0.5 * w
    return np.interp(np.asarray(qs) * w.sum(), c, v)


def spread(out_dir) -> list[dict]:
    """Per VTK file of a coupled run's series: process time [s] and the mass-weighted p10, p50,
    p90 of the cell d32 [m]."""
    import pyvista as pv
    rows = []
    files = sorted(Path(out_dir).rglob("*.vtu"))
    for f in files:
        grid = pv.read(f)
        if "d32_m" not in grid.cell_data or "M10" not in grid.cell_data:
            continue
        vol = grid.compute_cell_sizes(length=False, area=False)["Volume"]
        d32 = np.asarray(grid.cell_data["d32_m"], dtype=float)
        mass = np.asarray(grid.cell_data["M10"], dtype=float) * np.abs(vol)
        ok = np.isfinite(d32) & (mass > 0)
        if not ok.any():
            continue
        p10, p50, p90 = _weighted_quantiles(d32[ok], mass[ok], [0.1, 0.5, 0.9])
        t = float(grid.field_data["TimeValue"][0]) if "TimeValue" in grid.field_data else np.nan
        rows.append({"file": f.name, "time_s": t, "d32_p10_m": p10, "d32_p50_m": p50,
                     "d32_p90_m": p90, "p90_over_p10": p90 / p10, "cells": int(ok.sum())})
    return rows


def bracket(scene_path, case, time_name, diameters, work) -> list[dict]:
    """Re-run the CFD from ``case``'s written time ``time_name`` at each constant diameter [m];
    the bed state of each run (SI)."""
    from pbe_cfd.io.openfoam import rerun
    from pbe_cfd.runs.coupling import segment_domain
    from pbe_cfd.runs.coupling_output import bed_state
    from pbe_cfd.runs.domain import build_cells
    from pbe_cfd.scene.scene import load_scene
    scene = load_scene(scene_path)
    c = scene.coupling
    phase = "particles"
    rows = []
    for d in diameters:
        target = Path(work) / f"d_{d * 1e6:.1f}um"
        if not target.exists():
            rerun.continue_case(case, time_name, target, phase, d, c.flow_time, c.window_start,
                                log=None)
        end = rerun.latest_time_name(target)
        domain = segment_domain(scene, target, end, need_flux=False, first=False)
        _, active, spray, _ = build_cells(scene, domain.cells)
        rows.append({"diameter_m": d, "time": end, **bed_state(domain, active, spray)})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("spread")
    s.add_argument("out")
    b = sub.add_parser("bracket")
    b.add_argument("scene")
    b.add_argument("case")
    b.add_argument("time")
    b.add_argument("diameters", nargs="+", type=float)
    b.add_argument("--work", required=True)
    a = ap.parse_args(argv)
    rows = spread(a.out) if a.what == "spread" else bracket(a.scene, a.case, a.time,
                                                             a.diameters, a.work)
    json.dump(rows, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
