"""A 3-D fluid bed of any size as a snapshot (``pbe-cfd case make --cells N --3d``).

The bundled bed (0.15 m wide in x, 0.6 m high in y) extruded in depth (z, default 0.15 m) on a
structured hex mesh of near-cubic cells, cells numbered x fastest, then y, then z (the order
blockMesh gives one hex block). Written as a snapshot pair that ``pbe-cfd couple`` reads like
the bundled one (``domain.case = ".../bed3d.vtu"``): ``bed3d.vtu`` (mesh; alpha [-], Theta
[m2/s2], cell_volume [m3], cell_centre [m], cellID) and ``bed3d_flux.npz`` (the solids face
flux [m3/s]).

Fields are mapped, not computed: a CFD run on a 3-D mesh of 1e6 cells is beyond this machine's
budget. alpha and Theta are the bundled small snapshot's (a twoPhaseEulerFoam run), bilinearly
interpolated in (x, y) between its cell centres and the same at every depth.

The flux is divergence-free on every cell by construction, through discrete stream functions
on the mesh's edges: the in-plane circulation from the stream function psi(x, y) of the small
case's solids flux (made divergence-free on its closed box by the least-squares nearest
correction, as the transport does on its active set; integrated along x, interpolated bilinearly and scaled to the cell
depth), plus a depth-wise circulation chi(y, z) = DEPTH_CIRCULATION max_x|psi(x, y)|
sin(pi z / depth) in the (y, z) planes so that granules also cross the depth. Every cell's net
outflow is a telescoping sum of stream-function differences: zero to round-off. Nothing crosses
the outer boundary (psi = chi = 0 there); the transport's restriction to the active set then
cuts only the faces at its edge, and corrects those as it does for any case.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

#: Size of the bundled bed [m]: width (x) and height (y); the small mesh's depth (z).
WIDTH, HEIGHT, SMALL_DEPTH = 0.15, 0.6, 0.02
#: Depth of the 3-D bed unless given [m] (ours: a square cross-section, 0.15 m x 0.15 m).
DEFAULT_DEPTH = 0.15
#: Amplitude of the depth-wise circulation relative to the in-plane one [-] (ours: an
#: assumption to make the bed exchange granules across its depth; no CFD source).
DEPTH_CIRCULATION = 0.5
#: Names of the files written.
VTU_NAME, FLUX_NAME = "bed3d.vtu", "bed3d_flux.npz"


def grid_for(n_cells: int, depth: float = DEFAULT_DEPTH) -> tuple[int, int, int]:
    """(nx, ny, nz) of near-cubic cells whose product is close to ``n_cells`` [-] for the
    bed of WIDTH x HEIGHT x ``depth`` [m] (at least 2 cells each way)."""
    if n_cells < 8:
        raise ValueError(f"--cells {n_cells}: a 3-D bed needs at least 8 cells")
    h = (WIDTH * HEIGHT * depth / float(n_cells)) ** (1.0 / 3.0)
    return tuple(max(2, int(round(s / h))) for s in (WIDTH, HEIGHT, depth))


def _small_grid(cells, flux):
    """The small snapshot's cells on its (i, j) grid and psi at its vertices [m3/s per
    SMALL_DEPTH]: returns (x centres, y centres, alpha (nx, ny), Theta (nx, ny), psi
    (nx+1, ny+1))."""
    c = np.asarray(cells.cell_centre)
    xs, ys = np.unique(np.round(c[:, 0], 9)), np.unique(np.round(c[:, 1], 9))
    nx, ny = xs.size, ys.size
    if nx * ny != cells.n_cells:
        raise ValueError(f"the small snapshot is not a {nx} x {ny} structured grid")
    i = np.searchsorted(xs, np.round(c[:, 0], 9))
    j = np.searchsorted(ys, np.round(c[:, 1], 9))
    alpha = np.zeros((nx, ny))
    theta = np.zeros((nx, ny))
    alpha[i, j], theta[i, j] = cells.alpha, cells.theta
    o, nb = np.asarray(flux.owner), np.asarray(flux.neighbour)
    f = _closed_box_flux(o, nb, np.asarray(flux.flux, dtype=float), cells.n_cells)
    fy = np.zeros((nx, ny + 1))           # +y flux through the face below cell (i, j)
    vertical = j[o] != j[nb]
    sign = np.where(j[nb] > j[o], 1.0, -1.0)
    lo = np.minimum(j[o], j[nb])
    fy[i[o][vertical], lo[vertical] + 1] = (sign * f)[vertical]
    psi = np.zeros((nx + 1, ny + 1))      # psi(i+1, j) = psi(i, j) - Fy(i, j)
    psi[1:, :] = -np.cumsum(fy, axis=0)
    return xs, ys, alpha, theta, psi


def _closed_box_flux(owner, neighbour, flux, n):
    """The least-squares nearest inner-face flux [m3/s] with zero net outflow from each of
    the n cells of a connected mesh: flux - D^T lambda, (D D^T) lambda = D flux, one cell
    pinned (D the cell-face incidence), with one step of iterative refinement."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    m = len(flux)
    d = sp.csr_matrix((np.r_[np.ones(m), -np.ones(m)],
                       (np.r_[owner, neighbour], np.r_[np.arange(m), np.arange(m)])),
                      shape=(n, m))
    solve = spla.factorized((d @ d.T).tocsc()[1:, 1:])
    out = np.array(flux, dtype=float)
    for _ in range(2):
        lam = np.r_[0.0, solve((d @ out)[1:])]
        out = out - d.T @ lam
    return out


