"""OpenFOAM I/O for the fluid-bed case: run it, pick a time, read cell fields, write fields.

I/O only, no physics. All quantities are SI: lengths in m, volumes in m3, times in s,
granular temperature Theta in m2/s2, solids volume fractions dimensionless, face fluxes of
the solids volume (``alphaPhi.particles``) in m3/s.

Cell order is always OpenFOAM's cell order (cell i here is cell i of ``constant/polyMesh``).
foamToVTK writes its internal mesh (``VTK/<case>_<index>/internal.vtu``) with a ``cellID``
cell array (``-with-ids``); where polyhedra were split into several VTK cells, the VTK cells
are mapped back through ``cellID``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import subprocess
import threading
import time as _time
import warnings
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path

import meshio
import numpy as np

__all__ = [
    "OpenFOAMError",
    "OpenFOAMInstall",
    "RunResult",
    "CellData",
    "FaceFlux",
    "find_openfoam",
    "have_openfoam",
    "default_case_dir",
    "copy_case",
    "run_case",
    "written_times",
    "pick_time",
    "time_name",
    "read_cell_fields",
    "read_face_flux",
    "write_snapshot",
    "load_snapshot",
    "default_snapshot_path",
    "default_flux_path",
    "write_foam_fields",
    "check_foam_fields",
    "cell_volumes_and_centres",
]

#: OpenFOAM tools the case needs, in the order Allrun runs them.
TOOLS = ("blockMesh", "setFields", "twoPhaseEulerFoam", "foamToVTK")

#: Field names tried, in order, for the solids fraction and the granular temperature.
ALPHA_FIELDS = ("alpha.particlesMean", "alpha.particles")
THETA_FIELDS = ("Theta.particlesMean", "Theta.particles")
#: Face flux of the solids volume (m3/s), averaged and instantaneous.
FLUX_FIELDS = ("alphaPhi.particlesMean", "alphaPhi.particles")

SNAPSHOT_NAME = "fluid_bed_small.vtu"
FLUX_NAME = "fluid_bed_small_flux.npz"

_DEFAULT_PROJECT_DIRS = (
    "/usr/share/openfoam",
    "/usr/lib/openfoam/openfoam1912",
    "/opt/openfoam1912",
    "/opt/OpenFOAM/OpenFOAM-v1912",
)


class OpenFOAMError(RuntimeError):
    """OpenFOAM is missing, a tool failed, or a case file is not what was expected.

    Attributes: ``tool`` (the failing OpenFOAM tool or None), ``log_path`` (its log file or
    None) and ``log_tail`` (the last lines of that log, or "").
    """

    def __init__(self, message: str, tool: str | None = None,
                 log_path: Path | None = None, log_tail: str = ""):
        full = message
        if log_tail:
            full += f"\n--- last lines of {log_path} ---\n{log_tail}"
        super().__init__(full)
        self.tool = tool
        self.log_path = log_path
        self.log_tail = log_tail


# --------------------------------------------------------------------------- install / run

@dataclasses.dataclass(frozen=True)
class OpenFOAMInstall:
    """Where OpenFOAM lives: ``project_dir`` (WM_PROJECT_DIR), ``tools`` (name -> executable)."""

    project_dir: Path
    tools: dict[str, Path]

    def env(self) -> dict[str, str]:
        """The process environment to run OpenFOAM tools in (WM_PROJECT_DIR set)."""
        env = dict(os.environ)
        env["WM_PROJECT_DIR"] = str(self.project_dir)
        return env


def find_openfoam(tools: tuple[str, ...] = TOOLS + ("postProcess",)) -> OpenFOAMInstall:
    """Locate the OpenFOAM tools on PATH and a WM_PROJECT_DIR holding ``etc/controlDict``.

    Raises OpenFOAMError naming the missing tool or project directory.
    """
    found: dict[str, Path] = {}
    for tool in tools:
        exe = shutil.which(tool)
        if exe is None:
            raise OpenFOAMError(
                f"OpenFOAM tool '{tool}' not found on PATH; install OpenFOAM v1912 "
                "(Debian/Ubuntu: apt-get install -y openfoam)", tool=tool)
        found[tool] = Path(exe)
    candidates = []
    if os.environ.get("WM_PROJECT_DIR"):
        candidates.append(os.environ["WM_PROJECT_DIR"])
    candidates.extend(_DEFAULT_PROJECT_DIRS)
    for cand in candidates:
        if (Path(cand) / "etc" / "controlDict").is_file():
            return OpenFOAMInstall(Path(cand), found)
    raise OpenFOAMError(
        "OpenFOAM tools found but no project directory with etc/controlDict; set "
        f"WM_PROJECT_DIR (tried {', '.join(candidates)})")


def have_openfoam() -> bool:
    """True when find_openfoam() succeeds."""
    try:
        find_openfoam()
    except OpenFOAMError:
        return False
    return True


def default_case_dir() -> Path:
    """The fluid-bed case template: $PBE_CFD_CASE when set, else the one shipped with the
    package (``pbe_cfd/data/openfoam_case``; ``openfoam_case/`` at the repository root links to
    it), so an installed package finds it from any directory."""
    env = os.environ.get("PBE_CFD_CASE")
    if env:
        if (Path(env) / "Allrun").is_file():
            return Path(env).resolve()
        raise OpenFOAMError(f"PBE_CFD_CASE={env} is not a case template (no Allrun)")
    shipped = Path(str(resources.files("pbe_cfd") / "data" / "openfoam_case"))
    if (shipped / "Allrun").is_file():
        return shipped
    raise OpenFOAMError(
        f"the case template {shipped} is missing from this installation (reinstall pbe_cfd, "
        "or set PBE_CFD_CASE to a copy of openfoam_case/ from the source repository)")


def copy_case(src: str | os.PathLike, dest: str | os.PathLike) -> Path:
    """Copy the case template (0.orig, constant, system, Allrun, Allclean) to ``dest``.

    Results, meshes and logs are not copied. ``dest`` must not exist or be empty.
    """
    src, dest = Path(src), Path(dest)
    if not (src / "Allrun").is_file():
        raise OpenFOAMError(f"{src} is not a case template: no Allrun")
    if dest.exists() and any(dest.iterdir()):
        raise OpenFOAMError(f"copy_case: destination {dest} exists and is not empty")
    dest.mkdir(parents=True, exist_ok=True)
    ignore = shutil.ignore_patterns("polyMesh", "controlDict.override")
    for name in ("0.orig", "constant", "system"):
        shutil.copytree(src / name, dest / name, ignore=ignore)
    for name in ("Allrun", "Allclean", "README.md"):
        if (src / name).is_file():
            shutil.copy2(src / name, dest / name)
    return dest


@dataclasses.dataclass(frozen=True)
class RunResult:
    """Outcome of run_case: the case, mesh, latest written time (s), wall time per tool (s)."""

    case_dir: Path
    mesh: str
    latest_time: float
    wall_times: dict[str, float]


def _tail(path: Path, n: int = 30) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join(lines[-n:])


def _last_sim_time(log_path: Path) -> float | None:
    """Last 'Time = x' of a solver log (s), or None."""
    try:
        with open(log_path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - 20000))
            text = fh.read().decode(errors="replace")
    except OSError:
        return None
    hits = re.findall(r"^Time = ([0-9.eE+-]+)\s*$", text, flags=re.M)
    return float(hits[-1]) if hits else None


def run_case(case_dir: str | os.PathLike, mesh: str = "small",
             log: Callable[[str], None] | None = None,
             end_time: float | None = None, avg_start: float | None = None,
             timeout: float | None = None) -> RunResult:
    """Run the case's Allrun: blockMesh, setFields, twoPhaseEulerFoam, foamToVTK.

    ``mesh``: "small" (15 x 60 cells) or "full" (30 x 120). ``end_time`` (s) shortens or
    lengthens the run; ``avg_start`` (s) moves the start of the fieldAverage window (default
    end_time / 3 when end_time is given). ``log`` receives progress lines (the steps and the
    solver's simulated time). ``timeout`` (s of wall time) stops the run.

    Each tool logs to ``case_dir/log.<tool>``. A missing OpenFOAM, or a failing tool, raises
    one OpenFOAMError naming the tool with the tail of its log.
    """
    case_dir = Path(case_dir).resolve()
    if mesh not in ("small", "full"):
        raise ValueError(f"run_case: mesh must be 'small' or 'full', got {mesh!r}")
    if not (case_dir / "Allrun").is_file():
        raise OpenFOAMError(f"run_case: {case_dir} has no Allrun script")
    if end_time is not None and not (end_time > 0 and math.isfinite(end_time)):
        raise ValueError(f"run_case: end_time must be a positive time in s, got {end_time!r}")
    if avg_start is not None:
        if end_time is None:
            raise ValueError("run_case: avg_start needs end_time")
        if not 0 <= avg_start < end_time:
            raise ValueError(
                f"run_case: avg_start must be in [0, end_time={end_time}) s, got {avg_start}")
    install = find_openfoam()
    say = log or (lambda msg: None)

    args = ["bash", str(case_dir / "Allrun"), mesh]
    if end_time is not None:
        args.append(repr(float(end_time)))
        if avg_start is not None:
            args.append(repr(float(avg_start)))
    target = end_time
    if target is None:
        target = _control_value(case_dir / "system" / "controlDict", "endTime")

    wall: dict[str, float] = {}
    current: list = [None, _time.perf_counter()]  # tool, start time
    out_lines: list[str] = []

    proc = subprocess.Popen(args, cwd=case_dir, env=install.env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)

    def reader():
        assert proc.stdout is not None
        for line in proc.stdout:
            line = line.rstrip("\n")
            out_lines.append(line)
            m = re.match(r"Allrun: running (\S+)", line)
            now = _time.perf_counter()
            if m:
                if current[0] is not None:
                    wall[current[0]] = now - current[1]
                current[0], current[1] = m.group(1), now
            elif line.startswith("Allrun: done") and current[0] is not None:
                wall[current[0]] = now - current[1]
                current[0] = None
            say(line)

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    t0 = _time.perf_counter()
    last_reported = None
    while True:
        try:
            proc.wait(timeout=2.0)
            break
        except subprocess.TimeoutExpired:
            pass
        if current[0] == "twoPhaseEulerFoam":
            t = _last_sim_time(case_dir / "log.twoPhaseEulerFoam")
            if t is not None and t != last_reported:
                last_reported = t
                say(f"twoPhaseEulerFoam: t = {t:g} s of {target:g} s" if target
                    else f"twoPhaseEulerFoam: t = {t:g} s")
        if timeout is not None and _time.perf_counter() - t0 > timeout:
            proc.kill()
            proc.wait()
            tool = current[0] or "Allrun"
            lp = case_dir / f"log.{tool}"
            raise OpenFOAMError(f"{tool} in {case_dir} stopped after the {timeout} s timeout",
                                tool=tool, log_path=lp, log_tail=_tail(lp))
    thread.join(timeout=5.0)
    if proc.returncode != 0:
        tool = None
        for line in out_lines:
            m = re.match(r"Allrun: (\S+) failed", line)
            if m:
                tool = m.group(1)
        if tool is None:
            m = re.search(r"OpenFOAM tool '(\S+)' not found", "\n".join(out_lines))
            tool = m.group(1) if m else (current[0] or "Allrun")
        lp = case_dir / f"log.{tool}"
        tail = _tail(lp) if lp.is_file() else "\n".join(out_lines[-30:])
        raise OpenFOAMError(
            f"{tool} failed in {case_dir} (Allrun {mesh}, exit status {proc.returncode})",
            tool=tool, log_path=lp if lp.is_file() else None, log_tail=tail)
    latest = written_times(case_dir)[-1]
    return RunResult(case_dir, mesh, latest, wall)


def _control_value(path: Path, key: str) -> float | None:
    try:
        text = path.read_text()
    except OSError:
        return None
    m = re.search(rf"^\s*{key}\s+([0-9.eE+-]+)\s*;", text, flags=re.M)
    return float(m.group(1)) if m else None


# --------------------------------------------------------------------------- times

def _time_dirs(case_dir: Path) -> list[tuple[float, str]]:
    out = []
    if not case_dir.is_dir():
        raise OpenFOAMError(f"case directory {case_dir} does not exist")
    for p in case_dir.iterdir():
        if not p.is_dir():
            continue
        try:
            t = float(p.name)
        except ValueError:
            continue
        if math.isfinite(t):
            out.append((t, p.name))
    out.sort()
    return out


def written_times(case_dir: str | os.PathLike) -> list[float]:
    """Times (s) with a time directory in the case, ascending (0 included when present)."""
    return [t for t, _ in _time_dirs(Path(case_dir))]


def time_name(case_dir: str | os.PathLike, time: float) -> str:
    """Directory name of the written time ``time`` (s), e.g. 1.5 -> "1.5"."""
    case_dir = Path(case_dir)
    dirs = _time_dirs(case_dir)
    for t, name in dirs:
        if abs(t - time) <= 1e-9 + 1e-6 * abs(time):
            return name
    raise OpenFOAMError(
        f"no time directory for t = {time} s in {case_dir}; written times (s): "
        f"{[t for t, _ in dirs] or 'none (run the case first)'}")


def pick_time(case_dir: str | os.PathLike, which: str | float = "latest") -> float:
    """Resolve ``which`` ("latest", or a time in s) to a written time of the case (s).

    "latest" is the latest directory holding alpha.particles(Mean), so fields written back
    by write_foam_fields into a later time do not hide the CFD time (the latest directory of
    any kind when none holds alpha). A number must match a written time (to 1e-6 relative);
    otherwise the error lists the written times.
    """
    case_dir = Path(case_dir)
    times = written_times(case_dir)
    if not times:
        raise OpenFOAMError(f"no time directories in {case_dir}; run the case first "
                            "(openfoam_case/Allrun or pbe_cfd.cfd.openfoam.run_case)")
    if isinstance(which, str):
        if which.strip().lower() == "latest":
            # the latest CFD time: skip directories holding only written-back fields
            cfd = [t for t, name in _time_dirs(case_dir)
                   if any((case_dir / name / f).is_file() for f in ALPHA_FIELDS)]
            return cfd[-1] if cfd else times[-1]
        try:
            which = float(which)
        except ValueError:
            raise OpenFOAMError(
                f"time must be 'latest' or a number of seconds, got {which!r}") from None
    which = float(which)
    for t in times:
        if abs(t - which) <= 1e-9 + 1e-6 * abs(which):
            return t
    raise OpenFOAMError(f"t = {which} s is not a written time of {case_dir}; "
                        f"written times (s): {times}")


# --------------------------------------------------------------------------- cell data

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
    """

    alpha: np.ndarray
    theta: np.ndarray
    cell_volume: np.ndarray
    cell_centre: np.ndarray
    mesh: meshio.Mesh
    vtk_cell_id: np.ndarray
    time: float
    source: dict

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
    owner = case_dir / "constant" / "polyMesh" / "owner"
    try:
        with open(owner, "rb") as fh:
            head = fh.read(2000).decode(errors="replace")
    except OSError:
        return None
    m = re.search(r"nCells:\s*(\d+)", head)
    return int(m.group(1)) if m else None


def _pick_field(cell_data: Mapping[str, np.ndarray], names: tuple[str, ...], what: str,
                path: Path) -> tuple[str, np.ndarray]:
    for i, name in enumerate(names):
        if name in cell_data:
            if i > 0:
                warnings.warn(
                    f"{path}: no time-averaged '{names[0]}' (fieldAverage window not reached "
                    f"or not configured); using instantaneous '{name}' for {what}",
                    stacklevel=3)
            return name, np.asarray(cell_data[name], dtype=np.float64)
    raise OpenFOAMError(f"{path}: no {what} field; expected one of {list(names)}, "
                        f"found {sorted(cell_data)}")


def read_cell_fields(case_dir: str | os.PathLike, time: str | float = "latest") -> CellData:
    """Read alpha [-], Theta [m2/s2], cell volumes [m3] and centres [m] of a written time.

    Reads foamToVTK's ``internal.vtu`` of that time with meshio (running foamToVTK for it
    first when it is missing and OpenFOAM is installed). Prefers the time-averaged
    ``alpha.particlesMean`` / ``Theta.particlesMean`` and falls back to the instantaneous
    fields with a warning. Values are in OpenFOAM's cell order (through ``cellID``).
    """
    case_dir = Path(case_dir)
    t = pick_time(case_dir, time)
    path = _vtk_internal_file(case_dir, t)
    if path is None:
        try:
            install = find_openfoam(("foamToVTK",))
        except OpenFOAMError as exc:
            raise OpenFOAMError(
                f"no foamToVTK output for t = {t} s in {case_dir / 'VTK'} and OpenFOAM is "
                f"not available to write it ({exc})") from None
        name = time_name(case_dir, t)
        lp = case_dir / "log.foamToVTK"
        with open(lp, "w") as fh:
            r = subprocess.run(["foamToVTK", "-time", name, "-no-boundary", "-no-point-data",
                                "-with-ids"], cwd=case_dir, env=install.env(), stdout=fh,
                               stderr=subprocess.STDOUT)
        path = _vtk_internal_file(case_dir, t)
        if r.returncode != 0 or path is None:
            raise OpenFOAMError(f"foamToVTK failed for t = {t} s in {case_dir}",
                                tool="foamToVTK", log_path=lp, log_tail=_tail(lp))
    return _cell_data_from_vtu(path, t, n_expected=_n_cells_polymesh(case_dir),
                               polymesh_points=_polymesh_points(case_dir))


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
                        polymesh_points: np.ndarray | None = None) -> CellData:
    try:
        mesh = meshio.read(path)
    except Exception as exc:  # meshio raises assorted errors on bad files
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
    a_name, alpha = _pick_field(cd, ALPHA_FIELDS, "solids fraction", path)
    t_name, theta = _pick_field(cd, THETA_FIELDS, "granular temperature", path)
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
    }
    return CellData(alpha=alpha, theta=theta, cell_volume=vol, cell_centre=cen, mesh=bare,
                    vtk_cell_id=cell_id, time=t, source=source)


