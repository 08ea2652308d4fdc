"""Compact snapshots of a case time (mesh, alpha, Theta, volumes, centres, and the face flux)
and the bundled snapshot of the small case."""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
from importlib import resources
from pathlib import Path

import meshio
import numpy as np

from .case import _control_summary
from .fields import CellData, flow_fields, read_cell_fields
from .flux import FaceFlux, read_face_flux
from .install import OpenFOAMError


SNAPSHOT_NAME = "fluid_bed_small.vtu"
FLUX_NAME = "fluid_bed_small_flux.npz"


# --------------------------------------------------------------------------- snapshot

def default_snapshot_path() -> Path:
    """The bundled snapshot of the small case (``pbe_cfd/data/fluid_bed_small.vtu``)."""
    return Path(str(resources.files("pbe_cfd") / "data" / SNAPSHOT_NAME))


def default_flux_path() -> Path:
    """The bundled face flux of the small case (``pbe_cfd/data/fluid_bed_small_flux.npz``)."""
    return Path(str(resources.files("pbe_cfd") / "data" / FLUX_NAME))


def _flux_path_for(path: Path) -> Path:
    return path.with_name(path.stem + "_flux.npz")


def write_snapshot(case_dir: str | os.PathLike, time: str | float,
                   path: str | os.PathLike) -> tuple[Path, Path]:
    """Write a compact snapshot of a case time: ``path`` (.vtu) and ``<stem>_flux.npz``.

    The .vtu holds the mesh and cell data ``alpha`` [-], ``Theta`` [m2/s2], ``cell_volume``
    [m3], ``cell_centre`` [m], ``cellID`` and the phases' velocities and temperatures the case
    wrote (``CellData.flow``: ``U.<phase>`` [m/s], ``T.<phase>`` [K]), in OpenFOAM's cell
    order (one VTK cell per OpenFOAM cell is required). The .npz holds owner, neighbour, flux [m3/s], the boundary
    faces and the provenance. Returns the two paths.
    """
    case_dir = Path(case_dir)
    path = Path(path)
    cells = read_cell_fields(case_dir, time)
    flux = read_face_flux(case_dir, cells.time)
    if len(cells.vtk_cell_id) != cells.n_cells or not np.array_equal(
            cells.vtk_cell_id, np.arange(cells.n_cells)):
        raise OpenFOAMError("write_snapshot needs one VTK cell per OpenFOAM cell in order "
                            "(no split polyhedra)")
    if flux.n_cells != cells.n_cells:
        raise OpenFOAMError(f"{case_dir}: flux mesh has {flux.n_cells} cells, VTK has "
                            f"{cells.n_cells}")
    mesh = meshio.Mesh(
        cells.mesh.points, [(b.type, b.data) for b in cells.mesh.cells],
        cell_data={
            "alpha": [cells.alpha],
            "Theta": [cells.theta],
            "cell_volume": [cells.cell_volume],
            "cell_centre": [cells.cell_centre],
            "cellID": [np.arange(cells.n_cells, dtype=np.int32)],
            **{name: [values] for name, values in cells.flow.items()},
        },
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.write(path, mesh, file_format="vtu", compression="zlib")
    source = dict(cells.source)
    source["file"] = str(Path(source["file"]).relative_to(case_dir.resolve())
                         if Path(source["file"]).is_relative_to(case_dir.resolve())
                         else source["file"])
    source.update(case=case_dir.name, flux_field=flux.field, mesh_type=_mesh_type(case_dir),
                  control=_control_summary(case_dir))
    fpath = _flux_path_for(path)
    np.savez_compressed(
        fpath, owner=flux.owner.astype(np.int32), neighbour=flux.neighbour.astype(np.int32),
        flux=flux.flux, boundary_face_cell=flux.boundary_face_cell.astype(np.int32),
        boundary_face_flux=flux.boundary_face_flux,
        boundary_face_patch=flux.boundary_face_patch.astype(np.int32),
        patch_names=np.array(flux.patch_names), n_cells=np.array(flux.n_cells),
        field=np.array(flux.field), time_s=np.array(flux.time),
        window_start_s=np.array(flux.window_start),
        **({"alpha_start": flux.alpha_start, "alpha_end": flux.alpha_end}
           if flux.alpha_start is not None else {}),
        source=np.array(json.dumps(source)))
    return path, fpath


def _mesh_type(case_dir: Path) -> str:
    try:
        return (case_dir / "mesh.type").read_text().strip()
    except OSError:
        return "unknown"


def load_snapshot(path: str | os.PathLike | None = None,
                  with_flux: bool = False) -> CellData | tuple[CellData, FaceFlux]:
    """Load a snapshot written by write_snapshot (default: the bundled small case).

    Returns CellData (alpha [-], theta [m2/s2], cell_volume [m3], cell_centre [m]); with
    ``with_flux`` also the FaceFlux [m3/s] from the companion ``<stem>_flux.npz``. An
    unreadable or truncated file is one OpenFOAMError (meshio's own exit included).
    """
    path = Path(path) if path is not None else default_snapshot_path()
    if not path.is_file():
        raise OpenFOAMError(f"snapshot {path} not found")
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return _load_snapshot(path, with_flux)
    except OpenFOAMError:
        raise
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - meshio calls sys.exit on bad files
        text = (str(exc).strip().splitlines() or [""])[0][:160]
        raise OpenFOAMError(f"cannot read snapshot {path} or its flux file "
                            f"{_flux_path_for(path).name}: {type(exc).__name__} {text}".rstrip()
                            ) from None


def _load_snapshot(path: Path, with_flux: bool):
    mesh = meshio.read(path)
    cd = {k: np.concatenate([np.asarray(a) for a in v]) for k, v in mesh.cell_data.items()}
    for key in ("alpha", "Theta", "cell_volume", "cell_centre"):
        if key not in cd:
            raise OpenFOAMError(f"{path}: snapshot lacks cell data '{key}' "
                                f"(found {sorted(cd)})")
    n = len(cd["alpha"])
    order = np.asarray(cd["cellID"], dtype=np.int64) if "cellID" in cd else np.arange(n)
    if not np.array_equal(np.sort(order), np.arange(n)):
        raise OpenFOAMError(f"{path}: cellID is not a permutation of 0..{n - 1}")
    inv = np.empty(n, dtype=np.int64)
    inv[order] = np.arange(n)
    t = float(np.asarray(mesh.field_data.get("time_s", [np.nan])).ravel()[0])
    fpath = _flux_path_for(path)
    source = {"file": str(path), "alpha_field": "alpha", "theta_field": "Theta",
              "averaged": True, "time_s": t}
    flux = None
    if fpath.is_file():
        with np.load(fpath) as z:
            source.update(json.loads(str(z["source"])))
            source["file"] = str(path)
            if not math.isfinite(t):  # meshio's vtu writer drops field data
                t = float(z["time_s"])
            if with_flux:
                flux = FaceFlux(
                    owner=z["owner"].astype(np.int64), neighbour=z["neighbour"].astype(np.int64),
                    flux=z["flux"].astype(np.float64),
                    boundary_face_cell=z["boundary_face_cell"].astype(np.int64),
                    boundary_face_flux=z["boundary_face_flux"].astype(np.float64),
                    boundary_face_patch=z["boundary_face_patch"].astype(np.int64),
                    patch_names=[str(s) for s in z["patch_names"]], n_cells=int(z["n_cells"]),
                    field=str(z["field"]), time=float(z["time_s"]),
                    window_start=float(z["window_start_s"]) if "window_start_s" in z
                    else float("nan"),
                    alpha_start=z["alpha_start"] if "alpha_start" in z else None,
                    alpha_end=z["alpha_end"] if "alpha_end" in z else None)
    elif with_flux:
        raise OpenFOAMError(f"flux file {fpath} (companion of {path}) not found")
    cells = CellData(
        alpha=np.asarray(cd["alpha"], dtype=np.float64)[inv],
        theta=np.asarray(cd["Theta"], dtype=np.float64)[inv],
        cell_volume=np.asarray(cd["cell_volume"], dtype=np.float64)[inv],
        cell_centre=np.asarray(cd["cell_centre"], dtype=np.float64)[inv],
        mesh=meshio.Mesh(np.asarray(mesh.points, dtype=np.float64),
                         [(b.type, np.asarray(b.data)) for b in mesh.cells]),
        vtk_cell_id=order, time=t, source=source, flow=flow_fields(cd, inv))
    return (cells, flux) if with_flux else cells
