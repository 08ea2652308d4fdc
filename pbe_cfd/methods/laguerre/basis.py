"""Laguerre ROM: the basis (gamma weights, Laguerre polynomials, dual basis) and its quadrature.

Internal coordinates u = p / c, v = b / d (c, d the weight means [kg]). Weights are gamma
densities of mean 1,

    g_l(u) = l^l u^(l-1) exp(-l u) / Gamma(l)          (shape l = lambda in u, gamma in v).

Polynomials L_n^(l-1)(l u) = sum_i l_ni u^i with

    l_ni = (-1)^i Gamma(n + l) l^i / ((n - i)! Gamma(l + i) i!),   i <= n,

orthogonal: int g_l L_n L_k du = h_n delta_nk, h_n = Gamma(n + l) / (Gamma(l) n!).
Expansion n(u, v) = g_l(u) g_g(v) sum_{n, q < m} kappa_nq L_n(u) L_q(v); projecting on
L_n L_q gives kappa_nq = sum_{i<=n, j<=q} l_ni l'_qj M_ij / (h_n h'_q) (M in internal units).
Collecting terms by moment, n = sum_{ij} M_ij phi_ij with separable basis functions

    phi_ij(u, v) = psi_i(u) chi_j(v),  psi_i(u) = g_l(u) sum_s C_is u^s,
    C_is = sum_{n >= max(i, s)}^{m-1} l_ni l_ns / h_n   (C = inverse of the Hankel moment matrix
                                                       of g_l, a check used in the tests),

so int u^k psi_i du = delta_ik for k < m on the whole quadrant: the plain (seed) projection.
The dry class (granules with b = 0 exactly) uses the univariate basis psi_i(u) alone.

Moment-consistent correction: G[a, k] = int_S A_a phi_k over the support S with the quadrature
below, and phi~ = phi G^-1 (``consistent_inverse``), so that the reconstruction
n = sum_a M_a phi~_a reproduces every carried moment exactly on S.

Quadrature ("uniform", seed 000 table III): n_p x n_b cell midpoints p_j = (j + 1/2) p_max / n_p,
b_q = (q + 1/2) b_max / n_b, kept where b_q <= p_j. ("fraction"): n_p uniform cells in p and n_b
uniform cells in y = b/p on [0, min(1, b_max/p_j)] -- the efficiencies are steep in y (sigmoid
slope 35.1 around y = 0.129, i.e. b ~ 7e-11 kg for a primary particle, a third of one table III
b-cell), so this spacing resolves them. Both use product-midpoint weights that integrate the
singular weight factors u^(l-1), v^(g-1) exactly over each cell (gamma = 0.2 puts b^-0.8 at
b = 0, where the plain midpoint rule would miss two thirds of the first cell's integral).
("graded", the following support only): in p, GRADED_CELLS uniform cells on [0, p_max] with
the first one halved GRADED_LEVELS times toward p = 0, and in each cell the Gauss rule of
``points`` nodes for the gamma weight g_l itself restricted to the cell (``graded_mass_nodes``,
docs/physics.md section 9.2): exact for u^k g_l, k < 2 points, on every cell, whatever the
shape; in the binder fraction as "fraction".
"""
import math
from math import lgamma

import numpy as np
from scipy.special import gammainc, gammaincc, gammaln

SPACINGS = {"uniform": 0, "fraction": 1}
#: spacing code of the following support's graded quadrature (not a scene choice)
GRADED = 2
#: graded quadrature in p on [0, p_max = 8 c_m] (docs/physics.md section 9.2): uniform cells of
#: 8/6 c_m, the first one halved 6 times (its innermost cell [0, c_m / 48]). Ours, from the
#: errors of the rule (m = 3, 3 Gauss nodes a cell): u^k g_l for k < 6 to round-off at every
#: shape; the d43 numerator u^(4/3) g_l to 9e-5 at shape 1/32, 1e-5 at 1/4, 3.5e-7 at 1;
#: u^6..u^8 to 6e-4 at shape 8 (the narrowest weight, spanning under two uniform cells)
GRADED_CELLS = 6
GRADED_LEVELS = 6


def moment_index(m):
    """List of (i, j) exponents in state order (i-major, i, j < m)."""
    return [(i, j) for i in range(m) for j in range(m)]


def laguerre_coefficients(m, shape):
    """Monomial coefficients l[n, i] of L_n^(shape-1)(shape * u), n, i < m, and norms h[n].

    u is the coordinate scaled by the weight mean (dimensionless).
    """
    lcoef = np.zeros((m, m))
    h = np.zeros(m)
    for n in range(m):
        h[n] = math.exp(lgamma(n + shape) - lgamma(shape) - lgamma(n + 1))
        for i in range(n + 1):
            lcoef[n, i] = ((-1) ** i * math.exp(lgamma(n + shape) - lgamma(n - i + 1)
                                                - lgamma(shape + i) - lgamma(i + 1))
                           * shape ** i)
    return lcoef, h


