"""What a Dask worker runs when the states of a transport run stay on the workers: one block's
state (a dict of arrays held on its worker), its halo pieces, its transport parts and source
parts. States are the scaled moments per m3 of bed of ``couple.run_coupled``; times in s."""
from __future__ import annotations

import time as _time

import numpy as np
import scipy.sparse as sp

from ... import integrate
from ..batch import CellBatch
from .faults import _maybe_fail
from .tasks import _NUMBA_LOCK, _numba_threads, _set_threads

#: The arrays of a block's state kept on its worker (and stored at output times).
BLOCK_ARRAYS = ("states", "steps", "stats", "status", "reached", "smoothed")


class BlockFailed(Exception):
    """A block's task failed: ``block`` its number, ``reason`` one line; ``stopped`` True when
    a cell's integrator stopped (a simulation failure, not a cluster one)."""

    def __init__(self, block: int, reason: str, stopped: bool = False):
        super().__init__(block, reason, stopped)
        self.block, self.reason, self.stopped = int(block), str(reason), bool(stopped)

    def __str__(self):
        return self.reason


def block_state(states, steps, stats, status, reached, smoothed) -> dict:
    """A block's state dict from its arrays (copies), with the repair counters and the
    compute seconds (``compute_s`` = ``source_s`` + ``transport_s``, wall time in the tasks
    [s]) at zero."""
    return {"states": np.array(states, dtype=np.float64, order="C", copy=True),
            "steps": np.array(steps, dtype=np.float64, copy=True),
            "stats": np.array(stats, dtype=np.int64, copy=True),
            "status": np.array(status, dtype=np.int64, copy=True),
            "reached": np.array(reached, dtype=np.float64, copy=True),
            "smoothed": np.array(smoothed, dtype=bool, copy=True),
            "repaired": 0, "repair_max": 0.0, "compute_s": 0.0, "source_s": 0.0,
            "transport_s": 0.0}


def halo_take(block: dict, positions) -> np.ndarray:
    """Task: the states of the cells at ``positions`` of a block (the halo another block
    reads), (h, n_state)."""
    return np.ascontiguousarray(block["states"][positions])


def block_transport(block: dict, op: dict, pieces: list, dt: float, k: int, repair: bool,
                    shared: dict) -> dict:
    """Task: one transport part of a block, k substeps of dt [s] on the block and its halo
    (``transport.halo.advance_block``), then the method's re-projection of unrealizable
    mixtures on the block's cells when ``repair``. ``op``: the block's operator (ext size,
    CSR rows, where the owned cells and each halo piece sit); ``pieces``: the halo states in
    the order of ``op["piece_pos"]``. Returns the new block state."""
    from ...transport.halo import advance_block
    from ...transport.operator import cells_off_closure

    start = _time.perf_counter()
    out = dict(block)
    if k > 0:
        m = int(op["m"])
        ext = np.empty((m, block["states"].shape[1]))
        ext[op["own_in_ext"]] = block["states"]
        for pos, piece in zip(op["piece_pos"], pieces):
            ext[pos] = piece
        gen = sp.csr_matrix((op["data"], op["indices"], op["indptr"]), shape=(m, m))
        out["states"] = np.ascontiguousarray(advance_block(ext, gen, dt, k)[op["own_in_ext"]])
    else:
        out["states"] = block["states"].copy()
    if repair:
        fixed, change = cells_off_closure(out["states"], shared["aux"], shared["params"],
                                           shared["config"], fix=True)
        out["repaired"] = block["repaired"] + fixed
        out["repair_max"] = max(block["repair_max"], change)
    spent = _time.perf_counter() - start
    out["compute_s"] = block["compute_s"] + spent
    out["transport_s"] = block["transport_s"] + spent
    return out


def block_source(block: dict, rows: dict, shared: dict, t0: float, t1: float, threads,
                 fault, number: int) -> dict:
    """Task: the per-cell sources of a block from t0 to t1 [s] (one source part of a split
    step), as ``CellBatch.advance`` in the serial run. ``rows``: {"rows": cell rows,
    "cells": global cell numbers}. Raises BlockFailed when a cell stops (naming it) or the
    task fails. Returns the new block state."""
    try:
        _maybe_fail(fault, number, t0)
    except RuntimeError as exc:
        raise BlockFailed(number, f"{type(exc).__name__}: {exc}") from None
    start = _time.perf_counter()
    batch = CellBatch.of_chunk(shared, rows["rows"], block["states"], block["steps"])
    batch.smoothed = block["smoothed"].copy()
    with _NUMBA_LOCK:
        _set_threads(_numba_threads(threads))
        batch.advance(t0, t1)
    bad = np.flatnonzero(batch.status != integrate.OK)
    if bad.size:
        c = int(bad[0])
        why = integrate.failure_reason(int(batch.status[c]), batch.stats_counts[c],
                                       shared["params"], shared["config"])
        raise BlockFailed(number, f"cell {int(rows['cells'][c])} stopped at t = "
                          f"{batch.reached[c]:.6g} s: {why}", stopped=True)
    out = dict(block)
    spent = _time.perf_counter() - start
    out.update(states=batch.states, steps=batch.steps, stats=block["stats"] + batch.stats_counts,
               status=batch.status, reached=batch.reached, smoothed=batch.smoothed,
               compute_s=block["compute_s"] + spent, source_s=block["source_s"] + spent)
    return out


def worker_memory() -> dict:
    """Resident and peak resident memory of this process [bytes] (run on each worker)."""
    import resource

    import psutil
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return {"rss": int(psutil.Process().memory_info().rss), "peak_rss": int(peak)}
