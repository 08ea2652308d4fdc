"""The Laguerre ROM on the held-out suite of tests/methods/laguerre/laguerre_suite.py (fixed
before any method was run on it): aggregation (constant, sum, eke) with power-law breakage
(a = 1/3, 1, 2), uniform and equal daughters, with and without binder droplets, over the
time the mean mass grows 10x; references the fixed-pivot sectional solver and the bivariate cNMC
(tests/references/, numpy/scipy only, sharing no code with pbe_cfd).

The references are checked here against closed forms first. The targets (every case finishes,
worst error over M00, M10, M01, M20, M11, M02 at most 5% at m = 3, no worse than QMOM N = 3
on the same moment in at least 3 of 4 cases) are the aim of the following weight
(docs/physics.md section 9.2); measured today in docs/results/laguerre.md; where the ROM does
not reach them the test is a strict xfail with the measured numbers.
"""
import math
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "references"))

import cnmc_bivariate  # noqa: E402
import sectional  # noqa: E402
import sectional_kernels  # noqa: E402

import laguerre_suite as S  # noqa: E402

P0, N0 = S.P0, S.N0


# ---------------------------------------------------------------------------- the references
def test_suite_is_the_one_fixed_before_looking():
    names = [c["name"] for c in S.cases()]
    assert len(names) == 12 and len(set(names)) == 12
    for kernel in ("constant", "sum", "eke"):
        mine = [c for c in S.cases() if c["kernel"] == kernel]
        assert {c["exponent"] for c in mine} == set(S.EXPONENTS)
        assert {c["daughters"] for c in mine} == {"uniform", "equal"}
        assert {c["droplets"] for c in mine} == {True, False}


def test_sectional_sum_kernel_against_golovin_and_its_error_estimate():
    """Pure sum-kernel aggregation from an exponential start (Golovin): M0 = N0 e^(-tau),
    tau = k0 M1 t, M2 = M2(0) e^(2 tau). M0: the 5e-5 loss below x_0 and the grid's error on
    the initial moments (band 2e-3, tests/test_laguerre_following.py). M2: the fixed pivots
    conserve number and mass but not M2, so its error grows with every aggregation; it is
    second order in the pivot spacing, so the suite's band, Richardson's |M(8) - M(16)| / 3
    (8 and 16 pivots per octave), must be within a factor 2 of the true error (the factor-4
    ratio of the two grids' errors holding to within its square root)."""
    t = np.array([1.0, 2.0])
    tau = 0.05 * N0 * P0 * t
    got = {}
    for per_octave in (8, 16):
        x = S._pivots(per_octave)
        n0 = sectional.initial_exponential(x, N0, P0)
        got[per_octave] = sectional.moments(
            x, sectional_kernels.solve(x, n0, t, "sum", 0.05, 0.0, 1.0, P0), 2)
    M = got[16]
    assert np.max(np.abs(M[:, 0] / (N0 * np.exp(-tau)) - 1.0)) < 2e-3
    err = np.abs(M[:, 2] / (2 * N0 * P0 ** 2 * np.exp(2 * tau)) - 1.0)
    estimate = np.abs(got[8][:, 2] / M[:, 2] - 1.0) / 3.0
    assert np.all(err < 2.0 * estimate) and np.all(err > 0.5 * estimate), (err, estimate)


def test_sectional_equal_halves_against_closed_form():
    """Constant selection s with equal halves: M_k = M_k(0) exp(s t (2^(1-k) - 1))."""
    x = S._pivots()
    n0 = sectional.initial_exponential(x, N0, P0)
    t = np.array([5.0])
    M = sectional.moments(x, sectional_kernels.solve(x, n0, t, "constant", 0.0, 0.1, 0.0, P0,
                                                     "equal"), 2)
    for k in range(3):
        exact = N0 * P0 ** k * math.factorial(k) * math.exp(0.5 * (2.0 ** (1 - k) - 1.0))
        assert M[0, k] / exact == pytest.approx(1.0, abs=2e-3)


def test_sectional_eke_conserves_mass_and_matches_its_pair_sum():
    """The eke kernel per pivot pair against the formula at one pair, and mass conserved."""
    x = np.array([P0, 8 * P0])
    K = sectional_kernels.kernel_matrix(x, "eke", 2.0, P0)
    assert K[0, 1] == pytest.approx(2.0 * (1 + 2) ** 2 * math.sqrt(1 + 1 / 8), rel=1e-12,
                                    abs=0)
    x = S._pivots()
    n0 = sectional.initial_exponential(x, N0, P0)
    N = sectional_kernels.solve(x, n0, np.array([10.0]), "eke", S.K0["eke"], 0.0, 1.0, P0)
    assert N[0] @ x / (n0 @ x) == pytest.approx(1.0, abs=1e-6)


