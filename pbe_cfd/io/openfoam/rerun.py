"""Re-running the fluid-bed CFD for one segment of a two-way coupled run.

Every segment runs in a case directory pbe-cfd owns (a manifest lists each file it and the
OpenFOAM tools wrote; ``output.remove_written`` removes only those): the first is a copy of the
case template run from its packed bed (``start_case``), every later one a copy of the previous
segment's case -- mesh, dictionaries and the fields of its last written time -- that continues
the flow from that state (``continue_case``). Before a segment runs, the particle diameter d [m]
of the solids phase (``diameterModel constant``, ``constant/phaseProperties``) is set to the
population balance's, and the run window in ``system/controlDict``: startTime, endTime [s]
(CFD time) and the start of the fieldAverage window [s]. The time-averaged fields of the last
written time are then read like any case (``pbe_cfd.cfd.openfoam.read_cell_fields``).

The case the user gave is only read, never written. All quantities are SI.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import time as _time
import warnings
from collections.abc import Callable
from pathlib import Path

from .. import openfoam as of
from .. import output
from . import cases
from .case import _last_sim_time, _stop_group, _tail, remove_new_vtk, vtk_files
from .install import fatal_line  # noqa: F401 (rerun.fatal_line: API)

#: the solver a segment runs, and the tool that writes its VTK internal mesh afterwards
SOLVER = "twoPhaseEulerFoam"
VTK_TOOL = "foamToVTK"
#: the manifest kind of a segment's case directory
SEGMENT_KIND = "coupling segment case"
#: universal gas constant [J/(kmol K)] (molWeight in kg/kmol, as OpenFOAM's specie)
GAS_CONSTANT = 8314.47


def _foam_file(path: Path):
    from foamlib import FoamFile
    return FoamFile(path)


def _quiet():
    """foamlib's notes on duplicate keys (OpenFOAM keeps the last, as foamlib does)."""
    cm = warnings.catch_warnings()
    cm.__enter__()
    warnings.simplefilter("ignore")
    return cm


def set_diameter(case: Path, phase: str, diameter: float):
    """Set the constant particle diameter [m] of ``phase`` in ``case/constant/phaseProperties``
    (``diameterModel constant``; ``constantCoeffs d``). Raises OpenFOAMError when the phase's
    diameter model is another one."""
    path = Path(case) / "constant" / "phaseProperties"
    if not (diameter > 0 and math.isfinite(diameter)):
        raise ValueError(f"set_diameter: expected a positive diameter in m, got {diameter!r}")
    cm = _quiet()
    try:
        f = _foam_file(path)
        model = str(f[phase, "diameterModel"])
        if model != "constant":
            raise of.OpenFOAMError(f"{path}: the diameterModel of phase {phase!r} is {model!r}; "
                                   "two-way coupling sets a constant one (expected "
                                   "diameterModel constant)")
        f[phase, "constantCoeffs", "d"] = float(diameter)
    except KeyError as exc:
        raise of.OpenFOAMError(f"{path}: no entry {exc} for phase {phase!r} (expected "
                               f"{phase} {{ diameterModel constant; constantCoeffs {{ d ...; }} }}"
                               ")") from None
    finally:
        cm.__exit__(None, None, None)


def read_diameter(case: Path, phase: str) -> float:
    """The constant particle diameter [m] of ``phase`` in ``case/constant/phaseProperties``."""
    cm = _quiet()
    try:
        return float(_foam_file(Path(case) / "constant" / "phaseProperties")[
            phase, "constantCoeffs", "d"])
    finally:
        cm.__exit__(None, None, None)


def set_window(case: Path, start_name: str | None, end_time: float, avg_start: float):
    """Set the run window of ``case/system/controlDict``: start from the time directory
    ``start_name`` (None: keep the start), run to ``end_time`` [s], write at the end only, and
    average every fieldAverage function object over [avg_start, end_time] [s]."""
    path = Path(case) / "system" / "controlDict"
    cm = _quiet()
    try:
        f = _foam_file(path)
        with f:
            if start_name is not None:
                f["startFrom"] = "startTime"
                f["startTime"] = float(start_name)
            start = float(f["startTime"]) if start_name is not None else 0.0
            f["endTime"] = float(end_time)
            f["writeControl"] = "runTime"
            f["writeInterval"] = float(end_time - start)
            functions = f["functions"] if "functions" in f else {}
            averaged = 0
            for name in list(functions.keys()):
                if str(functions[name].get("type", "")) != "fieldAverage":
                    continue
                averaged += 1
                ts = functions[name].get("timeStart")
                if isinstance(ts, str) and ts.startswith("$"):
                    f[ts[1:]] = float(avg_start)
                else:
                    f["functions", name, "timeStart"] = float(avg_start)
                f["functions", name, "restartOnRestart"] = True
            if not averaged:
                raise of.OpenFOAMError(
                    f"{path}: no fieldAverage function object; two-way coupling reads the "
                    "time-averaged fields (expected a fieldAverage of alpha, Theta and alphaPhi "
                    "of the solids phase)")
    finally:
        cm.__exit__(None, None, None)


