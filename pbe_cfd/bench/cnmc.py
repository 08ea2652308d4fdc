"""The cNMC speed study: seed-scenario runs per replica (``pbe-cfd bench cnmc``)."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from ..runs import model
from ..methods.cnmc.ensemble import simulate_ensemble
from ..scene.scene import load_scene
from .common import (CNMC_STUDY, _git_describe, _machine_line, _say, _write_simple,
                     machine_info)


def cnmc_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Seed-scenario cNMC speed per replica: wall time, trials and accepted events per second
    (``seed_scenario_benchmark``, one core)."""
    sizes = (1000, 3000) if quick else (1000, 10_000, 100_000)
    end = 60.0 if quick else 600.0
    rows = []
    for n in sizes:
        _say(quiet, f"  cNMC seed scenario, {n} particles ...")
        res = seed_scenario_benchmark(particles=n, replicas=1, seed=0, end_time=end,
                                           output_interval=end / 10, verbose=False)
        r = res["result"]
        rows.append({"particles": n, "end_time_s": end, "wall_s": res["wall_s_per_replica"],
                     "trials_per_s": float(res["trials_per_s"]),
                     "accepted_per_s": float(res["accepted_per_s"]),
                     "trials": int(r["trials"]), "accepted": int(r["accepted"])})
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows}
    lines = ["| particles | simulated [s] | wall per replica [s] | trials/s | accepted/s | "
             "acceptance |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['particles']:g} | {r['end_time_s']:g} | {r['wall_s']:.3g} | "
                     f"{r['trials_per_s']:.3g} | {r['accepted_per_s']:.3g} | "
                     f"{r['accepted'] / max(r['trials'], 1):.2f} |")
    lines += ["", "Seed 000 scenario (eke, geometric + physical efficiency, droplets as their own "
              "population, injection), one replica per size, one core. Machine: "
              f"{_machine_line(result['machine'])}."]
    _write_simple(Path(out_dir), CNMC_STUDY, rows, "\n".join(lines) + "\n", result)
    return result


def seed_scenario_setup():
    """params, config, cell, initial of the seed 000 Wurster scenario (tables I-II), SI, taken
    from the bundled ``seed-wurster-cnmc`` scene (the one place those values are written)."""
    scene = load_scene("seed-wurster-cnmc")
    arrays = model.pack(scene)
    initial = dataclasses.asdict(scene.initial)     # the keys simulate_ensemble reads
    return arrays.params, arrays.config, model.well_mixed_cell(scene)[0], initial


def seed_scenario_benchmark(particles=10_000, replicas=1, seed=0, end_time=600.0,
                            output_interval=1.0, verbose=True):
    """Run the seed 000 scenario (see seed_scenario_setup) on one core and time it.

    particles: N per box; replicas: R; seed: int; end_time, output_interval [s].
    Returns {"result": simulate_ensemble's dict, "wall_s_per_replica" [s],
    "trials_per_s", "accepted_per_s" [1/s of wall time], "report": printable summary}.
    The first call includes numba compilation unless the cache is warm (it warms it with a
    tiny run first).
    """
    params, config, cell, initial = seed_scenario_setup()
    times = np.arange(0.0, end_time + 0.5 * output_interval, output_interval)
    simulate_ensemble(params, config, cell, initial, times[:3], 50, 1, seed)   # compile/warm
    t0 = time.perf_counter()
    res = simulate_ensemble(params, config, cell, initial, times, particles, replicas, seed)
    wall = time.perf_counter() - t0
    lines = [f"seed scenario: N = {particles}, R = {replicas}, {end_time:g} s, "
             f"wall {wall / replicas:.2f} s per replica",
             f"trials {int(res['trials'])} ({res['trials'] / wall:.3g}/s), accepted "
             f"{int(res['accepted'])} ({res['accepted'] / wall:.3g}/s), injections "
             f"{int(res['events_injection'])}"]
    for tq in (0.0, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0):
        if tq > end_time:
            continue
        k = int(np.argmin(np.abs(times - tq)))
        lines.append(f"t = {times[k]:6.1f} s  M00 = {res['M00'][k]:.4e} "
                     f"[{res['M00_lo'][k]:.4e}, {res['M00_hi'][k]:.4e}] 1/m3  "
                     f"n_d = {res['droplet_number_density'][k]:.3e}  "
                     f"M10 = {res['M10'][k]:.5e}  M01 = {res['M01'][k]:.5e}  "
                     f"M20 = {res['M20'][k]:.4e}  d43 = {res['d43_m'][k] * 1e6:.1f} um")
    report = "\n".join(lines)
    if verbose:
        print(report)
    return {"result": res, "wall_s_per_replica": wall / replicas,
            "trials_per_s": res["trials"] / wall, "accepted_per_s": res["accepted"] / wall,
            "report": report}