# --------------------------------------------------------------------------- face flux

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
                   fields: tuple[str, ...] = FLUX_FIELDS) -> FaceFlux:
    """Read owner/neighbour and the solids volume flux (m3/s) of a written time, via foamlib.

    Prefers ``alphaPhi.particlesMean`` (time-averaged, consistent with alpha.particlesMean)
    and falls back to ``alphaPhi.particles`` with a warning.
    """
    from foamlib import FoamFieldFile, FoamFile

    case_dir = Path(case_dir)
    t = pick_time(case_dir, time)
    tdir = case_dir / time_name(case_dir, t)
    mesh_dir = case_dir / "constant" / "polyMesh"
    try:
        owner = np.asarray(FoamFile(mesh_dir / "owner")[None], dtype=np.int64)
        neighbour = np.asarray(FoamFile(mesh_dir / "neighbour")[None], dtype=np.int64)
        boundary = FoamFile(mesh_dir / "boundary")[None]
    except FileNotFoundError as exc:
        raise OpenFOAMError(f"mesh file missing: {exc.filename}; run blockMesh first") from None
    n_int = len(neighbour)
    n_cells = _n_cells_polymesh(case_dir) or int(max(owner.max(), neighbour.max())) + 1

    field = None
    for i, name in enumerate(fields):
        if (tdir / name).is_file():
            field = name
            if i > 0:
                warnings.warn(f"{tdir}: no time-averaged '{fields[0]}'; using '{name}'",
                              stacklevel=2)
            break
    if field is None:
        raise OpenFOAMError(f"{tdir}: no face flux field; expected one of {list(fields)}")
    ff = FoamFieldFile(tdir / field)
    internal = np.asarray(ff.internal_field, dtype=np.float64)
    if internal.ndim == 0:
        internal = np.full(n_int, float(internal))
    if internal.shape != (n_int,):
        raise OpenFOAMError(f"{tdir / field}: internalField has shape {internal.shape}, "
                            f"expected ({n_int},) internal faces")
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
    t0, a0, a1 = _window_alpha(case_dir, t, n_cells) if field.endswith("Mean") else (
        float("nan"), None, None)
    return FaceFlux(owner=owner[:n_int].copy(), neighbour=neighbour, flux=internal,
                    boundary_face_cell=cat(b_cell, np.int64),
                    boundary_face_flux=cat(b_flux, np.float64),
                    boundary_face_patch=cat(b_patch, np.int64), patch_names=names,
                    n_cells=n_cells, field=field, time=t, window_start=t0,
                    alpha_start=a0, alpha_end=a1)


