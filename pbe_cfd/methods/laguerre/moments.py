"""SI moments, the reconstructed densities and the support shares of Laguerre cell states
(Python; state layout: ``rhs`` module doc)."""
import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_moment
from .layout import (AUX_FOLLOWING, AUX_OFF_SUPPORT, AUX_ORDER, AUX_P_MAX, free_droplets,
                     weight_corners, wet_support)
from .tensor import (basis_values, dry_particles, dry_support_functionals,
                     fraction_basis_values, projection_matrix, univariate_values, unpack_basis,
                     wet_particles)

__all__ = ["moments_from_state", "reconstruct", "reconstruct_dry", "reconstructed_moment",
           "support_share"]


def _droplet_moments(pd, bd, i, j):
    """p^i b^j [kg^(i+j)] of one droplet per row (arrays of masses and liquids [kg])."""
    return np.array([droplet_moment(p, b, i, j) for p, b in zip(pd, bd)])


def moments_from_state(state_rows, params, config, m, aux=None):
    """SI moments of one state or of rows of states (shape (n, N_STATE)).

    Returns dict of arrays (shape (n,), or floats for a 1-D state):
    "M{i}{j}" [kg^(i+j)/m3], i, j < m: the whole population, free droplets included (docs/physics.md
    section 11); "granule_M{i}{j}": granules only (wet + dry); "wet_M{i}{j}",
    "dry_M{i}0": each class; if droplets are separate, "droplet_number_density" [1/m3]. For
    m = 2, "M20" and "M02" are not carried: with ``aux`` they are added from the
    reconstruction on the support (an estimate), otherwise absent.
    """
    rows = np.asarray(state_rows, dtype=float)
    one = rows.ndim == 1
    rows = np.atleast_2d(rows)
    K = m * m
    nref = params[P.NUMBER_SCALE]
    pref = params[P.MASS_SCALE]
    sep = int(config[P.SEPARATE_DROPLETS]) == 1 and rows.shape[1] > K + m
    nd, pd, bd = free_droplets(rows, params, config)     # [1/m3], one droplet [kg]
    out = {}
    for i in range(m):
        out[f"dry_M{i}0"] = rows[:, K + i] * nref * pref ** i
        for j in range(m):
            w = rows[:, i * m + j] * nref * pref ** (i + j)
            out[f"wet_M{i}{j}"] = w
            g = w + out[f"dry_M{i}0"] if j == 0 else w
            out[f"granule_M{i}{j}"] = g
            out[f"M{i}{j}"] = g + nd * _droplet_moments(pd, bd, i, j)
    if sep:
        out["droplet_number_density"] = nd
    if m == 2 and aux is not None:
        for (i, j) in ((2, 0), (0, 2)):
            g = np.array([reconstructed_moment(r, aux, params, config, i, j) for r in rows])
            out[f"granule_M{i}{j}"] = g
            out[f"M{i}{j}"] = g + nd * _droplet_moments(pd, bd, i, j)
    if one:
        out = {k: float(v[0]) for k, v in out.items()}
    return out


def reconstruct(state, aux, params, config, p, b, clip_support=True):
    """Reconstructed density n(p, b) [1/(m3 kg2)] of the wet granules at masses p, b [kg]
    (arrays); the dry granules (a line density at b = 0): ``reconstruct_dry``. With adaptive
    weights the neighbouring weight slices' reconstructions are blended as the RHS blends them.

    clip_support: zero outside the support b <= p, p <= p_max, b <= b_max (where the ROM
    lives); False evaluates the expansion everywhere (the plain projection is defined on the
    whole quadrant).
    """
    p = np.asarray(p, float)
    b = np.asarray(b, float)
    shape = np.broadcast(p, b).shape
    pp = np.broadcast_to(p, shape).ravel()
    bb = np.broadcast_to(b, shape).ravel()
    n = np.zeros(pp.shape)
    for w, frac in weight_corners(state, aux):
        B = unpack_basis(aux, w)
        K = B["m"] ** 2
        coef = B["Ginv"] @ (np.asarray(state[:K], float) * B["r"])
        values = fraction_basis_values if aux[AUX_FOLLOWING] == 1.0 else basis_values
        phi = values(pp / B["c"], bb / B["d"], B["Cp"], B["Cb"], B["lam"], B["gam"])
        part = frac * (phi @ coef) * params[P.NUMBER_SCALE] / (B["c"] * B["d"])
        if clip_support:
            p_max, b_max = wet_support(aux, w)
            part = np.where((bb <= pp) & (pp <= p_max) & (bb <= b_max), part, 0.0)
        n += part
    return n.reshape(shape)


def reconstruct_dry(state, aux, params, p, clip_support=True):
    """Reconstructed density n_dry(p) [1/(m3 kg)] of the dry granules at masses p [kg]."""
    B = unpack_basis(aux)
    m = B["m"]
    p = np.asarray(p, float)
    coef = B["Ginv_dry"] @ (np.asarray(state[m * m:m * m + m], float) * B["r_dry"])
    psi = univariate_values(p.ravel() / B["c_dry"], projection_matrix(m, B["lam_dry"]),
                               B["lam_dry"])
    n = psi @ coef * params[P.NUMBER_SCALE] / B["c_dry"]
    if clip_support:
        n = np.where(p.ravel() <= aux[AUX_P_MAX], n, 0.0)
    return n.reshape(p.shape)


def reconstructed_moment(state, aux, params, config, i, j):
    """int_S p^i b^j n [kg^(i+j)/m3] of the reconstruction (wet, plus dry for j = 0) over the
    support, with the same quadrature as the tensors (so it returns the carried moments
    exactly when consistent)."""
    w, p, b = wet_particles(state, aux)
    val = np.sum(w * p ** i * b ** j)
    if j == 0:
        wd, pdry, _ = dry_particles(state, aux)
        val += np.sum(wd * pdry ** i)
    return float(val * params[P.NUMBER_SCALE])


def support_share(state, aux, params, config):
    """(number, mass) carried by the reconstruction on the support relative to M00, M10 of
    the granules [-]: 1 for the consistent variant by construction; the plain projection's
    deficit otherwise."""
    m = int(aux[AUX_ORDER])
    K = m * m
    s = np.asarray(state[:K], float)
    dry = np.asarray(state[K:K + m], float)
    dn, dm = dry_support_functionals(aux)
    number = dn @ dry
    mass = dm @ dry
    for w, frac in weight_corners(state, aux):
        o = int(aux[AUX_OFF_SUPPORT]) + w * 2 * K
        number += frac * (aux[o:o + K] @ s)
        mass += frac * (aux[o + K:o + 2 * K] @ s)
    return float(number / (s[0] + dry[0])), float(mass / (s[m] + dry[1]))
