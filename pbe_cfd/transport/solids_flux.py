"""The time-averaged solids face flux restricted to the cells that hold granules, made
divergence-free there, and the upwind rate matrix of the transport operator on it (SI: flux in
m3/s, volumes in m3). See ``pbe_cfd.transport.operator`` for the scheme these pieces build."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components


# ---------------------------------------------------------------------------- flux on a set
@dataclass
class ActiveFlux:
    """The solids flux restricted to a set of cells and made divergence-free on it.

    cells        (n,) global indices of the cells of the set (ascending)
    owner, neighbour (m,) local indices (into ``cells``) of the faces inside the set
    flux         (m,) corrected flux from owner to neighbour [m3/s]
    raw_flux     (m,) the flux as read, on the same faces [m3/s]
    stats        dict of the correction's size (see ``restrict_and_correct``)
    """
    cells: np.ndarray
    owner: np.ndarray
    neighbour: np.ndarray
    flux: np.ndarray
    raw_flux: np.ndarray
    stats: dict = field(default_factory=dict)


def _incidence(owner, neighbour, n):
    """Cell-face incidence D (n x m): +1 at the owner, -1 at the neighbour of each face."""
    m = len(owner)
    rows = np.concatenate([owner, neighbour])
    cols = np.concatenate([np.arange(m), np.arange(m)])
    vals = np.concatenate([np.ones(m), -np.ones(m)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, m))


#: Cells up to which the divergence correction factorizes its graph Laplacian (sparse LU);
#: above, Jacobi-preconditioned conjugate gradients (ours: the LU of a 3-D bed's Laplacian
#: fills in as n^(4/3), about 0.9 GB at 6e4 active cells, while CG needs a few vectors).
DIRECT_MAX_CELLS = 20_000
#: Residual (2-norm) of the CG solve relative to that of |D| |flux|, the cells' summed face
#: fluxes (the scale of the net outflows) [-] (ours: a few hundred times round-off).
CG_RTOL = 1e-13


def divergence_free(owner, neighbour, flux, n, direct_max=None):
    """The least-squares nearest flux [m3/s] with zero net outflow from each of n cells.

    owner, neighbour: (m,) local cell indices of the faces; flux (m,) owner -> neighbour [m3/s].
    Solves (D D^T) lambda = D flux on each connected component (one cell pinned) and returns
    flux - D^T lambda, whose net outflow is zero to round-off. A face set that is a tree (no
    loops) has only the zero divergence-free flux. Up to ``direct_max`` cells (default
    DIRECT_MAX_CELLS) the Laplacian is factorized; above, it is solved by conjugate gradients
    to CG_RTOL of the outflow scale, so the net outflow left is of that order.
    """
    flux = np.asarray(flux, dtype=float)
    if len(flux) == 0:
        return flux.copy()
    d = _incidence(owner, neighbour, n)
    lap = (d @ d.T).tocsr()
    n_comp, label = connected_components(lap, directed=False)
    pinned = np.zeros(n, dtype=bool)
    _, first = np.unique(label, return_index=True)
    pinned[first] = True
    keep = np.flatnonzero(~pinned)
    out = flux.copy()
    if keep.size == 0:
        return out
    sub = lap[keep][:, keep].tocsc()
    limit = DIRECT_MAX_CELLS if direct_max is None else int(direct_max)
    scale = float(np.linalg.norm(abs(d) @ np.abs(flux))) if keep.size > limit else 0.0
    solve = spla.factorized(sub) if keep.size <= limit else _cg_solver(sub.tocsr(), scale)
    for _ in range(2):           # one step of iterative refinement takes it to round-off
        rhs = d @ out
        lam = np.zeros(n)
        lam[keep] = solve(rhs[keep])
        out = out - d.T @ lam
    return out


def _cg_solver(lap, scale):
    """solve(rhs) for the SPD graph Laplacian ``lap`` by Jacobi-preconditioned conjugate
    gradients to an absolute residual CG_RTOL * ``scale`` [m3/s]."""
    inv_diag = 1.0 / lap.diagonal()
    precond = spla.LinearOperator(lap.shape, matvec=lambda x: inv_diag * x, dtype=float)

    def solve(rhs):
        x, info = spla.cg(lap, rhs, rtol=0.0, atol=CG_RTOL * scale, M=precond,
                          maxiter=20 * lap.shape[0])
        if info != 0:
            raise ValueError(f"divergence correction: conjugate gradients did not reach "
                             f"{CG_RTOL:g} of the outflow scale in {info} iterations")
        return x
    return solve


def restrict_and_correct(flux, volume_mask) -> ActiveFlux:
    """Restrict a FaceFlux to the cells of ``volume_mask`` and make it divergence-free there.

    flux: pbe_cfd.io.openfoam.FaceFlux (owner, neighbour, flux [m3/s], boundary faces);
    volume_mask: (n_cells,) bool, the cells that hold granules. Faces crossing the edge of the
    set and boundary faces carry nothing (closed bed). ``stats`` reports, all relative to the
    total |flux| on the faces inside the set (``flux_inside_m3_s``): the flux cut at the set's
    edge and at the outer boundary, the divergence before correction (sum over cells of
    |net outflow|), and the L1 and max size of the correction.
    """
    mask = np.asarray(volume_mask, dtype=bool)
    cells = np.flatnonzero(mask)
    local = np.full(mask.size, -1, dtype=np.int64)
    local[cells] = np.arange(cells.size)
    o, nb, f = (np.asarray(flux.owner), np.asarray(flux.neighbour),
                np.asarray(flux.flux, dtype=float))
    inside = mask[o] & mask[nb]
    edge = mask[o] ^ mask[nb]
    lo, ln, raw = local[o[inside]], local[nb[inside]], f[inside].copy()
    corrected = divergence_free(lo, ln, raw, cells.size)
    total = float(np.abs(raw).sum())
    denom = total if total > 0 else 1.0
    b_in = mask[np.asarray(flux.boundary_face_cell, dtype=np.int64)] if len(
        flux.boundary_face_cell) else np.zeros(0, dtype=bool)
    div_before = (np.bincount(lo, raw, cells.size) - np.bincount(ln, raw, cells.size))
    div_after = (np.bincount(lo, corrected, cells.size)
                 - np.bincount(ln, corrected, cells.size))
    full_div = flux.net_outflow()
    stats = {
        "field": str(getattr(flux, "field", "")),
        "faces_inside": int(inside.sum()),
        "flux_inside_m3_s": total,
        "cut_at_active_edge_rel": float(np.abs(f[edge]).sum()) / denom,
        "cut_at_boundary_rel": float(np.abs(np.asarray(flux.boundary_face_flux)[b_in]).sum())
        / denom,
        "divergence_as_read_rel": float(np.abs(full_div[mask]).sum()) / denom,
        "divergence_before_rel": float(np.abs(div_before).sum()) / denom,
        "correction_l1_rel": float(np.abs(corrected - raw).sum()) / denom,
        "correction_max_rel": float(np.abs(corrected - raw).max() / np.abs(raw).max())
        if raw.size and np.abs(raw).max() > 0 else 0.0,
        "faces_reversed": int(np.count_nonzero(np.sign(corrected) * np.sign(raw) < 0)),
        "divergence_after_rel": float(np.abs(div_after).sum()) / denom,
    }
    return ActiveFlux(cells=cells, owner=lo, neighbour=ln, flux=corrected, raw_flux=raw,
                      stats=stats)


def upwind_generator(af: ActiveFlux, alpha, volume):
    """Rate matrix L [1/s] of the upwind scheme acting on states per m3 of bed.

    dS/dt = L S for the cells of ``af``; alpha (n,) solids fraction [-] and volume (n,) [m3]
    of those cells. Entry (down, up) = |F| / (V_down alpha_up), diagonal -Out_c / W_c with
    W_c = alpha_c V_c [m3] the solids volume. Returns (L as CSR, Out_c / W_c [1/s]).
    """
    alpha = np.asarray(alpha, dtype=float)
    volume = np.asarray(volume, dtype=float)
    n = alpha.size
    pos = af.flux >= 0.0
    up = np.where(pos, af.owner, af.neighbour)
    down = np.where(pos, af.neighbour, af.owner)
    mag = np.abs(af.flux)
    solids = alpha * volume
    out_rate = np.bincount(up, mag, n) / solids
    off = sp.csr_matrix((mag / (volume[down] * alpha[up]), (down, up)), shape=(n, n))
    gen = (off - sp.diags(out_rate)).tocsr()
    gen.sum_duplicates()
    return gen, out_rate


def vertical_axis(centre) -> int:
    """The axis (0, 1, 2) taken as vertical: the largest extent of the cell centres [m]
    (the bed is taller than wide; the snapshot carries no gravity vector)."""
    centre = np.asarray(centre, dtype=float)
    return int(np.argmax(np.ptp(centre, axis=0))) if centre.size else 0


def circulation_time(af: ActiveFlux, centre, solids) -> float:
    """Solids volume / mean upward solids flux through horizontal sections [s].

    af: the corrected flux [m3/s] on local faces; centre (n, 3) cell centres [m]; solids (n,)
    solids volumes [m3]. Each face contributes its upward flux times the vertical distance
    it spans (between the two cell centres); the sum over faces divided by the bed height
    (the span of the centres plus one mean spacing) is the height-averaged upward flux.
    """
    centre = np.asarray(centre, dtype=float)
    if len(af.flux) == 0:
        return math.inf
    ax = vertical_axis(centre)
    dz = centre[af.neighbour, ax] - centre[af.owner, ax]
    upward = np.clip(np.sign(dz) * af.flux, 0.0, None)
    span = np.abs(dz)
    spacing = float(span[span > 0].mean()) if np.any(span > 0) else 0.0
    height = float(np.ptp(centre[:, ax])) + spacing
    q_up = float((upward * span).sum()) / height if height > 0 else 0.0
    return float(np.sum(solids)) / q_up if q_up > 0 else math.inf


def pair_weighted_average(values, alpha, volume, bed_volume=None) -> float:
    """Bed average of a per-cell kernel factor as seen by a well-mixed bed [units of values].

    In the fast-circulation limit the population per unit solids q is uniform, cell c holds
    n_c = alpha_c q per m3 of bed, and the bed's pair-collision rate is
    sum_c V_c n_c^2 beta_c / 2. A well-mixed bed with the bed-mean number density
    <n> = sum_c V_c n_c / V_bed has the same rate with the factor returned here:
    V_bed sum_c V_c alpha_c^2 x_c / (sum_c V_c alpha_c)^2 (x_c: values, e.g. g0 sqrt(Theta)
    of the ktgf kernel; alpha [-]; volume [m3]; bed_volume [m3], default sum of volume).
    """
    x = np.asarray(values, dtype=float)
    a = np.asarray(alpha, dtype=float)
    v = np.asarray(volume, dtype=float)
    vb = float(v.sum()) if bed_volume is None else float(bed_volume)
    return vb * float(np.sum(v * a * a * x)) / float(np.sum(v * a)) ** 2
