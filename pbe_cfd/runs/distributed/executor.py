"""``ClusterExecutor``: the per-cell source integration of a coupled run on a Dask cluster
(see the package docstring)."""
from __future__ import annotations

import json
import os
import statistics
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import integrate
from ...io.spool import Spool
from ..batch import SimulationError
from .decompose import write_processor_fields
from .partition import Partition, block_partition, processor_partition
from .store import STORE_SUFFIX, ChunkStore, fingerprint
from .cluster import numba_thread_table
from .tasks import _identity, chunk_history


class ChunkedSpool(Spool):
    """A ``Spool`` whose items are filled in pieces: ``reserve`` adds an output time as a
    file of zeros, ``fill`` writes the rows of one chunk into it through a memory map held
    only for that write (the pages go to the file, not the client's resident memory)."""

    def reserve(self, shape, dtype=np.float64) -> int:
        """Add output time len(self), an array of ``shape`` (zeros); returns its index."""
        k = len(self._items)
        arr = np.lib.format.open_memmap(self.path / f"{k}.npy", mode="w+", dtype=dtype,
                                        shape=tuple(int(x) for x in shape))
        self._bytes += arr.nbytes
        del arr
        self._items.append(None)
        return k

    def fill(self, k: int, rows, values) -> None:
        """Write ``values`` into rows ``rows`` (positions along the first axis) of item k."""
        arr = np.load(self.path / f"{int(k)}.npy", mmap_mode="r+", allow_pickle=False)
        arr[rows] = values
        arr.flush()
        del arr


class ChunksFailed(SimulationError):
    """Some chunks did not finish. ``failed`` maps chunk number -> reason; ``store`` is the
    chunk store holding the finished chunks (or None)."""

    def __init__(self, message, failed: dict, store: Path | None):
        super().__init__(message)
        self.failed = failed
        self.store = store


