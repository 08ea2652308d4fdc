"""Gamma-EQMOM against a fine sectional reference on aggregation + power-law breakage.

The cases were fixed before any run (issue 27): aggregation kernel constant, sum or EKE;
selection S = s0 (p / P0)^a with a = 1/3, 1, 2; uniform or equal daughters (18 cases, the full
set in the ``slow`` and ``study`` test; six of them, each kernel and each exponent twice, in
CI: about 30 s warm together). Every case:
exponential start N0 = 1e10 /m3 of mean P0 = 1e-9 kg, rho = 1000 kg/m3, s0 = 1 /s, t = 5 s;
the kernels' rates give each pair of mean granules a rate of order 1e-10 m3/s (K N0 ~ 1 /s):
constant k0 = 1e-10 m3/s, sum k0 = 0.05 m3/(kg s), EKE k0 = 1.77e-11 m3/s with v_ref the
mean granule's volume (reference_diameter = d(P0)).

Reference: tests/references/sectional_kernel_matrix.py (fixed pivots, sharing no code with
pbe_cfd) on 8 and 16 pivots per octave from 1e-4 P0 to 1e4 P0, Richardson-extrapolated for
its O(h^2) grid error: M_ref = (4 M_16 - M_8) / 3, its error estimated by |M_16 - M_8| / 3
(the grid error of M_16; the extrapolated value is better still), and requires the grid to
hold the mass (below 1e-4 of it within a factor 10 of either end). Each moment is decided
where that estimate cannot move its deviation across the 3% band (``check``); a case whose
outcome it could move is inconclusive (skipped with the numbers; the sum kernel with a = 1/3
puts mass on the finest pivots, where the fixed-pivot breakage map is coarsest, and its M30
carries a grid error of 1.3-1.9%, but the moments that decide both of its cases do not).

Claim (issue 27): on the cases where QMOM N = 3 misses M00, M10, M20 or M30 by more than 3%
at some output time (1.25 s .. 5 s), EQMOM with N = 3 kernels is within 3% of all four:
its deviation from the reference plus the reference's error estimate is below 3% (so its
error against the exact solution is, up to the integrators' rtol 1e-8). Cases where QMOM is already within 3% are reported, not asserted.
"""
import math
import os
import sys

import numpy as np
import pytest

from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "references"))
import sectional_kernel_matrix as SK  # noqa: E402

N0, P0, RHO, S0, END = 1.0e10, 1.0e-9, 1000.0, 1.0, 5.0
RATES = {"constant": 1.0e-10, "sum": 0.05, "eke": 1.77e-11}
D_REF = (6.0 * P0 / (math.pi * RHO)) ** (1.0 / 3.0)
TIMES = np.linspace(0.0, END, 5)
BAND = 0.03
MOMENTS = ("M00", "M10", "M20", "M30")

#: the full set, fixed before looking: (kernel, a, daughters)
ALL_CASES = [(k, a, d) for k in ("constant", "sum", "eke") for a in (1.0 / 3.0, 1.0, 2.0)
             for d in ("uniform", "equal")]
#: the CI subset: each kernel and each exponent twice, each daughter rule three times
CI_CASES = [("constant", 1.0 / 3.0, "uniform"), ("constant", 1.0, "equal"),
            ("sum", 1.0, "uniform"), ("sum", 2.0, "equal"),
            ("eke", 1.0 / 3.0, "equal"), ("eke", 2.0, "uniform")]


#: cases where EQMOM N = 3 misses too (measured, docs/results/eqmom.md; not tuned away). The
#: lognormal kernels miss both as well (13.35% and 3.61%; ``table()``), so none is asserted
#: for them
KNOWN_MISSES = {
    ("eke", 1.0 / 3.0, "uniform"): "EQMOM N = 3 misses M00 by 11.5% (QMOM N = 3: 25%)",
    ("eke", 1.0, "uniform"): "EQMOM N = 3 misses M00 by 3.08% (+0.18% reference error)",
    ("sum", 1.0 / 3.0, "uniform"): "EQMOM N = 3 misses M00 by 9.7% (reference error 0.04%)",
    ("sum", 1.0 / 3.0, "equal"): "EQMOM N = 3 misses M20 by 4.0% (reference error 0.35%)",
}


def case_id(case):
    k, a, d = case
    return f"{k}-a{a:.3g}-{d}"


def reference(case):
    """(moments (len(TIMES), 4) [kg^n/m3], estimated relative error (len(TIMES), 4))."""
    kernel, a, daughters = case
    out = []
    for per_octave in (8, 16):
        x = SK.pivots(P0 * 1e-4, P0 * 1e4, per_octave)
        K = SK.kernel_matrix(x, kernel, RATES[kernel], RHO, math.pi / 6.0 * D_REF ** 3)
        N = SK.solve(x, SK.initial_exponential(x, N0, P0), TIMES, K, S0, a, P0, daughters,
                     per_octave)
        low, high = SK.edge_mass_shares(x, N, fraction=0.1)
        assert low < 1e-4 and high < 1e-4, (case, low, high)
        out.append(SK.moments(x, N, 3))
    coarse, fine = out
    return (4.0 * fine - coarse) / 3.0, np.abs(fine - coarse) / 3.0 / np.abs(fine)


