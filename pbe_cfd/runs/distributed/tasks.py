"""The tasks a Dask worker runs: one chunk's cells as a ``CellBatch`` over all output times
(no transport); with transport the block tasks are in ``halo_tasks``."""
from __future__ import annotations

import threading
import time as _time

import numpy as np

from ... import integrate
from ..batch import CellBatch
from .faults import _maybe_fail

_NUMBA_LOCK = threading.Lock()


# ---------------------------------------------------------------------------- tasks
def _numba_threads(table) -> int:
    if isinstance(table, int):
        return max(1, table)
    try:
        from distributed import get_worker
        return max(1, int(table.get(get_worker().address, 1)))
    except (ValueError, ImportError):
        return 1


def _set_threads(n: int):
    import numba
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def _identity(x):
    return x


def _noop(x):
    return x


def chunk_history(chunk: int, states, rows, steps, shared, times, threads, fault=None) -> dict:
    """Task: integrate one chunk's cells over every output interval of ``times`` [s].

    states (n, n_state) scaled moments at times[0]; rows (n, N_CELL) cell fields; steps (n,)
    step memory [s]; shared: ``CellBatch.shared()`` of the run. Returns history (n_times, n,
    n_state), steps, stats (n, N_STATS), status, reached [s], fail_interval (index of the
    output time at which a cell stopped, -1 if none), compute_s (wall time of the integration
    [s]) and the worker's numba threads. A cell that stops ends the chunk (as the serial run
    stops at the end of that interval)."""
    _maybe_fail(fault, chunk, float(times[0]))
    start = _time.perf_counter()
    batch = CellBatch.of_chunk(shared, rows, states, steps)
    hist = np.empty((len(times),) + batch.states.shape)
    hist[0] = batch.states
    fail = np.full(batch.n_cells, -1, dtype=np.int64)
    nthreads = _numba_threads(threads)
    with _NUMBA_LOCK:
        _set_threads(nthreads)
        for k in range(1, len(times)):
            batch.advance(float(times[k - 1]), float(times[k]))
            hist[k] = batch.states
            new = (batch.status != integrate.OK) & (fail < 0)
            if new.any():
                fail[new] = k
                hist[k + 1:] = batch.states
                break
    return {"history": hist, "steps": batch.steps, "stats": batch.stats_counts,
            "status": batch.status, "reached": batch.reached, "fail_interval": fail,
            "compute_s": np.array(_time.perf_counter() - start),
            "threads": np.array(nthreads)}
