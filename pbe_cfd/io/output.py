"""Writers for run results (moments.csv, summary.json) and the rules that keep user data safe.

Every output directory pbe-cfd writes carries a manifest (``manifest.py``) listing the files
the program wrote and the verb that wrote them. The rules, for every verb:

* An output directory is never an input of the same run (the scene, the case or snapshot it
  reads, nor a directory holding or inside one), nor the current directory or its ancestors.
* An existing directory is written into only when it is empty or holds a manifest of the same
  verb (a `case run` case is never replaced by a `couple` output, nor the reverse); anything
  else is refused (``OutputRefused``, exit code 2) before any work.
* An earlier output is replaced only with ``--overwrite``; a file of it that changed since
  pbe-cfd wrote it (size, time or content), or a manifest entry naming a path outside the
  directory, is refused before any work. Any other file in the directory survives untouched.
* The output is written into ``.DIR.partial-*`` beside DIR; the files of the user there are
  hard-linked into it, its manifest is written last, and it is exchanged with DIR in one
  rename: a crash leaves the old output or the new one, never a mix (``output_guard``).
* One process at a time writes DIR (a lock beside it); leftovers of killed runs are cleaned
  by the next run into DIR.
* An OS error while writing (disk full, a vanished directory) raises ``OutputFailed`` (exit
  code 1) with the earlier output intact; a place that cannot be written at all (read-only,
  permission) is refused before any work.
* Single files (``compare --out F.png``) carry the marker ``written by pbe-cfd`` in their
  metadata; an existing file without it is never replaced.

Directories and files are created with the permissions of the user's umask.
"""
from __future__ import annotations

import contextlib
import errno
import fnmatch
import os
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

from . import output_guard as guard
from .tables import read_columns_csv, write_columns_csv, write_json  # noqa: F401 (re-exported)
from .manifest import (KIND_VERB, MANIFEST, PARTIAL_MARKER, empty_dirs_under, files_under,
                       member_problem, read_manifest, stat_entry, unchanged, write_manifest)

#: Text embedded in single files (PNG/PDF/SVG metadata, OpenFOAM field headers).
MARK = "written by pbe-cfd"

# the names other modules used before the manifest had its own module
_files_under, _unchanged, _stat_entry = files_under, unchanged, stat_entry
__all__ = ["MANIFEST", "read_manifest", "write_manifest"]


class UsageError(Exception):
    """Bad input to a command (a file, an option value): exit code 2, the message says what
    was expected."""


class OutputRefused(UsageError):
    """Writing would replace or delete something pbe-cfd did not write, or an earlier output
    without ``--overwrite``: bad input, exit code 2. The message says how to proceed."""


class OutputFailed(Exception):
    """The operating system refused a write of the output (disk full, a directory that
    vanished): exit code 1. Nothing half-written is left and the earlier output is intact."""


#: What an interrupted command kept, per output directory (for the one line at Ctrl-C).
_interrupt_notes: dict[Path, str] = {}


def note_interrupted(target, text: str):
    """Record what an interrupted command did to ``target`` (said at the interrupt)."""
    _interrupt_notes[Path(target)] = text


def interrupted_text() -> str:
    """One sentence: what is left of every output directory this process was writing."""
    parts = []
    for target in guard.held() + [t for t in _interrupt_notes if t not in guard.held()]:
        parts.append(_interrupt_notes.get(target) or _kept_text(target))
    return "; ".join(parts) or "no output written"


def _kept_text(target: Path) -> str:
    if read_manifest(target) is not None:
        return f"{target} not changed (the earlier output there is kept)"
    return f"{target} not written"


def release_claims():
    """Give up the locks of every output directory this process claimed."""
    guard.release_all()
    _interrupt_notes.clear()


def note(text: str):
    """Tell the user about the output directories (stderr, one line)."""
    print(f"pbe-cfd: {text}", file=sys.stderr)


# ---------------------------------------------------------------------------- permissions
def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def apply_umask(path, directory: bool = True):
    """Give ``path`` the mode a plain ``mkdir``/``open`` would (0o777 or 0o666 less the
    umask; ``directory`` True also for executables); ``tempfile`` creates 0o700/0o600."""
    base = 0o777 if directory else 0o666
    os.chmod(path, base & ~_umask())


