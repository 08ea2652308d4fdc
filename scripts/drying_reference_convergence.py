"""Does the independent reference of the spray-then-dry comparison resolve its own model?

    python scripts/drying_reference_convergence.py N:R:F [N:R:F ...]
    # e.g. 2000:8:0.2 2000:8:0.05 2000:8:0.01 500:32:0.2 1000:16:0.2 4000:8:0.2 8000:4:0.2

Runs tests/references/cnmc_drying.py (N particles x R replicas, seed 2026, the test's) over
the spray-then-dry scene of tests/methods/test_methods_drying.py with its RK4 drift steps at
most F times the smallest liquid time b / e (the reference's own F is 0.2), and prints M00,
M10, M01, M11, M02 and the evaporated liquid with their 95% half-widths at 5, 10, ..., 30 s
(SI: 1/m3, kg^(i+j)/m3, kg/m3). Same seed, other F: the constant kernel's event sequence does
not depend on the drift, so the runs are paired and any difference is the time step's.
Results: docs/physics.md section 15, "The reference's own resolution".
"""
import math
import sys
import time
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for folder in ("tests", "tests/methods", "tests/physics"):
    sys.path.insert(0, str(ROOT / folder))

import test_methods_drying as T                   # noqa: E402  the scene, fixed there
from references import cnmc_drying as R           # noqa: E402
from test_drying import N0, P0, RHO_S             # noqa: E402

from pbe_cfd.physics import drying                # noqa: E402  (the gas state only)

SHOWN = ("M00", "M10", "M01", "M11", "M02", "liquid_evaporated")


def _case():
    s = T.SPRAY_DRY
    air = s["air"]
    rho, mu, dv, _, drv = drying.gas_state(air["air_temperature"], air["air_humidity"], 101325.0)
    return dict(gas=dict(rho=rho, mu=mu, diffusivity=dv, driving=drv), slip=air["slip_velocity"],
                rho_s=RHO_S, rho_l=1000.0, x_cr=air["critical_moisture"], x_eq=0.0, k0=s["k0"],
                n0=N0, p0=P0, y0=s["y0"], droplet_mass=1000.0 * math.pi / 6.0 * s["d_drop"] ** 3,
                solids_fraction=s["solids"], rate=s["rate"], start=0.0, stop=s["stop"])


def _with_step(factor):
    """The reference module with its RK4 step factor 0.2 replaced by ``factor``."""
    if factor == 0.2:
        return R
    src = Path(R.__file__).read_text()
    assert "0.2 * np.min" in src
    module = types.ModuleType("cnmc_drying_step")
    exec(src.replace("0.2 * np.min", f"{factor!r} * np.min"), module.__dict__)
    return module


def main(args):
    case = _case()
    times = np.arange(0.0, T.SPRAY_DRY["end"] + 0.5, 1.0)
    cols = [R.NAMES.index(n) for n in SHOWN]
    for arg in args:
        n, reps, factor = arg.split(":")
        start = time.time()
        mean, half = _with_step(float(factor)).ensemble(case, int(n), int(reps), T.REF_SEED, times)
        print(f"N={n} replicas={reps} step={factor} wall={time.time() - start:.0f}s", flush=True)
        for k in range(5, len(times), 5):
            print(f"  t={times[k]:4.0f} " + " ".join(
                f"{R.NAMES[c]}={mean[k, c]:.5e}+-{half[k, c]:.1e}" for c in cols), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["500:4:0.2"])
