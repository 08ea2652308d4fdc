"""Reading the per-cell fields (alpha, Theta), volumes and centres of one case time from the
foamToVTK output, in OpenFOAM's cell order."""
from __future__ import annotations

import dataclasses
import gzip
import json
import os
import re
from collections.abc import Mapping
from pathlib import Path

import meshio
import numpy as np

from .case import pick_time, time_name
from .install import DEFAULT_PHASE, OpenFOAMError, phase_fields




# --------------------------------------------------------------------------- cell data

#: the bases of the per-phase fields kept in ``CellData.flow`` (velocity [m/s], temperature [K])
FLOW_FIELDS = ("U", "T")


def flow_fields(cell_data: Mapping[str, np.ndarray], order: np.ndarray) -> dict:
    """The ``U.<phase>``/``T.<phase>`` fields (and their ``...Mean``) of ``cell_data``, each
    taken at ``order`` (OpenFOAM's cell order), as float64."""
    return {k: np.asarray(v, dtype=np.float64)[order] for k, v in cell_data.items()
            if k.split(".", 1)[0] in FLOW_FIELDS and "." in k}

@dataclasses.dataclass
class CellData:
    """Per-cell fields of one time of a case, in OpenFOAM's cell order (n cells).

    alpha         (n,) solids volume fraction [-]
    theta         (n,) granular temperature [m2/s2]
    cell_volume   (n,) [m3]
    cell_centre   (n, 3) [m]
    mesh          meshio.Mesh with points [m] and cells (no data) to write VTK again
    vtk_cell_id   (n_vtk,) OpenFOAM cell of each VTK cell of ``mesh`` (identity unless
                  polyhedra were split)
    time          the case time [s]
    source        provenance: file, field names used, whether time-averaged, ...
    flow          the phases' velocities and temperatures the case wrote at that time, by
                  field name (``U.<phase>`` (n, 3) [m/s], ``T.<phase>`` (n,) [K], and their
                  ``...Mean``; ``FLOW_FIELDS``); empty where it wrote none
    """

    alpha: np.ndarray
    theta: np.ndarray
    cell_volume: np.ndarray
    cell_centre: np.ndarray
    mesh: meshio.Mesh
    vtk_cell_id: np.ndarray
    time: float
    source: dict
    flow: dict = dataclasses.field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        """Number of OpenFOAM cells."""
        return int(self.alpha.shape[0])

    @property
    def averaged(self) -> bool:
        """True when alpha and Theta are the time-averaged (fieldAverage) fields."""
        return bool(self.source.get("averaged", False))

    def to_vtk_cells(self, values: np.ndarray) -> np.ndarray:
        """Spread per-OpenFOAM-cell values (n, ...) onto the VTK cells of ``mesh``."""
        values = np.asarray(values)
        if values.shape[0] != self.n_cells:
            raise ValueError(f"expected {self.n_cells} cell values, got shape {values.shape}")
        return values[self.vtk_cell_id]


# VTK local faces of the cell types foamToVTK writes (polyhedra: use -poly-decomp).
_CELL_FACES = {
    "hexahedron": ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6),
                   (3, 0, 4, 7)),
    "wedge": ((0, 1, 2), (3, 5, 4), (0, 3, 4, 1), (1, 4, 5, 2), (2, 5, 3, 0)),
    "pyramid": ((0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
    "tetra": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (2, 0, 3)),
}


def _block_volumes(points: np.ndarray, conn: np.ndarray, cell_type: str):
    """Volumes (m3) and centroids (m) of one meshio cell block, OpenFOAM-style decomposition:
    each face is split into triangles around its face centre, each triangle forms a tetrahedron
    with the cell's vertex average. Exact for cells with planar faces."""
    try:
        faces = _CELL_FACES[cell_type]
    except KeyError:
        raise OpenFOAMError(
            f"cannot compute volumes of VTK '{cell_type}' cells; rerun foamToVTK with "
            "-poly-decomp so polyhedra are split into tetrahedra and pyramids") from None
    xyz = points[conn]                       # (m, k, 3)
    c0 = xyz.mean(axis=1)                    # (m, 3)
    vol = np.zeros(len(conn))
    mom = np.zeros((len(conn), 3))
    for face in faces:
        fp = xyz[:, face, :]                 # (m, f, 3)
        fc = fp.mean(axis=1)
        nf = len(face)
        for k in range(nf):
            a, b = fp[:, k, :], fp[:, (k + 1) % nf, :]
            v = np.abs(np.einsum("ij,ij->i", a - c0, np.cross(b - c0, fc - c0))) / 6.0
            vol += v
            mom += v[:, None] * (c0 + fc + a + b) / 4.0
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = mom / vol[:, None]
    return vol, centre