def test_cnmc_reference_against_closed_forms():
    """The bivariate cNMC on two closed forms, within its own 95% band (99% family-wise by
    Bonferroni over the checks) plus its O(1/N) bias: constant aggregation K with constant
    breakage s and uniform daughters (the logistic M0; M11 from dM2/dt = K M1^2 + s (2/3 - 1)
    M2 with b = y0 p), and droplets captured by a constant kernel without aggregation
    (dn_d/dt = R - f K M0 n_d, the granules' M01 gaining what the droplets lose)."""
    from scipy import stats
    K, s, t = 1e-10, 0.2, np.array([5.0])
    spec = {"kernel": "constant", "k0": K, "p_ref": P0, "s0": s, "exponent": 0.0,
            "daughters": "uniform", "mean": P0, "y0": 0.25, "n0": N0}
    mean, half = cnmc_bivariate.ensemble(spec, 2000, 8, 11, t)
    m0 = 2 * s / K / (1 + (2 * s / K / N0 - 1) * math.exp(-s * t[0]))
    M1 = N0 * P0
    m2s = 3 * K * M1 ** 2 / s
    m2 = m2s + (2 * N0 * P0 ** 2 - m2s) * math.exp(-s * t[0] / 3)
    q = stats.t.ppf(1 - 0.01 / 8, 7) / stats.t.ppf(0.975, 7)
    bias = 3.0 / 2000
    assert abs(mean[0, 0, 0] - m0) < q * half[0, 0, 0] + bias * m0
    assert abs(mean[0, 1, 1] - 0.25 * m2) < q * half[0, 1, 1] + bias * m2
    assert abs(mean[0, 1, 0] - M1) < q * half[0, 1, 0] + bias * M1
    f, R, pd, nd0 = 10.0, 1e9, 0.2 * P0, 1e9
    spec = {"kernel": "constant", "k0": K, "p_ref": P0, "s0": 0.0, "exponent": 0.0,
            "daughters": "uniform", "mean": P0, "y0": 0.0, "n0": N0, "factor": f,
            "p_d": pd, "rate": R, "nd0": nd0}
    t = np.array([0.3])
    mean, half = cnmc_bivariate.ensemble(spec, 2000, 8, 12, t)
    from scipy.integrate import solve_ivp

    def m0(tt):                                    # granules: constant-kernel aggregation
        return 2 * N0 / (2 + K * N0 * tt)

    nd = solve_ivp(lambda tt, y: [R - f * K * m0(tt) * y[0]], (0.0, t[0]), [nd0],
                   rtol=1e-10, atol=1.0).y[0, -1]
    binder = nd0 * pd + R * pd * t[0]              # granules + free droplets
    assert abs(mean[0, 0, 1] - binder) < q * half[0, 0, 1] + bias * binder
    assert abs(mean[0, 0, 0] - (m0(t[0]) + nd)) < q * half[0, 0, 0] + bias * N0


# ---------------------------------------------------------------------------- the methods
@pytest.fixture(scope="module")
def measured():
    return S.measure()


@pytest.mark.slow
@pytest.mark.study
def test_every_sectional_reference_holds_its_population(measured):
    """Under 1e-3 of the mass on the grid's top decade, where the last pivot keeps by mass
    what lands beyond it."""
    tops = {r["case"]: r["top_mass_share"] for r in measured if "top_mass_share" in r}
    assert len(tops) == 6 and max(tops.values()) < 1e-3, tops


@pytest.mark.slow
@pytest.mark.study
def test_every_case_finishes(measured):
    """Every case runs to its end with the following support (sum a=2 equal +droplets
    stopped at 6.697 s, its dry class unrealizable, until the dry-wet and capture rows were
    taken on the points; docs/results/laguerre.md)."""
    stopped = {r["case"]: r[label] for r in measured for label in S.METHODS
               if label.startswith("laguerre m=3 following") and isinstance(r[label], str)}
    assert not stopped, stopped


def _worst(row, label):
    e = row[label]
    return math.inf if isinstance(e, str) else max(e.values())


@pytest.mark.slow
@pytest.mark.study
@pytest.mark.xfail(strict=True, reason="measured (docs/results/laguerre.md, number row on "
                   "the points): sum a=1/3 equal 11.2%, sum a=2 uniform 31%, eke a=1 uniform "
                   "10.6%, eke a=2 equal 15.4% (bands 0.9%, 0.0%, 0.1%, 0.1%)")
def test_following_rom_within_5_percent_on_every_case(measured):
    bad = {r["case"]: _worst(r, "laguerre m=3 following") for r in measured
           if _worst(r, "laguerre m=3 following") > S.TARGET + max(r["band"].values())}
    assert not bad, bad


@pytest.mark.slow
@pytest.mark.study
@pytest.mark.xfail(strict=True, reason="measured (docs/results/laguerre.md, number row on "
                   "the points): no worse than QMOM N = 3 on 7 of 12 cases")
def test_following_rom_no_worse_than_qmom_on_3_of_4_cases(measured):
    wins = 0
    for r in measured:
        rom, q = r["laguerre m=3 following"], r["qmom N=3"]
        if isinstance(rom, str):
            continue
        worst = max(rom, key=rom.get)          # the ROM's worst moment, QMOM on the same
        if isinstance(q, str) or rom[worst] <= q[worst] + r["band"][worst]:
            wins += 1
    assert wins >= 0.75 * len(measured), wins
