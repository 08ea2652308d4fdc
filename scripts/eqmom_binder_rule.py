"""EQMOM's binder per kernel against the conditional rule, measured on the binder moments.

    python scripts/eqmom_binder_rule.py [OUT.json]

On the Laguerre ROM suite's six droplet cases (tests/methods/laguerre/laguerre_suite.py: a dry
start, binder arriving only with droplets, aggregation + power-law breakage), runs QMOM N = 3
(one binder value per node), CQMOM 3 x 2 and 3 x 3 (conditional binder nodes per size node)
and EQMOM N = 2, 3 (one binder fraction per kernel), and compares M00, M10, M20, M01, M11,
M21, M02 and M12 with the suite's independent bivariate cNMC (tests/references/cnmc_bivariate.py,
2000 granules x 8 replicas, the suite's seed) at half the end time and at the end time.
Prints one JSON line per case: the reference's 95% half-width per moment ("band", relative),
each method's largest relative deviation per moment (or the one-line reason it stopped) and its
wall time [s]. Docs: docs/results/eqmom.md, "Binder per kernel against the conditional rule".
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "methods" / "laguerre"))
import laguerre_suite as S  # noqa: E402
import cnmc_bivariate  # noqa: E402  (on the path laguerre_suite sets)

METHODS = {"qmom N=3": {"name": "qmom", "nodes": 3},
           "cqmom 3x2": {"name": "cqmom", "nodes": 3, "binder_nodes": 2},
           "cqmom 3x3": {"name": "cqmom", "nodes": 3, "binder_nodes": 3},
           "eqmom N=2": {"name": "eqmom", "nodes": 2},
           "eqmom N=3": {"name": "eqmom", "nodes": 3}}
NAMES = ("M00", "M10", "M20", "M01", "M11", "M21", "M02", "M12")


def run(case, method, t_end):
    """({name: values at (t_end / 2, t_end)} or the reason it stopped, wall seconds)."""
    from pbe_cfd.runs.simulate import run_well_mixed
    t0 = time.time()
    try:
        c = run_well_mixed(S.scene(case, method, t_end)).columns
    except Exception as exc:                  # a stop is a result of the study
        return str(exc).splitlines()[0][:200], time.time() - t0
    t = np.asarray(c["time_s"])
    if abs(t[-1] - t_end) > 1e-9 * t_end:
        return "stopped at t = %.4g s" % t[-1], time.time() - t0
    return ({n: np.interp([0.5 * t_end, t_end], t, c[n]) for n in NAMES if n in c},
            time.time() - t0)


def measure():
    rows = []
    for case in S.cases():
        if not case["droplets"]:
            continue                          # a uniform binder fraction: every rule is exact
        t_end, _ = S.end_time(case)
        times = np.array([0.5 * t_end, t_end])
        spec = {"kernel": case["kernel"], "k0": case["k0"], "p_ref": S.P0, "s0": case["s0"],
                "exponent": case["exponent"], "daughters": case["daughters"],
                "factor": S.FACTOR, "p_d": S.droplet_mass(), "rate": S.INJECTION,
                "mean": S.P0, "y0": 0.0, "n0": S.N0, "nd0": S.ND0_SHARE * S.N0}
        mean, half = cnmc_bivariate.ensemble(spec, S.CNMC_PARTICLES, S.CNMC_REPLICAS,
                                             S.CNMC_SEED, times)
        ref = {n: mean[:, int(n[1]), int(n[2])] for n in NAMES}
        row = {"case": case["name"], "t_end": t_end,
               "band": {n: float(np.max(half[:, int(n[1]), int(n[2])] / np.abs(ref[n])))
                        for n in NAMES}}
        for label, method in METHODS.items():
            res, seconds = run(case, method, t_end)
            row[label] = res if isinstance(res, str) else {
                n: float(np.max(np.abs(res[n] / ref[n] - 1.0))) for n in res}
            row[label + " s"] = seconds
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


if __name__ == "__main__":
    rows = measure()
    if len(sys.argv) > 1:
        Path(sys.argv[1]).write_text(json.dumps(rows, indent=1))
