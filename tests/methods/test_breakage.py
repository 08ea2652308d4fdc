"""Breakage against its closed forms (docs/physics.md section 8).

Three problems whose moments are known exactly (N0 granules per m3, binder fraction y0 = 0.25
on every granule, so M_ij = y0^j M_(i+j),0 for all t: binder splits in proportion to mass):

1. constant selection s, uniform daughters: M_ij(t) = M_ij(0) exp(s t (2/(i+j+1) - 1));
   equal halves: exp(s t (2^(1-i-j) - 1));
2. power selection S = k p (exponent 1, k = s0 / p_ref), uniform daughters, exponential start
   of mean v0: the population stays exponential, M_k = N0 v0^k k! (1 + k v0 t)^(1-k);
3. constant aggregation K with constant selection s, uniform daughters:
   dM0/dt = -K M0^2/2 + s M0 (logistic to 2 s / K), dM_k/dt = (K/2) sum_e C(k, e) M_e M_(k-e)
   + s (2/(k+1) - 1) M_k (k >= 2: M2 relaxes to 3 K M1^2 / s).

Tolerances. The moment methods: problems 1 and 3 close exactly under any quadrature (the
breakage term is diagonal in the moments and the constant kernel's sources are polynomials in
the carried moments), so what remains is the integrator's error: it keeps each step's local
error estimate below rtol = 1e-8 of the state, and over the few hundred steps of these runs
the global error stays below 100 rtol = 1e-6 (the bound of tests/methods/qmom/test_qmom_analytic.py).
Problem 2 closes for M0 and M1 only (dM_k/dt = k_s (2/(k+1) - 1) M_(k+1) needs M_(2N) of an
N-node quadrature): M0 and M1 to 1e-6; the carried higher moments are checked to 1e-6 against
the same closure computed independently here (a plain-NumPy Gauss rule from the moments),
and the closure error against the closed form is what docs/physics.md reports. M10 and M01
must stay exact to 1e-10 relative (their sources are zero node by node).

The cNMC: its ensemble mean must lie within the band t_q sd / sqrt(R) of the closed form at
every checked (moment, time); q = 1 - 0.01 / (2 m) for m checks (Bonferroni: family-wise
coverage 99% for an unbiased estimator). Its finite-N bias is O(1/N) per unit s t (the
constant-number thinning of methods.cnmc_breakage: relative rate bias cv^2 / (N + 1)), below
1e-3 at N = 2000, a tenth of the band. Seeds were fixed when this file was written.
"""
import math

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import solve_ivp

from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

N0 = 1.0e10          # 1/m3
P0 = 1.0e-9          # kg
Y0 = 0.25            # binder fraction of every granule
TOL = 1.0e-6         # 100 x rtol (module docstring)
EXACT = 1.0e-10      # M10, M01


def uniform_F(k):
    return 2.0 / (k + 1.0)


def equal_F(k):
    return 2.0 ** (1.0 - k)


def moment0(i, j):
    """M_ij(0) [kg^(i+j)/m3] of the exponential start with b = y0 p."""
    return N0 * P0 ** (i + j) * math.factorial(i + j) * Y0 ** j


def carried(columns):
    return [c for c in columns if len(c) == 3 and c[0] == "M" and c[1:].isdigit()]


def breakage_scene(method, breakage, end, outputs=10, aggregation=None):
    return make_scene(scene={"end_time": end, "output_interval": end / outputs},
                      initial={"distribution": "exponential", "binder_fraction": Y0},
                      aggregation=aggregation, breakage=breakage,
                      method=dict(method, _replace=True))


def assert_exact_mass_and_binder(c):
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M01"] / (Y0 * N0 * P0) - 1.0)) < EXACT


# ---------------------------------------------------------------------------- closed forms
def constant_selection(s, F):
    return lambda i, j, t: moment0(i, j) * np.exp(s * t * (F(i + j) - 1.0))


def power_selection(k_s):
    """M_ij(t) = y0^j M_(i+j)(t), M_n = N0 v0^n n! (1 + k v0 t)^(1 - n)."""
    return lambda i, j, t: moment0(i, j) * (1.0 + k_s * P0 * t) ** (1.0 - (i + j))


