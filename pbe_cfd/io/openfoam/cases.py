"""Case directories made by pbe-cfd (``pbe-cfd case run --dir DIR``, ``couple --run-case``):
copy the shipped template, run it, and record what was written, so that nothing of the
user's is ever replaced or deleted.

A new or empty DIR receives the template and the run; a DIR that holds an earlier case made by
pbe-cfd (its ``pbe-cfd-manifest.json`` lists every file the copy and the OpenFOAM tools wrote)
is replaced only with ``overwrite``, and then only those files; any other directory is refused.
The template's Allrun starts with Allclean, which deletes time directories, logs, ``VTK``,
``processor*`` and the mesh by name patterns: a user file in DIR matching one of them is
refused before anything runs.
"""
from __future__ import annotations

import fnmatch
import shutil
from collections.abc import Callable
from pathlib import Path

from .. import output
from .. import openfoam as of

#: Names Allclean removes at the top of a case (rm -rf patterns), and paths below it.
ALLCLEAN_PATTERNS = ("0", "[1-9]*", "0.[0-9]*", "VTK", "postProcessing", "processor*",
                     "log.*", "mesh.type", "case.foam")
ALLCLEAN_PATHS = ("constant/polyMesh", "system/controlDict.override")
#: The manifest kind of a case directory pbe-cfd made.
CASE_KIND = "openfoam case"


def _template_files(src: Path) -> list[str]:
    """Relative paths of the template files ``copy_case`` copies."""
    out = []
    for name in ("0.orig", "constant", "system"):
        for p in sorted((src / name).rglob("*")):
            rel = p.relative_to(src)
            if p.is_file() and "polyMesh" not in rel.parts and p.name != "controlDict.override":
                out.append(rel.as_posix())
    out += [n for n in ("Allrun", "Allclean", "README.md") if (src / n).is_file()]
    return out


def _at_risk(rel: str) -> bool:
    """True when Allclean would delete the file at relative path ``rel``."""
    top = rel.split("/", 1)[0]
    return (any(fnmatch.fnmatchcase(top, p) for p in ALLCLEAN_PATTERNS)
            or any(rel == p or rel.startswith(p + "/") for p in ALLCLEAN_PATHS))


def prepare_case_dir(target, overwrite: bool = False, flag: str = "--dir",
                     template=None) -> Path:
    """Check, before anything runs, that the case can be made in ``target`` (see the module
    docstring); returns it resolved. Raises output.OutputRefused."""
    target = output.prepare_directory(target, overwrite=overwrite, flag=flag, kind=CASE_KIND)
    if not target.exists():
        return target
    manifest = output.read_manifest(target)
    ours = manifest["files"] if manifest else {}
    src = Path(template) if template else of.default_case_dir()
    template_files = set(_template_files(src))
    user = [rel for rel in output._files_under(target)
            if rel not in ours or not output._unchanged(target / rel, ours[rel])]
    clash = [rel for rel in user if rel in template_files or _at_risk(rel)]
    if clash:
        shown = ", ".join(clash[:4]) + (" ..." if len(clash) > 4 else "")
        raise output.OutputRefused(
            f"{flag} {target}: {shown} not written by pbe-cfd would be replaced or deleted by "
            "the case template and its Allclean; nothing was changed: choose a new "
            f"{flag} or move those files away yourself")
    return target


def copy_and_run(target, mesh: str = "small", overwrite: bool = False, flag: str = "--dir",
                 log: Callable[[str], None] | None = None, template=None) -> of.RunResult:
    """Copy the case template into ``target`` and run it (``openfoam.run_case``), keeping every
    file that pbe-cfd did not write; the files written are listed in the case's manifest even
    when a tool fails. Raises output.OutputRefused (before any change) or OpenFOAMError."""
    target = prepare_case_dir(target, overwrite, flag, template)
    src = Path(template) if template else of.default_case_dir()
    if target.exists() and output.read_manifest(target) is not None:
        output.remove_written(target)            # the earlier case: only its own files
    target.mkdir(parents=True, exist_ok=True)
    before = set(output._files_under(target))
    interrupted = False
    try:
        for rel in _template_files(src):
            dest = target / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src / rel, dest)      # mode from the umask, not the install
            output.apply_umask(dest, directory=(src / rel).stat().st_mode & 0o111 != 0)
        return of.run_case(target, mesh=mesh, log=log)
    except KeyboardInterrupt:            # Ctrl-C, SIGTERM: remove the half-run case
        interrupted = True
        n = len(output.record_new_files(target, before, kind=CASE_KIND))
        gone = output.remove_written(target)
        output.note_interrupted(target, f"{flag} {target}: removed the {n} files of the "
                                "half-run case" + ("" if gone else "; your files there are kept"))
        raise
    finally:
        if not interrupted:
            output.record_new_files(target, before, kind=CASE_KIND)
