"""The OpenBLAS threads of this process, limited while a coupled run's vector work runs.

Why: numpy's bundled OpenBLAS threads a dot product or a matrix-vector product over all cores.
On a shared machine whose cores are busy, its threads wait for each other at every call: a
dot product of 6e4 doubles measured 31 ms with the default threads and 0.13 ms with one
(load average 19 on 2 cores), so the conjugate gradients of the divergence correction
(``transport.solids_flux``: two dot products per iteration) took 59 s at 1e5 cells and some
7 min at 1e6, almost all of it waiting. The vectors of a coupled run (a few times 1e5-1e6
entries, one pass each) gain little from threads even on an idle machine, so
``couple.run_coupled`` keeps one BLAS thread for the whole run.

``blas_threads(n)`` sets the thread count of every OpenBLAS library loaded in this process
(through its own ``*set_num_threads*`` entry point, found with ctypes; the loaded libraries
are read from /proc/self/maps) and restores the previous count on exit. Where no OpenBLAS is
found (another BLAS, another OS) it does nothing. The numba kernels do not call BLAS for
their small per-cell systems; results change only in the summation order of the BLAS calls
(round-off).
"""
from __future__ import annotations

import contextlib
import ctypes
from pathlib import Path

#: Entry points of OpenBLAS builds: (set, get) names, the plain and the scipy/numpy wheels'.
_ENTRY_POINTS = (("openblas_set_num_threads", "openblas_get_num_threads"),
                 ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
                 ("openblas_set_num_threads64_", "openblas_get_num_threads64_"))


def _loaded_openblas() -> list:
    """(set, get) ctypes functions of each OpenBLAS library mapped into this process."""
    maps = Path("/proc/self/maps")
    if not maps.exists():
        return []
    paths = sorted({line.split()[-1] for line in maps.read_text().splitlines()
                    if "openblas" in line.lower() and ".so" in line})
    out = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for set_name, get_name in _ENTRY_POINTS:
            if hasattr(lib, set_name) and hasattr(lib, get_name):
                setter, getter = getattr(lib, set_name), getattr(lib, get_name)
                setter.argtypes, setter.restype = [ctypes.c_int], None
                getter.argtypes, getter.restype = [], ctypes.c_int
                out.append((setter, getter))
                break
    return out


def blas_thread_counts() -> list:
    """Current thread count of each loaded OpenBLAS [-] ([] if none is found)."""
    return [int(get()) for _, get in _loaded_openblas()]


@contextlib.contextmanager
def blas_threads(n: int = 1):
    """Run the block with ``n`` OpenBLAS threads in every loaded OpenBLAS; restore after."""
    libs = _loaded_openblas()
    before = [int(get()) for _, get in libs]
    for setter, _ in libs:
        setter(max(1, int(n)))
    try:
        yield
    finally:
        for (setter, _), count in zip(libs, before):
            setter(count)
