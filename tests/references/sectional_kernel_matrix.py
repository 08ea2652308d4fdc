"""Independent reference for the univariate size moments and distribution under aggregation
with the constant, sum or EKE kernel and binary breakage with the power-law selection
S(p) = s0 (p / p_ref)^a and uniform or equal daughters: the fixed-pivot sectional solver of
``sectional`` (Kumar and Ramkrishna 1996) with a kernel matrix, the equal-halves daughter map
and an analytic Jacobian for scipy's BDF (the power-law selection makes the top pivots stiff).

Written from the population balance alone, numpy and scipy, sharing no code with pbe_cfd.

Kernels [m3/s] of two granules of masses x, y [kg]:
    constant  k0;   sum  k0 (x + y);
    eke       k0 (u^(1/3) + w^(1/3))^2 sqrt(1/u + 1/w),  u = x / (rho v_ref), w = y / (rho v_ref)
(Hounslow 1998, the equipartition-of-kinetic-energy kernel), rho [kg/m3], v_ref [m3].
Equal daughters: a parent at pivot k gives two granules of x_k / 2, which on a grid of
``per_octave`` pivots per factor 2 is exactly pivot k - per_octave (below the grid: kept at
x_0 by mass).
"""
import numpy as np
from scipy.integrate import solve_ivp

from sectional import _aggregation_map, _breakage_map, initial_exponential, moments, pivots

__all__ = ["pivots", "initial_exponential", "moments", "kernel_matrix", "solve",
           "edge_mass_shares"]


def kernel_matrix(x, kernel, k0, rho=None, v_ref=None):
    """K[j, k] [m3/s] of the pivots x [kg] for kernel 'constant', 'sum' or 'eke'."""
    if kernel == "constant":
        return np.full((len(x), len(x)), float(k0))
    if kernel == "sum":
        return k0 * (x[:, None] + x[None, :])
    if kernel == "eke":
        u = x / (rho * v_ref)
        c = np.cbrt(u)
        return k0 * (c[:, None] + c[None, :]) ** 2 * np.sqrt(1.0 / u[:, None] + 1.0 / u[None, :])
    raise ValueError(kernel)


def _equal_map(x, per_octave):
    """beta[i, k] of equal halves: 2 granules at pivot k - per_octave; below the grid the
    parent's mass x_k kept at x_0 (x_k / x_0 granules)."""
    n = len(x)
    beta = np.zeros((n, n))
    for k in range(n):
        if k >= per_octave:
            beta[k - per_octave, k] = 2.0
        else:
            beta[0, k] = x[k] / x[0]
    return beta


def solve(x, N0, times, K, s0, exponent, p_ref, daughters="uniform", per_octave=None):
    """Numbers per pivot [1/m3] at ``times`` [s] (array (len(times), len(x))); K the kernel
    matrix [m3/s], s0 [1/s], p_ref [kg]; per_octave (equal daughters) the grid's pivots per
    factor 2."""
    n = len(x)
    lo, eta, hi, eta_hi = _aggregation_map(x)
    if daughters == "uniform":
        beta = _breakage_map(x)
    else:
        beta = _equal_map(x, per_octave)
    S = s0 * (x / p_ref) ** exponent
    S[0] = 0.0                                       # the first pivot has no room below
    B = beta * S[None, :] - np.diag(S)
    lo_f, hi_f = lo.ravel(), hi.ravel()
    eta_f, eta_hi_f = eta.ravel(), eta_hi.ravel()
    col = np.broadcast_to(np.arange(n)[:, None], (n, n)).ravel()     # m of the pair (m, k)

    def rhs(_, N):
        NN = 0.5 * K * np.outer(N, N)
        birth = np.bincount(lo_f, eta_f * NN.ravel(), n)
        birth += np.bincount(hi_f, eta_hi_f * NN.ravel(), n)
        return birth - N * (K @ N) + B @ N

    def jac(_, N):
        KN = (K * N[None, :]).ravel()                # K[m, k] N[k]
        J = np.bincount(lo_f * n + col, eta_f * KN, n * n)
        J += np.bincount(hi_f * n + col, eta_hi_f * KN, n * n)
        J = J.reshape(n, n)
        J -= np.diag(K @ N) + N[:, None] * K
        return J + B

    sol = solve_ivp(rhs, (0.0, float(times[-1])), N0, t_eval=times, method="BDF", jac=jac,
                    rtol=1e-8, atol=1e-12 * N0.max())
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y.T


def edge_mass_shares(x, N, fraction=0.01):
    """(share of the mass on pivots below x_0 / fraction, share above x_last * fraction), the
    largest over the rows: the grid must hold the population at both ends."""
    mass = N * x
    total = mass.sum(axis=-1)
    low = (mass[..., x <= x[0] / fraction].sum(axis=-1) / total).max()
    high = (mass[..., x >= x[-1] * fraction].sum(axis=-1) / total).max()
    return float(low), float(high)