def projection_matrix(m, shape):
    """C[i, s] with psi_i(u) = g(u) sum_s C[i, s] u^s, the dual basis of 1, u, ..., u^(m-1)
    with respect to the gamma weight of mean 1 and the given shape (dimensionless)."""
    lcoef, h = laguerre_coefficients(m, shape)
    return (lcoef.T / h) @ lcoef


def gamma_weight(u, shape):
    """Gamma density of mean 1 and the given shape at u >= 0 (dimensionless, per unit u)."""
    u = np.asarray(u, dtype=float)
    out = np.zeros_like(u)
    pos = u > 0
    out[pos] = np.exp(shape * math.log(shape) + (shape - 1.0) * np.log(u[pos]) - shape * u[pos]
                      - lgamma(shape))
    zero = u == 0
    out[zero] = np.inf if shape < 1.0 else (shape if shape == 1.0 else 0.0)
    return out


def univariate_values(u, C, shape):
    """Univariate dual basis psi_i(u), i < m, at points u (internal units): shape (len(u), m),
    per unit u."""
    m = C.shape[0]
    u = np.asarray(u, float)
    up = u[:, None] ** np.arange(m)[None, :]
    return gamma_weight(u, shape)[:, None] * (up @ C.T)


def basis_values(u, v, Cp, Cb, lam, gam):
    """Raw basis phi_k(u, v), k = (i, j) in state order, at points u, v (internal units).

    Returns an array of shape (len(u), K), per unit u and v.
    """
    m = Cp.shape[0]
    psi = univariate_values(u, Cp, lam)                   # (N, m)
    chi = univariate_values(v, Cb, gam)
    return (psi[:, :, None] * chi[:, None, :]).reshape(len(psi), m * m)


def fraction_basis_values(u, v, Cp, Cb, lam, gam):
    """Raw basis in the binder fraction, phi_k(u, v) = psi_i(u) chi_j(v / u) / u, k = (i, j)
    in state order (internal units; per unit u and v): the binder part is a gamma weight in
    t = v / u = (b / p) / (d / c), the binder fraction over its mean, and 1 / u = dt / dv. A
    population whose binder fraction does not depend on the size then has a separable
    expansion, and its closure moments follow from the mass part alone
    (docs/physics.md section 9.2). Shape (len(u), K)."""
    m = Cp.shape[0]
    psi = univariate_values(u, Cp, lam) / np.asarray(u, float)[:, None]
    chi = univariate_values(np.asarray(v, float) / np.asarray(u, float), Cb, gam)
    return (psi[:, :, None] * chi[:, None, :]).reshape(len(psi), m * m)


def consistent_inverse(G):
    """(G^-1, cond) of a moment-basis matrix G[a, k] = int A_a phi_k, inverted after
    equilibrating rows (moments) and columns (basis functions): G spans many decades (u^3 v^3
    against 1), equilibration takes cond from ~1e12 to ~1e8 (m = 4). cond is that of the
    equilibrated matrix."""
    dr = 1.0 / np.abs(G).max(axis=1)
    Gs = G * dr[:, None]
    dc = 1.0 / np.abs(Gs).max(axis=0)
    Gs = Gs * dc[None, :]
    return dc[:, None] * np.linalg.inv(Gs) * dr[None, :], float(np.linalg.cond(Gs))


def _singular_midpoint_weights(edges, shape):
    """Midpoints of the cells between ``edges`` and weights that integrate x^(shape-1) exactly
    over each cell when multiplied by mid^(shape-1)."""
    mid = 0.5 * (edges[..., 1:] + edges[..., :-1])
    w = (edges[..., 1:] ** shape - edges[..., :-1] ** shape) / (shape * mid ** (shape - 1.0))
    return mid, w


def mass_nodes(c, lam, p_max, n_p):
    """Nodes u [internal units, u = p/c] and weights [du] of the univariate quadrature on
    [0, p_max]: n_p uniform cells, midpoint weights exact for u^(lam-1) over each cell."""
    edges = np.arange(n_p + 1) * (p_max / c / n_p)
    return _singular_midpoint_weights(edges, lam)


def gamma_cell_moments(a, b, shape, kmax):
    """int_a^b u^k g_shape(u) du for k = 0..kmax (u >= 0 dimensionless, g of mean 1): the
    Gamma ratio Gamma(shape + k) / (Gamma(shape) shape^k) times the difference of regularised
    incomplete gamma functions (the upper ones beyond the mode of u^k g, where the lower ones
    would cancel)."""
    out = np.empty(kmax + 1)
    for k in range(kmax + 1):
        s = shape + k
        f = math.exp(gammaln(s) - gammaln(shape) - k * math.log(shape))
        if shape * a > s:
            out[k] = f * (gammaincc(s, shape * a) - gammaincc(s, shape * b))
        else:
            out[k] = f * (gammainc(s, shape * b) - gammainc(s, shape * a))
    return out