@dataclass
class ClusterExecutor:
    """Runs the per-cell sources of ``couple.run_coupled`` on a Dask client.

    client      distributed.Client
    chunks      number of blocks (default 4 per worker), or a Partition
    decomposition  cellProcAddressing per processor (one chunk per processor), or None
    store_dir   the chunk store (``store_path(out)``) or None for no persistence
    resume      reuse the stored chunks (the store must match this problem)
    meta        extra manifest entries (scene, output directory)
    fault       fault injection (``parse_fault``), for tests
    cluster     a LocalCluster this executor owns (closed by ``close``)
    halo_substeps  with transport: substeps per halo exchange (the halo's depth in upwind
                hops); None: one exchange per transport part (depth = its substeps)
    balance     with transport on blocks of the flux graph: re-partition at an output time by
                the costs measured over the interval before it (``balance``) when the blocks'
                predicted max/mean load exceeds ``balance.REBALANCE_ABOVE`` (True) or the
                number given; False keeps the blocks of equal cells
    """
    client: object
    chunks: object = None
    decomposition: list | None = None
    store_dir: Path | None = None
    resume: bool = False
    meta: dict = field(default_factory=dict)
    fault: dict | None = None
    cluster: object = None
    case_dir: Path | None = None
    halo_substeps: int | None = None
    balance: bool | float = True
    _report: dict = field(default_factory=dict, repr=False)
    store: ChunkStore | None = field(default=None, repr=False)

    # -- the executor interface (pbe_cfd.runs.executor) ---------------------------------------
    def run(self, batch, times, transport=None, progress=None) -> list:
        """Advance ``batch`` (a ``CellBatch`` of the active cells) over all output ``times``
        [s] like ``SerialExecutor.run``; update its states and work arrays in place and return
        the history (one (n_active, n_state) array per output time)."""
        start = _time.perf_counter()
        states, rows, idx, steps = batch.states, batch.rows, batch.cell_ids, batch.steps
        n = states.shape[0]
        part = self._partition(n, idx, transport)
        shared = batch.shared()
        threads = numba_thread_table(self.client)
        layout = np.concatenate([np.r_[len(c), c] for c in part.chunks])
        extra = json.dumps({"method": batch.plan.method.name, "rtol": shared["rtol"],
                            "atol": shared["atol"], "max_steps": shared["max_steps"],
                            "transport": transport is not None})
        arrs = [states, rows, shared["aux"], shared["params"], shared["config"], times, idx,
                steps, layout]
        if transport is not None:
            g = transport.generator
            arrs += [g.data, g.indices, g.indptr, np.array([transport.split_step,
                     transport.dt_max, float(transport.splitting == "strang")])]
        fp = fingerprint(*arrs, extra=extra)
        if self.store_dir is not None:
            self.store = ChunkStore(self.store_dir).open(
                fp, {"chunks": part.n_chunks, "partition": part.kind,
                     "labels": part.labels, "active_cells": int(n),
                     "times_s": [float(t) for t in times], **self.meta}, self.resume)
        self._report = {"chunks": part.n_chunks, "partition": part.kind,
                        "workers": len(threads),
                        "numba_threads_per_task": sorted(set(threads.values())),
                        "store": str(self.store.path) if self.store else None,
                        "resumed": bool(self.resume)}
        if transport is None:
            history = self._run_independent(part, batch, times, shared, threads, progress)
        else:
            history = self._run_transport(part, batch, times, transport, shared, threads,
                                          progress)
        self._report["wall_s"] = _time.perf_counter() - start
        return history

    def report(self) -> dict:
        """What the cluster did: chunks, workers, threads, chunks computed and reused, wall
        and compute times [s], and for transport the data moved per split step [bytes]."""
        return dict(self._report)

    def close(self):
        """Close the client and the LocalCluster this executor started."""
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()

    def finish(self):
        """Remove the chunk store; call after the output directory was written."""
        if self.store is not None:
            self.store.remove()

    def mirror_to_processors(self, written, overwrite: bool = False) -> list:
        """For a decomposed case: copy fields written into the case root (paths
        ``CASE/<time>/<name>``, as ``couple._write_foam`` returns them) into every
        ``processorN/<time>/<name>`` with the processor's local cells (cellProcAddressing),
        same dimensions. Returns the files written ([] for an undecomposed case)."""
        written = [p for p in written or ()       # a decomposed time was written per processor
                   if self.case_dir is not None
                   and Path(p).parent.parent.resolve() == Path(self.case_dir).resolve()]
        if self.decomposition is None or self.case_dir is None or not written:
            return []
        from foamlib import FoamFieldFile

        by_time: dict = {}
        for path in written:
            path = Path(path)
            ff = FoamFieldFile(path)
            values = np.asarray(ff.internal_field, dtype=float)
            dims = ff.dimensions
            if not isinstance(dims, str):
                dims = "[" + " ".join(f"{float(x):g}" for x in np.asarray(dims).ravel()) + "]"
            fields, units = by_time.setdefault(path.parent.name, ({}, {}))
            fields[path.name] = values
            units[path.name] = dims
        out = []
        for tname, (fields, units) in by_time.items():
            out += write_processor_fields(self.case_dir, self.decomposition, tname, fields,
                                          dimensions=units, overwrite=overwrite)
        return out

    # -- pieces ------------------------------------------------------------------------
    def _partition(self, n, idx, transport=None) -> Partition:
        if isinstance(self.chunks, Partition):
            return self.chunks
        if self.decomposition is not None and self.chunks is None:
            n_cells = sum(len(a) for a in self.decomposition)
            return processor_partition(self.decomposition, np.asarray(idx), n_cells)
        k = self.chunks
        n_workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        if transport is not None:
            # blocks of the flux graph, one per worker unless --chunks says otherwise
            from ...transport.halo import level_partition
            labels = level_partition(transport.generator, int(k or n_workers))
            blocks = [np.flatnonzero(labels == b) for b in range(int(labels.max()) + 1)]
            return Partition(chunks=blocks, labels=[f"block {b}" for b in range(len(blocks))],
                             kind="flux graph")
        if k is None:
            k = 4 * n_workers
        return block_partition(n, int(k))

    def _run_independent(self, part, batch, times, shared, threads, progress):
        from distributed import as_completed

        states, rows = batch.states, batch.rows
        steps, stats, status, reached = (batch.steps, batch.stats_counts, batch.status,
                                         batch.reached)
        n_t = len(times)
        # the history goes to disk as the chunks arrive: one memory map per output time
        history = ChunkedSpool()
        for _ in range(n_t):
            history.reserve(states.shape)
        fail_interval = np.full(states.shape[0], -1, dtype=np.int64)
        done = self.store.finished_chunks() if (self.store and self.resume) else set()
        done &= set(range(part.n_chunks))
        total = states.shape[0]
        cells_done = 0

        def accept(k, res):
            nonlocal cells_done
            pos = part.chunks[k]
            for j in range(n_t):
                history.fill(j, pos, res["history"][j])
            steps[pos] = res["steps"]
            stats[pos] += res["stats"]
            status[pos] = res["status"]
            reached[pos] = res["reached"]
            fail_interval[pos] = res["fail_interval"]
            cells_done += pos.size

        for k in sorted(done):
            accept(k, self.store.load_chunk(k))
        futures = {}
        shared_f = self.client.submit(_identity, shared, pure=False)
        for k, pos in enumerate(part.chunks):
            if k in done:
                continue
            fut = self.client.submit(chunk_history, k, states[pos], rows[pos], steps[pos],
                                     shared_f, np.asarray(times), threads, self.fault,
                                     pure=False, key=f"pbe-chunk-{k:05d}-{os.urandom(4).hex()}")
            futures[fut] = k
        failed, compute = {}, []
        if progress is not None:
            progress(cells_done / total, f"{len(done)} chunk(s) from the store")
        for fut in as_completed(list(futures)):
            k = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - any task failure is reported per chunk
                failed[k] = f"{type(exc).__name__}: {exc}"
            else:
                if self.store is not None:
                    self.store.save_chunk(k, res)
                accept(k, res)
                compute.append(float(res["compute_s"]))
            fut.release()
            if progress is not None:
                progress(cells_done / total,
                         f"chunk {len(compute) + len(done)}/{part.n_chunks}"
                         + (f", {len(failed)} failed" if failed else ""))
        shared_f.release()
        self._report.update({
            "computed_chunks": sorted(set(futures.values()) - set(failed)),
            "reused_chunks": sorted(done), "failed_chunks": sorted(failed),
            "task_compute_s": {"sum": float(sum(compute)),
                               "median": float(statistics.median(compute)) if compute else 0.0,
                               "max": float(max(compute)) if compute else 0.0}})
        if failed:
            raise self._failure(failed, part)
        states[...] = history[-1]
        bad = fail_interval >= 0
        if bad.any():
            first = int(fail_interval[bad].min())
            batch.raise_if_failed(failed=np.flatnonzero(fail_interval == first))
        return history

    def _run_transport(self, part, batch, times, transport, shared, threads, progress):
        from .halo_run import run_on_workers
        return run_on_workers(self, part, batch, times, transport, shared, threads, progress)

    def _failure(self, failed: dict, part: Partition, at=None) -> ChunksFailed:
        names = ", ".join(f"{k} ({part.labels[k]}: {why})" for k, why in sorted(failed.items()))
        where = f" in the source step {at[0]:.6g}-{at[1]:.6g} s" if at else ""
        if self.store is not None:
            out = self.meta.get("out") or str(self.store.path)[:-len(STORE_SUFFIX)]
            kept = ("the finished chunks are stored" if at is None else
                    "the states of every finished output time are stored")
            hint = (f"; {kept} in {self.store.path}; `pbe-cfd couple --resume {out}` "
                    "computes only what is missing")
        else:
            hint = "; no chunk store was given, nothing was kept"
        msg = (f"{len(failed)} of {part.n_chunks} chunk(s) failed{where}: {names}{hint}")
        return ChunksFailed(msg, failed, self.store.path if self.store else None)
