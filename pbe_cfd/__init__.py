"""pbe_cfd: population balance of fluid-bed granulation coupled to OpenFOAM fields.

numba's on-disk cache is keyed by each module's own source file, so a compiled caller keeps
inlined code of a callee from another module after that callee changed. To make the cache
always consistent with the code, it lives in a directory keyed by a hash of the package's
source files that compiled code can read (under NUMBA_CACHE_DIR when the user sets it): the
compiled folders and the few modules outside them that compiled code imports, ``COMPILED``.
Inside it, a module's entries are named by its place in the package, not on disk
(``util/kernel_cache.py``), so a cache built once (``pbe-cfd compile``) serves the same sources
wherever they are installed.
Everything else (the CLI, the runs' orchestration, the pictures, the benchmarks) is left out
of the hash (``tests/test_layers.py`` checks over the import graph that compiled code reads
none of it), so a change there does not recompile the kernels.
"""
import os
from pathlib import Path

__version__ = "0.1.0"

#: What compiled code can read (paths relative to the package, a trailing "/" for a folder):
#: the compiled folders, the folders below them that they import (scene, I/O, utilities), and
#: the modules of other folders that hold numba functions or that compiled code imports.
COMPILED = ("__init__.py", "physics/", "methods/", "integrate/", "distribution/", "transport/",
            "scene/", "io/", "util/", "runs/__init__.py", "runs/model.py", "runs/domain.py",
            "runs/cell_gas.py",
            "bench/breakdown.py", "bench/sweeps.py")


def _compiled_sources(root: Path) -> list[Path]:
    """The package's .py files that can change compiled code (those under COMPILED)."""
    from .util.kernel_cache import compiled_sources
    return compiled_sources(root, COMPILED)


def _source_hash() -> str:
    from .util.kernel_cache import source_hash
    return source_hash(Path(__file__).resolve().parent, COMPILED)


def _configure_numba_cache():
    from .util import kernel_cache
    root = kernel_cache.install(_source_hash())
    if root is not None and not os.environ.get("NUMBA_CACHE_DIR"):
        import numba
        numba.config.CACHE_DIR = str(root)   # numba functions outside the package


_configure_numba_cache()
