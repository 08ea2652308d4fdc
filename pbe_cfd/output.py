"""Writers for run results (moments.csv, summary.json) and the rules that keep user data safe.

Every output directory pbe-cfd writes carries a manifest, ``pbe-cfd-manifest.json``, listing
the files the program wrote (path, size, modification time). The rules, for every verb:

* A new directory is written into a temporary sibling and renamed into place only when
  everything was written: a failed run leaves nothing behind.
* An existing directory is written into only when it is empty or holds a manifest (an earlier
  pbe-cfd output); anything else is refused (``OutputRefused``, exit code 2) before any work.
* An earlier output is replaced only with ``--overwrite``, and then only the files the manifest
  lists and this program wrote; any other file in the directory survives untouched.
* The current directory and its ancestors are refused as output directories.
* Single files (``compare --out F.png``) carry the marker ``written by pbe-cfd`` in their
  metadata; an existing file without it is never replaced.

Directories and files are created with the permissions of the user's umask.
"""
from __future__ import annotations

import contextlib
import csv
import fnmatch
import json
import math
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

#: The file that marks a directory as pbe-cfd output and lists what was written into it.
MANIFEST = "pbe-cfd-manifest.json"
MANIFEST_VERSION = 1
#: Text embedded in single files (PNG/PDF/SVG metadata, OpenFOAM field headers).
MARK = "written by pbe-cfd"


class UsageError(Exception):
    """Bad input to a command (a file, an option value): exit code 2, the message says what
    was expected."""


class OutputRefused(UsageError):
    """Writing would replace or delete something pbe-cfd did not write, or an earlier output
    without ``--overwrite``: bad input, exit code 2. The message says how to proceed."""


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


# ---------------------------------------------------------------------------- manifest
def read_manifest(directory) -> dict | None:
    """The manifest of ``directory`` (``{"files": {relpath: {"size", "mtime_ns"}}, ...}``), or
    None when the directory holds none (or an unreadable one)."""
    path = Path(directory) / MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict):
        return None
    return data


