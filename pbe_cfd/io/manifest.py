"""The manifest that marks a directory as pbe-cfd output: ``pbe-cfd-manifest.json`` lists every
file the program wrote there (relative path, size [bytes], modification time [ns], and for files
up to ``HASH_LIMIT`` bytes a SHA-256 of the content) and the verb that wrote them (``kind``).

A file counts as still pbe-cfd's only when it is a regular file (not a symlink) whose size,
modification time and (where recorded) hash all match its entry; anything else is the user's.
A manifest entry must name a path inside the directory (no absolute path, no ``..``, no
symlinked parent leading out): ``member_problem`` says why one does not.
"""
from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

#: The file that marks a directory as pbe-cfd output and lists what was written into it.
MANIFEST = "pbe-cfd-manifest.json"
MANIFEST_VERSION = 2
#: Marker file inside a temporary ``.DIR.partial-*`` directory pbe-cfd is filling.
PARTIAL_MARKER = ".pbe-cfd-partial"
#: Files up to this size [bytes] are hashed; larger ones are compared by size and time only.
HASH_LIMIT = 8 << 20

#: The verb that writes each kind of output directory (for the messages).
KIND_VERB = {"run": "`pbe-cfd run`", "couple": "`pbe-cfd couple`",
             "openfoam case": "`pbe-cfd case run`", "bench": "`pbe-cfd bench`",
             "render": "`pbe-cfd render`", "output": "pbe-cfd"}


def read_manifest(directory) -> dict | None:
    """The manifest of ``directory`` (``{"kind", "files": {relpath: entry}, ...}``), or None
    when the directory holds none (or an unreadable one)."""
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


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def stat_entry(path) -> dict:
    """The manifest entry of the file at ``path``: size [bytes], mtime [ns], sha256 (small
    files)."""
    path = Path(path)
    st = path.lstat()
    entry = {"size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}
    if stat.S_ISREG(st.st_mode) and st.st_size <= HASH_LIMIT:
        entry["sha256"] = _sha256(path)
    return entry


def unchanged(path, entry) -> bool:
    """True when ``path`` is still the regular file pbe-cfd wrote: same size, modification
    time and (where the entry records one) content hash."""
    path = Path(path)
    try:
        st = path.lstat()
    except OSError:
        return False
    if not isinstance(entry, dict) or not stat.S_ISREG(st.st_mode):
        return False
    if st.st_size != entry.get("size") or st.st_mtime_ns != entry.get("mtime_ns"):
        return False
    if "sha256" in entry:
        try:
            return _sha256(path) == entry["sha256"]
        except OSError:
            return False
    return True


def member_problem(root, rel) -> str | None:
    """Why the manifest entry ``rel`` does not name a path inside ``root`` (None when it
    does): an absolute path, a ``..`` part, or a parent directory that is a symlink leading
    out of ``root``."""
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        return "is not a relative path"
    parts = Path(rel).parts
    if Path(rel).is_absolute() or rel.startswith(("/", "\\")):
        return "is an absolute path"
    if ".." in parts or any(p in ("", ".") for p in rel.split("/")):
        return "leaves the directory (..)"
    root = Path(root).resolve()
    parent = (root / rel).parent
    try:
        real = parent.resolve()
    except (OSError, RuntimeError):
        return "has a parent that cannot be resolved"
    if real != root and root not in real.parents:
        return f"has a parent leading out of the directory (to {real})"
    return None


def write_manifest(directory, files: dict, kind: str):
    """Write the manifest of ``directory`` atomically: ``files`` maps relative paths to their
    entries; ``kind`` names the verb that wrote them."""
    from .. import __version__
    directory = Path(directory)
    data = {"written_by": f"pbe-cfd {__version__}", "version": MANIFEST_VERSION,
            "kind": kind, "files": dict(sorted(files.items()))}
    tmp = directory / f".{MANIFEST}.tmp"
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    os.replace(tmp, directory / MANIFEST)


def files_under(root) -> list[str]:
    """Relative paths (POSIX) of every file and symlink below ``root`` (symlinked directories
    are listed, not followed), the manifest and the partial marker excluded."""
    root = Path(root)
    out = []
    for dirpath, dirnames, names in os.walk(root):
        here = Path(dirpath)
        links = [d for d in dirnames if (here / d).is_symlink()]
        for name in names + links:
            rel = (here / name).relative_to(root).as_posix()
            if rel not in (MANIFEST, PARTIAL_MARKER, f".{MANIFEST}.tmp"):
                out.append(rel)
    return sorted(out)


def empty_dirs_under(root) -> list[str]:
    """Relative paths of the directories below ``root`` that hold nothing."""
    root = Path(root)
    out = []
    for dirpath, dirnames, names in os.walk(root):
        here = Path(dirpath)
        if here != root and not dirnames and not names:
            out.append(here.relative_to(root).as_posix())
    return sorted(out)