def _bilinear(xs, ys, values, x, y):
    """Values on the grid (xs, ys) interpolated at points (x, y), held at the edge values
    outside the grid."""
    from scipy.interpolate import RegularGridInterpolator
    f = RegularGridInterpolator((xs, ys), values, bounds_error=False, fill_value=None)
    pts = np.column_stack([np.clip(x, xs[0], xs[-1]), np.clip(y, ys[0], ys[-1])])
    return f(pts)


def make_bed(n_cells: int, depth: float = DEFAULT_DEPTH):
    """The 3-D bed's mesh, fields and flux (see the module docstring). Returns (points
    (n_points, 3) [m], hexes (n, 8), cell fields dict, FaceFlux)."""
    from .fields import CellData  # noqa: F401  (the reader's types, for the docs)
    from .flux import FaceFlux
    from .snapshot import load_snapshot

    nx, ny, nz = grid_for(n_cells, depth)
    small, sflux = load_snapshot(with_flux=True)
    xs, ys, alpha_s, theta_s, psi_s = _small_grid(small, sflux)
    dx, dy, dz = WIDTH / nx, HEIGHT / ny, depth / nz
    xv, yv, zv = (np.linspace(0.0, WIDTH, nx + 1), np.linspace(0.0, HEIGHT, ny + 1),
                  np.linspace(-0.5 * depth, 0.5 * depth, nz + 1))
    xc, yc, zc = 0.5 * (xv[1:] + xv[:-1]), 0.5 * (yv[1:] + yv[:-1]), 0.5 * (zv[1:] + zv[:-1])
    # in-plane stream function on the vertices, per unit depth of the small mesh
    vx_s, vy_s = np.linspace(0.0, WIDTH, psi_s.shape[0]), np.linspace(0.0, HEIGHT, psi_s.shape[1])
    X, Y = np.meshgrid(xv, yv, indexing="ij")
    psi = _bilinear(vx_s, vy_s, psi_s, X.ravel(), Y.ravel()).reshape(nx + 1, ny + 1)
    psi[0, :] = psi[-1, :] = psi[:, 0] = psi[:, -1] = 0.0
    psi *= dz / SMALL_DEPTH
    # depth-wise stream function chi(y, z) on the (y, z) vertices, per cell width dx
    amp = np.abs(psi).max(axis=0) * (dx / dz)                      # (ny+1,)
    chi = DEPTH_CIRCULATION * amp[:, None] * np.sin(math.pi * (zv - zv[0]) / depth)[None, :]
    chi[:, 0] = chi[:, -1] = 0.0
    cid = np.arange(nx * ny * nz).reshape(nz, ny, nx).transpose(2, 1, 0)   # cid[i, j, k]
    owners, neigh, fluxes = [], [], []
    # x-faces between (i-1, j, k) and (i, j, k): psi(i, j+1) - psi(i, j), same at every k
    fx = (psi[1:-1, 1:] - psi[1:-1, :-1])[:, :, None] * np.ones(nz)
    owners.append(cid[:-1].ravel()), neigh.append(cid[1:].ravel()), fluxes.append(fx.ravel())
    # y-faces between (i, j-1, k) and (i, j, k): -(psi(i+1, j) - psi(i, j)) + chi diff in z
    fy = -(psi[1:, 1:-1] - psi[:-1, 1:-1])[:, :, None] + (chi[1:-1, 1:] - chi[1:-1, :-1])[None]
    owners.append(cid[:, :-1].ravel()), neigh.append(cid[:, 1:].ravel()), fluxes.append(fy.ravel())
    # z-faces between (i, j, k-1) and (i, j, k): -(chi(j+1, k) - chi(j, k))
    fz = np.broadcast_to(-(chi[1:, 1:-1] - chi[:-1, 1:-1])[None], (nx, ny, nz - 1))
    owners.append(cid[:, :, :-1].ravel()), neigh.append(cid[:, :, 1:].ravel())
    fluxes.append(np.ascontiguousarray(fz).ravel())
    owner, neighbour, flux = (np.concatenate(owners), np.concatenate(neigh),
                              np.concatenate(fluxes))
    # cells (x fastest) and their fields
    I, J, K = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    order = np.argsort(cid.ravel())
    ii, jj, kk = I.ravel()[order], J.ravel()[order], K.ravel()[order]
    centre = np.column_stack([xc[ii], yc[jj], zc[kk]])
    alpha = np.clip(_bilinear(xs, ys, alpha_s, centre[:, 0], centre[:, 1]), 0.0, 1.0)
    theta = np.maximum(_bilinear(xs, ys, theta_s, centre[:, 0], centre[:, 1]), 0.0)
    pid = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nz + 1, ny + 1, nx + 1)
    pid = pid.transpose(2, 1, 0)
    hexes = np.column_stack([pid[ii, jj, kk], pid[ii + 1, jj, kk], pid[ii + 1, jj + 1, kk],
                             pid[ii, jj + 1, kk], pid[ii, jj, kk + 1], pid[ii + 1, jj, kk + 1],
                             pid[ii + 1, jj + 1, kk + 1], pid[ii, jj + 1, kk + 1]])
    PX, PY, PZ = np.meshgrid(xv, yv, zv, indexing="ij")
    porder = np.argsort(pid.ravel())
    points = np.column_stack([PX.ravel()[porder], PY.ravel()[porder], PZ.ravel()[porder]])
    fields = {"alpha": alpha, "Theta": theta, "cell_volume": np.full(alpha.size, dx * dy * dz),
              "cell_centre": centre, "cellID": np.arange(alpha.size, dtype=np.int32)}
    empty = np.zeros(0, dtype=np.int64)
    face_flux = FaceFlux(owner=owner.astype(np.int64), neighbour=neighbour.astype(np.int64),
                         flux=flux, boundary_face_cell=empty, boundary_face_flux=np.zeros(0),
                         boundary_face_patch=empty, patch_names=[], n_cells=int(alpha.size),
                         field="alphaPhi.particlesMean (mapped, stream functions)",
                         time=float(sflux.time))
    meta = {"grid": [nx, ny, nz], "depth_m": depth, "cell_m": [dx, dy, dz],
            "fields": "alpha, Theta bilinear from the bundled small snapshot, same at every "
                      "depth", "flux": "stream functions: in-plane from the small case, "
                      f"depth-wise amplitude {DEPTH_CIRCULATION}", "time_s": float(sflux.time)}
    return points, hexes, fields, face_flux, meta


