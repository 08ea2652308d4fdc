"""Independent reference for the size moments with any aggregation kernel and either daughter
rule: the fixed-pivot sectional solver of ``sectional.py`` (Kumar and Ramkrishna 1996) with
the kernel evaluated per pivot pair and equal-halves daughters beside the uniform ones.

Written from the population balance alone, in numpy and scipy, sharing no code with pbe_cfd.
Kernels (docs/physics.md section 4, written here again from their formulas):

    constant  beta = k0
    sum       beta = k0 (p + p')
    eke       beta = k0 (x^(1/3) + x'^(1/3))^2 sqrt(1/x + 1/x'),  x = p / p_ref

Breakage: S(p) = s0 (p / p_ref)^a, binary; ``uniform`` daughters (density 2 / p' on (0, p')) or
``equal`` halves (two daughters at p' / 2, shared between the pivots around p' / 2 by the
tent that conserves their number and mass). Binder: every granule of the cases this serves has
the same binder fraction y0 at all times (no droplets; aggregation of two granules of fraction
y0 and a split that keeps the parent's fraction both keep it), so M_ij = y0^j M_(i+j),0.

Units: masses [kg], number densities [1/m3], k0 [m3/s] (sum: [m3/(kg s)]), s0 [1/s].
"""
import numpy as np
from scipy.integrate import solve_ivp

from sectional import _aggregation_map, _breakage_map


def kernel_matrix(x, kernel, k0, p_ref):
    """beta(x_j, x_k) [m3/s] on the pivots."""
    a, b = x[:, None], x[None, :]
    if kernel == "constant":
        return np.full((len(x), len(x)), float(k0))
    if kernel == "sum":
        return k0 * (a + b)
    if kernel == "eke":
        u, v = a / p_ref, b / p_ref
        return k0 * (np.cbrt(u) + np.cbrt(v)) ** 2 * np.sqrt(1.0 / u + 1.0 / v)
    raise ValueError(kernel)


def _tent_share(x, v):
    """(lower index, its share, upper index, its share) of a particle of mass v [kg] between
    the pivots (number and mass conserved); v below x_0 is kept at x_0 by mass."""
    i = int(np.searchsorted(x, v, side="right")) - 1
    if i < 0:
        return 0, v / x[0], 0, 0.0
    if i >= len(x) - 1:
        return len(x) - 1, v / x[-1], len(x) - 1, 0.0
    eta = (x[i + 1] - v) / (x[i + 1] - x[i])
    return i, eta, i + 1, 1.0 - eta


def equal_breakage_map(x):
    """beta[i, k]: the two halves of a parent at pivot k assigned to pivot i."""
    n = len(x)
    beta = np.zeros((n, n))
    for k in range(1, n):
        lo, e_lo, hi, e_hi = _tent_share(x, 0.5 * x[k])
        beta[lo, k] += 2.0 * e_lo
        beta[hi, k] += 2.0 * e_hi
    return beta


def _rhs(x, kernel, k0, s0, exponent, p_ref, daughters):
    lo, eta, hi, eta_hi = _aggregation_map(x)
    K = kernel_matrix(x, kernel, k0, p_ref)
    beta = _breakage_map(x) if daughters == "uniform" else equal_breakage_map(x)
    S = s0 * (x / p_ref) ** exponent
    S[0] = 0.0                                       # the first pivot has no room below
    n = len(x)

    def rhs(_, N):
        NN = 0.5 * K * np.outer(N, N)
        birth = np.bincount(lo.ravel(), (eta * NN).ravel(), n)
        birth += np.bincount(hi.ravel(), (eta_hi * NN).ravel(), n)
        out = birth - N * (K @ N)
        out += beta @ (S * N) - S * N
        return out
    return rhs


def solve(x, N0, times, kernel, k0, s0, exponent, p_ref, daughters="uniform"):
    """Numbers per pivot [1/m3] at ``times`` [s] (array (len(times), len(x)))."""
    rhs = _rhs(x, kernel, k0, s0, exponent, p_ref, daughters)
    sol = solve_ivp(rhs, (0.0, float(times[-1])), N0, t_eval=times, method="LSODA",
                    rtol=1e-9, atol=1e-12 * N0.max())
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y.T


def time_of_growth(x, N0, kernel, k0, s0, exponent, p_ref, daughters, factor, t_max):
    """(First time [s] at which the mean mass M1/M0 reaches ``factor`` times its start, the
    solver's dense output N(t) [1/m3 per pivot]); bisection to 1e-9 relative on the
    interpolant."""
    rhs = _rhs(x, kernel, k0, s0, exponent, p_ref, daughters)
    start = (N0 @ x) / N0.sum()

    def excess(N):
        return (N @ x) / N.sum() - factor * start

    sol = solve_ivp(rhs, (0.0, float(t_max)), N0, method="LSODA", rtol=1e-9,
                    atol=1e-12 * N0.max(), dense_output=True)
    t = np.linspace(0.0, t_max, 2001)
    f = np.array([excess(sol.sol(tt)) for tt in t])
    above = np.nonzero(f >= 0.0)[0]
    if len(above) == 0:
        raise RuntimeError("the mean mass does not reach %g x within %g s" % (factor, t_max))
    a, b = t[above[0] - 1], t[above[0]]
    while b - a > 1e-9 * b:
        mid = 0.5 * (a + b)
        if excess(sol.sol(mid)) >= 0.0:
            b = mid
        else:
            a = mid
    return b, sol.sol
