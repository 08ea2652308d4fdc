"""The Laguerre tensor study: build time per order and grid, the RHS rate with the
Theta-interpolated tensor, and the cost per RHS of the weight variants (adaptive weights, the
following support with a fixed shape, with the shape axis) on the same states
(``pbe-cfd bench laguerre``)."""
from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path

import numba as nb
import numpy as np

from ..runs import model
from ..methods.laguerre import tensor as LT
from ..physics import parameters as P
from .common import (LAGUERRE_STUDY, _git_describe, _machine_line, _say, _write_simple,
                     machine_info)
from .sweeps import rhs_sweep
from .throughput import (cell_states, measure_rhs_rate, synthetic_cells, throughput_case,
                         throughput_scene, trajectory_states)

#: the weight variants whose cost per RHS the study compares: (label, [method] keys)
WEIGHT_VARIANTS = (("adaptive weights (default)", {}),
                   ("following support, fixed shape", {"following_support": True,
                                                      "following_shape": False}),
                   ("following support, shape axis", {"following_support": True}))


def weight_variant_costs(n_cells=2000, rounds=3, target_evals=100_000, order=3):
    """Cost per RHS [us] of each WEIGHT_VARIANTS entry on the seed throughput scene: the same
    cell states (the default's trajectory) and cells for all, the well-mixed cell's u0 (one
    tensor slice), one thread; the variants alternate within each round, the result is the
    median over rounds with each variant's ratio to the first."""
    from ..methods.registry import METHODS
    nb.set_num_threads(1)
    entry = METHODS[LAGUERRE_STUDY]
    scene = throughput_scene(LAGUERRE_STUDY, order)
    arrays = model.pack(scene)
    cells = synthetic_cells(n_cells, seed=0)
    states = cell_states(trajectory_states(scene, arrays, entry.aux(scene, arrays, None)),
                         n_cells, seed=1)
    cases = []
    for label, keys in WEIGHT_VARIANTS:
        sc = scene.with_method(**keys)
        arrays = model.pack(sc)
        cases.append((label, arrays, entry.aux(sc, arrays, None)))
    reps = max(1, int(round(target_evals / n_cells)))
    out = np.zeros_like(states)
    for _, arrays, aux in cases:                    # compile and warm
        rhs_sweep(states, cells, aux, arrays.params, arrays.config, 1, out)
    walls = {label: [] for label, _, _ in cases}
    for _ in range(rounds):
        for label, arrays, aux in cases:
            t0 = time.perf_counter()
            rhs_sweep(states, cells, aux, arrays.params, arrays.config, reps, out)
            walls[label].append((time.perf_counter() - t0) / (reps * n_cells))
            if not np.all(np.isfinite(out)):
                raise FloatingPointError(f"Laguerre {label}: non-finite RHS in the sweep")
    us = {label: 1e6 * statistics.median(w) for label, w in walls.items()}
    first = us[cases[0][0]]
    return [{"variant": label, "us_per_rhs": us[label], "ratio": us[label] / first,
             "cells": n_cells, "rounds": rounds} for label, _, _ in cases]


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
    variants = weight_variant_costs(n_cells=500 if quick else 2000, rounds=1 if quick else 3,
                                    target_evals=10_000 if quick else 100_000)
    for v in variants:
        _say(quiet, f"  Laguerre m=3 {v['variant']}: {v['us_per_rhs']:.3g} us per RHS "
             f"({v['ratio']:.2f}x)")
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows,
              "weight_variants": variants}
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
              "Theta-interpolated tensor. Machine: " + _machine_line(result["machine"]) + ".",
              "", "| weight variant (m = 3) | us per RHS | ratio |", "|---|---|---|"]
    lines += [f"| {v['variant']} | {v['us_per_rhs']:.3g} | {v['ratio']:.2f}x |"
              for v in variants]
    lines += ["", f"Seed throughput scene, the same {variants[0]['cells']} cell states for "
              "every variant, one tensor slice, 1 thread, median of "
              f"{variants[0]['rounds']} alternating rounds."]
    _write_simple(Path(out_dir), LAGUERRE_STUDY, rows, "\n".join(lines) + "\n", result)
    return result