def aggregation_breakage(K, s, n_max):
    """Moments M_n(t) of problem 3 (univariate in n = i + j; M_ij = y0^j M_n), integrated
    from the closed moment hierarchy with scipy (rtol 1e-12); M0 is the logistic."""
    def rhs(t, m):
        out = np.empty_like(m)
        out[0] = -0.5 * K * m[0] ** 2 + s * m[0]
        out[1] = 0.0
        for n in range(2, len(m)):
            gain = sum(math.comb(n, e) * m[e] * m[n - e] for e in range(1, n))
            out[n] = 0.5 * K * gain + s * (uniform_F(n) - 1.0) * m[n]
        return out
    m0 = np.array([moment0(n, 0) for n in range(n_max + 1)])

    def moments(i, j, t):
        sol = solve_ivp(rhs, (0.0, float(np.max(t))), m0, t_eval=t, rtol=1e-12,
                        atol=1e-300 + 1e-14 * np.abs(m0), method="DOP853")
        return Y0 ** j * sol.y[i + j]
    return moments


def logistic(K, s, t):
    steady = 2.0 * s / K
    return steady / (1.0 + (steady / N0 - 1.0) * np.exp(-s * t))


# ---------------------------------------------------------------------------- QMOM
@pytest.mark.parametrize("daughters,F", [("uniform", uniform_F), ("equal", equal_F)])
@pytest.mark.parametrize("nodes", [2, 3])
def test_qmom_constant_selection(daughters, F, nodes):
    s = 0.1
    scene = breakage_scene({"name": "qmom", "nodes": nodes},
                           {"selection": "constant", "rate": s, "daughters": daughters}, 20.0)
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    exact = constant_selection(s, F)
    for name in carried(c):
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name
    assert c["M00"][-1] / N0 == pytest.approx(math.exp(s * 20.0 * (F(0) - 1)), rel=TOL, abs=0)
    assert_exact_mass_and_binder(c)


def gauss_rule(moments):
    """N-node Gauss rule (nodes, weights) of 2N moments by the Stieltjes procedure on the
    moment functional (polynomials as coefficient vectors), then the Jacobi matrix's eigen-
    decomposition with numpy: independent of the package's Wheeler / QL code."""
    m = np.asarray(moments, float)
    n = len(m) // 2

    def inner(f, g):
        h = np.convolve(f, g)
        return float(h @ m[:len(h)])
    prev, cur = np.zeros(1), np.array([1.0])
    a, b = [], []
    norm_prev = None
    for k in range(n):
        norm = inner(cur, cur)
        xk = np.concatenate(([0.0], cur))
        a.append(inner(xk, cur) / norm)
        if k > 0:
            b.append(norm / norm_prev)
        nxt = xk - a[-1] * np.concatenate((cur, [0.0]))
        if k > 0:
            nxt -= b[-1] * np.concatenate((prev, [0.0, 0.0]))
        prev, cur, norm_prev = cur, nxt, norm
    J = np.diag(a) + np.diag(np.sqrt(b), 1) + np.diag(np.sqrt(b), -1)
    x, v = np.linalg.eigh(J)
    return x, m[0] * v[0] ** 2


def qmom_power_closure(k_s, nodes, times):
    """The size moments M_0..M_(2N-1) of QMOM with S = k p, uniform daughters: the moment chain
    dM_n/dt = k (2/(n+1) - 1) M_(n+1) with M_2N from the N-node Gauss rule of the carried
    moments (scaled by p0 and N0), integrated by scipy (rtol 1e-12)."""
    n_mom = 2 * nodes

    def rhs(t, m):
        top = gauss_rule(m)
        m_next = np.append(m[1:], np.sum(top[1] * top[0] ** n_mom))
        return np.array([k_s * P0 * (uniform_F(n) - 1.0) * m_next[n] for n in range(n_mom)])
    m0 = np.array([math.factorial(n) for n in range(n_mom)], float)     # units N0 p0^n
    sol = solve_ivp(rhs, (0.0, times[-1]), m0, t_eval=times, rtol=1e-12, atol=1e-14,
                    method="DOP853")
    return {n: sol.y[n] * N0 * P0 ** n for n in range(n_mom)}


@pytest.mark.parametrize("nodes", [2, 3])
def test_qmom_power_selection(nodes):
    s0 = 0.1                        # S = s0 p / p0: k v0 = 0.1 /s, k v0 t = 1 at 10 s
    scene = breakage_scene({"name": "qmom", "nodes": nodes},
                           {"selection": "power", "rate": s0, "exponent": 1.0}, 10.0)
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    exact = power_selection(s0 / P0)
    for name in ("M00", "M10", "M01"):
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name
    assert c["M00"][-1] == pytest.approx(2 * N0, rel=TOL, abs=0)      # (1 + k v0 t) = 2
    closure = qmom_power_closure(s0 / P0, nodes, t)
    for n in range(2, 2 * nodes):
        assert np.max(np.abs(c[f"M{n}0"] / closure[n] - 1.0)) < TOL, n
    for n in range(1, nodes):                  # binder moments follow M_(n+1),0 times y0
        assert np.max(np.abs(c[f"M{n}1"] / (Y0 * closure[n + 1]) - 1.0)) < TOL, n
    assert_exact_mass_and_binder(c)


