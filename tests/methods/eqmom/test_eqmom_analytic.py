"""Gamma-EQMOM against closed forms (docs/physics.md sections 8 and 10, section "EQMOM").

Exponential start (N0 granules per m3 of mean mass P0), binder fraction y0 on every granule,
so M_ij = y0^j M_(i+j),0 at all times (aggregation and breakage both keep every granule's
binder fraction when all granules share one):

1. constant aggregation K: the population stays exponential, M_k = N k! (M1 / N)^k with
   N = 2 N0 / (2 + K N0 t);
2. constant selection s: M_ij = M_ij(0) exp(s t (F(i + j) - 1)), F(k) = 2/(k+1) (uniform
   daughters) or 2^(1-k) (equal halves);
3. Ziff and McGrady (1985): S = k p, uniform daughters: the population stays exponential,
   M_n = N0 P0^n n! (1 + k P0 t)^(1 - n);
4. constant aggregation with constant selection: the closed moment hierarchy
   dM0/dt = -K M0^2 / 2 + s M0, dM_n/dt = K/2 sum_e C(n, e) M_e M_(n-e) + s (F(n) - 1) M_n,
   integrated here by scipy (rtol 1e-12).

Tolerance. Problems 1, 3 and 4' sources are polynomials in the moments of the reconstruction
(constant kernel, constant selection) or integrals of x^(k+1) of degree <= 2N + 1 over the
kernels (problem 3), which the N + 2 secondary Gauss nodes per kernel integrate exactly; the
reconstruction reproduces the carried M0 .. M2N (the exponential is one gamma kernel). What
remains is the integrator's error: rtol = 1e-8 per step, below 100 rtol = 1e-6 over the few
hundred steps of these runs (the bound of tests/test_qmom_analytic.py). M10 and M01 are exact
to 1e-10 relative (their sources vanish particle by particle).

Lognormal kernels (``kernel = "lognormal"``, docs/physics.md section 16): problems 1, 2 and 4
are closed in the carried moments whatever the kernels, but the 20 Gauss-Hermite particles per
kernel integrate x^k only to the rule's error on e^(k sigma t): below 6e-8 relative for
k sigma <= 4 (these runs: k <= 2N, sigma <= 0.7 for N = 2 and 0.44 for N = 3, k sigma <= 2.8),
so the same 1e-6 holds (measured: 2e-9 on M60, problem 1, N = 3). Problem 3 is no closed form for
them (the source of M_2N needs the reconstruction's M_(2N+1), exact only for kernels that
contain the exponential): M00 (its source s0 M10 / P0), M10 and M01 are asserted.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

N0, P0, Y0 = 1.0e10, 1.0e-9, 0.25
KERNELS = ("gamma", "lognormal")
TOL, EXACT = 1.0e-6, 1.0e-10


def scene(nodes, end, aggregation=None, breakage=None, outputs=8, kernel="gamma"):
    return make_scene(scene={"end_time": end, "output_interval": end / outputs},
                      initial={"distribution": "exponential", "number_density": N0,
                               "mean_mass": P0, "binder_fraction": Y0},
                      aggregation=aggregation, breakage=breakage,
                      method={"_replace": True, "name": "eqmom", "nodes": nodes,
                              "kernel": kernel})


def carried(columns, nodes):
    return [f"M{k}0" for k in range(2 * nodes + 1)] + [f"M{k}1" for k in range(nodes)]


def assert_moments(c, nodes, exact):
    t = c["time_s"]
    for name in carried(c, nodes):
        i, j = int(name[1:-1]), int(name[-1])             # "M100": M_(10)0
        err = np.max(np.abs(c[name] / (Y0 ** j * exact(i + j, t)) - 1.0))
        assert err < TOL, (name, err)
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M01"] / (Y0 * N0 * P0) - 1.0)) < EXACT


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("nodes", [2, 3, 5])
def test_constant_aggregation(nodes, kernel):
    K = 1.0e-10                                  # K N0 = 1 /s: N falls to N0 / 6 by 10 s

    def exact(n, t):
        number = 2.0 * N0 / (2.0 + K * N0 * t)
        return number * math.factorial(n) * (N0 * P0 / number) ** n
    c = run_well_mixed(scene(nodes, 10.0, aggregation={"kernel": "constant", "rate": K},
                             kernel=kernel)).columns
    assert c["M00"][-1] == pytest.approx(N0 / 6.0, rel=TOL, abs=0)
    assert_moments(c, nodes, exact)


@pytest.mark.parametrize("daughters,F", [("uniform", lambda k: 2.0 / (k + 1.0)),
                                         ("equal", lambda k: 2.0 ** (1.0 - k))])
@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("nodes", [2, 3])
def test_constant_breakage(nodes, daughters, F, kernel):
    s = 0.1

    def exact(n, t):
        return N0 * P0 ** n * math.factorial(n) * np.exp(s * t * (F(n) - 1.0))
    c = run_well_mixed(scene(nodes, 20.0, breakage={"selection": "constant", "rate": s,
                                                     "daughters": daughters},
                             kernel=kernel)).columns
    assert c["M00"][-1] == pytest.approx(N0 * math.exp(2.0), rel=TOL, abs=0)
    assert_moments(c, nodes, exact)


@pytest.mark.parametrize("nodes", [2, 3])
def test_ziff_mcgrady_linear_selection(nodes, kernel="gamma"):
    s0 = 0.1                                     # S = s0 p / P0: k P0 t = 1 at 10 s

    def exact(n, t):
        return N0 * P0 ** n * math.factorial(n) * (1.0 + s0 * t) ** (1.0 - n)
    c = run_well_mixed(scene(nodes, 10.0, breakage={"selection": "power", "rate": s0,
                                                     "exponent": 1.0,
                                                     "reference_mass": P0},
                             kernel=kernel)).columns
    assert c["M00"][-1] == pytest.approx(2.0 * N0, rel=TOL, abs=0)
    assert_moments(c, nodes, exact)


@pytest.mark.parametrize("kernel", KERNELS)
def test_constant_aggregation_with_constant_breakage(kernel):
    K, s, nodes = 1.0e-10, 0.25, 2              # M0 -> 2 s / K = N0 / 2

    def rhs(t, m):
        out = np.empty_like(m)
        out[0] = -0.5 * K * m[0] ** 2 + s * m[0]
        out[1] = 0.0
        for n in range(2, len(m)):
            gain = sum(math.comb(n, e) * m[e] * m[n - e] for e in range(1, n))
            out[n] = 0.5 * K * gain + s * (2.0 / (n + 1.0) - 1.0) * m[n]
        return out
    m0 = np.array([N0 * P0 ** n * math.factorial(n) for n in range(2 * nodes + 1)])
    c = run_well_mixed(scene(nodes, 20.0, aggregation={"kernel": "constant", "rate": K},
                             breakage={"selection": "constant", "rate": s},
                             kernel=kernel)).columns
    sol = solve_ivp(rhs, (0.0, 20.0), m0, t_eval=c["time_s"], rtol=1e-12,
                    atol=1e-14 * np.abs(m0), method="DOP853")
    assert_moments(c, nodes, lambda n, t: sol.y[n])


@pytest.mark.parametrize("nodes", [2, 3])
def test_ziff_mcgrady_lognormal_number_and_mass(nodes):
    """Lognormal kernels: S = s0 p makes dM_k/dt need M_(k+1), so the source of M_2N needs
    M_(2N+1) of the reconstruction, which N lognormal kernels fitted to an exponential's
    M_0 .. M_2N do not give exactly (a closure, not a closed form: M20 .. M(2N)0 drift by
    0.05-1.4%, docs/results/eqmom.md). Closed here: M00 (its source is s0 M10 / P0, M10
    carried) and M10, M01 (sources zero particle by particle)."""
    s0 = 0.1
    c = run_well_mixed(scene(nodes, 10.0, breakage={"selection": "power", "rate": s0,
                                                     "exponent": 1.0, "reference_mass": P0},
                             kernel="lognormal")).columns
    exact = N0 * (1.0 + s0 * c["time_s"])
    assert np.max(np.abs(c["M00"] / exact - 1.0)) < TOL
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M01"] / (Y0 * N0 * P0) - 1.0)) < EXACT
