"""pbe_cfd: population balance of fluid-bed granulation coupled to OpenFOAM fields.

numba's on-disk cache is keyed by each module's own source file, so a compiled caller keeps
inlined code of a callee from another module after that callee changed. To make the cache
always consistent with the code, it lives in a directory keyed by a hash of every source file
of the package (unless NUMBA_CACHE_DIR is set by the user).
"""
import hashlib
import os
from pathlib import Path

__version__ = "0.1.0"


def _source_hash() -> str:
    digest = hashlib.sha1()
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
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
