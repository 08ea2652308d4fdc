"""Why the Laguerre ROM stops on a sprayed, drying cell: the RHS of its last good state split
by term (docs/results/batch.md, "With CQMOM and the Laguerre ROM").

Runs a well-mixed scene (one cell) in output intervals until the integrator stops, keeps the
last state it reached, and splits that state's RHS into the drying term (config DRYING on
against off), the injection (the cell's injection on against 0) and the rest (aggregation),
entry by entry; then the margins of the b <= p conditions W(i,j+1) <= W(i+1,j) with their
rates, and the wet class's relative evaporation rate (evaporation over the liquid held) against
the fastest a particle of the scene can have: the falling-rate period of the smallest dry mass
(a dried droplet residue, s p_d), e_c / ((X_cr - X_eq) s p_d).

    python scripts/laguerre_drying_stop.py SCENE.toml [--end 0.75] [--interval 0.01]
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np


def last_good_state(scene):
    """(time [s], scaled state, problem, batch) of the last output time the run reached."""
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.runs.problem import problem_of
    problem = problem_of(scene)
    batch = CellBatch.for_problem(problem)
    times = problem.times
    last, t_last = problem.states[0].copy(), 0.0
    for k in range(1, len(times)):
        try:
            batch.step(times[k - 1], times[k])
        except Exception as err:                     # the stop is what is looked for
            print(f"stopped in ({times[k - 1]:g}, {times[k]:g}] s: {str(err)[:160]}")
            break
        last, t_last = batch.states[0].copy(), float(times[k])
    return t_last, last, problem, batch


def split(state, problem, batch):
    """(total, drying, injection) RHS of the state [scaled units per s]."""
    from pbe_cfd.methods.entry import WORK_SIZE
    from pbe_cfd.methods.laguerre.rhs import laguerre_rhs
    from pbe_cfd.physics import parameters as P
    aux, config = problem.aux, problem.arrays.config
    cell = np.ascontiguousarray(problem.rows[0], dtype=float)
    params = np.ascontiguousarray(batch.params, dtype=float)
    work = np.empty(WORK_SIZE)

    def rate(cfg, row):
        out = np.zeros(len(state))
        laguerre_rhs(state, out, row, aux, params, cfg, work)
        return out
    total = rate(config, cell)
    no_drying = config.copy()
    no_drying[P.DRYING] = 0
    no_spray = cell.copy()
    no_spray[P.INJECTION] = 0.0
    return total, total - rate(no_drying, cell), total - rate(config, no_spray)


def fastest_relative_rate(arrays):
    """e / b [1/s] of a dried droplet residue (dry mass s p_d) in its falling-rate period."""
    from pbe_cfd.physics import parameters as P
    from pbe_cfd.physics.drying import drying_rate, scene_gas
    q = arrays.params
    dry = q[P.DROPLET_SOLIDS] * q[P.DROPLET_MASS]
    b = 0.5 * (q[P.DRY_CRITICAL] + q[P.DRY_EQUILIBRIUM]) * dry
    return drying_rate(dry + b, b, scene_gas(q), q) / b


def main(argv=None):
    from pbe_cfd.scene.scene import load_scene
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--end", type=float, default=0.75, help="end time [s]")
    ap.add_argument("--interval", type=float, default=0.01, help="output interval [s]")
    args = ap.parse_args(argv)
    scene = dataclasses.replace(load_scene(args.scene), end_time=args.end,
                                output_interval=args.interval)
    t, state, problem, batch = last_good_state(scene)
    names = problem.arrays.state_names
    total, drying, spray = split(state, problem, batch)
    print(f"last good state at t = {t:g} s (scaled units; per s)")
    print(f"{'entry':18s} {'state':>11s} {'total':>11s} {'drying':>11s} {'injection':>11s}"
          f" {'rest':>11s}")
    for k, n in enumerate(names):
        print(f"{n:18s} {state[k]: .4e} {total[k]: .4e} {drying[k]: .4e} {spray[k]: .4e}"
              f" {total[k] - drying[k] - spray[k]: .4e}")
    m = int(problem.scene.method.options.order)
    for i in range(m - 1):
        for j in range(m - 1):
            hi, lo = (i + 1) * m + j, i * m + j + 1
            gap, closing = state[hi] - state[lo], total[hi] - total[lo]
            left = gap / -closing if closing < 0 else float("inf")
            print(f"W{i}{j + 1} <= W{i + 1}{j}: margin {gap: .4e}, its rate {closing: .4e}"
                  f" (drying {drying[hi] - drying[lo]: .4e}), closes in {left:.3g} s")
    liquid = names.index("wet_M01")
    print(f"wet class: evaporation / liquid held = {-drying[liquid] / state[liquid]:.4g} 1/s; "
          f"fastest particle of the scene (a dried droplet residue, falling rate): "
          f"{fastest_relative_rate(problem.arrays):.4g} 1/s")


if __name__ == "__main__":
    main()
