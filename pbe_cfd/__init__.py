"""pbe_cfd: population balance of fluid-bed granulation coupled to OpenFOAM fields.

numba's on-disk cache is keyed by each module's own source file, so a compiled caller keeps
inlined code of a callee from another module after that callee changed. To make the cache
always consistent with the code, it lives in a directory keyed by a hash of the package's
source files that compiled code can read (unless NUMBA_CACHE_DIR is set by the user): the
compiled folders and the few modules outside them that compiled code imports, ``COMPILED``.
Everything else (the CLI, the runs' orchestration, the pictures, the benchmarks) is left out
of the hash (``tests/test_layers.py`` checks over the import graph that compiled code reads
none of it), so a change there does not recompile the kernels.
"""
import hashlib
import os
from pathlib import Path

__version__ = "0.1.0"

#: What compiled code can read (paths relative to the package, a trailing "/" for a folder):
#: the compiled folders, the folders below them that they import (scene, I/O, utilities), and
#: the modules of other folders that hold numba functions or that compiled code imports.
COMPILED = ("__init__.py", "physics/", "methods/", "integrate/", "distribution/", "transport/",
            "scene/", "io/", "util/", "runs/__init__.py", "runs/model.py", "runs/domain.py",
            "bench/breakdown.py", "bench/sweeps.py")


def _compiled_sources(root: Path) -> list[Path]:
    """The package's .py files that can change compiled code (those under COMPILED)."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if any(rel == c or (c.endswith("/") and rel.startswith(c)) for c in COMPILED):
            out.append(path)
    return out


def _source_hash() -> str:
    digest = hashlib.sha1()
    root = Path(__file__).resolve().parent
    for path in _compiled_sources(root):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _configure_numba_cache():
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pbe_cfd" / "numba"
    target = base / _source_hash()
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    import numba
    numba.config.CACHE_DIR = str(target)


_configure_numba_cache()
