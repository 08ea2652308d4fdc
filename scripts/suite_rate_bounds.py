"""What the carried moments fix in the rates of the held-out suite's missed moments.

For the six cases of tests/methods/laguerre/laguerre_suite.py without droplets (every
granule at the binder fraction 0.25, so the question is univariate), on the suite's own
sectional reference at half and full time (its pivots as a measure; masses in P0):

- breakage with S = s0 (p / P0)^a gives dM_k/dt = (F(k) - 1) s0 M_(k+a) (docs/physics.md 8);
  the constant and sum kernels' aggregation rates of M0 and M2 are closed in M0, M1, M2;
- the range of M_(k+a), k = 0, 2, over every positive measure with exactly the carried
  moments (M0..M2: the Laguerre ROM at m = 3; M0..M5: QMOM N = 3): the linear programmes of
  tests/distribution/psd_moment_bounds.py (``linear_extremes``, scipy HiGHS) on a log grid of masses from the reference's smallest pivot to a top (its largest
  pivot, or 10 times the mass that 1e-6 of the mass lies above: the maximum of an order above
  the carried ones is the Stieltjes problem's, unbounded, and grows with the top);
- the value of a gamma fitted to M0, M1, M2 and of the three-node Gauss rule of M0..M5
  (Wheeler's algorithm), and the error each makes in the moment's whole rate;
- for the EKE kernel, whose aggregation rates no finite set of moments closes: the rate of
  M0 and M2 over the gamma and over the three-node rule against the reference's.

Usage: python scripts/suite_rate_bounds.py [--points 1600]   (about 2 min on 2 cores)
The results are in docs/results/laguerre.md, "What the carried moments fix in the suite's
missed rates". Own code only (numpy, scipy); the suite module gives the cases and the
reference solver.
"""
import argparse
import os
import sys

import numpy as np
from scipy.special import gammaln

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.join(HERE, "..", "tests"),
                os.path.join(HERE, "..", "tests", "methods", "laguerre"),
                os.path.join(HERE, "..", "tests", "references"),
                os.path.join(HERE, "..", "tests", "distribution")]
import laguerre_suite as S  # noqa: E402
import sectional_kernels as SK  # noqa: E402
from psd_moment_bounds import linear_extremes  # noqa: E402


def gain(k, daughters):
    """F(k) - 1 of the daughter rule (docs/physics.md 8)."""
    return 2.0 / (k + 1.0) - 1.0 if daughters == "uniform" else 2.0 ** (1.0 - k) - 1.0


def gamma_moment(M, s):
    """M_s of the gamma density with moments M[0], M[1], M[2]."""
    k = M[1] ** 2 / (M[0] * M[2] - M[1] ** 2)
    theta = M[1] / (M[0] * k)
    return M[0] * theta ** s * np.exp(gammaln(k + s) - gammaln(k))


def gamma_measure(M, points=6000):
    """(masses, weights): the gamma of M[0..2] on a log grid (trapezoid in ln x)."""
    k = M[1] ** 2 / (M[0] * M[2] - M[1] ** 2)
    theta = M[1] / (M[0] * k)
    u = np.logspace(np.log10(theta) - 12, np.log10(theta) + 3.5, points)
    return u, M[0] * np.exp(k * np.log(u / theta) - u / theta - gammaln(k)) * np.gradient(
        np.log(u))


def wheeler(M, n):
    """(nodes, weights) of the n-node Gauss rule of the moments M[0..2n-1] (Wheeler 1974)."""
    nu = np.asarray(M[:2 * n], float) / M[0]
    a, b = np.zeros(n), np.zeros(n)
    sig = np.zeros((n + 1, 2 * n))
    sig[1, :] = nu
    a[0] = nu[1]
    for k in range(1, n):
        for j in range(k, 2 * n - k):
            sig[k + 1, j] = sig[k, j + 1] - a[k - 1] * sig[k, j] - b[k - 1] * sig[k - 1, j]
        a[k] = sig[k + 1, k + 1] / sig[k + 1, k] - sig[k, k] / sig[k, k - 1]
        b[k] = sig[k + 1, k] / sig[k, k - 1]
    J = np.diag(a) + np.diag(np.sqrt(b[1:]), 1) + np.diag(np.sqrt(b[1:]), -1)
    lam, V = np.linalg.eigh(J)
    return lam, M[0] * V[0, :] ** 2