def record_new_files(directory, before: set, kind: str) -> dict:
    """Add every file of ``directory`` not in ``before`` (relative paths present before a tool
    wrote into it) to its manifest; returns the manifest's file table. For directories filled
    in place by external tools (an OpenFOAM case)."""
    directory = Path(directory)
    old = read_manifest(directory)
    files = dict(old["files"]) if old else {}
    for rel in files_under(directory):
        if rel not in before or rel in files:
            files[rel] = stat_entry(directory / rel)
    write_manifest(directory, files, kind)
    return files


# ---------------------------------------------------------------------------- checks
def _flag_text(flag: str, target: Path) -> str:
    return f"{flag} {target}" if flag else str(target)


def _instead(flag: str) -> str:
    """What the user can do instead of replacing: another target (or, for render, other
    fields or times)."""
    if flag == "render":
        return "draw other --fields/--times"
    return f"choose a new {flag or 'directory'}"


def check_not_cwd(target, flag: str = "--out") -> Path:
    """Refuse the current directory and any of its ancestors as an output directory."""
    target = Path(target).expanduser().resolve()
    cwd = Path.cwd().resolve()
    if target == cwd or target in cwd.parents:
        raise OutputRefused(
            f"{_flag_text(flag, target)}: that is the current directory or one of its parents; "
            f"pbe-cfd writes its output as a new directory: name one, e.g. {flag or '--out'} run1")
    return target


def check_not_input(target, inputs, flag: str = "--out") -> Path:
    """Refuse ``target`` when it is one of ``inputs`` (``(what, path)`` pairs: the scene, the
    case, a snapshot), holds one, or lies inside an input directory. Returns it resolved."""
    target = Path(target).expanduser().resolve()
    for what, path in inputs:
        path = Path(path).expanduser().resolve()
        if target == path:
            relation = "is"
        elif target in path.parents:
            relation = "holds"
        elif path in target.parents:
            relation = "lies inside"
        else:
            continue
        raise OutputRefused(
            f"{_flag_text(flag, target)}: {relation} {what} {path}, an input of this run; "
            f"nothing was changed: choose {flag or 'an output'} outside the run's inputs")
    return target


def _check_kind(target: Path, manifest: dict, kind: str | None, flag: str):
    found = manifest.get("kind", "output")
    if kind is None or found == kind or (kind == "render" and found == "couple"):
        return
    raise OutputRefused(
        f"{_flag_text(flag, target)}: holds the output of {KIND_VERB.get(found, found)} "
        f"(kind {found!r}), not of {KIND_VERB.get(kind, kind)}; nothing was changed: "
        f"{_instead(flag)}")


def _check_members(target: Path, manifest: dict, flag: str):
    """Refuse a manifest that names a path outside ``target`` (it was edited)."""
    for rel in manifest["files"]:
        problem = member_problem(target, rel)
        if problem:
            raise OutputRefused(
                f"{_flag_text(flag, target)}: its {MANIFEST} lists {rel!r}, which {problem}; "
                "pbe-cfd removes only files inside its output directory, and nothing was "
                "changed: move the directory away or choose a new one")


def _check_edited(target: Path, manifest: dict, flag: str):
    """Refuse, before any work, an earlier output one of whose files changed since."""
    changed = [rel for rel, entry in manifest["files"].items()
               if os.path.lexists(target / rel) and not unchanged(target / rel, entry)]
    if changed:
        shown = ", ".join(changed[:3]) + (" ..." if len(changed) > 3 else "")
        raise OutputRefused(
            f"{_flag_text(flag, target)}: {shown} changed since pbe-cfd wrote it; nothing was "
            f"changed: move it away to keep it, or {_instead(flag)}")


def _claim(target: Path, flag: str):
    """Lock ``target`` for this process (its parent must exist) and clean the leftovers of
    interrupted runs into it. Raises OutputRefused when another run holds it or the parent
    cannot be written."""
    try:
        guard.claim(target)
    except guard.Busy as exc:
        raise OutputRefused(
            f"{_flag_text(flag, target)}: another pbe-cfd run (pid {exc}) is writing it; "
            f"nothing was changed: wait for it to finish, or {_instead(flag)}") from None
    except OSError as exc:
        raise OutputRefused(f"{_flag_text(flag, target)}: cannot write in {target.parent} "
                            f"({exc.strerror}); nothing was changed: choose a place you can "
                            "write") from None
    try:
        for text in guard.recover(target):
            note(text)
    except OSError as exc:
        guard.release(target)
        raise OutputRefused(f"{_flag_text(flag, target)}: cannot clean the leftovers of an "
                            f"interrupted run ({exc}); nothing else was changed") from None


