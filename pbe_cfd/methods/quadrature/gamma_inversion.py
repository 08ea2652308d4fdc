"""EQMOM inversion (Yuan, Laurent and Fox 2012, J. Aerosol Sci. 51, 1-23): gamma kernels, and
lognormal ones through ``family`` = LOGNORMAL (``lognormal_kernels``: their moments, star moments
and sigma range replace the gamma kernels' below; the search and the fallbacks are the same).

The number density in granule mass x (scaled: x = p / p_ref) is a sum of N gamma kernels of a
common width sigma,

    n(x) = sum_a w_a x^(l_a - 1) e^(-x / sigma) / (Gamma(l_a) sigma^l_a),   l_a = x_a / sigma,

kernel a of mean x_a and variance x_a sigma. Its moments are rising factorials in sigma,

    m_k = sum_a w_a x_a (x_a + sigma) ... (x_a + (k - 1) sigma) = sum_i s(k, i) sigma^(k-i) m*_i,

s(k, i) the unsigned Stirling numbers of the first kind and m*_i = sum_a w_a x_a^i the moments
of the kernels' centres; inverted, m*_k = sum_i (-1)^(k-i) S(k, i) sigma^(k-i) m_i with the
Stirling numbers of the second kind S(k, i). For a given sigma, the Gauss rule of N nodes of
m*_0 .. m*_(2N-1) gives (w_a, x_a); sigma is the root of the last moment,

    J(sigma) = (m_2N - sum_a w_a x_a (x_a + sigma) ... (x_a + (2N-1) sigma)) / m_2N = 0.

J(0) >= 0 for a realizable set (the Gauss rule underestimates m_2N); the mixture's variance is
var* + sigma mean, so sigma <= sigma_max = var / mean. The root is searched on [0, sigma_max]:
J at SCAN_POINTS equidistant points, the first sign change refined by the Illinois variant of
regula falsi. Fallbacks (``status``):

* FIT          a root sigma > 0 (the N kernels reproduce m_0 .. m_2N);
* DISCRETE     J(0) within ROOT_TOLERANCE of 0: m_2N on the boundary of moment space, sigma = 0
               (QMOM with N nodes);
* REDUCED      m_0 .. m_(2N-1) on the boundary (a Gauss rule of n < N nodes): sigma = 0, n
               nodes (QMOM with n nodes; the carried moments beyond are the caller's to check);
* FEWER        (``min_shape`` >= 0, EQMOM's own inversion) no usable root with N kernels
               (none, or one with a kernel of shape <= min_shape): where the golden-section
               search below finds a usable |J| <= 1e3 ROOT_TOLERANCE that sigma is a root (FIT);
               else n = N - 1, N - 2, ... 1 kernels of sigma > 0 fitted to m_0 .. m_2n (the
               same search on the first 2n + 1 moments; n = 1 always fits: sigma = sigma_max),
               exact in those; m_(2n+1) .. m_2N are not reproduced (``project`` writes the
               reconstruction's values). Taken unless the closest sigma below is usable and
               misses m_2N by less than it misses those. docs/physics.md, EQMOM;
* CLOSEST      no sign change on [0, sigma_max] (and, with ``min_shape``, no better fewer-kernel
               fit): the sigma of the scan with the smallest |J|, refined by golden-section
               search (m_2N is not reproduced; ``project`` writes the reconstruction's value);
* EMPTY / FAILED  M00 = 0 / not invertible (non-finite or non-positive moments).

Everything is in the method's scaled units and normalised inside by M00 and the mean. numba
kernels, no allocation: the caller passes a work array (``work_length``).
"""
import math

import numba as nb
import numpy as np

from .gauss import tridiagonal_eigen, wheeler_nodes
from . import lognormal_kernels as L

#: the most kernels a scene may ask for (Stirling tables below go to order 2 MAX_KERNELS)
MAX_KERNELS = 5
#: the most secondary (Gauss-Laguerre) nodes per kernel
MAX_SECONDARY = 8
#: |J| (relative to m_2N) below which sigma is accepted as a root, and below which J(0) means
#: the set is discrete: the integrator carries m_2N to rtol ~ 1e-8; 1e-11 is round-off of the
#: Stirling transform of normalised moments of order <= 10 (terms up to ~1e3, eps 2e-16)
ROOT_TOLERANCE = 1.0e-11
#: a fit of fewer nodes than kernels stands for the set where it reproduces the moments it
#: was not fitted to within this (relative; the integrator's 1e-8 with a margin of 10)
REPRODUCTION_TOLERANCE = 1.0e-7
#: equidistant points of the sign scan on (0, sigma_max]
SCAN_POINTS = 8
#: iterations of the Illinois refinement and of the golden-section fallback
ROOT_ITERATIONS = 80
GOLDEN_ITERATIONS = 60

