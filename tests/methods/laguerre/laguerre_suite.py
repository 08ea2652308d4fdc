"""The Laguerre ROM's held-out suite: aggregation with power-law breakage over the time the
mean mass grows 10x, against independent references (docs/results/laguerre.md).

The suite was fixed before any method was run on it (the classic combinations of Marchisio,
Vigil and Fox 2003): kernels constant, sum and eke; selection S = s0 (p / P0)^a with
a = 1/3, 1, 2; uniform and equal-halves daughters; with and without binder droplets. Twelve
cases: for kernel r (0, 1, 2) the exponent a_k takes the pattern P[(k + r) mod 3] of
P = ((uniform, no droplets), (equal, no droplets), (uniform, droplets)), and a fourth case per
kernel is (equal, droplets) at a = (1, 2, 1/3)[r].

Common start: exponential masses, N0 = 1e10 /m3, mean P0 = 1e-9 kg, density 1000 kg/m3.
k0 per kernel so that beta(P0, P0) N0 = 1 /s (constant 1e-10 m3/s, sum 0.05 m3/(kg s), eke
1e-10 / (4 sqrt 2) m3/s, eke sizes normalised by P0). s0 = 0.2 nu10 / 10^a: breakage at the
10x mean mass a fifth of the aggregation frequency there, nu10 = beta(10 P0, 10 P0) N0 / 10
(+ the sum kernel's k0 M10 share): constant 0.1, sum 1.0, eke 0.1468 /s.
Without droplets: binder fraction y0 = 0.25 in every granule (M_ij = y0^j M_(i+j),0 for all
t), reference the fixed-pivot sectional solver (16 pivots per octave, P0 1e-4 .. 3e3, the
sum kernel's to 3e5), end time the first time its M10 / M00 reaches 10 P0.
With droplets: a dry start (y0 = 0), free droplets of p_d = 0.2 P0 (nd0 = 0.1 N0 at t = 0,
injected at R = 1e9 /(m3 s)), captured at f = 10 times the kernel; reference the bivariate
cNMC (tests/references/cnmc_bivariate.py: 2000 granules x 8 replicas, seed fixed before
looking), end time that of the same case without droplets.
Compared: M00, M10, M01, M20, M11, M02 (free droplets included, as the output columns) at half
the end time and at the end time.

Run ``python tests/methods/laguerre/laguerre_suite.py`` to print the table of
docs/results/laguerre.md.
"""
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
TESTS = os.path.join(HERE, "..", "..")
sys.path.insert(0, TESTS)                        # conftest's make_scene
sys.path.insert(0, os.path.join(TESTS, "references"))

import cnmc_bivariate  # noqa: E402
import sectional  # noqa: E402
import sectional_kernels  # noqa: E402

N0, P0, Y0 = 1.0e10, 1.0e-9, 0.25
RHO = 1000.0
K0 = {"constant": 1.0e-10, "sum": 0.05, "eke": 1.0e-10 / (4.0 * math.sqrt(2.0))}
NU10 = {"constant": 0.1, "sum": 1.0, "eke": 0.1468}
PD_SHARE, ND0_SHARE, INJECTION, FACTOR = 0.2, 0.1, 1.0e9, 10.0
EXPONENTS = (1.0 / 3.0, 1.0, 2.0)
PATTERN = (("uniform", False), ("equal", False), ("uniform", True))
MOMENTS = ("M00", "M10", "M01", "M20", "M11", "M02")
CNMC_PARTICLES, CNMC_REPLICAS, CNMC_SEED = 2000, 8, 2612
TARGET = 0.05


def _case(kernel, a, daughters, droplets):
    return {"kernel": kernel, "exponent": a, "daughters": daughters, "droplets": droplets,
            "k0": K0[kernel], "s0": 0.2 * NU10[kernel] / 10.0 ** a,
            "name": "%s a=%s %s%s" % (kernel, {1 / 3: "1/3", 1.0: "1", 2.0: "2"}[a],
                                      daughters, " +droplets" if droplets else "")}


