"""Running the fluid-bed case (copy the template, Allrun with progress and per-tool wall times)
and picking its written times."""
from __future__ import annotations

import dataclasses
import math
import os
import re
import shutil
import subprocess
import threading
import time as _time
from collections.abc import Callable
from importlib import resources
from pathlib import Path


from .install import (DEFAULT_PHASE, OpenFOAMError, bound_to_parent, fatal_line, find_openfoam,
                      phase_fields)


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


def vtk_files(case_dir: Path) -> set:
    """Paths (str) of every file and directory under ``case_dir/VTK`` (foamToVTK's output),
    the directory itself included if it exists."""
    vtk = Path(case_dir) / "VTK"
    if not vtk.is_dir():
        return set()
    return {str(vtk)} | {str(p) for p in vtk.rglob("*")}


def remove_new_vtk(case_dir: Path, before: set, since_ns: int) -> int:
    """After a failed OpenFOAM tool: remove the partial output a failing foamToVTK wrote under
    ``case_dir/VTK``: every file not in ``before`` (``vtk_files`` taken before the tool ran)
    or modified since ``since_ns`` (time.time_ns() before the tool ran: an Allrun cleans VTK/
    and foamToVTK writes the same names again), then the directories not in ``before`` that
    this leaves empty. Any other file is never touched. Returns the number of files removed."""
    new = sorted(vtk_files(case_dir), key=lambda p: -len(Path(p).parts))
    removed = 0
    for name in new:
        p = Path(name)
        if p.is_symlink() or not p.is_file():
            continue
        if name not in before or p.stat().st_mtime_ns >= since_ns:
            p.unlink(missing_ok=True)
            removed += 1
    new = [name for name in new if name not in before]
    for name in new:
        p = Path(name)
        if p.is_dir() and not p.is_symlink() and not any(p.iterdir()):
            p.rmdir()
    return removed


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
    _check_run_arguments(case_dir, mesh, end_time, avg_start)
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

    vtk_before, started_ns = vtk_files(case_dir), _time.time_ns()
    proc = subprocess.Popen(bound_to_parent(args), cwd=case_dir, env=install.env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    watch = _AllrunWatch(proc, say)
    try:
        watch.wait(case_dir, target, timeout)
    except BaseException:                 # Ctrl-C, SIGTERM: stop Allrun and its tools too
        _stop_group(proc)
        raise
    if proc.returncode != 0:
        remove_new_vtk(case_dir, vtk_before, started_ns)
        raise watch.failure(case_dir, mesh)
    latest = written_times(case_dir)[-1]
    return RunResult(case_dir, mesh, latest, watch.wall)


def _stop_group(proc):
    """Terminate the process group of Allrun (the script and the tool it runs), then kill."""
    import os
    import signal
    for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=grace)
            return
        except subprocess.TimeoutExpired:
            continue


def _check_run_arguments(case_dir: Path, mesh, end_time, avg_start):
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


class _AllrunWatch:
    """Follows a running Allrun: its output lines, the tool running and each tool's wall time
    [s] (from the "Allrun: running TOOL" / "Allrun: done" lines), the solver's simulated time."""

    def __init__(self, proc, say):
        self.proc = proc
        self.say = say
        self.wall: dict[str, float] = {}
        self.current = None
        self.started = _time.perf_counter()
        self.lines: list[str] = []
        self.failed = False
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.lines.append(line)
            m = re.match(r"Allrun: running (\S+)", line)
            now = _time.perf_counter()
            if m:
                if self.current is not None:
                    self.wall[self.current] = now - self.started
                self.current, self.started = m.group(1), now
            elif line.startswith("Allrun: done") and self.current is not None:
                self.wall[self.current] = now - self.started
                self.current = None
            elif re.match(r"Allrun: (\S+) failed", line):
                self.failed = True        # the error names it; Allrun's log tail follows
            if not self.failed:
                self.say(line)

    def wait(self, case_dir: Path, target, timeout):
        """Wait for Allrun to end, reporting the solver's time; kill it after ``timeout`` [s]."""
        t0 = _time.perf_counter()
        last_reported = None
        while True:
            try:
                self.proc.wait(timeout=2.0)
                break
            except subprocess.TimeoutExpired:
                pass
            if self.current == "twoPhaseEulerFoam":
                t = _last_sim_time(case_dir / "log.twoPhaseEulerFoam")
                if t is not None and t != last_reported:
                    last_reported = t
                    self.say(f"twoPhaseEulerFoam: t = {t:g} s of {target:g} s" if target
                             else f"twoPhaseEulerFoam: t = {t:g} s")
            if timeout is not None and _time.perf_counter() - t0 > timeout:
                self.proc.kill()
                self.proc.wait()
                tool = self.current or "Allrun"
                lp = case_dir / f"log.{tool}"
                raise OpenFOAMError(f"{tool} in {case_dir} stopped after the {timeout} s "
                                    "timeout", tool=tool, log_path=lp, log_tail=_tail(lp))
        self.thread.join(timeout=5.0)

    def failure(self, case_dir: Path, mesh) -> OpenFOAMError:
        """The error of a failed Allrun, naming the tool that failed with its log's tail."""
        tool = None
        for line in self.lines:
            m = re.match(r"Allrun: (\S+) failed", line)
            if m:
                tool = m.group(1)
        if tool is None:
            m = re.search(r"OpenFOAM tool '(\S+)' not found", "\n".join(self.lines))
            tool = m.group(1) if m else (self.current or "Allrun")
        lp = case_dir / f"log.{tool}"
        tail = _tail(lp) if lp.is_file() else "\n".join(self.lines[-30:])
        return OpenFOAMError(
            f"{tool} failed in {case_dir} (Allrun {mesh}, exit status {self.proc.returncode}): "
            f"{fatal_line(tail)}", tool=tool, log_path=lp if lp.is_file() else None,
            log_tail=tail)


