"""The Laguerre tensor study: build time per order and grid, and the RHS rate with the
Theta-interpolated tensor (``pbe-cfd bench laguerre``)."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numba as nb
import numpy as np

from ..runs import model
from ..methods.laguerre import tensor as LT
from ..physics import parameters as P
from .common import (LAGUERRE_STUDY, _git_describe, _machine_line, _say, _write_simple,
                     machine_info)
from .throughput import measure_rhs_rate, throughput_case


def laguerre_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Laguerre tensor build time per order and grid (one u0 slice, and a Theta grid of
    slices as the coupling builds it) and the RHS rate with the Theta-interpolated tensor."""
    orders = (2, 3) if quick else (2, 3, 4)
    grids = (8, 12) if quick else (20, 40)
    slices = 4 if quick else 24
    n_cells = 1000 if quick else 10_000
    rows = []
    for m in orders:
        case = throughput_case(LAGUERRE_STUDY, m)
        sc, arrays = case.scene, case.arrays
        for g in grids:
            weights, support = LT.scene_weights_support(sc)
            support = dict(support, n_p=g, n_b=g)
            u0 = float(model.well_mixed_cell(sc)[0, P.COLLISION_VELOCITY])
            t0 = time.perf_counter()
            LT.build_aux(arrays.params, arrays.config, m, weights=weights, support=support,
                         consistent=True, collision_velocity=u0, use_cache=False)
            one = time.perf_counter() - t0
            t0 = time.perf_counter()
            aux = LT.build_aux(arrays.params, arrays.config, m, weights=weights, support=support,
                               consistent=True, theta_grid=np.geomspace(1e-6, 2e-4, slices),
                               use_cache=False)
            many = time.perf_counter() - t0
            c = dataclasses.replace(case, aux=aux)
            rates = {th: measure_rhs_rate(c, n_cells, th, target_evals=50_000 if quick
                                          else 300_000, repeats=1 if quick else 3)[0]
                     for th in (1, 2) if th <= nb.config.NUMBA_NUM_THREADS}
            rows.append({"order": m, "grid": g, "nodes": int(aux[LT.AUX_N_NODES]),
                         "build_one_slice_s": one, "slices": slices,
                         "build_theta_grid_s": many,
                         **{f"rhs_per_s_{th}thr": v for th, v in rates.items()}})
            _say(quiet, f"  Laguerre m={m} grid {g}: build {one:.2f} s / {many:.2f} s "
                 f"({slices} slices), RHS {rates}")
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows}
    ths = [th for th in (1, 2) if th <= nb.config.NUMBA_NUM_THREADS]
    lines = ["| m | grid | nodes on support | build, 1 slice [s] | build, Theta grid [s] | "
             + " | ".join(f"RHS/s {th} thr" for th in ths) + " |",
             "|---|---|---|---|---|" + "---|" * len(ths)]
    for r in rows:
        lines.append(f"| {r['order']} | {r['grid']} x {r['grid']} | {r['nodes']} | "
                     f"{r['build_one_slice_s']:.3g} | {r['build_theta_grid_s']:.3g} "
                     f"({r['slices']} slices) | "
                     + " | ".join(f"{r[f'rhs_per_s_{th}thr']:.3g}" for th in ths) + " |")
    lines += ["", f"ktgf + geometric + physical scene; RHS on {n_cells} cells with the "
              "Theta-interpolated tensor. Machine: " + _machine_line(result["machine"]) + "."]
    _write_simple(Path(out_dir), LAGUERRE_STUDY, rows, "\n".join(lines) + "\n", result)
    return result
