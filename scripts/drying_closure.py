"""How well a QMOM quadrature integrates the evaporation rate of a population it did not make.

    python scripts/drying_closure.py [k0]       # k0 [m3/s] of the constant kernel, default 2e-11
    python scripts/drying_closure.py [k0] --bounds   # and what the carried moments allow
    python scripts/drying_closure.py [k0] --bounds --second   # ... and M_k2, k < N too

Runs one box of the independent cNMC (tests/references/cnmc_drying.py, 2000 particles, seed 7)
over the spray-then-dry scene of tests/methods/test_methods_drying.py and, at a few output
times, compares the box's exact evaporation rate sum_i e(p_i, b_i) [kg/(m3 s)] with the rate of
the N-node QMOM quadrature of the same box: nodes and weights from its M_k0 (k < 2N), each
node's liquid b_a from its M_k1 (k < N), the rate e(p_a, b_a) summed with the weights, the
liquid clipped to [0, p_a] as ``methods/quadrature/drying_sources.py`` does. The rate function
is the reference's own, so what is measured is the closure alone (no time integration, no
method code). Prints, per time, the box's liquid M01 [kg/m3] and, per N, the relative error of
the quadrature's rate and the nodes' liquid fractions b_a / p_a.

With ``--bounds``, also the range of the evaporation rate over every positive population that
has the box's carried moments (M_k0, k < 2N, and M_k1, k < N, each to a relative 1e-4): a
linear programme (scipy's HiGHS) over the weights of a grid of particles, 90 masses from
5e-12 to 6e-8 kg times 46 liquid fractions b/p (0, and 1e-4 to 0.95), minimising and
maximising the rate, printed relative to the box's exact rate. A closure of those moments can
be right only within that range; where the range is wide, its accuracy is a property of the
shape it assumes, not of the moments it carries. ``--second`` adds the moments M_k2 (k < N)
to those matched, as a method with a liquid spread per size node (CQMOM) carries.
"""
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for folder in ("tests", "tests/methods", "tests/physics"):
    sys.path.insert(0, str(ROOT / folder))

import test_methods_drying as T                   # noqa: E402  the scene, fixed there
from references import cnmc_drying as C           # noqa: E402
from test_drying import N0, P0, RHO_S             # noqa: E402

from pbe_cfd.physics import drying                # noqa: E402  (the gas state only)

TIMES = (3, 6, 10, 15, 20, 25, 30)


def _case(k0):
    s = T.SPRAY_DRY
    air = s["air"]
    rho, mu, dv, _, drv = drying.gas_state(air["air_temperature"], air["air_humidity"], 101325.0)
    return dict(gas=dict(rho=rho, mu=mu, diffusivity=dv, driving=drv), slip=air["slip_velocity"],
                rho_s=RHO_S, rho_l=1000.0, x_cr=air["critical_moisture"], x_eq=0.0, k0=k0,
                n0=N0, p0=P0, y0=s["y0"], droplet_mass=1000.0 * math.pi / 6.0 * s["d_drop"] ** 3,
                solids_fraction=s["solids"], rate=s["rate"], start=0.0, stop=s["stop"])


def _quadrature(p, b, n):
    """(nodes [kg], weights, liquid [kg]) of the n-node QMOM of the particles (p, b)."""
    scale = p.mean()
    m = np.array([np.sum((p / scale) ** k) for k in range(2 * n)])
    hankel = np.array([[m[i + j] for j in range(n)] for i in range(n)])
    shifted = np.array([[m[i + j + 1] for j in range(n)] for i in range(n)])
    x = np.sort(np.real(np.linalg.eigvals(np.linalg.solve(hankel, shifted))))
    vander = np.vander(x, n, increasing=True).T
    w = np.linalg.solve(vander, m[:n])
    mb = np.array([np.sum((p / scale) ** k * b / scale) for k in range(n)])
    liquid = np.linalg.solve(vander * w, mb)
    return x * scale, w, np.clip(liquid * scale, 0.0, x * scale)


#: the grid of the bound: masses [kg] and liquid fractions b/p [-] (the box's particles lie
#: within: dried droplet residues ~1e-11 kg, granules to ~1e-8 kg, droplets at b/p = 0.9)
BOUND_MASSES = np.geomspace(5e-12, 6e-8, 90)
BOUND_FRACTIONS = np.concatenate([[0.0], np.geomspace(1e-4, 0.95, 45)])
BOUND_TOLERANCE = 1e-4