def prepare_directory(target, overwrite: bool = False, flag: str = "--out",
                      names=None, allow_cwd: bool = False, kind: str | None = None,
                      inputs=()) -> Path:
    """Check, before any work, that ``target`` may receive an output; returns it resolved and
    claimed for this process (see the module docstring).

    ``names`` None (replace mode: run, couple, case): ``target`` must be new, empty, or an
    earlier pbe-cfd output of ``kind`` (None: any) whose files are unchanged, which is replaced
    only with ``overwrite``. ``names`` a list of relative paths (add mode: bench, render): an
    earlier output may receive new files; those of ``names`` it already holds are replaced only
    with ``overwrite``. Files pbe-cfd did not write are never replaced. ``allow_cwd`` (add mode
    only) accepts the current directory. ``inputs``: ``(what, path)`` pairs the output must
    not be, hold or lie in. Raises OutputRefused."""
    if allow_cwd and names is not None:
        target = Path(target).expanduser().resolve()
    else:
        target = check_not_cwd(target, flag)
    check_not_input(target, inputs, flag)
    for parent in target.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputRefused(f"{_flag_text(flag, target)}: {parent} is a file, not a "
                                    "directory")
            break
    if target.parent.is_dir():
        _claim(target, flag)
    try:
        _check_target(target, overwrite, flag, names, kind, refuse_edited=True)
    except BaseException:
        guard.release(target)
        raise
    return target


def _check_target(target: Path, overwrite: bool, flag: str, names, kind, refuse_edited: bool):
    if not os.path.lexists(target):
        return
    if not target.is_dir() or target.is_symlink():
        raise OutputRefused(f"{_flag_text(flag, target)}: exists and is not a directory; choose "
                            "a new name")
    if not any(target.iterdir()):
        return
    manifest = read_manifest(target)
    if manifest is None:
        raise OutputRefused(
            f"{_flag_text(flag, target)}: the directory exists and was not written by pbe-cfd "
            f"(it has no {MANIFEST}); nothing was changed: {_instead(flag)} "
            "or move its contents away yourself")
    _check_kind(target, manifest, kind, flag)
    _check_members(target, manifest, flag)
    if names is None:
        if not overwrite:
            raise OutputRefused(
                f"{_flag_text(flag, target)}: holds an earlier pbe-cfd output; add --overwrite "
                "to replace the files that run wrote (other files there are kept), or "
                f"{_instead(flag)}")
        if refuse_edited:
            _check_edited(target, manifest, flag)
        return
    _check_collisions(target, manifest, names, overwrite, flag)


def _check_collisions(target: Path, manifest: dict | None, names, overwrite: bool, flag: str):
    files = manifest["files"] if manifest else {}
    ours, foreign = [], []
    for rel in names:
        rel = Path(rel).as_posix()
        path = target / rel
        blocked = [q for q in path.relative_to(target).parents if str(q) != "."
                   and os.path.lexists(target / q) and not (target / q).is_dir()]
        if blocked:
            foreign.append(blocked[-1].as_posix())
            continue
        if not os.path.lexists(path):
            continue
        if rel in files and unchanged(path, files[rel]):
            ours.append(rel)
        else:
            foreign.append(rel)
    if foreign:
        shown = ", ".join(foreign[:3]) + (" ..." if len(foreign) > 3 else "")
        raise OutputRefused(
            f"{_flag_text(flag, target)}: {shown} exist(s) and pbe-cfd did not write it (or it "
            f"changed since); nothing was changed: {_instead(flag)} or move those files away "
            "yourself")
    if ours and not overwrite:
        shown = ", ".join(ours[:3]) + (" ..." if len(ours) > 3 else "")
        raise OutputRefused(
            f"{_flag_text(flag, target)}: {shown}: written by an earlier pbe-cfd run; add "
            f"--overwrite to replace, or {_instead(flag)}")