#: kernel families (``family`` of the functions below): gamma in x, lognormal in x
GAMMA = 0
LOGNORMAL = 1

FIT = 0
DISCRETE = 1
REDUCED = 2
CLOSEST = 3
EMPTY = 4
FAILED = 5
FEWER = 6
STATUS_TEXT = ("fitted", "discrete (sigma = 0, QMOM with N nodes)",
               "reduced (moments on the boundary: fewer nodes, sigma = 0)",
               "closest sigma (no root of the last moment; M_2N re-projected)",
               "empty", "not invertible (no kernels)",
               "fewer kernels (no usable root with N kernels: n < N kernels of sigma > 0 "
               "fitted to M_0 .. M_2n; the moments beyond re-projected)")


def _stirling2(n):
    table = np.zeros((n + 1, n + 1))
    table[0, 0] = 1.0
    for k in range(1, n + 1):
        for i in range(1, k + 1):
            table[k, i] = i * table[k - 1, i] + table[k - 1, i - 1]
    return table


#: S(k, i), k, i <= 2 MAX_KERNELS (Stirling numbers of the second kind)
STIRLING2 = _stirling2(2 * MAX_KERNELS)


@nb.njit(cache=True)
def work_length(n_max, n_sec):
    """Floats of work ``invert`` needs for n_max kernels (its scratch; see ``_offsets``)."""
    return 6 * n_max + 2 + (2 * n_max + 1) * (2 * n_max + 1) + 4 * n_max + 3 * n_sec


@nb.njit(cache=True, error_model="numpy")
def star_moments(u, sigma, n_mom, out):
    """m*_k, k < n_mom, of normalised moments u at kernel width sigma (same units)."""
    for k in range(n_mom):
        acc = 0.0
        for i in range(k + 1):
            term = STIRLING2[k, i] * u[i]
            e = k - i
            if e > 0:
                term *= (-sigma) ** e
            acc += term
        out[k] = acc


@nb.njit(cache=True, inline="always")
def kernel_moment(x, sigma, k):
    """k-th moment of a unit gamma kernel of mean x and width sigma: x (x + sigma) ... (x +
    (k - 1) sigma)."""
    value = 1.0
    for j in range(k):
        value *= x + j * sigma
    return value


@nb.njit(cache=True, inline="always")
def family_moment(x, sigma, k, family):
    """k-th moment of a unit kernel of the family (GAMMA: ``kernel_moment``, sigma in units
    of x; LOGNORMAL: ``lognormal_kernels.kernel_moment``, x the median, sigma of ln x)."""
    if family == LOGNORMAL:
        return L.kernel_moment(x, sigma, k)
    return kernel_moment(x, sigma, k)


@nb.njit(cache=True, inline="always")
def sigma_limit(u, family):
    """The largest sigma of normalised moments u (u_0 = u_1 = 1): one kernel of the mean and
    variance, u_2 - 1 (GAMMA) or sqrt(ln u_2) (LOGNORMAL)."""
    if family == LOGNORMAL:
        return L.sigma_max(u[2])
    return u[2] - 1.0


@nb.njit(cache=True, error_model="numpy")
def _target(u, sigma, n_max, nodes, weights, work, family):
    """J(sigma) (module docstring) of normalised moments u[0 .. 2 n_max]; the Gauss rule of
    the star moments into nodes, weights; returns (J, node count)."""
    star = work[0:2 * n_max + 1]
    if family == LOGNORMAL:
        L.star_moments(u, sigma, 2 * n_max, star)
    else:
        star_moments(u, sigma, 2 * n_max, star)
    n = wheeler_nodes(star, n_max, nodes, weights, work[2 * n_max + 1:])
    if n == 0:
        return math.nan, 0
    if n < n_max:
        # fewer nodes than kernels: the fit reproduces m_0 .. m_(2n-1) only; it stands for the
        # set only where it also reproduces the rest (a set of fewer kernels)
        for k in range(2 * n, 2 * n_max):
            pred = 0.0
            for a in range(n):
                pred += weights[a] * family_moment(nodes[a], sigma, k, family)
            if not (abs(pred - u[k]) <= REPRODUCTION_TOLERANCE * abs(u[k])):
                return math.nan, n
    top = u[2 * n_max]
    pred = 0.0
    for a in range(n):
        pred += weights[a] * family_moment(nodes[a], sigma, 2 * n_max, family)
    return (top - pred) / top, n