@pytest.mark.parametrize("nodes", [2, 3])
def test_qmom_constant_aggregation_with_constant_breakage(nodes):
    K, s = 1.0e-10, 0.25            # K N0 = 1 /s; M0 -> 2 s / K = N0 / 2
    scene = breakage_scene({"name": "qmom", "nodes": nodes},
                           {"selection": "constant", "rate": s}, 20.0,
                           aggregation={"kernel": "constant", "rate": K})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    assert np.max(np.abs(c["M00"] / logistic(K, s, t) - 1.0)) < TOL
    exact = aggregation_breakage(K, s, 2 * nodes - 1)
    for name in carried(c):
        i, j = int(name[1]), int(name[2])
        assert np.max(np.abs(c[name] / exact(i, j, t) - 1.0)) < TOL, name
    m1 = N0 * P0
    m2s = 3 * K * m1 ** 2 / s
    m2 = m2s + (moment0(2, 0) - m2s) * np.exp(-s * t / 3)
    assert np.max(np.abs(c["M20"] / m2 - 1.0)) < TOL
    assert_exact_mass_and_binder(c)


# ---------------------------------------------------------------------------- cNMC
def assert_in_band(c, exact, names, times_idx, replicas, family=0.01):
    """Every (moment, time) within the Bonferroni band of the ensemble (module docstring)."""
    m = len(names) * len(times_idx)
    t95 = stats.t.ppf(0.975, replicas - 1)
    tq = stats.t.ppf(1.0 - family / (2 * m), replicas - 1)
    t = c["time_s"]
    for name in names:
        i, j = int(name[1]), int(name[2])
        for k in times_idx:
            sem = (c[name + "_hi"][k] - c[name][k]) / t95
            target = exact(i, j, t[k])
            assert abs(c[name][k] - target) <= tq * sem, (name, t[k], c[name][k], target, sem)


CNMC_MOMENTS = ("M00", "M20", "M11", "M02")


@pytest.mark.parametrize("daughters,F,seed", [("uniform", uniform_F, 16001),
                                              ("equal", equal_F, 16002)])
def test_cnmc_constant_selection(daughters, F, seed):
    s, replicas = 0.1, 32
    scene = breakage_scene({"name": "cnmc", "particles": 2000, "replicas": replicas,
                            "seed": seed},
                           {"selection": "constant", "rate": s, "daughters": daughters}, 20.0,
                           outputs=4)
    res = run_well_mixed(scene)
    c = res.columns
    assert_in_band(c, constant_selection(s, F), CNMC_MOMENTS, range(1, 5), replicas)
    assert res.stats["events_breakage"] > replicas * 2000      # every granule broke ~2 times
    assert np.allclose(c["M10"], c["M10"][0], rtol=1e-12, atol=0)
    # every granule keeps y0: the binder mass follows the mass to round-off
    assert np.allclose(c["M01"], Y0 * c["M10"], rtol=1e-12, atol=0)


def test_cnmc_power_selection():
    s0, replicas = 0.1, 32
    scene = breakage_scene({"name": "cnmc", "particles": 2000, "replicas": replicas,
                            "seed": 16003},
                           {"selection": "power", "rate": s0, "exponent": 1.0}, 10.0,
                           outputs=4)
    res = run_well_mixed(scene)
    c = res.columns
    assert_in_band(c, power_selection(s0 / P0), CNMC_MOMENTS, range(1, 5), replicas)
    assert np.allclose(c["M01"], Y0 * c["M10"], rtol=1e-12, atol=0)


@pytest.mark.slow
def test_cnmc_constant_aggregation_with_constant_breakage():
    K, s, replicas = 1.0e-10, 0.25, 32
    scene = breakage_scene({"name": "cnmc", "particles": 2000, "replicas": replicas,
                            "seed": 16004},
                           {"selection": "constant", "rate": s}, 20.0, outputs=4,
                           aggregation={"kernel": "constant", "rate": K})
    res = run_well_mixed(scene)
    c = res.columns
    exact = aggregation_breakage(K, s, 2)
    assert_in_band(c, lambda i, j, t: exact(i, j, np.array([t]))[0], CNMC_MOMENTS, range(1, 5),
                   replicas)
    assert res.stats["accepted"] > 0 and res.stats["events_breakage"] > 0