def _window_alpha(case_dir: Path, t: float, n_cells: int):
    """(window start [s], alpha.particles at start, at t) from the case, or (nan, None, None)."""
    from foamlib import FoamFieldFile

    t0 = _control_summary(case_dir).get("avgStart")
    if t0 is None or not t0 < t:
        return float("nan"), None, None
    out = []
    for tt in (t0, t):
        try:
            name = time_name(case_dir, tt)
            arr = np.asarray(FoamFieldFile(case_dir / name / "alpha.particles").internal_field,
                             dtype=np.float64)
        except (OpenFOAMError, FileNotFoundError):
            return float(t0), None, None
        if arr.ndim == 0:
            arr = np.full(n_cells, float(arr))
        out.append(arr)
    return float(t0), out[0], out[1]


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
    [m3], ``cell_centre`` [m] and ``cellID``, in OpenFOAM's cell order (one VTK cell per
    OpenFOAM cell is required). The .npz holds owner, neighbour, flux [m3/s], the boundary
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


def _control_summary(case_dir: Path) -> dict:
    out = {}
    for f in ("controlDict", "controlDict.override"):
        p = case_dir / "system" / f
        for key in ("endTime", "avgStart", "deltaT"):
            v = _control_value(p, key)
            if v is not None:
                out[key] = v
    return out


