"""Bounds and references the trajectory tests share, independent of the code they check.

Global error of a tolerance-controlled run (``error_bound``): every accepted step keeps its
local error estimate below atol + rtol |y|. Step sizes follow the solution's own time scale,
so the error a run can collect grows with the number of time scales it spans, the e-folds
E = sum |d ln y| of the *reference* solution (the closed form or a run at 100 times tighter
rtol), never with the step count of the run under test. Bound: SAFETY rtol (1 + E), SAFETY =
10 for the embedded error estimate (a lower-order solution: it can understate the error of the
propagated one by a few times) and for the controller's 0.9 step safety factor.

Realizability (``hankel_realizable``): a sequence m_0 .. m_{2n-1} is the moment sequence of a
positive measure on [0, inf) with at most n points iff the Hankel matrices H0 = [m_{i+j}] and
H1 = [m_{i+j+1}] (i, j < n) are positive semidefinite (Stieltjes); written here with numpy's
eigenvalues, not the package's realizability test.

Reference moments (``aggregation_moments``): the exact moment equations of the constant and the
sum kernel, integrated with scipy's DOP853 at rtol 1e-13. For k >= 1 the loss of M_k cancels the
j = 0 and j = k terms of the birth sum, so every moment needs only moments of order <= k:
  constant: dM_k/dt = (k0 / 2) sum_{j=1}^{k-1} C(k, j) M_j M_{k-j},  dM_0/dt = -(k0 / 2) M_0^2;
  sum:      dM_k/dt = (k0 / 2) sum_{j=1}^{k-1} C(k, j) (M_{j+1} M_{k-j} + M_j M_{k-j+1}),
            dM_0/dt = -k0 M_0 M_1.
QMOM with N nodes evaluates these sources exactly for every carried moment (k < 2N): the
integrands are polynomials of degree <= 2N - 1 in each mass.
"""
from math import comb

import numpy as np
from scipy.integrate import solve_ivp

SAFETY = 10.0


def efolds(*series):
    """Largest total variation of ln|y| over the given series (each sampled at the output
    times; a series that is zero somewhere is skipped)."""
    worst = 0.0
    for y in series:
        y = np.abs(np.asarray(y, dtype=float))
        if np.all(y > 0):
            worst = max(worst, float(np.sum(np.abs(np.diff(np.log(y))))))
    return worst


def error_bound(rtol, *reference_series):
    """Relative global error allowed of a run at ``rtol`` against a reference (see above)."""
    return SAFETY * rtol * (1.0 + efolds(*reference_series))


def assert_close_to_reference(got, reference, rtol, names, floor=1e-6):
    """Each column ``got[name]`` within error_bound(rtol, reference[name]) of the reference,
    relative to |reference| + floor max|reference| (floor: the integrator's atol over rtol,
    1e-14 / 1e-8, in the scaled units where the start is of order one)."""
    for name in names:
        ref = np.asarray(reference[name], dtype=float)
        bound = error_bound(rtol, ref)
        scale = np.abs(ref) + floor * np.max(np.abs(ref))
        err = np.abs(np.asarray(got[name]) - ref) / np.where(scale > 0, scale, 1.0)
        assert np.all(err <= bound), (name, float(np.max(err)), bound)


def hankel_realizable(moments, rel=1e-10):
    """True when m_0 .. m_{2n-1} (n = len // 2) is a moment sequence on [0, inf): H0 and H1
    positive semidefinite to ``rel`` of their largest eigenvalue, after scaling m_k by
    m_0 mean^k (mean = m_1 / m_0) so the test does not depend on units."""
    m = np.asarray(moments, dtype=float)
    if m[0] == 0.0:
        return bool(np.all(m == 0.0))
    if not (m[0] > 0.0 and m[1] > 0.0):
        return False
    mean = m[1] / m[0]
    x = m / (m[0] * mean ** np.arange(len(m)))
    n = len(x) // 2
    h0 = np.array([[x[i + j] for j in range(n)] for i in range(n)])
    h1 = np.array([[x[i + j + 1] for j in range(n)] for i in range(n)])
    for h in (h0, h1):
        ev = np.linalg.eigvalsh(h)
        if ev[0] < -rel * max(ev[-1], 1.0):
            return False
    return True


def size_moments(columns, row, n_mom):
    """M_00 .. M_(n_mom-1)0 of one output row, SI."""
    return np.array([columns[f"M{k}0"][row] for k in range(n_mom)])


def aggregation_moments(kernel, k0, m_init, t):
    """Exact moments M_0 .. M_{K-1} [SI] at times t [s] of a pure-aggregation population with
    moments m_init at t = 0 (see the module docstring); returns an array (K, len(t))."""
    m_init = np.asarray(m_init, dtype=float)
    K = len(m_init)
    scale = m_init.copy()                 # integrate in units of the initial moments

    def rhs(_, y):
        M = y * scale
        d = np.zeros(K)
        if kernel == "constant":
            d[0] = -0.5 * k0 * M[0] ** 2
            for k in range(2, K):
                d[k] = 0.5 * k0 * sum(comb(k, j) * M[j] * M[k - j] for j in range(1, k))
        elif kernel == "sum":
            d[0] = -k0 * M[0] * M[1]
            for k in range(2, K):
                d[k] = 0.5 * k0 * sum(comb(k, j) * (M[j + 1] * M[k - j] + M[j] * M[k - j + 1])
                                      for j in range(1, k))
        else:
            raise ValueError(kernel)
        return d / scale

    sol = solve_ivp(rhs, (0.0, float(np.max(t))), np.ones(K), t_eval=t, method="DOP853",
                    rtol=1e-13, atol=1e-30)
    assert sol.success
    return sol.y * scale[:, None]