@nb.njit(cache=True, error_model="numpy")
def _closest(u, lo, hi, n_max, nodes, weights, work, family):
    """sigma in [lo, hi] minimising |J| by golden-section search."""
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    a, b = lo, hi
    c = b - g * (b - a)
    d = a + g * (b - a)
    fc = _abs_or_inf(_target(u, c, n_max, nodes, weights, work, family)[0])
    fd = _abs_or_inf(_target(u, d, n_max, nodes, weights, work, family)[0])
    for _ in range(GOLDEN_ITERATIONS):
        if not (fc <= fd):
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = _abs_or_inf(_target(u, d, n_max, nodes, weights, work, family)[0])
        else:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = _abs_or_inf(_target(u, c, n_max, nodes, weights, work, family)[0])
    return 0.5 * (a + b)


@nb.njit(cache=True, inline="always")
def _abs_or_inf(f):
    return abs(f) if math.isfinite(f) else math.inf


@nb.njit(cache=True, error_model="numpy")
def _root(u, lo, f_lo, hi, f_hi, n_max, nodes, weights, work, family):
    """Illinois regula falsi for J = 0 on [lo, hi] with f_lo > 0 >= f_hi; returns sigma."""
    side = 0
    best, f_best = hi, f_hi
    for _ in range(ROOT_ITERATIONS):
        s = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (s > lo and s < hi):
            s = 0.5 * (lo + hi)
        f = _target(u, s, n_max, nodes, weights, work, family)[0]
        if not math.isfinite(f):
            f = -1.0            # past the star moments' realizable range: treat as overshoot
        if abs(f) < abs(f_best):
            best, f_best = s, f
        if abs(f) <= ROOT_TOLERANCE or (hi - lo) <= 1.0e-15 * hi:
            return s
        if f > 0.0:
            lo, f_lo = s, f
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi, f_hi = s, f
            if side == -1:
                f_lo *= 0.5
            side = -1
    return best


@nb.njit(cache=True, error_model="numpy")
def _search(u, n_max, f0, nodes, weights, work, result, family):
    """Root of J (n_max kernels, J(0) = f0 > 0) on (0, sigma_max]: the scan and the Illinois
    refinement. Found: result = (sigma, J), returns (True, node count); not found: result =
    (the scan's sigma of smallest |J|, that J), returns (False, 0)."""
    sigma_max = sigma_limit(u, family)
    lo, f_lo = 0.0, f0
    best, f_best = 0.0, f0
    for j in range(1, SCAN_POINTS + 1):
        s = sigma_max * j / SCAN_POINTS
        f, nj = _target(u, s, n_max, nodes, weights, work, family)
        if not math.isfinite(f):
            continue
        if abs(f) <= ROOT_TOLERANCE:
            result[0] = s
            result[1] = f
            return True, nj
        if abs(f) < abs(f_best):
            best, f_best = s, f
        if f < 0.0:
            s = _root(u, lo, f_lo, s, f, n_max, nodes, weights, work, family)
            f, nj = _target(u, s, n_max, nodes, weights, work, family)
            if abs(f) <= 1.0e3 * ROOT_TOLERANCE:
                result[0] = s
                result[1] = f
                return True, nj
            break                      # a jump of J, not a root: the closest sigma below
        lo, f_lo = s, f
    result[0] = best
    result[1] = f_best
    return False, 0


@nb.njit(cache=True, error_model="numpy")
def _closest_fit(u, n_max, best, f_best, nodes, weights, work, result, family):
    """The closest-sigma fit around the scan's best sigma (``_closest``) into nodes, weights,
    result = (sigma, J); returns its node count."""
    sigma_max = sigma_limit(u, family)
    h = sigma_max / SCAN_POINTS
    s = _closest(u, max(best - h, 0.0), min(best + h, sigma_max), n_max, nodes, weights, work,
                 family)
    f, nj = _target(u, s, n_max, nodes, weights, work, family)
    if not (abs(f) <= abs(f_best)):
        s = best
        f, nj = _target(u, s, n_max, nodes, weights, work, family)
    result[0] = s
    result[1] = f
    return nj


@nb.njit(cache=True, inline="always")
def _usable(nodes, n, sigma, min_shape):
    """True if every kernel's shape x_a / sigma exceeds min_shape (sigma > 0)."""
    for a in range(n):
        if not (nodes[a] > min_shape * sigma):
            return False
    return True


@nb.njit(cache=True, error_model="numpy")
def _fewer(u, n_max, min_shape, nodes, weights, work, result, family):
    """The fewer-kernel fallback: the first n = n_max - 1, n_max - 2, ... 1 for which the
    n-kernel J of u[0 .. 2n] has a root sigma > 0 (J(0) > ROOT_TOLERANCE; the same search as
    n_max kernels, the golden-section search's result accepted where |J| <= 1e3
    ROOT_TOLERANCE) with every shape above min_shape (n = 1: any shape; it always has the
    root sigma = sigma_max). Returns the node count of that fit (0: none)."""
    for n in range(n_max - 1, 0, -1):
        f0, n0 = _target(u, 0.0, n, nodes, weights, work, family)
        if not (f0 > ROOT_TOLERANCE) or n0 < n:
            continue
        found, nj = _search(u, n, f0, nodes, weights, work, result, family)
        if not found:
            nj = _closest_fit(u, n, result[0], result[1], nodes, weights, work, result, family)
            found = abs(result[1]) <= 1.0e3 * ROOT_TOLERANCE
        if found and nj > 0 and result[0] > 0.0 and \
                (n == 1 or _usable(nodes, nj, result[0], min_shape)):
            return nj
    return 0