def _stat_entry(path: Path) -> dict:
    st = path.stat()
    return {"size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}


def _unchanged(path: Path, entry: dict) -> bool:
    """True when ``path`` is still the file pbe-cfd wrote (same size and modification time)."""
    try:
        return _stat_entry(path) == {"size": entry.get("size"),
                                     "mtime_ns": entry.get("mtime_ns")}
    except OSError:
        return False


def write_manifest(directory, files: dict, kind: str):
    """Write the manifest of ``directory`` atomically: ``files`` maps relative paths to their
    stat entries; ``kind`` names the verb that wrote them."""
    from . import __version__
    directory = Path(directory)
    data = {"written_by": f"pbe-cfd {__version__}", "version": MANIFEST_VERSION,
            "kind": kind, "files": dict(sorted(files.items()))}
    tmp = directory / f".{MANIFEST}.tmp"
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    os.replace(tmp, directory / MANIFEST)


def _files_under(root: Path) -> list[str]:
    """Relative paths (POSIX) of every file below ``root``, manifest excluded."""
    out = []
    for dirpath, _, names in os.walk(root):
        for name in names:
            rel = (Path(dirpath) / name).relative_to(root).as_posix()
            if rel != MANIFEST:
                out.append(rel)
    return sorted(out)


def record_new_files(directory, before: set, kind: str) -> dict:
    """Add every file of ``directory`` not in ``before`` (relative paths present before a tool
    wrote into it) to its manifest; returns the manifest's file table. For directories filled
    in place by external tools (an OpenFOAM case)."""
    directory = Path(directory)
    old = read_manifest(directory)
    files = dict(old["files"]) if old else {}
    for rel in _files_under(directory):
        if rel not in before or rel in files:
            files[rel] = _stat_entry(directory / rel)
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


def prepare_directory(target, overwrite: bool = False, flag: str = "--out",
                      names=None, allow_cwd: bool = False) -> Path:
    """Check, before any work, that ``target`` may receive an output; returns it resolved.

    ``names`` None (replace mode: run, couple, case): ``target`` must be new, empty, or an
    earlier pbe-cfd output, which is replaced only with ``overwrite``. ``names`` a list of
    relative paths (add mode: bench, render): an earlier output may receive new files; those
    of ``names`` it already holds are replaced only with ``overwrite``. Files pbe-cfd did not
    write are never replaced. ``allow_cwd`` (add mode only: files are added one by one, the
    directory itself is never replaced) accepts the current directory. Raises OutputRefused."""
    if allow_cwd and names is not None:
        target = Path(target).expanduser().resolve()
    else:
        target = check_not_cwd(target, flag)
    if not target.exists():
        for parent in target.parents:
            if parent.exists():
                if not parent.is_dir():
                    raise OutputRefused(f"{_flag_text(flag, target)}: {parent} is a file, not a "
                                        "directory")
                break
        return target
    if not target.is_dir():
        raise OutputRefused(f"{_flag_text(flag, target)}: exists and is not a directory; choose "
                            "a new name")
    if not any(target.iterdir()):
        return target
    manifest = read_manifest(target)
    if manifest is None:
        raise OutputRefused(
            f"{_flag_text(flag, target)}: the directory exists and was not written by pbe-cfd "
            f"(it has no {MANIFEST}); nothing was changed: {_instead(flag)} "
            "or move its contents away yourself")
    if names is None:
        if not overwrite:
            raise OutputRefused(
                f"{_flag_text(flag, target)}: holds an earlier pbe-cfd output; add --overwrite "
                "to replace the files that run wrote (other files there are kept), or "
                f"{_instead(flag)}")
        return target
    _check_collisions(target, manifest, names, overwrite, flag)
    return target


def _check_collisions(target: Path, manifest: dict | None, names, overwrite: bool, flag: str):
    files = manifest["files"] if manifest else {}
    ours, foreign = [], []
    for rel in names:
        rel = Path(rel).as_posix()
        path = target / rel
        blocked = [q for q in path.relative_to(target).parents if str(q) != "."
                   and (target / q).exists() and not (target / q).is_dir()]
        if blocked:
            foreign.append(blocked[-1].as_posix())
            continue
        if not path.exists() and not path.is_symlink():
            continue
        if rel in files and path.is_file() and _unchanged(path, files[rel]):
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
@contextlib.contextmanager
def atomic_directory(target, overwrite: bool = False, flag: str = "--out",
                     kind: str = "output", add: bool = False):
    """Yield a temporary directory next to ``target``; on success its files go into ``target``.

    A new ``target``: one rename, so the output appears complete or not at all. An empty one or
    an earlier pbe-cfd output (``overwrite`` needed unless ``add``): file by file, each an
    atomic replace; the files of the earlier output that this one does not write again are
    removed (unless ``add``) when they are unchanged since pbe-cfd wrote them; every other file
    is kept. On any exception the temporary directory is removed and ``target`` is untouched.
    Raises OutputRefused (before yielding, or on success if the target changed meanwhile)."""
    target = prepare_directory(target, overwrite=overwrite, flag=flag,
                               names=[] if add else None, allow_cwd=add)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=target.parent))
    apply_umask(tmp)
    try:
        yield tmp
        _commit(tmp, target, overwrite, flag, kind, add)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _commit(tmp: Path, target: Path, overwrite: bool, flag: str, kind: str, add: bool):
    new = _files_under(tmp)
    if not target.exists():
        write_manifest(tmp, {rel: _stat_entry(tmp / rel) for rel in new}, kind)
        tmp.rename(target)
        return
    prepare_directory(target, overwrite=overwrite, flag=flag, names=new if add else None,
                      allow_cwd=add)
    old = read_manifest(target)
    old_files = dict(old["files"]) if old else {}
    _check_collisions(target, old, new, True, flag)      # never replace a foreign file
    stale = [] if add else [rel for rel in old_files if rel not in new]
    # claim everything first, so that an interrupted commit leaves every file accounted for
    write_manifest(target, {**old_files, **{rel: _stat_entry(tmp / rel) for rel in new}}, kind)
    files = dict(old_files) if add else {}
    for rel in new:
        dest = target / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp / rel, dest)
        files[rel] = _stat_entry(dest)
    for rel in stale:
        path = target / rel
        if not (path.exists() or path.is_symlink()):
            continue
        if path.is_file() and _unchanged(path, old_files[rel]):
            path.unlink()
            _remove_empty_parents(path.parent, target)
        else:
            warnings.warn(f"kept {path}: it changed since pbe-cfd wrote it", stacklevel=3)
    write_manifest(target, files, kind)


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
    True when the directory is gone."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    if manifest is None:
        return not directory.exists()
    files = manifest["files"]
    kept = {}
    for rel, entry in files.items():
        path = directory / rel
        if not (path.is_file() and _unchanged(path, entry)):
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
    from . import __version__
    text = f"{MARK} {__version__}" + (f" ({what})" if what else "")
    fmt = fmt.lower().lstrip(".")
    if fmt == "png":
        return {"Software": text}
    if fmt == "pdf":
        return {"Creator": text}
    if fmt == "svg":
        return {"Creator": text}
    return {}


# ---------------------------------------------------------------------------- tables
def write_columns_csv(path, columns: dict):
    """Write equal-length 1-D columns (first the time) to CSV with full float precision."""
    names = list(columns)
    rows = len(next(iter(columns.values())))
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(names)
        for r in range(rows):
            writer.writerow([_fmt(columns[n][r]) for n in names])


def _fmt(value):
    value = float(value)
    return repr(value) if math.isfinite(value) else "nan"


def read_columns_csv(path) -> dict:
    """Read a CSV written by ``write_columns_csv`` into name -> float array. Raises ValueError
    naming the file when it is not such a table."""
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
            data = [[float(v) for v in row] for row in reader if row]
        except StopIteration:
            raise ValueError(f"{path}: empty file") from None
        except (ValueError, csv.Error, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a table of numbers under a header ({exc})") from None
    if not header or header[0] != "time_s" or any(len(r) != len(header) for r in data):
        raise ValueError(f"{path}: expected a header starting with time_s and rows of "
                         f"{len(header)} numbers")
    arr = np.array(data, dtype=float).reshape(-1, len(header))
    return {name: arr[:, k] for k, name in enumerate(header)}


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else str(v)
    return value


def write_json(path, data: dict):
    """Write a dict as indented JSON (numpy values converted, non-finite floats as strings)."""
    with open(path, "w") as fh:
        json.dump(_jsonable(data), fh, indent=2)
        fh.write("\n")