def cases():
    out = []
    for r, kernel in enumerate(("constant", "sum", "eke")):
        for k, a in enumerate(EXPONENTS):
            daughters, droplets = PATTERN[(k + r) % 3]
            out.append(_case(kernel, a, daughters, droplets))
        out.append(_case(kernel, (1.0, 2.0, 1.0 / 3.0)[r], "equal", True))
    return out


def droplet_mass():
    return PD_SHARE * P0


def droplet_diameter():
    return (6.0 * droplet_mass() / (math.pi * RHO)) ** (1.0 / 3.0)


# ---------------------------------------------------------------------------- references
#: the top pivot [P0] per kernel: the grid must hold the population (under 1e-3 of the mass
#: on its top decade, checked per case); the sum kernel's tail reaches further
P_TOP = {"constant": 3e3, "sum": 3e5, "eke": 3e3}


def _pivots(per_octave=16, kernel="constant"):
    return sectional.pivots(P0 * 1e-4, P0 * P_TOP[kernel], per_octave)


#: a bound on the end time [s] per kernel: four times pure aggregation's time to 10x
T_MAX = {"constant": 80.0, "sum": 20.0, "eke": 80.0}


def end_time(case):
    """(First time [s] the sectional reference of the case without droplets reaches a 10x
    mean mass, its dense output N(t))."""
    x = _pivots(kernel=case["kernel"])
    n0 = sectional.initial_exponential(x, N0, P0)
    return sectional_kernels.time_of_growth(x, n0, case["kernel"], case["k0"], case["s0"],
                                            case["exponent"], P0, case["daughters"], 10.0,
                                            T_MAX[case["kernel"]])


def reference(case, t_end, dense):
    """({name: array over (t_end / 2, t_end)} of the reference's moments [SI], the reference's
    own relative error band per moment (cNMC: its 95% half-width; sectional: the grid error
    estimated from a second grid of half the resolution), extra facts)."""
    times = np.array([0.5 * t_end, t_end])
    if not case["droplets"]:
        x = _pivots(kernel=case["kernel"])
        N = np.array([dense(t) for t in times])
        top = sectional.top_mass_share(x, N)
        M = sectional.moments(x, N, 2)
        # the grid's own error, second order in the pivot spacing: Richardson's estimate
        # |M(8 per octave) - M(16 per octave)| / 3
        xc = _pivots(8, case["kernel"])
        Mc = sectional.moments(xc, sectional_kernels.solve(
            xc, sectional.initial_exponential(xc, N0, P0), times, case["kernel"], case["k0"],
            case["s0"], case["exponent"], P0, case["daughters"]), 2)
        out, band = {}, {}
        for n in MOMENTS:
            k, j = int(n[1]) + int(n[2]), int(n[2])
            out[n] = Y0 ** j * M[:, k]
            band[n] = np.abs(Mc[:, k] / M[:, k] - 1.0) / 3.0
        return out, band, {"top_mass_share": top}
    spec = {"kernel": case["kernel"], "k0": case["k0"], "p_ref": P0, "s0": case["s0"],
            "exponent": case["exponent"], "daughters": case["daughters"],
            "factor": FACTOR, "p_d": droplet_mass(), "rate": INJECTION,
            "mean": P0, "y0": 0.0, "n0": N0, "nd0": ND0_SHARE * N0}
    mean, half = cnmc_bivariate.ensemble(spec, CNMC_PARTICLES, CNMC_REPLICAS, CNMC_SEED,
                                         times)
    out = {n: mean[:, int(n[1]), int(n[2])] for n in MOMENTS}
    band = {n: half[:, int(n[1]), int(n[2])] / np.abs(out[n]) for n in MOMENTS}
    return out, band, {}