def load_snapshot(path: str | os.PathLike | None = None,
                  with_flux: bool = False) -> CellData | tuple[CellData, FaceFlux]:
    """Load a snapshot written by write_snapshot (default: the bundled small case).

    Returns CellData (alpha [-], theta [m2/s2], cell_volume [m3], cell_centre [m]); with
    ``with_flux`` also the FaceFlux [m3/s] from the companion ``<stem>_flux.npz``.
    """
    path = Path(path) if path is not None else default_snapshot_path()
    if not path.is_file():
        raise OpenFOAMError(f"snapshot {path} not found")
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
        vtk_cell_id=order, time=t, source=source)
    return (cells, flux) if with_flux else cells


# --------------------------------------------------------------------------- write back

_CONSTRAINT_TYPES = {"empty", "symmetry", "symmetryPlane", "wedge", "cyclic", "cyclicAMI",
                     "processor"}


def check_foam_fields(case_dir: str | os.PathLike, time_name: str, names,
                      overwrite: bool = False, flag: str = "--foam-fields") -> None:
    """Refuse (``output.OutputRefused``) to write fields ``names`` into ``case_dir/time_name``
    (and every ``processor*/time_name``) where a file of that name exists that pbe-cfd did
    not write (its header lacks the mark), or one it wrote earlier and ``overwrite`` is off."""
    from ..output import OutputRefused, file_is_marked
    case_dir = Path(case_dir)
    dirs = [case_dir / str(time_name)] + sorted(
        p / str(time_name) for p in case_dir.glob("processor*") if p.is_dir())
    foreign, ours = [], []
    for d in dirs:
        for name in names:
            p = d / name
            if p.exists() or p.is_symlink():
                (ours if p.is_file() and file_is_marked(p) else foreign).append(p)
    if foreign:
        raise OutputRefused(f"{flag}: {foreign[0]} exists and was not written by pbe-cfd; "
                            "nothing was changed: move it away yourself to write the fields")
    if ours and not overwrite:
        raise OutputRefused(f"{flag}: {ours[0]} was written by an earlier pbe-cfd run; add "
                            "--overwrite to replace the pbe.* fields of that time")


