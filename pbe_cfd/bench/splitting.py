"""The splitting study: what the operator-splitting step of transport costs and how far it
moves the bed moments (a part of ``pbe-cfd bench integrators``).

The bundled ``fluid-bed-transport`` scene with Strang splitting at split steps of 0.25 s (its
own), 0.5 s and 1 s, and Lie at 0.25 s, each against a Strang reference at 0.0625 s (Strang's
error is O(h^2), so the reference's own splitting error is about 1/16 of the 0.25 s run's; the
differences below are those errors to within about 7%). Per variant, in one process after a
warm-up run: the run's CPU time (process time of ``run_coupled``, every thread), its solve
phase [s], the RHS calls, the split steps, and the largest relative difference from the
reference over every output time of the bed's M00, M20, M11, M02, d43 and free droplets.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..scene.scene import load_scene
from .common import _say

#: (splitting, split step [s]) of the variants, and of the reference
VARIANTS = (("strang", 0.25), ("strang", 0.5), ("strang", 1.0), ("lie", 0.25))
REFERENCE = ("strang", 0.0625)
#: bed columns compared with the reference
COMPARED = ("M00", "M20", "M11", "M02", "d43_m", "droplet_number_density")


def _max_rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.abs(b) > 0
    return float(np.max(np.abs(a[ok] - b[ok]) / np.abs(b[ok]))) if ok.any() else 0.0


def splitting_rows(quiet=False, quick=False) -> list:
    """One row per variant (and the reference): CPU [s], solve phase [s], RHS calls, split
    steps and the largest relative difference of each COMPARED bed column from the
    reference (quick: the first 10 s of the scene)."""
    from ..runs.couple import run_coupled
    from ..runs.domain import load_domain
    base = load_scene("fluid-bed-transport")
    if quick:
        base = dataclasses.replace(base, end_time=10.0, output_interval=5.0)
    domain = load_domain(base, need_flux=True)
    run_coupled(dataclasses.replace(base, end_time=base.output_interval), domain)  # warm-up
    results = {}
    for kind, h in (REFERENCE,) + VARIANTS:
        scene = dataclasses.replace(base, transport=dataclasses.replace(
            base.transport, splitting=kind, split_step=h))
        cpu0 = time.process_time()
        res = run_coupled(scene, domain)
        results[(kind, h)] = (time.process_time() - cpu0, res)
        _say(quiet, f"  splitting {kind} {h:g} s: {results[(kind, h)][0]:.3g} s CPU, "
             f"{res.stats['rhs_calls']} RHS")
    ref = results[REFERENCE][1].bed_columns
    rows = []
    for (kind, h), (cpu, res) in results.items():
        row = {"splitting": kind, "split_step_s": h, "reference": (kind, h) == REFERENCE,
               "cpu_s": cpu, "solve_s": res.phases["solve_s"],
               "rhs_calls": res.stats["rhs_calls"],
               "accepted_steps": res.stats["accepted_steps"],
               "split_steps": res.stats["transport"]["split_steps"]}
        for key in COMPARED:
            row[f"max_rel_{key}"] = _max_rel(res.bed_columns[key], ref[key])
        rows.append(row)
    return rows


def splitting_markdown(rows, plain_rhs=None) -> list:
    """The study's table (Markdown lines); ``plain_rhs``: RHS calls of the scene without
    [transport], for the ratio column."""
    head = " / ".join(k.replace("_m", "").replace("droplet_number_density", "droplets")
                      for k in COMPARED)
    lines = ["", f"| fluid-bed-transport splitting | split step [s] | run CPU [s] | solve "
             f"[s] | RHS calls{' (x no transport)' if plain_rhs else ''} | max rel. "
             f"difference from the reference: {head} |", "|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f" ({r['rhs_calls'] / plain_rhs:.1f})" if plain_rhs else ""
        diffs = " / ".join(f"{r[f'max_rel_{k}']:.1e}" for k in COMPARED)
        label = f"{r['splitting']}{' (reference)' if r['reference'] else ''}"
        lines.append(f"| {label} | {r['split_step_s']:g} | {r['cpu_s']:.3g} | "
                     f"{r['solve_s']:.3g} | {r['rhs_calls']}{ratio} | {diffs} |")
    lines += ["", "Splitting: Strang = transport h/2, sources h, transport h/2; the "
              "reference is Strang at 0.0625 s. The RHS calls fall more slowly than the split "
              "steps: every source part opens on the transient of the droplets the transport "
              "part carried into dense cells."]
    return lines
