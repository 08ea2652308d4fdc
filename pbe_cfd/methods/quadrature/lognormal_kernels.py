"""Lognormal kernels of the EQMOM (Madadi-Kandjani and Passalacqua 2015, Chem. Eng. Sci. 131,
323-339; the extended quadrature of Yuan, Laurent and Fox 2012 with lognormal kernels).

A kernel of centre x_a (its median, scaled granule mass) and width sigma (standard deviation of
ln x, dimensionless) is

    n_a(x) = w_a / (x sigma sqrt(2 pi)) exp(-(ln x - ln x_a)^2 / (2 sigma^2)),

with the moments m_k = w_a x_a^k exp(k^2 sigma^2 / 2). A mixture of N such kernels of one
sigma has m_k = exp(k^2 sigma^2 / 2) m*_k, m*_k = sum_a w_a x_a^k the moments of the centres: the
star moments are the carried moments times exp(-k^2 sigma^2 / 2), and one kernel of the
normalised moments 1, 1, u_2 has exp(sigma^2) = u_2, so 0 <= sigma <= sqrt(ln u_2).

Secondary quadrature: in t = (ln x - ln x_a) / sigma the kernel is the standard normal density,
so its Gauss-Hermite rule (probabilists' weight exp(-t^2/2) / sqrt(2 pi)) of n nodes t_j,
weights h_j gives the particles x_a exp(sigma t_j) of weight w_a h_j. It integrates
x^q exp(...) = exp(q sigma t) smoothly for any real q (fractional and negative too), exactly
for no q != 0: the relative error of the moment of order q is that of the rule on e^(q sigma t)
(docs/physics.md section 16). numba kernels of floats and arrays.
"""
import math

import numba as nb

from .gauss import tridiagonal_eigen

#: the most Gauss-Hermite nodes per kernel
MAX_HERMITE = 20


@nb.njit(cache=True, inline="always")
def kernel_moment(x, sigma, k):
    """k-th moment of a unit lognormal kernel of median x and log-width sigma [-]:
    x^k exp(k^2 sigma^2 / 2) (units of x^k)."""
    return x ** k * math.exp(0.5 * k * k * sigma * sigma)


@nb.njit(cache=True, error_model="numpy")
def star_moments(u, sigma, n_mom, out):
    """m*_k = u_k exp(-k^2 sigma^2 / 2), k < n_mom, the moments of the kernels' centres of
    normalised moments u at log-width sigma [-]."""
    for k in range(n_mom):
        out[k] = u[k] * math.exp(-0.5 * k * k * sigma * sigma)


@nb.njit(cache=True, inline="always")
def sigma_max(u2):
    """The largest log-width of normalised moments with u_2 = m_2 m_0 / m_1^2: sqrt(ln u_2)
    (one kernel of the mean and variance); 0 where u_2 <= 1."""
    return math.sqrt(math.log(u2)) if u2 > 1.0 else 0.0


@nb.njit(cache=True, error_model="numpy")
def hermite_rule(n, points, weights, work):
    """Gauss rule of n nodes of the standard normal density (probabilists' Hermite
    polynomials; Golub and Welsch 1969): Jacobi matrix of zero diagonal and squared
    off-diagonal k (k = 1 .. n - 1), its eigenvalues the points, the squared first components
    of its eigenvectors the weights (sum 1). Dimensionless. work: length >= 2 n. Returns False
    if the eigen-solve failed."""
    diag = work[0:n]
    off = work[n:2 * n]
    for k in range(n):
        diag[k] = 0.0
    for k in range(n - 1):
        off[k] = math.sqrt(k + 1.0)
    ok = tridiagonal_eigen(diag, off, weights, n)
    for k in range(n):
        points[k] = diag[k]
        weights[k] = weights[k] * weights[k]
    return ok