def _bound_grid(case):
    """(masses [kg], liquids [kg], evaporation rates [kg/s]) of the bound's grid particles."""
    mass, fraction = np.meshgrid(BOUND_MASSES, BOUND_FRACTIONS, indexing="ij")
    mass, liquid = mass.ravel(), (mass * fraction).ravel()
    return mass, liquid, C._rate(mass, liquid, case)


def _rate_range(p, b, n, case, grid, second=False):
    """(lowest, highest) evaporation rate over the positive populations on the bound's grid
    (``_bound_grid``) with the box's M_k0 (k < 2n) and M_k1 (k < n), and M_k2 (k < n) if
    ``second``, relative to the box's exact rate; None where no population on the grid has
    them."""
    from scipy.optimize import linprog
    mass, liquid, rate = grid
    scale = p.mean()
    rows = [(mass / scale) ** k for k in range(2 * n)]
    targets = [np.sum((p / scale) ** k) for k in range(2 * n)]
    rows += [(mass / scale) ** k * liquid / scale for k in range(n)]
    targets += [np.sum((p / scale) ** k * b / scale) for k in range(n)]
    if second:
        rows += [(mass / scale) ** k * (liquid / scale) ** 2 for k in range(n)]
        targets += [np.sum((p / scale) ** k * (b / scale) ** 2) for k in range(n)]
    a = np.array([r / t for r, t in zip(rows, targets)])
    a_ub = np.vstack([a, -a])
    b_ub = np.concatenate([np.full(len(a), 1.0 + BOUND_TOLERANCE),
                           np.full(len(a), -(1.0 - BOUND_TOLERANCE))])
    cost = rate / C._rate(p, b, case).sum()
    low = linprog(cost, A_ub=a_ub, b_ub=b_ub, bounds=(0, None), method="highs")
    high = linprog(-cost, A_ub=a_ub, b_ub=b_ub, bounds=(0, None), method="highs")
    if low.status != 0 or high.status != 0:
        return None
    return low.fun, -high.fun


def main(k0, bounds=False, second=False):
    case = _case(k0)
    snaps = []
    moments = C._moments

    def keep(p, b, vol, evaporated):
        snaps.append((p.copy(), b.copy(), vol))
        return moments(p, b, vol, evaporated)

    C._moments = keep
    C.run_box(case, 2000, np.arange(0.0, T.SPRAY_DRY["end"] + 0.5, 1.0),
              np.random.default_rng(7))
    C._moments = moments
    print(f"k0 = {k0:g} m3/s; rate of the N-node quadrature / exact - 1 (node b/p)")
    for t in TIMES:
        p, b, vol = snaps[t]
        exact = C._rate(p, b, case).sum()
        parts = []
        for n in (2, 3, 4):
            try:
                x, w, liquid = _quadrature(p, b, n)
            except np.linalg.LinAlgError:
                parts.append(f"N={n} singular (fewer than {n} distinct particles)")
                continue
            rate = (w * C._rate(x, liquid, case)).sum()
            parts.append(f"N={n} {rate / exact - 1:+.4f} "
                         f"({np.array2string(liquid / x, precision=3)})")
        print(f"t = {t:2d} s  M01 = {b.sum() / vol:.4g}  " + " | ".join(parts))
    if not bounds:
        return
    print("range of the rate over the populations with the carried moments"
          + (" and M_k2" if second else "") + ", / exact - 1")
    grid = _bound_grid(case)
    for t in TIMES:
        p, b, _vol = snaps[t]
        parts = []
        for n in (2, 3, 4):
            found = _rate_range(p, b, n, case, grid, second)
            parts.append(f"N={n} " + ("no population on the grid" if found is None else
                                      f"[{found[0] - 1:+.3f}, {found[1] - 1:+.3f}]"))
        print(f"t = {t:2d} s  " + " | ".join(parts))


if __name__ == "__main__":
    flags = {"--bounds", "--second"}
    args = [a for a in sys.argv[1:] if a not in flags]
    main(float(args[0]) if args else T.SPRAY_DRY["k0"], bounds="--bounds" in sys.argv[1:],
         second="--second" in sys.argv[1:])