def _gauss_cell(a, b, shape, n):
    """Nodes and weights of the n-point Gauss rule for g_shape restricted to [a, b] (exact for
    u^k g, k < 2n), from the cell's moments in x = (u - a) / (b - a): the monic orthogonal
    polynomial's coefficients solve the n x n Hankel system, its roots are the nodes, the
    weights solve the Vandermonde system of the first n moments."""
    h = b - a
    mu = gamma_cell_moments(a, b, shape, 2 * n - 1)
    nu = np.array([sum(math.comb(k, i) * mu[i] * (-a) ** (k - i) for i in range(k + 1))
                   / h ** k for k in range(2 * n)])
    x0 = (np.arange(n) + 0.5) / n
    if not (nu[0] > 0.0 and np.all(np.isfinite(nu))):
        return a + h * x0, np.zeros(n)            # no weight on the cell (underflow)
    H = np.array([[nu[i + j] for j in range(n)] for i in range(n)])
    coef = np.linalg.solve(H, -nu[n:2 * n])
    x = np.sort(np.roots(np.concatenate([[1.0], coef[::-1]])).real)
    w = np.linalg.solve(np.vander(x, n, increasing=True).T, nu[:n])
    return a + h * x, w


def graded_mass_nodes(c, lam, p_max, points, cells=GRADED_CELLS, levels=GRADED_LEVELS):
    """Nodes u [internal units, u = p / c] and weights [du] of the graded quadrature on
    [0, p_max]: ``cells`` uniform cells, the first halved ``levels`` times toward 0, each with
    the ``points``-node Gauss rule for the gamma weight g_lam on the cell. The weights are per
    du (the basis multiplies by g_lam at the node): W g_lam(u) is the Gauss weight, so
    sum W g u^k = int_0^(p_max/c) u^k g du for k < 2 points (docs/physics.md section 9.2)."""
    h = p_max / c / cells
    edges = np.concatenate([[0.0], h * 2.0 ** -np.arange(levels, 0, -1),
                            h * np.arange(1, cells + 1)])
    nodes, weights = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        x, w = _gauss_cell(float(a), float(b), lam, int(points))
        nodes.append(x)
        weights.append(w)
    u, wg = np.concatenate(nodes), np.concatenate(weights)
    g = gamma_weight(u, lam)
    return u, np.where(wg > 0.0, wg / np.where(g > 0.0, g, 1.0), 0.0)


def quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing=0, points=3, y_max=1.0):
    """Nodes (u, v) [internal units, u = p/c, v = b/d] and weights [du dv] on the support
    b <= p, p <= p_max, b <= b_max (and b <= y_max p in the binder fraction's spacings).

    spacing 0 ("uniform", seed 000 table III): cell midpoints of a uniform n_p x n_b grid in
    (p, b), kept where b <= p. spacing 1 ("fraction"): n_p uniform cells in p and, at each
    p-cell midpoint p_j, n_b uniform cells in the binder fraction y = b/p on
    [0, min(1, b_max/p_j)] (b = p_j y, db = p_j dy), which resolves the efficiencies' steep
    dependence on y for small granules. Both use product-midpoint weights exact for the
    singular weight factors u^(lam-1) and v^(gam-1) (resp. y^(gam-1)) over each cell.
    spacing 2 (GRADED, the following support): as 1 in y, the graded Gauss rule of
    ``points`` nodes a cell in p (``graded_mass_nodes``; n_p is not used). y_max [-]: the
    top of the binder fraction's support in spacings 1 and 2 (the following support's slices
    of a low mean fraction, ``laguerre_build``).
    """
    if int(spacing) == GRADED:
        um, wu = graded_mass_nodes(c, lam, p_max, points)
    else:
        um, wu = mass_nodes(c, lam, p_max, n_p)
    if int(spacing) in (1, GRADED):
        pj = um * c
        ytop = np.minimum(min(1.0, y_max), b_max / pj)              # (n_p,)
        t = np.arange(n_b + 1) / n_b
        ym, wy = _singular_midpoint_weights(ytop[:, None] * t[None, :], gam)
        U = np.broadcast_to(um[:, None], ym.shape)
        V = pj[:, None] * ym / d
        W = wu[:, None] * wy * (pj[:, None] / d)
        return U.ravel().copy(), V.ravel().copy(), W.ravel().copy()
    vm, wv = _singular_midpoint_weights(np.arange(n_b + 1) * (b_max / d / n_b), gam)
    U, V = np.meshgrid(um, vm, indexing="ij")
    W = wu[:, None] * wv[None, :]
    keep = (V * d) <= (U * c) * (1.0 + 1e-12)
    return U[keep], V[keep], W[keep]