# ---------------------------------------------------------------------------- directories
def _os_failure(exc: OSError, target: Path, flag: str, existed: bool) -> OutputFailed:
    where = f" ({exc.filename})" if exc.filename else ""
    kept = ("the earlier output there is intact" if existed
            else "nothing was left behind")
    return OutputFailed(f"{_flag_text(flag, target)}: could not write the output: "
                        f"{exc.strerror or exc}{where}; {kept}")


@contextlib.contextmanager
def atomic_directory(target, overwrite: bool = False, flag: str = "--out",
                     kind: str = "output", add: bool = False):
    """Yield a temporary directory next to ``target``; on success it becomes ``target``.

    The files of the earlier output that this one does not write again are dropped (unless
    ``add``) when unchanged since pbe-cfd wrote them; every other file there is hard-linked
    into the new directory and so kept. The new directory, manifest written last, is exchanged
    with ``target`` in one rename. On any exception the temporary directory is removed and
    ``target`` is untouched. Raises OutputRefused (before yielding, or on success if the target
    changed meanwhile) or OutputFailed (an OS error while writing)."""
    target = prepare_directory(target, overwrite=overwrite, flag=flag,
                               names=[] if add else None, allow_cwd=add, kind=kind)
    existed = target.exists()
    tmp = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        _claim(target, flag)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=target.parent))
        (tmp / PARTIAL_MARKER).write_text(f"{os.getpid()}\n")
        apply_umask(tmp)
        yield tmp
        _commit(tmp, target, overwrite, flag, kind, add)
    except OSError as exc:
        raise _os_failure(exc, target, flag, existed) from None
    except KeyboardInterrupt:
        _interrupt_notes.setdefault(target, _kept_text(target))
        raise
    finally:
        try:
            if tmp is not None and os.path.lexists(tmp):
                guard.remove_leftover(tmp, target)
        finally:
            guard.release(target)


def _commit(tmp: Path, target: Path, overwrite: bool, flag: str, kind: str, add: bool):
    new = files_under(tmp)
    if not os.path.lexists(target):
        write_manifest(tmp, {rel: stat_entry(tmp / rel) for rel in new}, kind)
        (tmp / PARTIAL_MARKER).unlink()
        try:
            os.rename(tmp, target)
        except OSError as exc:
            if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):
                raise OutputRefused(f"{_flag_text(flag, target)}: appeared while this run "
                                    f"computed; nothing was changed there: {_instead(flag)}"
                                    ) from None
            raise
        return
    _check_target(target, overwrite, flag, new if add else None, kind, refuse_edited=False)
    old = read_manifest(target)
    old_files = dict(old["files"]) if old else {}
    _check_collisions(target, old, new, True, flag)      # never replace a foreign file
    carried = []
    for rel in files_under(target):
        if rel in new:
            continue                                     # ours, unchanged: replaced
        ours = rel in old_files and unchanged(target / rel, old_files[rel])
        if ours and not add:
            continue                                     # ours, stale: dropped
        if rel in old_files and not ours:
            warnings.warn(f"kept {target / rel}: it changed since pbe-cfd wrote it",
                          stacklevel=4)
        carried.append(rel)
    for rel in carried:
        guard.carry(target, tmp, rel)
    for rel in empty_dirs_under(target):
        guard.make_dirs(target, tmp, rel)
    shutil.copymode(target, tmp)
    files = {rel: stat_entry(tmp / rel) for rel in new}
    if add:
        files = {**{r: old_files[r] for r in carried if r in old_files}, **files}
        kind = (old or {}).get("kind", kind)
    write_manifest(tmp, files, kind)                     # the new directory is complete
    (tmp / PARTIAL_MARKER).unlink()
    old_dir = guard.swap(tmp, target)
    note_interrupted(target, f"{target} written (the new output is complete)")
    try:
        kept = guard.remove_leftover(old_dir, target)
    except OSError as exc:
        kept = [str(exc)]
    if kept:
        note(f"kept {old_dir} (the earlier output's directory): it holds {', '.join(kept[:3])}")


def _remove_empty_parents(directory: Path, root: Path):
    while directory != root and root in directory.parents:
        try:
            directory.rmdir()            # only succeeds when empty
        except OSError:
            return
        directory = directory.parent