def cell_volumes_and_centres(mesh: meshio.Mesh, vtk_cell_id: np.ndarray | None = None,
                             n_cells: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cell volumes (m3) and volume centroids (m) of a meshio mesh, summed per OpenFOAM cell.

    ``vtk_cell_id`` maps VTK cells to OpenFOAM cells (identity when None).
    """
    points = np.asarray(mesh.points, dtype=np.float64)
    vols, cents = [], []
    for block in mesh.cells:
        v, c = _block_volumes(points, np.asarray(block.data), block.type)
        vols.append(v)
        cents.append(c)
    vol = np.concatenate(vols)
    cen = np.concatenate(cents)
    if vtk_cell_id is None:
        return vol, cen
    n = int(n_cells if n_cells is not None else vtk_cell_id.max() + 1)
    V = np.bincount(vtk_cell_id, weights=vol, minlength=n)
    C = np.stack([np.bincount(vtk_cell_id, weights=vol * cen[:, k], minlength=n)
                  for k in range(3)], axis=1) / V[:, None]
    return V, C


def _vtk_internal_file(case_dir: Path, time: float) -> Path | None:
    """foamToVTK's internal.vtu for ``time`` (s), from VTK/*.vtm.series; None if not there."""
    vtk_dir = case_dir / "VTK"
    if not vtk_dir.is_dir():
        return None
    for series in sorted(vtk_dir.glob("*.vtm.series")):
        try:
            entries = json.loads(series.read_text())["files"]
        except (OSError, ValueError, KeyError) as exc:
            raise OpenFOAMError(f"cannot parse {series}: {exc}") from None
        for entry in entries:
            if abs(float(entry["time"]) - time) <= 1e-6 * max(1.0, abs(time)):
                cand = vtk_dir / entry["name"].removesuffix(".vtm") / "internal.vtu"
                if cand.is_file():
                    return cand
    return None


def _n_cells_polymesh(case_dir: Path) -> int | None:
    from .readable import foam_path
    owner = foam_path(case_dir / "constant" / "polyMesh" / "owner")
    try:
        opener = gzip.open if owner.suffix == ".gz" else open
        with opener(owner, "rb") as fh:
            head = fh.read(2000).decode(errors="replace")
    except OSError:
        return None
    m = re.search(r"nCells:\s*(\d+)", head)
    return int(m.group(1)) if m else None


def _pick_field(cell_data: Mapping[str, np.ndarray], names: tuple[str, ...], what: str,
                path) -> tuple[str, np.ndarray, str | None]:
    for i, name in enumerate(names):
        if name in cell_data:
            note = None
            if i > 0:
                note = (f"{path}: no time-averaged '{names[0]}' (the case's fieldAverage does "
                        f"not average it, or its window has not started); using the "
                        f"instantaneous '{name}' for {what} (add it to the fieldAverage, or "
                        "choose an averaged time with [domain] time)")
            return name, np.asarray(cell_data[name], dtype=np.float64), note
    found = sorted(k for k in cell_data if k != "cellID")
    raise OpenFOAMError(f"{path}: no {what} field; expected one of {list(names)}, found "
                        f"{found}; choose a written time that holds it with [domain] time, "
                        "or the phase with [domain] phase")


@dataclasses.dataclass(frozen=True)
class CaseTime:
    """One written time of a user's case, resolved: ``case`` (the case, absolute), ``time``
    [s], ``name`` (its directory name), ``decomposed`` (held only by ``processor*/``), and
    ``read_dir``, where its files are read from: pbe-cfd's readable copy (``readable``), or
    the case itself when it holds only foamToVTK output and no mesh to convert."""

    case: Path
    time: float
    name: str
    decomposed: bool
    read_dir: Path


def case_time(case_dir: str | os.PathLike, time: str | float = "latest",
              phase: str = DEFAULT_PHASE) -> CaseTime:
    """Resolve ``time`` of ``case_dir`` and make (or find) its readable copy (``readable``);
    the user's case is only read. Raises OpenFOAMError."""
    from .case import _control_summary, is_decomposed_time
    from .readable import has_mesh, readable_copy

    case_dir = Path(case_dir).resolve()
    t = pick_time(case_dir, time, phase)
    name = time_name(case_dir, t)
    decomposed = is_decomposed_time(case_dir, name, phase)
    if not has_mesh(case_dir):
        if not decomposed and _vtk_internal_file(case_dir, t) is not None:
            return CaseTime(case_dir, t, name, False, case_dir)
        raise OpenFOAMError(f"{case_dir}: no complete mesh in constant/polyMesh (points, "
                            "faces, owner, neighbour, boundary); run blockMesh, or for a "
                            "decomposed case keep the mesh decomposePar read")
    names = [name]
    start = _control_summary(case_dir).get("avgStart")
    if start is not None and start < t:
        try:
            names.append(time_name(case_dir, start))
        except OpenFOAMError:
            pass
    return CaseTime(case_dir, t, name, decomposed, readable_copy(case_dir, names, decomposed))


def read_cell_fields(case_dir: str | os.PathLike, time: str | float = "latest",
                     phase: str = DEFAULT_PHASE) -> CellData:
    """Read alpha [-], Theta [m2/s2], cell volumes [m3] and centres [m] of a written time.

    Reads foamToVTK's ``internal.vtu`` of that time from pbe-cfd's readable copy of the case
    (``case_time``; plain, binary, compressed or decomposed cases alike). Prefers the
    time-averaged ``alpha.<phase>Mean`` / ``Theta.<phase>Mean`` and falls back to the
    instantaneous fields with a warning. Values are in OpenFOAM's cell order (``cellID``).
    """
    ct = case_time(case_dir, time, phase)
    path = _vtk_internal_file(ct.read_dir, ct.time)
    if path is None:
        raise OpenFOAMError(f"no foamToVTK output for t = {ct.time} s in {ct.read_dir / 'VTK'}")
    cells = _cell_data_from_vtu(path, ct.time, n_expected=_n_cells_polymesh(ct.read_dir),
                                polymesh_points=_polymesh_points(ct.read_dir), phase=phase,
                                where=f"{ct.case / ct.name}")
    cells.source.update(case=str(ct.case), time_dir=ct.name, decomposed=ct.decomposed,
                        read_from=str(ct.read_dir))
    return cells


def _polymesh_points(case_dir: Path) -> np.ndarray | None:
    """constant/polyMesh/points (m, double precision), or None when unreadable."""
    pts = case_dir / "constant" / "polyMesh" / "points"
    if not pts.is_file():
        return None
    try:
        from foamlib import FoamFile

        arr = np.asarray(FoamFile(pts)[None], dtype=np.float64)
    except Exception:  # noqa: BLE001 - optional refinement only
        return None
    return arr if arr.ndim == 2 and arr.shape[1] == 3 else None


def _cell_data_from_vtu(path: Path, t: float, n_expected: int | None = None,
                        polymesh_points: np.ndarray | None = None,
                        phase: str = DEFAULT_PHASE, where: str | None = None) -> CellData:
    try:
        mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises assorted errors, or exits
        raise OpenFOAMError(f"cannot read {path} with meshio: {exc}") from None
    # foamToVTK stores points as float32; its first points are the polyMesh points in order,
    # so take those in double precision (volumes then match OpenFOAM's to round-off)
    points = np.asarray(mesh.points, dtype=np.float64)
    if polymesh_points is not None and len(polymesh_points) <= len(points):
        head = points[:len(polymesh_points)]
        scale = max(1.0, float(np.abs(polymesh_points).max()))
        if np.allclose(head, polymesh_points, rtol=0, atol=1e-6 * scale):
            points = points.copy()
            points[:len(polymesh_points)] = polymesh_points
    mesh.points = points
    n_vtk = sum(len(b.data) for b in mesh.cells)
    cd = {k: np.concatenate([np.asarray(a) for a in v]) for k, v in mesh.cell_data.items()}
    if "cellID" in cd:
        cell_id = cd["cellID"].astype(np.int64).ravel()
        n = int(cell_id.max()) + 1
        if np.bincount(cell_id, minlength=n).min() == 0:
            raise OpenFOAMError(f"{path}: cellID does not cover cells 0..{n - 1}")
    else:
        cell_id = np.arange(n_vtk)
        n = n_vtk
    if n_expected is not None and n != n_expected:
        raise OpenFOAMError(f"{path}: {n} cells, but constant/polyMesh has {n_expected}; "
                            "the VTK output is stale (rerun foamToVTK)")
    # first VTK cell of each OpenFOAM cell carries the cell's value
    first = np.full(n, -1, dtype=np.int64)
    first[cell_id[::-1]] = np.arange(n_vtk)[::-1]
    alpha_names, theta_names, _ = phase_fields(phase)
    where = where or str(path)
    a_name, alpha, a_note = _pick_field(cd, alpha_names, "solids fraction", where)
    t_name, theta, t_note = _pick_field(cd, theta_names, "granular temperature", where)
    alpha, theta = alpha[first], theta[first]
    for name, arr in ((a_name, alpha), (t_name, theta)):
        if not np.all(np.isfinite(arr)):
            raise OpenFOAMError(f"{path}: field '{name}' has non-finite values")
    vol, cen = cell_volumes_and_centres(mesh, cell_id, n)
    bare = meshio.Mesh(np.asarray(mesh.points, dtype=np.float64),
                       [(b.type, np.asarray(b.data)) for b in mesh.cells])
    source = {
        "file": str(path),
        "alpha_field": a_name,
        "theta_field": t_name,
        "averaged": a_name.endswith("Mean") and t_name.endswith("Mean"),
        "time_s": t,
        "warnings": [n for n in (a_note, t_note) if n],
    }
    return CellData(alpha=alpha, theta=theta, cell_volume=vol, cell_centre=cen, mesh=bare,
                    vtk_cell_id=cell_id, time=t, source=source, flow=flow_fields(cd, first))


# --------------------------------------------------------------------------- face flux
