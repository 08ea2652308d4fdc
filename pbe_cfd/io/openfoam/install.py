"""Finding OpenFOAM: its tools on PATH and its project directory; the error every OpenFOAM
problem is reported as."""
from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path




TOOLS = ("blockMesh", "setFields", "twoPhaseEulerFoam", "foamToVTK")

#: Field names tried, in order, for the solids fraction and the granular temperature.
ALPHA_FIELDS = ("alpha.particlesMean", "alpha.particles")
THETA_FIELDS = ("Theta.particlesMean", "Theta.particles")
#: Face flux of the solids volume (m3/s), averaged and instantaneous.
FLUX_FIELDS = ("alphaPhi.particlesMean", "alphaPhi.particles")
#: The solids phase's name when a scene gives none (``[domain] phase``).
DEFAULT_PHASE = "particles"


def phase_fields(phase: str = DEFAULT_PHASE) -> tuple[tuple[str, ...], ...]:
    """The (alpha, Theta, face flux) field names tried, averaged first, for the solids phase
    named ``phase`` (e.g. ``alpha.solidsMean``, ``alpha.solids``)."""
    return tuple((f"{base}.{phase}Mean", f"{base}.{phase}")
                 for base in ("alpha", "Theta", "alphaPhi"))

_DEFAULT_PROJECT_DIRS = (
    "/usr/share/openfoam",
    "/usr/lib/openfoam/openfoam1912",
    "/opt/openfoam1912",
    "/opt/OpenFOAM/OpenFOAM-v1912",
)


class OpenFOAMError(RuntimeError):
    """OpenFOAM is missing, a tool failed, or a case file is not what was expected.

    Attributes: ``tool`` (the failing OpenFOAM tool or None), ``log_path`` (its log file or
    None) and ``log_tail`` (the last lines of that log, or ""). The message is one line: a
    log's tail is kept in ``log_tail`` and the message names the log file instead.
    """

    def __init__(self, message: str, tool: str | None = None,
                 log_path: Path | None = None, log_tail: str = ""):
        full = " ".join(message.split())
        if log_path is not None and str(log_path) not in full:
            full += f" (log: {log_path})"
        super().__init__(full)
        self.tool = tool
        self.log_path = log_path
        self.log_tail = log_tail


def fatal_line(text: str) -> str:
    """The first line after a FOAM FATAL header of an OpenFOAM log (the error itself), or the
    log's last non-empty line."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if "FOAM FATAL" in line:
            for nxt in lines[i + 1:]:
                if nxt.strip() and not nxt.strip().startswith(("From ", "in file")):
                    return nxt.strip()
    rest = [x.strip() for x in lines if x.strip()]
    return rest[-1] if rest else "(empty log)"


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


def bound_to_parent(argv: list[str]) -> list[str]:
    """``argv`` run so that the tool dies with pbe-cfd: a tool started in a session of its own
    (so that Ctrl-C reaches pbe-cfd, which then stops it) would otherwise outlive a pbe-cfd
    killed outright (SIGKILL, OOM) and go on writing into a case that a resume cleans up.
    util-linux ``setpriv --pdeathsig KILL`` sets the parent-death signal and execs the tool;
    without setpriv the command is unchanged."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        return list(argv)
    return [setpriv, "--pdeathsig", "KILL", "--", *argv]


def have_openfoam() -> bool:
    """True when find_openfoam() succeeds."""
    try:
        find_openfoam()
    except OpenFOAMError:
        return False
    return True