def add_to_directory(target, kind: str = "output", flag: str = "--out"):
    """``atomic_directory`` in add mode for writers that share a directory (bench studies,
    renders): new files are added, files pbe-cfd wrote earlier are replaced, a file pbe-cfd did
    not write is never replaced (OutputRefused). The command checks ``--overwrite`` first with
    ``prepare_directory(..., names=...)``."""
    return atomic_directory(target, overwrite=True, flag=flag, kind=kind, add=True)


def remove_written(directory, patterns=("*",)) -> bool:
    """Remove the files of ``directory`` that its manifest lists and that are unchanged since,
    whose names match one of ``patterns``; then the directory itself if it is empty. Returns
    True when the directory is gone. Raises OutputRefused, before removing anything, when the
    manifest names a path outside ``directory``."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    if manifest is None:
        return not directory.exists()
    _check_members(directory, manifest, "")
    files = manifest["files"]
    kept = {}
    for rel, entry in files.items():
        path = directory / rel
        if not unchanged(path, entry):
            continue                     # gone, or changed since: no longer ours to remove
        if any(fnmatch.fnmatch(Path(rel).name, p) for p in patterns):
            path.unlink()
            _remove_empty_parents(path.parent, directory)
        else:
            kept[rel] = entry
    if kept:
        write_manifest(directory, kept, manifest.get("kind", "output"))
        return False
    (directory / MANIFEST).unlink(missing_ok=True)
    try:
        directory.rmdir()
    except OSError:
        return False
    return True


def remove_matching(directory, patterns) -> bool:
    """Remove the files directly in ``directory`` whose names match ``patterns`` (a store
    whose own manifest identifies it, e.g. the Dask chunk store), then the directory if that
    left it empty. Other files stay. Returns True when the directory is gone."""
    directory = Path(directory)
    if not directory.is_dir():
        return not directory.exists()
    for path in directory.iterdir():
        if path.is_file() and any(fnmatch.fnmatch(path.name, p) for p in patterns):
            path.unlink()
    try:
        directory.rmdir()
    except OSError:
        return False
    return True


# ---------------------------------------------------------------------------- single files
def file_is_marked(path) -> bool:
    """True when the file carries ``MARK`` (pbe-cfd wrote it)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(4 << 20)
    except OSError:
        return False
    return MARK.encode() in data


def prepare_file(target, overwrite: bool = False, flag: str = "--out") -> Path:
    """Check that a single output file may be written: new, or marked as pbe-cfd's and
    ``overwrite`` given. Returns the resolved path. Raises OutputRefused."""
    target = Path(target).expanduser().resolve()
    if target.is_dir():
        raise OutputRefused(f"{_flag_text(flag, target)}: is a directory; name a file, e.g. "
                            f"{flag} compare.png")
    for parent in target.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputRefused(f"{_flag_text(flag, target)}: {parent} is not a directory")
            break
    if target.exists() or target.is_symlink():
        if not file_is_marked(target):
            raise OutputRefused(f"{_flag_text(flag, target)}: the file exists and was not "
                                "written by pbe-cfd; nothing was changed: choose another name")
        if not overwrite:
            raise OutputRefused(f"{_flag_text(flag, target)}: written by an earlier pbe-cfd "
                                "run; add --overwrite to replace it, or choose another name")
    return target


@contextlib.contextmanager
def atomic_file(target, overwrite: bool = False, flag: str = "--out"):
    """Yield a temporary path next to ``target`` (same suffix); on success it replaces
    ``target`` in one rename. The writer must embed ``MARK`` (e.g. ``figure_metadata()``)."""
    target = prepare_file(target, overwrite, flag)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.stem}.partial-", suffix=target.suffix,
                                dir=target.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        apply_umask(tmp, directory=False)
        prepare_file(target, overwrite, flag)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def figure_metadata(fmt: str, what: str = "") -> dict:
    """Matplotlib ``savefig(metadata=...)`` carrying ``MARK`` for png, pdf and svg."""
    from .. import __version__
    text = f"{MARK} {__version__}" + (f" ({what})" if what else "")
    fmt = fmt.lower().lstrip(".")
    if fmt == "png":
        return {"Software": text}
    if fmt == "pdf":
        return {"Creator": text}
    if fmt == "svg":
        return {"Creator": text}
    return {}
