"""The mid-plane section of a VTK cell mesh, for drawing one field in 2-D.

The section is normal to the mesh's thinnest extent, through the middle of the mesh. A mesh
one cell thick along that axis (a 2-D OpenFOAM case: hexahedra and prisms extruded through one
layer) is its own section: each cell's polygon is its face in the plane of the layer,
read with meshio in a few milliseconds. Any other mesh is cut with pyvista (VTK's slice filter).
Both give (polygons as (k, 2) vertex arrays in m, cell data per polygon, the two in-plane
axis names, a note saying where the cut is; empty for a one-cell-thick mesh). A plane named by
the user (``plane = ("z", 0.01)``: normal to z at z = 0.01 m, ``parse_plane("z=0.01")``) is
cut with pyvista on any mesh.
"""
from __future__ import annotations

import os

import numpy as np

AXIS_NAMES = "xyz"
#: Faces of a VTK cell that can lie in the plane of a layer (vertex indices, in order around):
#: the six faces of a hexahedron, the two triangles of a wedge
_LAYER_FACES = {"hexahedron": np.array([[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5],
                                        [2, 3, 7, 6], [3, 0, 4, 7]]),
                "wedge": np.array([[0, 1, 2], [3, 4, 5]])}


def _plane(bounds: np.ndarray) -> tuple[int, list[int], np.ndarray]:
    ext = bounds[:, 1] - bounds[:, 0]
    normal = int(np.argmin(ext))
    return normal, [a for a in range(3) if a != normal], bounds.mean(axis=1)


def thin_section(path: str | os.PathLike):
    """The section of a one-cell-thick mesh read with meshio, or None when the mesh is not one
    layer of hexahedra/wedges spanning its thinnest extent (then use ``section``)."""
    import contextlib
    import io

    import meshio
    try:
        with contextlib.redirect_stderr(io.StringIO()), \
                contextlib.redirect_stdout(io.StringIO()):   # meshio prints, then exits
            mesh = meshio.read(str(path))
    except (Exception, SystemExit):  # noqa: BLE001 - not a file meshio reads: let VTK try
        return None
    pts = np.asarray(mesh.points, dtype=float)
    if pts.size == 0 or not mesh.cells:
        return None
    bounds = np.stack([pts.min(axis=0), pts.max(axis=0)], axis=1)
    normal, axes, _ = _plane(bounds)
    thickness = bounds[normal, 1] - bounds[normal, 0]
    tol = 1e-9 * max(float(np.max(np.abs(bounds))), thickness, 1e-300)
    polys = []
    for block in mesh.cells:
        faces = _LAYER_FACES.get(block.type)
        if faces is None:
            return None
        cells = np.asarray(block.data)
        depth = pts[cells][:, :, normal]
        if (np.any(np.abs(depth.min(axis=1) - bounds[normal, 0]) > tol)
                or np.any(np.abs(depth.max(axis=1) - bounds[normal, 1]) > tol)):
            return None                        # a cell short of the full depth: not one layer
        # the outline is a face lying in one plane of the layer: its vertices in order
        flat = np.ptp(depth[:, faces], axis=2) <= tol          # (cells, faces)
        if not np.all(flat.any(axis=1)):
            return None                        # a cell not extruded along the thin axis
        outline = faces[np.argmax(flat, axis=1)]               # (cells, vertices)
        polys.extend(pts[np.take_along_axis(cells, outline, axis=1)][:, :, axes])
    data = {}
    for name, blocks in mesh.cell_data.items():
        data[name] = np.concatenate([np.asarray(b) for b in blocks])
    return polys, data, (AXIS_NAMES[axes[0]], AXIS_NAMES[axes[1]]), ""


def parse_plane(text: str) -> tuple[str, float]:
    """``"z=0.01"`` -> ("z", 0.01): the axis normal to a section plane and its position [m].
    Raises ValueError naming the expected form."""
    axis, sep, value = str(text).replace(" ", "").partition("=")
    try:
        pos = float(value)
    except ValueError:
        pos = float("nan")
    if not sep or axis.lower() not in AXIS_NAMES or not np.isfinite(pos):
        raise ValueError(f"--section {text!r}: expected AXIS=POSITION with AXIS x, y or z and "
                         "the position in m, e.g. z=0.01")
    return axis.lower(), pos


def section(mesh, plane: tuple[str, float] | None = None):
    """The section of a pyvista mesh: through ``plane`` = (axis, position [m]) where given,
    else the mid-plane normal to its thinnest extent. Returns (polygons as a list of (k, 2)
    vertex arrays in m, the cut's cell data (name -> values per polygon), the two in-plane
    axis names, a note saying where the cut is). A plane outside the mesh is a ValueError
    naming the mesh's extent along that axis."""
    bounds = np.asarray(mesh.bounds, dtype=float).reshape(3, 2)
    normal, axes, origin = _plane(bounds)
    if plane is not None:
        normal = AXIS_NAMES.index(plane[0])
        axes = [a for a in range(3) if a != normal]
        lo, hi = bounds[normal]
        if not lo <= plane[1] <= hi:
            raise ValueError(f"--section {plane[0]}={plane[1]:g}: outside the mesh, which "
                             f"spans {plane[0]} = {lo:.4g} to {hi:.4g} m")
        origin = origin.copy()
        origin[normal] = plane[1]
    cut = mesh.slice(normal=AXIS_NAMES[normal], origin=origin)
    if cut.n_cells == 0:
        raise ValueError("the mesh has no cells to draw")
    pts = np.asarray(cut.points)[:, axes]
    polys = [pts[np.asarray(f)] for f in cut.irregular_faces]
    data = {k: np.asarray(cut.cell_data[k]) for k in cut.cell_data.keys()}
    thin = cut.n_cells == mesh.n_cells          # one cell thick: the section is the mesh
    note = ("" if thin and plane is None
            else f"section {AXIS_NAMES[normal]} = {origin[normal]:.3g} m")
    return polys, data, (AXIS_NAMES[axes[0]], AXIS_NAMES[axes[1]]), note


def read_section(path: str | os.PathLike, plane: tuple[str, float] | None = None):
    """The section of the VTK file at ``path`` through ``plane`` (``section``; default the
    mid-plane: ``thin_section`` where it applies, else pyvista's cut). Raises ValueError for a
    file neither can read."""
    thin = thin_section(path) if plane is None else None
    if thin is not None:
        return thin
    import warnings

    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkObject
    shown = vtkObject.GetGlobalWarningDisplay()
    vtkObject.GlobalWarningDisplayOff()      # a truncated file: a page of VTK reader errors
    try:
        with warnings.catch_warnings(), pv.vtk_verbosity("off"):
            warnings.simplefilter("ignore")          # VTK's reader warns, then returns nothing
            mesh = pv.read(str(path))
    except Exception as exc:  # noqa: BLE001 - VTK raises plain errors for unreadable files
        raise ValueError(f"cannot read {path}: {exc}") from None
    finally:
        vtkObject.SetGlobalWarningDisplay(shown)
    if mesh.n_cells == 0:
        raise ValueError(f"cannot read {path}: no cells in it (not a VTK mesh file?)")
    return section(mesh, plane)
