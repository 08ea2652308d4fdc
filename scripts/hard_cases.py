"""The hard case of docs/results/hard-cases.md, one variant per line of JSON.

    python scripts/hard_cases.py --method qmom --theta 2 --width 0 --rtol 1e-8 >> rows.jsonl

A well-mixed ktgf cell (study-ktgf: friction cap 0.5) at solids fraction ``--alpha`` (default
0.6199, packing 0.62), granular temperature ``--theta`` [m2/s2], k0 = 1e-3, binder injected at
1e4 x the seed rate, 20 s with outputs every 2 s, the viscous Stokes criterion sharp
(``--width 0``, the default) or smooth of the width given; the [method] table of the method's
seed scene (QMOM: study-ktgf's N = 3, EQMOM: the same N = 3; cNMC with ``--particles`` x ``--replicas``). Prints one
JSON object: whether it finished, the time reached or the stop message, wall time [s], the
final M00 [1/m3], M20 [kg2/m3], d43 [m], whether the cell was smoothed, the accepted steps.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np

from pbe_cfd.runs.batch import SimulationError
from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.scene.scene import SceneError, load_scene
from pbe_cfd.runs.simulate import run_well_mixed

SEED_RATE = 1.485e8          # droplets/(m3 s), seed 000
SOURCES = {"qmom": "study-ktgf", "cqmom": "seed-wurster-cqmom",
           "laguerre": "seed-wurster-laguerre", "cnmc": "seed-wurster-cnmc",
           "eqmom": "study-ktgf"}


def hard_scene(method, theta, alpha, width, rtol, particles=2000, replicas=4):
    """The hard case with the [method] table of ``SOURCES[method]`` (see the module doc)."""
    s = load_scene("study-ktgf")
    m = load_scene(SOURCES[method]).method
    if method == "cnmc":
        m = m.replaced(particles=particles, replicas=replicas)
    if method == "eqmom":       # no bundled scene: study-ktgf's N = 3 as gamma EQMOM
        m = m.replaced(name="eqmom")
    return dataclasses.replace(
        s, end_time=20.0, output_interval=2.0,
        domain=dataclasses.replace(s.domain, solids_fraction=alpha, granular_temperature=theta),
        aggregation=dataclasses.replace(s.aggregation, rate=1e-3),
        binder_injection=dataclasses.replace(s.binder_injection, rate=1e4 * SEED_RATE),
        material=dataclasses.replace(s.material, stokes_switch_width=width),
        method=dataclasses.replace(m, rtol=rtol, atol=1e-14 * rtol / 1e-8))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", choices=sorted(SOURCES), default="qmom")
    ap.add_argument("--theta", type=float, default=2.0)
    ap.add_argument("--alpha", type=float, default=0.6199)
    ap.add_argument("--width", type=float, default=0.0)
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--end", type=float, default=20.0, help="end time [s] (outputs: 10)")
    ap.add_argument("--outputs", type=int, default=10, help="number of output intervals")
    ap.add_argument("--series", action="store_true",
                    help="also print time_s, M00 [1/m3] and d43 [m] at every output "
                         "(series_*)")
    ap.add_argument("--particles", type=int, default=2000)
    ap.add_argument("--replicas", type=int, default=4)
    a = ap.parse_args(argv)
    scene = hard_scene(a.method, a.theta, a.alpha, a.width, a.rtol, a.particles, a.replicas)
    scene = dataclasses.replace(scene, end_time=a.end, output_interval=a.end / a.outputs)
    row = {"method": a.method, "theta": a.theta, "alpha": a.alpha, "width": a.width,
           "rtol": a.rtol}
    start = time.perf_counter()
    try:
        res = run_well_mixed(scene)
    except (SimulationError, SceneError, FloatingPointError) as exc:
        row.update(finished=False, stop=str(exc), wall_s=time.perf_counter() - start)
    else:
        c = res.columns
        pd = droplet_mass(60e-6, 1000.0)
        mass_err = float(np.max(np.abs(c["M10"] - (c["M10"][0] + 1e4 * SEED_RATE * pd
                                                   * c["time_s"])) / c["M10"]))
        row.update(finished=True, wall_s=time.perf_counter() - start,
                   t_end=float(c["time_s"][-1]),
                   finite=bool(all(np.all(np.isfinite(c[k])) for k in ("M00", "M10", "M20"))),
                   M00=float(c["M00"][-1]), M20=float(c["M20"][-1]),
                   d43=float(c["d43_m"][-1]), M10_rel_err=mass_err,
                   smoothed=int(res.stats.get("smooth_stokes_cells", 0)),
                   accepted_steps=int(res.stats.get("accepted_steps", 0)),
                   stokes_switch_steps=int(res.stats.get("stokes_switch_steps", 0)),
                   warnings=[w[:160] for w in res.warnings])
        if a.series:
            row.update({"series_" + k: [float(v) for v in c[k]]
                        for k in ("time_s", "M00", "d43_m")})
    print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
