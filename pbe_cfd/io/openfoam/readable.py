"""pbe-cfd's own readable copy of one time of a user's OpenFOAM case.

A user's case is only ever read. To read a time as it is (ascii, binary, compressed, or
decomposed into ``processor*/`` without the root holding that time), the files that time
depends on are copied into a directory pbe-cfd owns, the cache (``$PBE_CFD_CACHE``, else
``$XDG_CACHE_HOME/pbe-cfd``, else ``~/.cache/pbe-cfd``), and the OpenFOAM tools run there:
``reconstructPar`` for a decomposed time, ``foamFormatConvert`` to plain ascii, ``foamToVTK``
for the cell mesh. Their logs and dictionaries stay in the copy.

A copy is keyed by what it was made from: the case's absolute path, the time names, and the
size and modification time (ns) of every file read (``constant/``, ``system/``, the time
directories, the processor directories' mesh and times). An edited field makes a new key, so a
copy is never served stale. A copy is built in a temporary directory and renamed into place
when complete: a failing tool leaves no partial copy (its log is kept under ``failed/``).
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from .install import OpenFOAMError, find_openfoam

CACHE_ENV = "PBE_CFD_CACHE"
#: Name of the file in each copy saying what it was made from.
SOURCE_FILE = "pbe-cfd-source.json"
_MESH_FILES = ("points", "faces", "owner", "neighbour", "boundary")


def _copy_tree(src: Path, dest: Path):
    """Copy a directory; links decomposePar left dangling (``uniform``) are skipped."""
    shutil.copytree(src, dest, ignore_dangling_symlinks=True)


def cache_root() -> Path:
    """The directory pbe-cfd owns for converted cases (see the module docstring)."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "pbe-cfd"


def foam_path(path: Path) -> Path:
    """``path`` or, when only that exists, ``path.gz`` (OpenFOAM's compressed files)."""
    path = Path(path)
    gz = path.with_name(path.name + ".gz")
    return gz if not path.is_file() and gz.is_file() else path


def has_foam_file(path: Path) -> bool:
    """True when the OpenFOAM file ``path`` exists plain or compressed (``.gz``)."""
    return foam_path(path).is_file()


def has_mesh(case_dir: Path) -> bool:
    """True when ``case_dir/constant/polyMesh`` holds a complete mesh (plain or .gz)."""
    pm = Path(case_dir) / "constant" / "polyMesh"
    return all(has_foam_file(pm / f) for f in _MESH_FILES)


def _files(root: Path, rels) -> list[tuple[str, int, int]]:
    """(relative path, size [B], mtime [ns]) of every file under the paths ``rels``."""
    out = []
    for rel in rels:
        top = root / rel
        paths = [top] if top.is_file() else sorted(p for p in top.rglob("*") if p.is_file())
        for p in paths:
            st = p.stat()
            out.append((p.relative_to(root).as_posix(), st.st_size, st.st_mtime_ns))
    return out


def _processors(case_dir: Path) -> list[Path]:
    procs = [p for p in case_dir.glob("processor*")
             if p.is_dir() and p.name[len("processor"):].isdigit()]
    return sorted(procs, key=lambda p: int(p.name[len("processor"):]))


def _inputs(case_dir: Path, names: list[str], decomposed: bool) -> list[str]:
    rels = ["constant", "system"]
    if decomposed:
        for p in _processors(case_dir):
            rels.append(f"{p.name}/constant/polyMesh")
            rels += [f"{p.name}/{n}" for n in names if (p / n).is_dir()]
    else:
        rels += [n for n in names if (case_dir / n).is_dir()]
    return rels


def source_key(case_dir: Path, names: list[str], decomposed: bool) -> tuple[str, dict]:
    """The cache key of a copy of times ``names`` of ``case_dir`` and the record it hashes."""
    case_dir = Path(case_dir).resolve()
    record = {"case": str(case_dir), "times": list(names), "decomposed": bool(decomposed),
              "files": _files(case_dir, _inputs(case_dir, names, decomposed))}
    digest = hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:32]
    return digest, record


def _ascii_control_dict(path: Path):
    """Rewrite the copy's controlDict to write plain ascii, uncompressed."""
    text = path.read_text(errors="replace")
    for key, value in (("writeFormat", "ascii"), ("writeCompression", "off")):
        pattern = rf"^(\s*{key}\s+)[^;]*;"
        if re.search(pattern, text, flags=re.M):
            text = re.sub(pattern, rf"\g<1>{value};", text, count=1, flags=re.M)
        else:
            text += f"\n{key} {value};\n"
    path.write_text(text)


def _run(tool: str, args: list[str], cwd: Path, install, what: str):
    log = cwd / f"log.{tool}"
    with open(log, "w") as fh:
        r = subprocess.run([tool, *args], cwd=cwd, env=install.env(), stdout=fh,
                           stderr=subprocess.STDOUT)
    text = log.read_text(errors="replace")
    if r.returncode != 0 or "FOAM FATAL" in text:
        kept = cache_root() / "failed" / f"{cwd.name}.log.{tool}"
        kept.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(log, kept)
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        fatal = next((i for i, ln in enumerate(lines) if "FOAM FATAL" in ln), None)
        reason = " ".join(lines[fatal + 1:fatal + 3]) if fatal is not None else (
            lines[-1] if lines else f"exit status {r.returncode}")
        raise OpenFOAMError(f"{tool} failed on {what}: {reason} (log: {kept})", tool=tool)


def readable_copy(case_dir, names: list[str], decomposed: bool) -> Path:
    """The cached readable copy of times ``names`` (directory names, the first the CFD time
    read) of ``case_dir``: plain ascii, reconstructed when ``decomposed``, with foamToVTK's
    ``VTK/`` of the first time. Built on first use (needs OpenFOAM); raises OpenFOAMError."""
    case_dir = Path(case_dir).resolve()
    key, record = source_key(case_dir, names, decomposed)
    root = cache_root()
    final = root / key
    if (final / SOURCE_FILE).is_file():
        return final
    install = find_openfoam(("foamToVTK", "foamFormatConvert")
                            + (("reconstructPar",) if decomposed else ()))
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".build-{key}-", dir=root))
    what = f"t = {names[0]} s of {case_dir}"
    try:
        _copy_tree(case_dir / "system", tmp / "system")
        _copy_tree(case_dir / "constant", tmp / "constant")
        _ascii_control_dict(tmp / "system" / "controlDict")
        times = ",".join(names)
        if decomposed:
            for p in _processors(case_dir):
                _copy_tree(p / "constant", tmp / p.name / "constant")
                for n in names:
                    if (p / n).is_dir():
                        _copy_tree(p / n, tmp / p.name / n)
            _run("reconstructPar", ["-time", times], tmp, install, what)
            for p in _processors(case_dir):
                shutil.rmtree(tmp / p.name)
        else:
            for n in names:
                if (case_dir / n).is_dir():
                    _copy_tree(case_dir / n, tmp / n)
        _run("foamFormatConvert", ["-constant", "-time", times], tmp, install, what)
        for gz in tmp.rglob("*.gz"):     # files the converter left alone (uniform/, ...)
            gz.unlink()
        _run("foamToVTK", ["-time", names[0], "-no-boundary", "-no-point-data", "-with-ids"],
             tmp, install, what)
        (tmp / SOURCE_FILE).write_text(json.dumps(record, indent=1))
        try:
            os.rename(tmp, final)
        except OSError:                  # another run made the same copy meanwhile
            if not (final / SOURCE_FILE).is_file():
                raise
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final
