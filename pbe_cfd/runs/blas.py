"""The OpenBLAS threads of this process, limited while a coupled run's vector work runs.

Why: numpy's bundled OpenBLAS threads a dot product or a matrix-vector product over all cores.
On a shared machine whose cores are busy, its threads wait for each other at every call: a
dot product of 6e4 doubles measured 31 ms with the default threads and 0.13 ms with one
(load average 19 on 2 cores), so the conjugate gradients of the divergence correction
(``transport.solids_flux``: two dot products per iteration) took 59 s at 1e5 cells and some
7 min at 1e6, almost all of it waiting. The vectors of a coupled run (a few times 1e5-1e6
entries, one pass each) gain little from threads even on an idle machine, so
``couple.run_coupled`` keeps one BLAS thread for the whole run.

``blas_threads(n)`` limits every BLAS library loaded in this process to ``n`` threads and
restores the previous counts on exit (threadpoolctl, which finds the loaded OpenBLAS, MKL or
BLIS and calls its own thread-count entry point). The numba kernels do not call BLAS for their
small per-cell systems; results change only in the summation order of the BLAS calls
(round-off).
"""
from __future__ import annotations

from threadpoolctl import threadpool_info, threadpool_limits


def blas_thread_counts() -> list:
    """Current thread count of each loaded OpenBLAS [-] ([] if none is found)."""
    return [int(lib["num_threads"]) for lib in threadpool_info()
            if lib.get("internal_api") == "openblas"]


def blas_threads(n: int = 1):
    """Context manager: the block runs with ``n`` threads in every loaded BLAS; restored
    after (also on an error)."""
    return threadpool_limits(limits=max(1, int(n)), user_api="blas")