def _run_tool(case: Path, tool: str, args: list, env: dict, say, target: float | None):
    """Run one OpenFOAM tool in ``case`` with its output in ``log.<tool>``; progress lines of
    the solver's time; on failure an OpenFOAMError naming the tool, its FOAM FATAL lines and
    the tail of its log. Stops the tool on Ctrl-C or SIGTERM, also one raised by ``say``
    (which is first called once the tool has started, when ``target`` is given)."""
    log_path = case / f"log.{tool}"
    vtk_before, started_ns = vtk_files(case), _time.time_ns()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(of.bound_to_parent([tool, *args]), cwd=case, env=env,
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        last = None
        try:
            if target is not None:
                say(f"{tool}: running to t = {target:g} s")
            while True:
                try:
                    proc.wait(timeout=2.0)
                    break
                except subprocess.TimeoutExpired:
                    pass
                t = _last_sim_time(log_path) if tool == SOLVER else None
                if t is not None and t != last:
                    last = t
                    say(f"{tool}: t = {t:g} s of {target:g} s")
        except BaseException:
            _stop_group(proc)
            raise
    text = log_path.read_text(errors="replace")
    if proc.returncode != 0 or "FOAM FATAL" in text:
        remove_new_vtk(case, vtk_before, started_ns)
        raise of.OpenFOAMError(f"{tool} failed in {case} (exit status {proc.returncode}): "
                               f"{fatal_line(text)}", tool=tool, log_path=log_path,
                               log_tail=_tail(log_path))


def _owned(target: Path, before: set, body):
    """Run ``body()`` filling ``target``; every file written is listed in its manifest, on
    failure too; a Ctrl-C removes the half-made case (only its own files)."""
    try:
        return body()
    except KeyboardInterrupt:
        output.record_new_files(target, before, kind=SEGMENT_KIND)
        output.remove_written(target)
        raise
    finally:
        if target.exists():
            output.record_new_files(target, before, kind=SEGMENT_KIND)


def start_case(target, phase: str, diameter: float, flow_time: float, avg_start: float,
               mesh: str = "small", log: Callable[[str], None] | None = None) -> Path:
    """The first segment: copy the case template into the new directory ``target``, set the
    particle diameter [m] and run it from its packed bed for ``flow_time`` [s] of flow,
    averaging over [avg_start, flow_time] [s]. Returns the case directory."""
    target = Path(target)
    if target.exists():
        raise output.OutputRefused(f"{target}: a segment case must be a new directory")
    src = of.default_case_dir()
    target.mkdir(parents=True)

    def body():
        for rel in cases._template_files(src):
            dest = target / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src / rel, dest)
            output.apply_umask(dest, directory=(src / rel).stat().st_mode & 0o111 != 0)
        set_diameter(target, phase, diameter)
        output.record_new_files(target, set(), kind=SEGMENT_KIND)   # ours, before any tool
        of.run_case(target, mesh=mesh, log=log, end_time=flow_time, avg_start=avg_start)
        return target
    return _owned(target, set(), body)


