"""Run the independent particle-list reference on the cases of psd_cases.py and write its
percentiles, Q3 on GRID and moments as JSON (python psd_reference_run.py OUT.json [case ...]).
"""
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "references"))
import cnmc_particles  # noqa: E402
import psd_cases  # noqa: E402

#: the diameter grid [m] of the reference's Q3: 1 um .. 5 mm, 60 points per decade
GRID = np.geomspace(1e-6, 5e-3, int(round(60 * np.log10(5e3))) + 1)


def run(case, particles=None, replicas=None, seed=None):
    """{percentiles, percentiles_half [m] (3,), q3, q3_half on GRID, moments, moments_half,
    particles, replicas, seed, seconds} at the case's end time."""
    n, r, s = psd_cases.REFERENCE_RUN[case]
    n, r, s = particles or n, replicas or r, seed or s
    t0 = time.time()
    e = cnmc_particles.ensemble(psd_cases.reference_spec(case), n, r, s,
                                [psd_cases.END[case]], grid=GRID)
    return {"percentiles": e["percentiles"][0][-1].tolist(),
            "percentiles_half": e["percentiles"][1][-1].tolist(),
            "q3": e["q3"][0][-1].tolist(), "q3_half": e["q3"][1][-1].tolist(),
            "moments": e["moments"][0][-1].tolist(), "moments_half": e["moments"][1][-1].tolist(),
            "particles": n, "replicas": r, "seed": s, "seconds": time.time() - t0}


if __name__ == "__main__":
    out = {"grid_m": GRID.tolist()}
    for case in sys.argv[2:] or psd_cases.CASES:
        out[case] = run(case)
        print(case, np.round(np.array(out[case]["percentiles"]) * 1e6, 2),
              "+-", np.round(np.array(out[case]["percentiles_half"]) * 1e6, 2),
              "%.0f s" % out[case]["seconds"], flush=True)
        with open(sys.argv[1], "w") as fh:
            json.dump(out, fh)
