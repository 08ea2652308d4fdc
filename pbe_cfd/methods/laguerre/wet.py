"""Laguerre ROM, wet class: tensors of the granules that carry binder (b > 0).

RHS of the wet-wet aggregation (DESIGN section 3): dM_a/dt = 1/2 int_S int_S beta(r, r')
D_a(r, r') n(r) n(r') with D_a = A_a(r + r') - A_a(r) - A_a(r'), A_a = p^i b^j. Expanding
(p+p')^i (b+b')^j binomially, D_a = sum_{e <= a, e != 0, e != a} C(a, e) A_e(r) A_{a-e}(r')
for a != 0 (all terms non-negative, no cancellation) and D_0 = -1, so with
Psi[s, (e, k)] = w_s A_e(r_s) phi~_k(r_s) and the symmetric kernel matrix B[s, t] =
beta(r_s, r_t) (evaluated once per unordered pair: the pair symmetry of seed 000 eq. 21),
Z = Psi^T B Psi and

    T[a, k, l] = 1/2 sum_e C(a, e) Z[(e, k), (a - e, l)],   symmetric in (k, l).

Droplets as a population of their own (density n_d, mass p_d, liquid b_d: p_d for pure
binder, (1 - s) p_d for a solution, physics.injection):
dM_a/dt += n_d int_S k_d(r) [A_a(r + r_d) - A_a(r)] n(r),  dn_d/dt -= n_d int_S k_d(r) n(r),
k_d = droplet_capture_rate. Both are linear in M: matrices Cd[a, k] and Cd0[k]. Droplets that
evaporate (drying) are the class's mean point r_d = (s p_d + l, l), l = L_d / n_d, which moves:
then Cd[f, k] = int k_d A_f phi~_k, and the RHS writes the gain sum_{f < a} C(a, f)
r_d^(a - f) (Cd M)_f at the droplet's point (``rhs.capture_gain``); the kernel k_d stays the
sprayed droplet's (docs/physics.md section 15).

Scaling: the state holds M~_a = M_a / (N_ref p_ref^(i+j)); internal moments are
M_int_a = M~_a r_a with r_a = p_ref^(i+j) / (c^i d^j). Tensors are returned in state units with
the kernel rate k0 and N_ref factored out: dM~_a/dt = k0 N_ref [mult] sum_{k<=l} Q[k,l,a] M~_k M~_l.
"""
from math import comb

import numba as nb
import numpy as np

from ...physics.rates import droplet_capture_rate, symmetric_aggregation_rate_matrix
from .basis import (basis_values, consistent_inverse, fraction_basis_values,
                    moment_index, projection_matrix, quadrature)


# ---- kernel matrices (numba) -----------------------------------------------------------------
@nb.njit(cache=True, nogil=True)
def capture_rate_vector(p, b, u0, params, config, out):
    """out[s] = droplet_capture_rate(node s) [m3/s per unit k0], unit ktgf multiplier."""
    for s in range(p.shape[0]):
        out[s] = droplet_capture_rate(p[s], b[s], 0.0, 1.0, u0, 1.0, params, config)


def _aggregation_tensor(Bmat, u, v, W, Phi, m):
    """T[a, k, l] (internal units) from the kernel matrix on the nodes, see module doc."""
    K = m * m
    idx = moment_index(m)
    # Psi[s, e*K + k] = w_s u^e1 v^e2 phi_k
    mon = np.stack([u ** i * v ** j for (i, j) in idx], axis=1)           # (N, K)
    Pw = Phi * W[:, None]
    Psi = (mon[:, :, None] * Pw[:, None, :]).reshape(len(u), K * K)
    Z = Psi.T @ (Bmat @ Psi)
    Z = Z.reshape(K, K, K, K)                                               # e, k, f, l
    T = np.zeros((K, K, K))
    T[0] = -0.5 * Z[0, :, 0, :]              # a = (0, 0): D = 1 - 1 - 1 = -1
    for a, (i, j) in enumerate(idx):
        for e1 in range(i + 1):
            for e2 in range(j + 1):
                if (e1, e2) == (0, 0) or (e1, e2) == (i, j):
                    continue
                e = e1 * m + e2
                f = (i - e1) * m + (j - e2)
                T[a] += 0.5 * comb(i, e1) * comb(j, e2) * Z[e, :, f, :]
    return 0.5 * (T + T.transpose(0, 2, 1))


def _capture_matrices(kd, u, v, W, Phi, m, ud, vd):
    """Cd[a, k] = int k_d [A_a(r + r_d) - A_a(r)] phi_k, Cd0[k] = int k_d phi_k (internal)."""
    idx = moment_index(m)
    Pw = Phi * (W * kd)[:, None]
    Cd = np.zeros((m * m, m * m))
    for a, (i, j) in enumerate(idx):
        # (u + ud)^i (v + vd)^j - u^i v^j expanded to avoid cancellation
        da = np.zeros_like(u)
        for e1 in range(i + 1):
            for e2 in range(j + 1):
                if (e1, e2) == (i, j):
                    continue
                da += comb(i, e1) * comb(j, e2) * u ** e1 * v ** e2 * ud ** (i - e1) \
                    * vd ** (j - e2)
        Cd[a] = da @ Pw
    return Cd, Pw.sum(axis=0)


