"""pbe_cfd: population balance of fluid-bed granulation coupled to OpenFOAM fields.

numba's on-disk cache is keyed by each module's own source file, so a compiled caller keeps
inlined code of a callee from another module after that callee changed. To make the cache
always consistent with the code, it lives in a directory keyed by a hash of the package's
source files (unless NUMBA_CACHE_DIR is set by the user). Files in UNCOMPILED are left out of
the hash: no compiled function is in them or reads anything from them (``tests/test_layers.py``
checks this over the import graph), so a change to the CLI, the pictures or the benchmarks
does not recompile the kernels.
"""
import hashlib
import os
from pathlib import Path

__version__ = "0.1.0"

#: Source files (paths relative to the package, a trailing "/" for a whole directory) that no
#: numba-compiled code imports, directly or through other modules.
UNCOMPILED = ("cli.py", "plan.py", "results.py", "plotting.py", "progress.py", "simulate.py",
              "couple.py", "executor.py", "batch.py", "cfd/render.py", "cfd/section.py",
              "cfd/figure_pool.py", "cfd/figure_parts.py", "cfd/bed_moments.py", "cfd/vtk.py",
              "cfd/cases.py", "distributed/", "runs/", "io/", "physics/fluidisation.py",
              "bench/__init__.py", "bench/accuracy.py", "bench/accuracy_report.py",
              "bench/analytic.py", "bench/cluster.py", "bench/cnmc.py", "bench/common.py",
              "bench/couple.py", "bench/integrators.py", "bench/laguerre.py",
              "bench/numpy_baseline.py", "bench/throughput.py", "bench/peer.py",
              "bench/peer_case.py", "bench/peer_reference.py", "bench/peer_report.py")


def _compiled_sources(root: Path) -> list[Path]:
    """The package's .py files that can change compiled code (all but UNCOMPILED)."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if not any(rel == u or (u.endswith("/") and rel.startswith(u)) for u in UNCOMPILED):
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