@nb.njit(cache=True, error_model="numpy")
def invert_normalised(u, n_max, nodes, weights, work, result, min_shape=-1.0, family=GAMMA):
    """Gamma-EQMOM of normalised moments u[0 .. 2 n_max] (u_0 = u_1 = 1): nodes, weights
    (normalised) of the kernels' centres; result[0] = sigma (normalised), result[1] = J at
    the result. ``min_shape`` >= 0 (EQMOM's own inversion): a root with a kernel of shape
    x_a / sigma <= min_shape is not used, a closest sigma of |J| <= 1e3 ROOT_TOLERANCE is a
    root, and where there is no root to use, the fewer-kernel fit (FEWER) is taken unless the
    closest sigma is usable and misses m_2N by no more than the fewer-kernel fit misses the
    moments it drops (module docstring); < 0: neither. ``family``: GAMMA (sigma normalised by
    the mean) or LOGNORMAL (sigma of ln x, nodes the kernels' medians; ``lognormal_kernels``).
    Returns (status, kernel count)."""
    n = wheeler_nodes(u, n_max, nodes, weights, work)
    result[0] = 0.0
    result[1] = 0.0
    if n == 0:
        return FAILED, 0
    if n < n_max:
        return REDUCED, n
    f0, n0 = _target(u, 0.0, n_max, nodes, weights, work, family)
    result[1] = f0
    if not math.isfinite(f0):
        return FAILED, 0
    if abs(f0) <= ROOT_TOLERANCE:
        return DISCRETE, n
    if f0 < 0.0:                       # m_2N below the Gauss rule's: not realizable
        return FAILED, 0
    fewer = min_shape >= 0.0
    found, nj = _search(u, n_max, f0, nodes, weights, work, result, family)
    if found and (not fewer or _usable(nodes, nj, result[0], min_shape)):
        return FIT, nj
    best, f_best = result[0], result[1]
    closest_miss = math.inf            # the closest sigma's miss of m_2N, where usable
    if not found:
        nj = _closest_fit(u, n_max, best, f_best, nodes, weights, work, result, family)
        if fewer and nj > 0 and _usable(nodes, nj, result[0], min_shape):
            closest_miss = abs(result[1])
            if closest_miss <= 1.0e3 * ROOT_TOLERANCE and result[0] > 0.0:
                return FIT, nj
    if fewer:
        nf = _fewer(u, n_max, min_shape, nodes, weights, work, result, family)
        if nf > 0 and _miss(u, n_max, nf, nodes, weights, result[0], family) < closest_miss:
            return FEWER, nf
        nj = _closest_fit(u, n_max, best, f_best, nodes, weights, work, result, family)
    if nj == 0:
        return FAILED, 0
    return CLOSEST, nj


@nb.njit(cache=True, error_model="numpy")
def _miss(u, n_max, n, nodes, weights, sigma, family):
    """Largest relative miss of u[2n + 1 .. 2 n_max] by n kernels (the moments they drop)."""
    worst = 0.0
    for k in range(2 * n + 1, 2 * n_max + 1):
        pred = 0.0
        for a in range(n):
            pred += weights[a] * family_moment(nodes[a], sigma, k, family)
        worst = max(worst, abs(pred - u[k]) / abs(u[k]))
    return worst


@nb.njit(cache=True, error_model="numpy")
def gamma_rule(shape, n_sec, points, weights, work):
    """Gauss rule of n_sec nodes of the unit gamma density of shape ``shape`` (> 0) and scale
    1: the generalised Laguerre Jacobi matrix (diagonal 2k + shape, squared off-diagonal
    k (k + shape - 1)) solved by ``tridiagonal_eigen``; points and weights (sum 1) into the
    arrays. work: length >= 2 n_sec. Returns False if the eigen-solve failed."""
    diag = work[0:n_sec]
    off = work[n_sec:2 * n_sec]
    for k in range(n_sec):
        diag[k] = 2.0 * k + shape
    for k in range(n_sec - 1):
        off[k] = math.sqrt((k + 1.0) * (k + shape))
    ok = tridiagonal_eigen(diag, off, weights, n_sec)
    for k in range(n_sec):
        points[k] = diag[k]
        weights[k] = weights[k] * weights[k]
    return ok
