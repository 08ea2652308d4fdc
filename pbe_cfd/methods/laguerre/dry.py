"""Laguerre ROM, dry class: tensors of the granules that carry exactly no binder.

Wet granulation starts dry. A granule with b = 0 exactly is not a limit of the bivariate
expansion (its binder marginal is a point mass at b = 0, which m x m moments and a gamma weight
in b cannot hold: their reconstruction spreads it into a signed density whose binder moments
vanish, and the efficiencies, steep in b/p near 0, then act on garbage). The ROM therefore keeps
the dry granules apart, as a univariate population in p,

    n(p, b) = n_dry(p) delta(b) + n_wet(p, b),    D_k = int p^k n_dry dp,  k < m,

with n_dry expanded in the p-part of the basis (gamma weight of shape lambda, mean c; the
moment-consistent map G_dry^-1 on [0, p_max] or the seed's plain projection). Processes:

    dry + dry -> dry      dD_a/dt  = 1/2 int int beta(p, 0; p', 0) [(p+p')^a - p^a - p'^a] n n'
    dry + wet -> wet      dW_ij/dt += int int beta(p, 0; r') [(p+p')^i - p'^i] b'^j n_dry n_wet
                          dD_e/dt  -= int int beta(p, 0; r') p^e n_dry n_wet
    dry + droplet -> wet  L_e = n_d int k_d(p, 0) p^e n_dry,  dD_e/dt -= L_e,  dn_d/dt -= L_0,
                          dW_ij/dt += sum_{e<=i} C(i, e) p_d^(i-e) b_d^j L_e   ((p+p_d)^i b_d^j)

(b_d the droplet's liquid: p_d for pure binder, (1 - s) p_d for a solution.) The droplet gain
of the wet class is written through the dry loss L_e (binomial map CAPMAP), so that granule
mass W_10 + D_1 + p_d n_d and binder W_01 + b_d n_d are conserved to round-off by
construction; the cross loss of D_1 is the negated cross gain of W_10, entry by entry.

Tensors (internal units u = p / c; state units applied by the caller):
Psi_d[r, (e, k)] = w_r u_r^e psi~_k(u_r) on the dry nodes, Psi_w[s, (f, l)] = W_s A_f phi~_l on
the wet nodes, kernel matrices B_dd[r, r'] = beta(dry r, dry r'), B_dw[r, s] = beta(dry r,
wet s), Z_dd = Psi_d^T B_dd Psi_d, Z_dw = Psi_d^T B_dw Psi_w.
"""
from math import comb

import numpy as np

from ...physics.injection import droplet_moment
from ...physics.rates import aggregation_rate_matrix, symmetric_aggregation_rate_matrix
from .basis import (consistent_inverse, mass_nodes, moment_index, projection_matrix,
                    univariate_values)
from .wet import capture_rate_vector


# ---- dry basis ------------------------------------------------------------------------------
def dry_basis(m, c_dry, lam_dry, p_max, n_dry, consistent, p_ref):
    """The dry class's quadrature and basis in state units.

    Nodes x = p / p_ref on n_dry uniform cells of [0, p_max] (singular-midpoint weights w
    [per unit u = p / c_dry], exact for u^(lam_dry - 1) over each cell), the state-unit basis
    psiS (n_dry, m) with n_dry(p) = sum_k D~_k psiS_k (D~_k = D_k / (N_ref p_ref^k)), the
    map G_dry^-1 (internal units u), the scaling r_dry = (p_ref / c_dry)^k and the condition
    number of the equilibrated G_dry (1 for the plain projection).
    """
    u, w = mass_nodes(c_dry, lam_dry, p_max, n_dry)
    psi = univariate_values(u, projection_matrix(m, lam_dry), lam_dry)
    if consistent:
        G = (u[:, None] ** np.arange(m)[None, :]).T @ (psi * w[:, None])
        Ginv, cond = consistent_inverse(G)
    else:
        Ginv, cond = np.eye(m), 1.0
    rd = (p_ref / c_dry) ** np.arange(m)
    return u * c_dry / p_ref, w, (psi @ Ginv) * rd[None, :], Ginv, rd, cond


def _weighted_monomials(mon, w, basis):
    """Psi[s, e * n_basis + k] = w_s mon[s, e] basis[s, k]."""
    n, ne = mon.shape
    return (mon[:, :, None] * (basis * w[:, None])[:, None, :]).reshape(n, ne * basis.shape[1])


def dry_dry_tensor(Bdd, x, w, psi, m):
    """T[a, k, l] (state units, a, k, l < m), symmetric in (k, l): dry-dry aggregation."""
    Psi = _weighted_monomials(x[:, None] ** np.arange(m)[None, :], w, psi)
    Z = (Psi.T @ (Bdd @ Psi)).reshape(m, m, m, m)          # e, k, f, l
    T = np.zeros((m, m, m))
    T[0] = -0.5 * Z[0, :, 0, :]
    for a in range(2, m):
        for e in range(1, a):
            T[a] += 0.5 * comb(a, e) * Z[e, :, a - e, :]
    return 0.5 * (T + T.transpose(0, 2, 1))