# ---------------------------------------------------------------------------- the methods
def scene(case, method, t_end):
    from conftest import make_scene
    aggregation = {"kernel": case["kernel"], "rate": case["k0"]}
    initial = {"distribution": "exponential", "number_density": N0, "mean_mass": P0,
               "binder_fraction": 0.0 if case["droplets"] else Y0}
    tables = {}
    if case["droplets"]:
        aggregation["droplet_factor"] = FACTOR
        initial["droplet_number_density"] = ND0_SHARE * N0
        tables["binder_injection"] = {"rate": INJECTION,
                                      "droplet_diameter": droplet_diameter()}
    return make_scene(scene={"end_time": t_end, "output_interval": 0.5 * t_end},
                      initial=dict(initial, _replace=True), aggregation=aggregation,
                      breakage={"selection": "power", "rate": case["s0"],
                                "exponent": case["exponent"],
                                "daughters": case["daughters"]},
                      method=dict(method, _replace=True), **tables)


METHODS = {"laguerre m=3": {"name": "laguerre", "order": 3},
           "laguerre m=3 following": {"name": "laguerre", "order": 3,
                                      "following_support": True},
           "qmom N=3": {"name": "qmom", "nodes": 3}}
#: measured beside the suite on the droplet cases (a dry start): the dry class's weight shape
DRY_SHAPE_VARIANT = ("laguerre m=3 following, dry shape 2",
                     {"name": "laguerre", "order": 3, "following_support": True,
                      "dry_weight_shape_mass": 2.0})


def run_method(case, method, t_end):
    """{name: array over (t_end / 2, t_end)} of the method's output columns, or the one-line
    reason it stopped."""
    from pbe_cfd.runs.simulate import run_well_mixed
    try:
        c = run_well_mixed(scene(case, method, t_end)).columns
    except Exception as exc:                  # a stop is a result of the suite
        return str(exc).splitlines()[0][:200]
    t = np.asarray(c["time_s"])
    if abs(t[-1] - t_end) > 1e-9 * t_end:
        return "stopped at t = %.4g s" % t[-1]
    return {n: np.interp([0.5 * t_end, t_end], t, c[n]) for n in MOMENTS}


def errors(run, ref):
    """{name: max over the two times of |method / reference - 1|}."""
    return {n: float(np.max(np.abs(run[n] / ref[n] - 1.0))) for n in MOMENTS}


def measure(selected=None):
    rows = []
    for case in cases():
        if selected and case["name"] not in selected:
            continue
        t0 = time.time()
        t_end, dense = end_time(case)
        ref, band, info = reference(case, t_end, dense)
        row = {"case": case["name"], "t_end": t_end, "band": {n: float(band[n].max())
                                                           for n in MOMENTS}, **info}
        row["reference"] = {n: [float(v) for v in ref[n]] for n in MOMENTS}
        variants = list(METHODS.items()) + ([DRY_SHAPE_VARIANT] if case["droplets"] else [])
        for label, method in variants:
            run = run_method(case, method, t_end)
            row[label] = run if isinstance(run, str) else errors(run, ref)
        row["seconds"] = time.time() - t0
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def table(rows):
    lines = ["| case | t_end [s] | ref. band | " + " | ".join(METHODS) + " |",
             "|---|---|---|" + "---|" * len(METHODS)]
    for r in rows:
        cells = []
        for label in METHODS:
            e = r[label]
            if isinstance(e, str):
                cells.append("stops: " + e[:60])
            else:
                worst = max(e, key=e.get)
                cells.append("%.1f%% (%s)" % (100 * e[worst], worst))
        lines.append("| %s | %.3g | %.1f%% | %s |" % (r["case"], r["t_end"],
                                                      100 * max(r["band"].values()),
                                                      " | ".join(cells)))
    return "\n".join(lines)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else None
    rows = measure(sys.argv[2:])
    if out:
        with open(out, "w") as fh:
            json.dump(rows, fh, indent=1)
    print(table(rows))