def _control_value(path: Path, key: str) -> float | None:
    try:
        text = path.read_text()
    except OSError:
        return None
    m = re.search(rf"^\s*{key}\s+([0-9.eE+-]+)\s*;", text, flags=re.M)
    return float(m.group(1)) if m else None


# --------------------------------------------------------------------------- times

def _numeric_dirs(directory: Path) -> list[tuple[float, str]]:
    out = []
    for p in directory.iterdir():
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


def _time_dirs(case_dir: Path) -> list[tuple[float, str]]:
    """(time [s], name) of the case's time directories: the root's and, for a decomposed case,
    those of ``processor0`` (times a parallel run wrote without reconstructPar)."""
    if not case_dir.is_dir():
        raise OpenFOAMError(f"case directory {case_dir} does not exist")
    out = dict((name, t) for t, name in _numeric_dirs(case_dir))
    proc = case_dir / "processor0"
    if proc.is_dir():
        for t, name in _numeric_dirs(proc):
            out.setdefault(name, t)
    return sorted((t, name) for name, t in out.items())


def written_times(case_dir: str | os.PathLike) -> list[float]:
    """Times (s) with a time directory in the case (root or processor0), ascending (0
    included when present)."""
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


def _holds_alpha(directory: Path, phase: str) -> bool:
    from .readable import has_foam_file
    return any(has_foam_file(directory / f) for f in phase_fields(phase)[0])


def is_decomposed_time(case_dir: str | os.PathLike, name: str,
                       phase: str = DEFAULT_PHASE) -> bool:
    """True when time ``name`` holds the solids fraction only in the processor directories
    (a parallel run not reconstructed), so it is read from them."""
    case_dir = Path(case_dir)
    return (not _holds_alpha(case_dir / name, phase)
            and _holds_alpha(case_dir / "processor0" / name, phase))


def pick_time(case_dir: str | os.PathLike, which: str | float = "latest",
              phase: str = DEFAULT_PHASE) -> float:
    """Resolve ``which`` ("latest", or a time in s, a number or a string) to a written time
    of the case (s), root or processor directories.

    "latest" is the latest directory holding alpha.<phase>(Mean), in the root or in
    processor0, so fields written back by write_foam_fields into a later time do not hide the
    CFD time (the latest directory of any kind when none holds alpha). A number must match a
    written time (to 1e-6 relative); otherwise the error lists the written times.
    """
    case_dir = Path(case_dir)
    dirs = _time_dirs(case_dir)
    times = [t for t, _ in dirs]
    if not times:
        raise OpenFOAMError(f"no time directories in {case_dir}; run the case first "
                            "(openfoam_case/Allrun or pbe_cfd.io.openfoam.run_case)")
    if isinstance(which, str):
        if which.strip().lower() == "latest":
            # the latest CFD time: skip directories holding only written-back fields
            cfd = [t for t, name in dirs
                   if _holds_alpha(case_dir / name, phase)
                   or _holds_alpha(case_dir / "processor0" / name, phase)]
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


def _control_summary(case_dir: Path) -> dict:
    out = {}
    for f in ("controlDict", "controlDict.override"):
        p = case_dir / "system" / f
        for key in ("endTime", "avgStart", "deltaT"):
            v = _control_value(p, key)
            if v is not None:
                out[key] = v
    return out