def dry_wet_tensors(Bdw, x, w, psi, xw, yw, Ww, phi, m):
    """(X[a, k, l], XL[e, k, l]) in state units: gain of wet moment a = (i, j) and loss of
    dry moment e < m from aggregation of dry basis function k with wet basis function l
    (xw, yw: wet nodes' p / p_ref, b / p_ref; phi: the wet state-unit basis on them)."""
    K = m * m
    Pd = _weighted_monomials(x[:, None] ** np.arange(m)[None, :], w, psi)      # (n_d, m*m)
    mon = np.stack([xw ** i * yw ** j for (i, j) in moment_index(m)], axis=1)
    Pw = _weighted_monomials(mon, Ww, phi)                                       # (N, K*K)
    Z = (Pd.T @ (Bdw @ Pw)).reshape(m, m, K, K)                                  # e, k, f, l
    X = np.zeros((K, m, K))
    for a, (i, j) in enumerate(moment_index(m)):
        for e in range(1, i + 1):
            X[a] += comb(i, e) * Z[e, :, (i - e) * m + j, :]
    # (X[(1, 0)] = Z[1, :, 0, :] exactly: the dry mass lost is the wet mass gained, bitwise)
    return X, -Z[:, :, 0, :]


def dry_capture_matrix(kd, x, w, psi, m):
    """Cdd[e, k] = int k_d x^e psiS_k (state units): droplets captured by dry granules."""
    return ((x[:, None] ** np.arange(m)[None, :]) * (w * kd)[:, None]).T @ psi


def capture_map(m, xd, xl):
    """CAPMAP[e, a] = C(i, e) xd^(i - e) xl^j for e <= i, a = (i, j): the wet moments a dry
    granule's loss moments L_e become once it has captured one droplet (xd = p_d / p_ref,
    xl = b_d / p_ref its liquid, xd for pure binder)."""
    out = np.zeros((m, m * m))
    for a, (i, j) in enumerate(moment_index(m)):
        for e in range(i + 1):
            out[e, a] = comb(i, e) * droplet_moment(xd, xl, i - e, j)
    return out


def dry_class(m, c_dry, lam_dry, p_max, n_dry, consistent, p_ref, pd, bd):
    """The dry class's basis and its weight-independent blocks: a dict with the nodes x
    (p / p_ref), weights w, state-unit basis psi, the functionals f43 (m), the CAPMAP
    (m, K), the reconstruction block ``basis`` (n_dry, c_dry, lam_dry, Ginv, r_dry, support
    functionals) and cond(G_dry)."""
    x, w, psi, Ginv, rd, cond = dry_basis(m, c_dry, lam_dry, p_max, n_dry, consistent, p_ref)
    support = np.concatenate([w @ psi, (x * w) @ psi])
    basis = np.concatenate([[float(n_dry), c_dry, lam_dry], Ginv.ravel(), rd, support])
    return dict(x=x, w=w, psi=psi, p=x * p_ref, f43=(x ** (4.0 / 3.0) * w) @ psi,
                capmap=capture_map(m, pd / p_ref, bd / p_ref),
                basis=basis, cond=cond)


def dry_kernels(dry, p_wet, b_wet, u0, uparams, ucfg, separate):
    """Kernel data of the dry nodes at collision velocity u0 [m/s]: dry-dry and dry-wet
    pair-rate matrices and the dry capture-rate vector [m3/s per unit k0] (wet nodes' masses
    p_wet, b_wet [kg]). Independent of the weights."""
    p = dry["p"]
    zeros = np.zeros_like(p)
    Bdd = np.empty((len(p), len(p)))
    # unit ktgf multiplier: alpha = 0 -> g0 = 1, theta = 1, d43 = 1
    symmetric_aggregation_rate_matrix(p, zeros, 0.0, 1.0, u0, 1.0, uparams, ucfg, Bdd)
    kd = np.zeros(len(p))
    if separate:
        capture_rate_vector(p, zeros, u0, uparams, ucfg, kd)
    return Bdd, dry_wet_rates(dry, p_wet, b_wet, u0, uparams, ucfg), kd


def dry_wet_rates(dry, p_wet, b_wet, u0, uparams, ucfg):
    """The dry-wet pair-rate matrix [m3/s per unit k0] of ``dry_kernels`` alone (dry nodes by
    wet nodes of masses p_wet, b_wet [kg]) at collision velocity u0 [m/s]: what a weight slice
    with nodes of its own needs; the dry-dry block depends on the dry nodes only."""
    p = dry["p"]
    Bdw = np.empty((len(p), len(p_wet)))
    aggregation_rate_matrix(p, np.zeros_like(p), p_wet, b_wet, 0.0, 1.0, u0, 1.0, uparams, ucfg,
                            Bdw)
    return Bdw


def dry_tensors(dry, Bdd, kd, m):
    """(Qdd[pair, a], Cdd[k, e]) in state units at one slice: dry-dry aggregation and droplet
    capture by dry granules."""
    iu = np.triu_indices(m)
    fold = np.where(iu[0] == iu[1], 1.0, 2.0)
    T = dry_dry_tensor(Bdd, dry["x"], dry["w"], dry["psi"], m)
    Qdd = (T[:, iu[0], iu[1]] * fold[None, :]).T
    Cdd = dry_capture_matrix(kd, dry["x"], dry["w"], dry["psi"], m).T
    return Qdd, Cdd


def cross_tensors(dry, wet, Bdw, m, p_ref):
    """(X[k, l, a], XL[k, l, e]) in state units: dry + wet -> wet for one wet basis ``wet``
    (``laguerre_wet.wet_basis``) at one slice."""
    phiS = wet["PhiC"] * wet["r"][None, :]
    X, XL = dry_wet_tensors(Bdw, dry["x"], dry["w"], dry["psi"], wet["p"] / p_ref,
                            wet["b"] / p_ref, wet["W"], phiS, m)
    return X.transpose(1, 2, 0), XL.transpose(1, 2, 0)
