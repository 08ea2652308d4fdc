"""Reading the solids face flux (alphaPhi) of one case time, in OpenFOAM's face order."""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from .case import _control_summary, time_name
from .fields import _n_cells_polymesh, case_time
from .install import DEFAULT_PHASE, OpenFOAMError, phase_fields




@dataclasses.dataclass
class FaceFlux:
    """Solids volume flux through the faces of the mesh (OpenFOAM face order), m3/s.

    owner, neighbour    (n_internal,) cells on either side of each internal face
    flux                (n_internal,) flux from owner to neighbour [m3/s]
    boundary_face_cell  (n_bfaces,) cell next to each boundary face (empty patches left out)
    boundary_face_flux  (n_bfaces,) outward flux through each boundary face [m3/s]
    boundary_face_patch (n_bfaces,) index into patch_names
    patch_names         names of the non-empty boundary patches
    n_cells             number of cells
    field, time         the field read and the case time [s]
    window_start        start of the averaging window [s] (nan when unknown)
    alpha_start, alpha_end  instantaneous alpha.particles [-] at the window's start and end
                        (None when not written); the mean flux obeys
                        net_outflow() = -(alpha_end - alpha_start) V / (time - window_start)
                        up to the time discretisation (0.2 % on the bundled snapshot)
    notes               one-line warnings of the reading (an instantaneous field used)
    """

    owner: np.ndarray
    neighbour: np.ndarray
    flux: np.ndarray
    boundary_face_cell: np.ndarray
    boundary_face_flux: np.ndarray
    boundary_face_patch: np.ndarray
    patch_names: list[str]
    n_cells: int
    field: str
    time: float
    window_start: float = float("nan")
    alpha_start: np.ndarray | None = None
    alpha_end: np.ndarray | None = None
    notes: list = dataclasses.field(default_factory=list)

    @property
    def patch_flux(self) -> dict[str, float]:
        """Outward flux summed per boundary patch [m3/s]."""
        tot = np.bincount(self.boundary_face_patch, weights=self.boundary_face_flux,
                          minlength=len(self.patch_names))
        return {name: float(tot[i]) for i, name in enumerate(self.patch_names)}

    def net_outflow(self) -> np.ndarray:
        """Net outward flux of each cell [m3/s] (the discrete divergence times volume)."""
        out = np.bincount(self.owner, weights=self.flux, minlength=self.n_cells)
        out -= np.bincount(self.neighbour, weights=self.flux, minlength=self.n_cells)
        out += np.bincount(self.boundary_face_cell, weights=self.boundary_face_flux,
                           minlength=self.n_cells)
        return out


def read_face_flux(case_dir: str | os.PathLike, time: str | float = "latest",
                   fields: tuple[str, ...] | None = None,
                   phase: str = DEFAULT_PHASE) -> FaceFlux:
    """Read owner/neighbour and the solids volume flux (m3/s) of a written time, via foamlib,
    from pbe-cfd's readable copy of the case (``fields.case_time``).

    Prefers ``alphaPhi.<phase>Mean`` (time-averaged, consistent with alpha.<phase>Mean)
    and falls back to ``alphaPhi.<phase>`` with a warning.
    """
    ct = case_time(case_dir, time, phase)
    try:
        return _read_face_flux(ct, fields or phase_fields(phase)[2])
    except OpenFOAMError:
        raise
    except Exception as exc:  # noqa: BLE001 - foamlib's parser raises assorted errors
        raise OpenFOAMError(f"{ct.case / ct.name}: cannot read the face flux "
                            f"({type(exc).__name__}: {str(exc).splitlines()[0][:200]})"
                            ) from None