def write_foam_fields(case_dir: str | os.PathLike, time_name: str,
                      fields: Mapping[str, np.ndarray],
                      dimensions: Mapping[str, str | tuple] | None = None,
                      overwrite: bool = False) -> list[Path]:
    """Write cell values as OpenFOAM volScalarFields into ``case_dir/time_name/``.

    ``fields``: name -> (n_cells,) values in OpenFOAM cell order, SI units. Boundaries are
    zeroGradient (constraint patches such as empty keep their type). ``dimensions``: name ->
    SI exponents "[kg m s K mol A cd]" (e.g. "[0 -3 0 0 0 0 0]" for 1/m3), default
    dimensionless. Plain ASCII. ParaView's OpenFOAM reader lists only numeric time
    directories: use the CFD time (e.g. "1.5", next to alpha and Theta) or the PBE time in s
    (e.g. "600"); other names work but warn. Each file's header says it was written by
    pbe-cfd; a file of the same name that pbe-cfd did not write is never replaced, one it wrote
    only with ``overwrite`` (``check_foam_fields``, ``output.OutputRefused``). Returns the files.
    """
    from foamlib import FoamFile

    from ..output import MARK

    case_dir = Path(case_dir)
    time_name = str(time_name)
    if not time_name or "/" in time_name or time_name in (".", ".."):
        raise ValueError(f"write_foam_fields: bad time directory name {time_name!r}")
    try:
        float(time_name)
    except ValueError:
        warnings.warn(f"write_foam_fields: '{time_name}' is not a number; OpenFOAM tools and "
                      "ParaView's OpenFOAM reader only list numeric time directories "
                      "(e.g. '600' or the CFD time '1.5')", stacklevel=2)
    mesh_dir = case_dir / "constant" / "polyMesh"
    try:
        boundary = FoamFile(mesh_dir / "boundary")[None]
    except FileNotFoundError:
        raise OpenFOAMError(f"{mesh_dir / 'boundary'} not found; run blockMesh first") from None
    n_cells = _n_cells_polymesh(case_dir)
    if n_cells is None:
        n_cells = int(np.asarray(FoamFile(mesh_dir / "owner")[None]).max()) + 1
    out_dir = case_dir / time_name
    for name in fields:
        p = out_dir / name
        if p.exists() or p.is_symlink():
            check_foam_fields(case_dir, time_name, [name], overwrite, flag="write_foam_fields")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, values in fields.items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.:]*", name):
            raise ValueError(f"write_foam_fields: {name!r} is not a valid OpenFOAM field name")
        arr = np.asarray(values, dtype=np.float64).ravel()
        if arr.shape != (n_cells,):
            raise ValueError(f"write_foam_fields: field '{name}' has {arr.size} values, the "
                             f"mesh of {case_dir} has {n_cells} cells")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"write_foam_fields: field '{name}' has non-finite values")
        dim = (dimensions or {}).get(name, "[0 0 0 0 0 0 0]")
        if not isinstance(dim, str):
            dim = "[" + " ".join(str(int(x)) for x in dim) + "]"
        lines = [
            f"// {name}: {MARK} (population balance moments; any other file of this name",
            "// is never replaced by pbe-cfd)",
            "FoamFile", "{", "    version     2.0;", "    format      ascii;",
            "    class       volScalarField;", f'    location    "{time_name}";',
            f"    object      {name};", "}", "",
            f"dimensions      {dim};", "",
            "internalField   nonuniform List<scalar>", str(n_cells), "(",
        ]
        lines.extend(f"{v:.10g}" for v in arr)
        lines += [")", ";", "", "boundaryField", "{"]
        for pname, pdict in boundary:
            ptype = pdict.get("type", "patch")
            btype = ptype if ptype in _CONSTRAINT_TYPES else "zeroGradient"
            lines += [f"    {pname}", "    {", f"        type            {btype};", "    }"]
        lines += ["}", ""]
        p = out_dir / name
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text("\n".join(lines))
        os.replace(tmp, p)
        written.append(p)
    return written