def method_moments(case, method, nodes, family=None):
    kernel, a, daughters = case
    agg = {"kernel": kernel, "rate": RATES[kernel]}
    if kernel == "eke":
        agg["reference_diameter"] = D_REF
    scene = make_scene(scene={"end_time": END, "output_interval": END / (len(TIMES) - 1)},
                       material={"density": RHO},
                       initial={"distribution": "exponential", "number_density": N0,
                                "mean_mass": P0},
                       aggregation=agg,
                       breakage={"selection": "power", "rate": S0, "exponent": a,
                                 "reference_mass": P0, "daughters": daughters},
                       method={"_replace": True, "name": method, "nodes": nodes,
                               **({"kernel": family} if family else {})})
    c = run_well_mixed(scene).columns
    assert np.allclose(c["time_s"], TIMES, rtol=0, atol=1e-9)
    return np.column_stack([c[m] for m in MOMENTS])


#: the runs of ``errors``: label -> (method, nodes, [method] kernel); LOGNORMAL's too in table()
RUNS = {"qmom3": ("qmom", 3, None), "eqmom3": ("eqmom", 3, None), "eqmom2": ("eqmom", 2, None)}
LOGNORMAL = {"lognormal3": ("eqmom", 3, "lognormal"), "lognormal2": ("eqmom", 2, "lognormal")}


def errors(case, runs=RUNS):
    """{'ref_error', and a label of ``runs`` each}: the largest relative deviation per moment
    over the output times after the start (arrays of 4)."""
    ref, ref_err = reference(case)
    out = {"ref_error": ref_err[1:].max(axis=0)}
    for label, (method, nodes, family) in runs.items():
        got = method_moments(case, method, nodes, family)
        out[label] = np.abs(got[1:] / ref[1:] - 1.0).max(axis=0)
    return out


def check(case):
    """Each moment is decided where the reference's error cannot move its deviation across
    the band: a miss where deviation - error >= BAND, within where deviation + error < BAND.
    A case misses on one decided miss; it is inconclusive (skipped with the numbers) where
    QMOM's miss or EQMOM's outcome is not decided."""
    e = errors(case)
    print(case_id(case), {k: np.round(100 * v, 3).tolist() for k, v in e.items()})
    err = e["ref_error"]
    if not np.any(e["qmom3"] - err >= BAND):
        if np.any(e["qmom3"] + err >= BAND):
            pytest.skip(f"{case_id(case)}: whether QMOM N = 3 misses is within the sectional "
                        "reference's grid error: inconclusive (docs/results/eqmom.md)")
        return                                     # QMOM within: reported, not asserted
    dev = e["eqmom3"]
    if not np.any(dev - err >= BAND) and np.any(dev + err >= BAND):
        pytest.skip(f"{case_id(case)}: EQMOM's deviation {np.round(100 * dev, 2)}% is within "
                    f"the reference's grid error {np.round(100 * err, 2)}% of the band: "
                    "inconclusive (docs/results/eqmom.md)")
    # the method's deviation plus the reference's error bound: its error is below the band
    assert np.all(dev + err < BAND), (case, e)


def marked(cases):
    return [pytest.param(c, marks=pytest.mark.xfail(reason=KNOWN_MISSES[c], strict=True))
            if c in KNOWN_MISSES else c for c in cases]


@pytest.mark.slow
@pytest.mark.parametrize("case", marked(CI_CASES), ids=case_id)
def test_eqmom_within_3_percent_where_qmom_misses(case):
    check(case)


@pytest.mark.slow
@pytest.mark.study
@pytest.mark.parametrize("case", marked([c for c in ALL_CASES if c not in CI_CASES]),
                         ids=case_id)
def test_eqmom_within_3_percent_where_qmom_misses_full_set(case):
    check(case)


def table():
    """Markdown rows of every case (python tests/methods/eqmom/test_eqmom_sectional.py)."""
    print("| case | reference error % | QMOM N=3 % (M00 M10 M20 M30) | EQMOM N=3 % | "
          "EQMOM N=2 % | lognormal EQMOM N=3 % | lognormal EQMOM N=2 % |")
    print("|---|---|---|---|---|---|---|")
    for case in ALL_CASES:
        e = errors(case, {**RUNS, **LOGNORMAL})
        fmt = lambda v: " ".join(f"{100 * x:.2f}" for x in v)  # noqa: E731
        print(f"| {case_id(case)} | {100 * e['ref_error'].max():.2g} | "
              + " | ".join(fmt(e[k]) for k in (*RUNS, *LOGNORMAL)) + " |", flush=True)


if __name__ == "__main__":
    table()
