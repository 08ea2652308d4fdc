"""Independent reference for the univariate size moments: a fixed-pivot sectional solver
(Kumar and Ramkrishna 1996, Chem. Eng. Sci. 51, 1311) for aggregation with a constant kernel and
binary breakage with the power-law selection S(p) = s0 (p / p_ref)^a and uniform daughters.

Written from the population balance alone, in numpy and scipy, sharing no code with pbe_cfd.

Pivots x_i on a geometric grid; a new particle of mass v between pivots x_i <= v <= x_(i+1)
is shared between them with the fractions that conserve its number and mass,
eta_i = (x_(i+1) - v) / (x_(i+1) - x_i), eta_(i+1) = 1 - eta_i (aggregation), and the daughters
of a break, density 2 / x_k on (0, x_k), are assigned to pivot i with the same tent function
integrated against that density (breakage). Number and mass are conserved by every event
(except a daughter below the first pivot, which is kept at x_0 by mass).

    dN_i/dt = 1/2 sum_jk K N_j N_k eta_i(x_j + x_k) - K N_i sum_k N_k
              + sum_k S_k N_k beta_ik - S_i N_i

Units: masses [kg], number densities [1/m3], K [m3/s], s0 [1/s].
"""
import numpy as np
from scipy.integrate import solve_ivp


def pivots(p_low, p_high, per_octave):
    """Geometric pivots [kg] from p_low to (at least) p_high, per_octave points per factor 2."""
    n = int(np.ceil(np.log2(p_high / p_low) * per_octave)) + 1
    return p_low * 2.0 ** (np.arange(n) / per_octave)


def _aggregation_map(x):
    """(lower pivot index, its share, upper pivot index, its share) of every pair sum
    x_j + x_k; a sum beyond the last pivot is kept there by mass (the share v / x_last; the
    caller checks that the grid holds the population, ``top_mass_share``)."""
    v = x[:, None] + x[None, :]
    i = np.searchsorted(x, v, side="right") - 1
    inside = i < len(x) - 1
    lo = np.where(inside, i, len(x) - 1)
    hi = np.where(inside, i + 1, len(x) - 1)
    eta = np.where(inside, (x[np.minimum(hi, len(x) - 1)] - v)
                   / (x[np.minimum(hi, len(x) - 1)] - x[np.minimum(i, len(x) - 2)]),
                   v / x[-1])
    return lo, eta, hi, np.where(inside, 1.0 - eta, 0.0)


def _breakage_map(x):
    """beta[i, k]: daughters of a parent at pivot k assigned to pivot i (uniform binary
    daughters, 2 / x_k on (0, x_k)), conserving number (2) and mass (x_k)."""
    n = len(x)
    beta = np.zeros((n, n))
    for k in range(1, n):
        dens = 2.0 / x[k]
        for i in range(k + 1):
            if i > 0:                                # left half of the tent, (x_(i-1), x_i)
                a, b = x[i - 1], x[i]
                # int_a^b (v - a) / (b - a) dv = (b - a) / 2
                beta[i, k] += dens * 0.5 * (b - a)
            else:                                    # (0, x_0): kept at x_0 by mass
                beta[0, k] += dens * 0.5 * x[0]
            if i < k:                                # right half, (x_i, x_(i+1))
                a, b = x[i], x[i + 1]
                beta[i, k] += dens * 0.5 * (b - a)
    return beta


def initial_exponential(x, n0, mean):
    """Number per pivot of an exponential density n0/mean exp(-p/mean), by the tent functions
    (number and mass of every sub-interval assigned to its two pivots; the part below x_0 kept
    at x_0 by mass)."""
    fine = np.linspace(0.0, 1.0, 401)
    N = np.zeros(len(x))
    pdf = lambda v: n0 / mean * np.exp(-v / mean)  # noqa: E731
    v = fine * x[0]
    N[0] += np.trapezoid(pdf(v) * v / x[0], v)
    for i in range(len(x) - 1):
        a, b = x[i], x[i + 1]
        v = a + fine * (b - a)
        f = pdf(v)
        N[i] += np.trapezoid(f * (b - v) / (b - a), v)
        N[i + 1] += np.trapezoid(f * (v - a) / (b - a), v)
    return N


def solve(x, N0, times, K, s0, exponent, p_ref):
    """Numbers per pivot [1/m3] at ``times`` [s] (array (len(times), len(x)))."""
    lo, eta, hi, eta_hi = _aggregation_map(x)
    beta = _breakage_map(x)
    S = s0 * (x / p_ref) ** exponent
    S[0] = 0.0                                       # the first pivot has no room below
    n = len(x)

    def rhs(_, N):
        NN = 0.5 * K * np.outer(N, N)
        birth = np.bincount(lo.ravel(), (eta * NN).ravel(), n)
        birth += np.bincount(hi.ravel(), (eta_hi * NN).ravel(), n)
        out = birth - K * N * N.sum()
        out += beta @ (S * N) - S * N
        return out

    sol = solve_ivp(rhs, (0.0, float(times[-1])), N0, t_eval=times, method="LSODA",
                    rtol=1e-9, atol=1e-12 * N0.max())
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y.T


def moments(x, N, n_max):
    """M_n = sum_i N_i x_i^n [kg^n/m3], n = 0..n_max, for each row of N."""
    return np.stack([N @ x ** k for k in range(n_max + 1)], axis=-1)


def top_mass_share(x, N, fraction=0.1):
    """Share [-] of the mass on the top ``fraction`` of the pivots (the grid must hold it)."""
    top = x >= x[-1] * fraction
    return float((N[..., top] @ x[top]).max() / (N @ x).max())