def write_bed(directory, n_cells: int, depth: float = DEFAULT_DEPTH) -> dict:
    """Write ``bed3d.vtu`` and ``bed3d_flux.npz`` into ``directory`` (an existing directory
    the caller made for this output). Returns the bed's description (grid, cell sizes [m],
    cells, faces, the largest net outflow relative to the largest face flux)."""
    import meshio

    points, hexes, fields, flux, meta = make_bed(n_cells, depth)
    d = Path(directory)
    mesh = meshio.Mesh(points, [("hexahedron", hexes)],
                       cell_data={k: [v] for k, v in fields.items()})
    meshio.write(d / VTU_NAME, mesh, file_format="vtu", compression="zlib")
    source = {"case": "pbe-cfd case make --3d", **meta}
    np.savez_compressed(
        d / FLUX_NAME, owner=flux.owner.astype(np.int32),
        neighbour=flux.neighbour.astype(np.int32), flux=flux.flux,
        boundary_face_cell=flux.boundary_face_cell.astype(np.int32),
        boundary_face_flux=flux.boundary_face_flux,
        boundary_face_patch=flux.boundary_face_patch.astype(np.int32),
        patch_names=np.array([], dtype="<U1"), n_cells=np.array(flux.n_cells),
        field=np.array(flux.field), time_s=np.array(flux.time),
        window_start_s=np.array(float("nan")), source=np.array(json.dumps(source)))
    div = np.abs(flux.net_outflow()).max() / max(np.abs(flux.flux).max(), 1e-300)
    return {**meta, "cells": int(flux.n_cells), "faces": int(flux.flux.size),
            "max_net_outflow_rel": float(div), "vtu": str(d / VTU_NAME),
            "flux_file": str(d / FLUX_NAME)}


def make_case(directory, n_cells, depth=None, three_d=True, overwrite=False) -> str:
    """``pbe-cfd case make``: write the 3-D bed of ``n_cells`` cells and ``depth`` [m] (None:
    DEFAULT_DEPTH) into ``directory`` atomically (an earlier bed there is replaced only with
    ``overwrite``; files pbe-cfd did not write are never touched). Returns the summary line.
    Raises output.UsageError on bad input."""
    from .. import output
    if not three_d or n_cells is None:
        raise output.UsageError("case make: give --3d and --cells N (the 3-D bed is the one "
                                "kind made)")
    depth = DEFAULT_DEPTH if depth is None else float(depth)
    if not depth > 0.0:
        raise output.UsageError(f"case make: --depth {depth}: expected a depth > 0 in m")
    if n_cells < 8:
        raise output.UsageError(f"case make: --cells {n_cells}: a 3-D bed needs at least 8 "
                                "cells")
    target = Path(directory)
    with output.atomic_directory(target, overwrite, flag="--dir", kind="3-D bed") as tmp:
        info = write_bed(tmp, n_cells, depth)
    nx, ny, nz = info["grid"]
    return (f"3-D bed {target}: {nx} x {ny} x {nz} = {info['cells']} cells of "
            f"{1e3 * info['cell_m'][0]:.3g} mm, {info['faces']} inner faces, largest net "
            f"outflow {info['max_net_outflow_rel']:.1e} of the largest face flux; use "
            f'domain.case = "{(target / VTU_NAME).resolve()}"')