def tail_mass(x, N, share=1e-6):
    """The mass [P0] that ``share`` of the mass lies above."""
    above = np.cumsum((N * x)[::-1])[::-1] / (N * x).sum()
    return x[np.nonzero(above >= share)[0][-1]]


def eke_matrix(x, k0):
    """EKE kernel on masses x [P0] in the suite's normalisation (the reference's own)."""
    return SK.kernel_matrix(x * S.P0, "eke", k0, S.P0)


def aggregation_rates(Kmat, w, x):
    return -0.5 * w @ Kmat @ w, (w * x) @ Kmat @ (w * x)


def case_rows(case, points):
    t_end, dense = S.end_time(case)
    x = S._pivots(kernel=case["kernel"]) / S.P0
    Kref = SK.kernel_matrix(x * S.P0, case["kernel"], case["k0"], S.P0)
    a, s0 = case["exponent"], case["s0"]
    rows = []
    for share in (0.5, 1.0):
        N = dense(share * t_end)
        M = [float(N @ x ** k) for k in range(6)]
        tops = (x[-1], 10.0 * tail_mass(x, N))
        nodes, weights = wheeler(M, 3)
        agg = aggregation_rates(Kref, N, x)
        for k in (0, 2):
            s = k + a
            true = float(N @ x ** s)
            brk = gain(k, case["daughters"]) * s0 * true
            total = agg[k // 2] + brk
            row = {"case": case["name"], "t": share, "k": k, "s": s,
                   "brk/tot": brk / total, "gamma": gamma_moment(M, s) / true,
                   "qmom": float(weights @ nodes ** s) / true}
            for label, n in (("M0-2", 3), ("M0-5", 6)):
                if s == int(s) and s < n:
                    row[label] = "carried"
                    continue
                grids = [np.logspace(np.log10(x[0]), np.log10(top), points) for top in tops]
                bounds = [linear_extremes(M[:n], g, g ** s) or (np.nan, np.nan)
                          for g in grids]
                row[label] = "%.3g .. %.3g (top %.3g P0) / %.3g (top %.3g P0)" % (
                    bounds[0][0] / true, bounds[0][1] / true, tops[0], bounds[1][1] / true,
                    tops[1])
            row["rate error gamma / qmom"] = "%+.1f%% / %+.1f%%" % (
                100 * (row["gamma"] - 1) * row["brk/tot"], 100 * (row["qmom"] - 1) * row["brk/tot"])
            if case["kernel"] == "eke":
                u, w = gamma_measure(M)
                by_gamma = aggregation_rates(eke_matrix(u, case["k0"]), w, u)[k // 2]
                by_rule = aggregation_rates(eke_matrix(nodes, case["k0"]), weights, nodes)[
                    k // 2]
                row["eke aggregation gamma / qmom"] = "%.4f / %.4f (of the rate: %+.1f%% / " \
                    "%+.1f%%)" % (by_gamma / agg[k // 2], by_rule / agg[k // 2],
                                  100 * (by_gamma - agg[k // 2]) / total,
                                  100 * (by_rule - agg[k // 2]) / total)
            rows.append(row)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1600, help="masses of the LP grid")
    args = ap.parse_args(argv)
    for case in S.cases():
        if case["droplets"]:
            continue
        for row in case_rows(case, args.points):
            print("; ".join("%s: %s" % (k, ("%.4g" % v) if isinstance(v, float) else v)
                            for k, v in row.items()), flush=True)


if __name__ == "__main__":
    main()