def continue_case(source, time_name: str, target, phase: str, diameter: float,
                  flow_time: float, avg_from: float,
                  log: Callable[[str], None] | None = None) -> Path:
    """A later segment: copy the mesh, the dictionaries and the flow fields of ``source``'s time
    directory ``time_name`` (not its time averages) into the new directory ``target``, set the
    particle diameter [m] and run the solver from that time for ``flow_time`` [s] of flow,
    averaging over its last ``flow_time - avg_from`` [s]; then foamToVTK of the last time.
    ``source`` is only read. Returns the case directory."""
    source, target = Path(source), Path(target)
    if target.exists():
        raise output.OutputRefused(f"{target}: a segment case must be a new directory")
    install = of.find_openfoam()
    t0 = float(time_name)
    say = log or (lambda msg: None)
    target.mkdir(parents=True)

    def body():
        shutil.copytree(source / "constant", target / "constant")
        shutil.copytree(source / "system", target / "system",
                        ignore=shutil.ignore_patterns("controlDict.override"))
        (target / time_name).mkdir()
        for p in sorted((source / time_name).iterdir()):
            if p.is_file() and not p.name.endswith("Mean"):
                shutil.copyfile(p, target / time_name / p.name)
        set_diameter(target, phase, diameter)
        set_window(target, time_name, t0 + flow_time, t0 + avg_from)
        (target / "case.foam").touch()
        output.record_new_files(target, set(), kind=SEGMENT_KIND)   # ours, before any tool
        started = _time.perf_counter()
        _run_tool(target, SOLVER, [], install.env(), say, t0 + flow_time)
        _run_tool(target, VTK_TOOL, ["-latestTime", "-no-boundary", "-no-point-data",
                                     "-with-ids"], install.env(), say, None)
        say(f"{SOLVER}: {flow_time:g} s of flow in {_time.perf_counter() - started:.1f} s")
        return target
    return _owned(target, set(), body)


def latest_time_name(case) -> str:
    """The directory name of the latest written time of ``case``."""
    times = of.written_times(case)
    return of.time_name(case, times[-1])


def fluidisation_inputs(case, phase: str = "particles") -> dict:
    """What Wen & Yu's minimum fluidisation velocity needs from a twoPhaseEulerFoam case, all
    SI: the gas density [kg/m3] (perfect gas at the initial p [Pa] and T.<gas> [K], molWeight
    [kg/kmol]), the gas viscosity mu [Pa s], the inlet's superficial velocity [m/s]
    (``inletVelocity`` or ``value`` of the gas's inlet patch) and the gas phase's name. Values
    it cannot read are None."""
    case = Path(case)
    start = case / ("0.orig" if (case / "0.orig").is_dir() else latest_time_name(case))
    cm = _quiet()
    try:
        phases = [str(p) for p in _foam_file(case / "constant" / "phaseProperties")["phases"]]
        gas = next((p for p in phases if p != phase), None)
        thermo = _foam_file(case / "constant" / f"thermophysicalProperties.{gas}")
        mu = _number(lambda: thermo["mixture", "transport", "mu"])
        mw = _number(lambda: thermo["mixture", "specie", "molWeight"])
        temp = _uniform(start / f"T.{gas}")
        pressure = _uniform(start / "p")
        rho = (pressure * mw / (GAS_CONSTANT * temp)
               if None not in (pressure, mw, temp) else None)
        velocity = _inlet_speed(start / f"U.{gas}")
    except Exception:  # noqa: BLE001 - a case without these entries gives None values
        return {"gas": None, "gas_density": None, "gas_viscosity": None,
                "inlet_velocity": None}
    finally:
        cm.__exit__(None, None, None)
    return {"gas": gas, "gas_density": rho, "gas_viscosity": mu, "inlet_velocity": velocity}


def _number(get):
    try:
        return float(get())
    except Exception:  # noqa: BLE001
        return None


def _uniform(path: Path):
    """The value of ``internalField uniform x`` of a field file (regex: 0.orig fields are
    ascii), or None."""
    try:
        m = re.search(r"internalField\s+uniform\s+([0-9.eE+-]+)\s*;", path.read_text())
    except OSError:
        return None
    return float(m.group(1)) if m else None


def _inlet_speed(path: Path):
    """|inletVelocity| (or |value|) of the ``inlet`` patch of a vector field file [m/s]."""
    try:
        text = path.read_text()
    except OSError:
        return None
    m = re.search(r"\binlet\s*\{([^}]*)\}", text)
    if not m:
        return None
    for key in ("inletVelocity", "value"):
        v = re.search(rf"\b{key}\s+uniform\s+\(([^)]*)\)", m.group(1))
        if v:
            comps = [float(x) for x in v.group(1).split()]
            return math.sqrt(sum(c * c for c in comps))
    return None


def copy_logs(case, dest):
    """Copy the logs and the two dictionaries a segment ran with (``log.*``,
    ``constant/phaseProperties``, ``system/controlDict``) into the new directory ``dest``."""
    case, dest = Path(case), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    for p in sorted(case.glob("log.*")):
        shutil.copyfile(p, dest / p.name)
    for rel in ("constant/phaseProperties", "system/controlDict"):
        if (case / rel).is_file():
            shutil.copyfile(case / rel, dest / Path(rel).name)
    return sorted(os.listdir(dest))