def _read_face_flux(ct, fields) -> FaceFlux:
    from foamlib import FoamFieldFile, FoamFile

    case_dir, t = ct.read_dir, ct.time
    tdir = case_dir / ct.name
    where = ct.case / ct.name
    mesh_dir = case_dir / "constant" / "polyMesh"
    try:
        owner = np.asarray(FoamFile(mesh_dir / "owner")[None], dtype=np.int64)
        neighbour = np.asarray(FoamFile(mesh_dir / "neighbour")[None], dtype=np.int64)
        boundary = FoamFile(mesh_dir / "boundary")[None]
    except FileNotFoundError as exc:
        raise OpenFOAMError(f"{ct.case}: mesh file {Path(exc.filename).name} missing in "
                            "constant/polyMesh; run blockMesh first") from None
    n_int = len(neighbour)
    n_cells = _n_cells_polymesh(case_dir) or int(max(owner.max(), neighbour.max())) + 1

    field, notes = None, []
    for i, name in enumerate(fields):
        if (tdir / name).is_file():
            field = name
            if i > 0:
                notes.append(f"{where}: no time-averaged '{fields[0]}'; using the "
                             f"instantaneous '{name}' for the transport flux (add it to the "
                             "case's fieldAverage)")
            break
    if field is None:
        raise OpenFOAMError(f"{where}: no face flux field; expected one of {list(fields)} "
                            "(add alphaPhi of the solids phase to the case's fieldAverage, "
                            "or drop [transport])")
    ff = FoamFieldFile(tdir / field)
    internal = np.asarray(ff.internal_field, dtype=np.float64)
    if internal.ndim == 0:
        internal = np.full(n_int, float(internal))
    if internal.shape != (n_int,):
        raise OpenFOAMError(f"{where / field}: internalField has shape {internal.shape}, "
                            f"expected ({n_int},) internal faces of the mesh")
    bfield = ff.boundary_field
    b_cell, b_flux, b_patch, names = [], [], [], []
    for pname, pdict in boundary:
        if pdict.get("type") == "empty":
            continue
        start, nf = int(pdict["startFace"]), int(pdict["nFaces"])
        try:
            val = bfield[pname].get("value", 0.0)
        except KeyError:
            raise OpenFOAMError(f"{tdir / field}: no boundaryField entry for patch "
                                f"'{pname}'") from None
        val = np.asarray(val, dtype=np.float64)
        if val.ndim == 0:
            val = np.full(nf, float(val))
        if val.shape != (nf,):
            raise OpenFOAMError(f"{tdir / field}: patch '{pname}' value has shape "
                                f"{val.shape}, expected ({nf},)")
        b_cell.append(owner[start:start + nf])
        b_flux.append(val)
        b_patch.append(np.full(nf, len(names), dtype=np.int64))
        names.append(pname)
    cat = (lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt))
    phase = fields[1].split(".", 1)[1]
    t0, a0, a1 = (_window_alpha(ct.case, case_dir, t, n_cells, phase)
                  if field.endswith("Mean") else (float("nan"), None, None))
    return FaceFlux(owner=owner[:n_int].copy(), neighbour=neighbour, flux=internal,
                    boundary_face_cell=cat(b_cell, np.int64),
                    boundary_face_flux=cat(b_flux, np.float64),
                    boundary_face_patch=cat(b_patch, np.int64), patch_names=names,
                    n_cells=n_cells, field=field, time=t, window_start=t0,
                    alpha_start=a0, alpha_end=a1, notes=notes)


def _window_alpha(case: Path, case_dir: Path, t: float, n_cells: int, phase: str):
    """(window start [s], alpha.<phase> at start, at t) from the readable copy ``case_dir`` of
    ``case``, or (nan, None, None)."""
    from foamlib import FoamFieldFile

    t0 = _control_summary(case).get("avgStart")
    if t0 is None or not t0 < t:
        return float("nan"), None, None
    out = []
    for tt in (t0, t):
        try:
            name = time_name(case_dir, tt)
            arr = np.asarray(FoamFieldFile(case_dir / name / f"alpha.{phase}").internal_field,
                             dtype=np.float64)
        except (OpenFOAMError, FileNotFoundError):
            return float(t0), None, None
        if arr.ndim == 0:
            arr = np.full(n_cells, float(arr))
        out.append(arr)
    return float(t0), out[0], out[1]