def _capture_moment_matrix(kd, u, v, W, Phi, m):
    """Cw[f, k] = int k_d A_f phi_k (internal units): the moments of the granules that capture,
    from which the wet gain of a droplet (ud, vd) is the binomial map of ``capture_gain``."""
    mon = np.stack([u ** i * v ** j for (i, j) in moment_index(m)], axis=1)   # (N, K)
    return mon.T @ (Phi * (W * kd)[:, None])


def wet_basis(m, weights, grid, consistent, p_ref):
    """The wet class's quadrature and corrected basis for one weight (c [kg], d [kg], lambda,
    gamma); grid: dict(p_max, b_max [kg], n_p, n_b, spacing[, fraction_basis]: the basis in
    the binder fraction, ``laguerre_basis.fraction_basis_values``[, y_max]: the binder
    fraction's top [-], default 1). Returns a dict with the nodes
    (u, v, W) in internal units, their masses p, b [kg], the corrected basis PhiC (N, K), the
    state <-> internal scaling r, the functionals f43 (K) and sup (2K) in state units, the
    reconstruction block ``basis`` (c, d, lambda, gamma, Cp, Cb, Ginv, r) and cond(G)."""
    c, d, lam, gam = weights
    K = m * m
    idx = moment_index(m)
    Cp = projection_matrix(m, lam)
    Cb = projection_matrix(m, gam)
    u, v, W = quadrature(c, d, lam, gam, grid["p_max"], grid["b_max"], grid["n_p"],
                         grid["n_b"], grid["spacing"], points=m, y_max=grid.get("y_max", 1.0))
    values = fraction_basis_values if grid.get("fraction_basis") else basis_values
    Phi = values(u, v, Cp, Cb, lam, gam)                            # raw basis (N, K)
    mon = np.stack([u ** i * v ** j for (i, j) in idx], axis=1)     # (N, K)
    G = mon.T @ (Phi * W[:, None])                                  # G[a, k]
    Ginv, cond = consistent_inverse(G) if consistent else (np.eye(K), 1.0)
    PhiC = Phi @ Ginv                                               # phi~ (N, K)
    # state <-> internal scaling: M_int = M~ * r
    r = np.array([p_ref ** (i + j) / (c ** i * d ** j) for (i, j) in idx])
    f43 = ((u * c / p_ref) ** (4.0 / 3.0) * W) @ PhiC * r
    sup = np.concatenate([(W @ PhiC) * r, ((u * c / p_ref) * W) @ PhiC * r])
    basis = np.concatenate([[c, d, lam, gam], Cp.ravel(), Cb.ravel(), Ginv.ravel(), r])
    return dict(u=u, v=v, W=W, p=u * c, b=v * d, c=c, d=d, PhiC=PhiC, r=r, f43=f43, sup=sup,
                basis=basis, cond=cond)


def wet_kernels(p, b, u0, uparams, ucfg, separate):
    """Kernel data on the wet nodes (masses p, b [kg]) at collision velocity u0 [m/s]: the
    pair-rate matrix and, if droplets are separate, the capture-rate vector [m3/s per unit k0].
    Independent of the weights."""
    B = np.empty((len(p), len(p)))
    # unit ktgf multiplier: alpha = 0 -> g0 = 1, theta = 1, d43 = 1
    symmetric_aggregation_rate_matrix(p, b, 0.0, 1.0, u0, 1.0, uparams, ucfg, B)
    kd = np.zeros(len(p))
    if separate:
        capture_rate_vector(p, b, u0, uparams, ucfg, kd)
    return B, kd


def wet_tensors(basis, B, kd, m, pd, separate, bd, capture_moments):
    """(Q[pair, a], Cd[k, a], Cd0[k]) in state units for one weight's basis and one slice's
    kernel data (module doc); pd the droplet mass [kg], bd its liquid binder [kg] (pd: pure
    binder; (1 - s) pd for a solution of solids fraction s). capture_moments: Cd[k, f] holds
    the capturing granules' moments int k_d A_f phi~_k instead (droplets whose point changes
    as they evaporate; the RHS maps the gain at their point)."""
    K = m * m
    u, v, W, PhiC, r = basis["u"], basis["v"], basis["W"], basis["PhiC"], basis["r"]
    iu = np.triu_indices(K)
    fold = np.where(iu[0] == iu[1], 1.0, 2.0)
    T = _aggregation_tensor(B, u, v, W, PhiC, m)                     # internal units
    # state units: dM~_a = sum_kl T[a,k,l] (M~_k r_k)(M~_l r_l) / r_a
    Ts = T * r[None, :, None] * r[None, None, :] / r[:, None, None]
    Q = (Ts[:, iu[0], iu[1]] * fold[None, :]).T
    Cd = np.zeros((K, K))
    Cd0 = np.zeros(K)
    if separate:
        if capture_moments:
            cd = _capture_moment_matrix(kd, u, v, W, PhiC, m)
            cd0 = (PhiC * (W * kd)[:, None]).sum(axis=0)
        else:
            cd, cd0 = _capture_matrices(kd, u, v, W, PhiC, m, pd / basis["c"],
                                        bd / basis["d"])
        Cd = (cd * r[None, :] / r[:, None]).T                        # [k, a] or [k, f]
        Cd0 = cd0 * r
    return Q, Cd, Cd0
