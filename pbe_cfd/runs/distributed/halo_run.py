"""A transport run with the states kept on the workers (``ClusterExecutor`` with transport).

Each block of cells (``Partition``: the processor decomposition, or a partition of the flux
graph) lives on one worker as a state dict (``halo_tasks.BLOCK_ARRAYS``). Per transport part
each block reads, worker to worker through Dask's dependency transfer, only the states of its
halo (the cells within k upwind hops in other blocks, k the substeps of that part), advances
its own cells through the k substeps (``transport.halo``) and re-projects unrealizable
mixtures; per source part it integrates its own cells. The client submits the task graph of a
whole output interval at once (control messages only: keys, times, substep counts) and gathers
the states once per output time, for the outputs and the checkpoint in the chunk store.

Results are bitwise the serial run's: the local rows of the step matrix keep the global rows'
entries in order, the re-projection and the sources are per cell.

A worker lost during an interval is found by polling the scheduler's worker list while the
interval runs: the run stops naming the blocks and the worker, the last stored output time is
in the chunk store, and ``--resume`` continues from there.
"""
from __future__ import annotations

import math
import statistics
import time as _time

import numpy as np

from ..batch import SimulationError
from .balance import REBALANCE_ABOVE, cell_costs, rebalanced, rhs_calls
from .halo_tasks import BLOCK_ARRAYS, BlockFailed, block_source, block_state, block_transport, \
    halo_take

#: Seconds between checks of the worker list while an output interval runs.
POLL_S = 1.0


def _interval_parts(transport, t0: float, t1: float) -> list:
    """The parts of ``Transport.advance`` from t0 to t1 [s], in order: ("T", duration [s])
    and ("S", ta [s], tb [s]); the serial operator's own plan."""
    return transport.plan(t0, t1)


def _substeps(transport, duration):
    """(k, dt [s]) of one transport part, k = 0 where nothing moves."""
    if duration <= 0.0 or transport.n == 0:
        return 0, duration
    k, dt = transport.substeps(duration)
    if not (math.isfinite(transport.dt_max) and transport.out_rate.size):
        k = 0
    return k, dt


def _client_sent(client) -> int:
    """Bytes the client has sent to the scheduler on its batched stream [bytes]."""
    comm = getattr(client, "scheduler_comm", None)
    return int(getattr(comm, "byte_count", 0) or 0)


class HaloRun:
    """One transport run of a ClusterExecutor ``ex`` over Partition ``part`` (see module)."""

    def __init__(self, ex, part, batch, times, transport, shared, threads):
        self.ex, self.part, self.batch, self.times = ex, part, batch, np.asarray(times)
        self.tr, self.shared, self.threads = transport, shared, threads
        self.client = ex.client
        durations = [p[1] for k in range(1, len(times))
                     for p in _interval_parts(transport, times[k - 1], times[k]) if p[0] == "T"]
        self.depth = max([_substeps(transport, d)[0] for d in durations] or [0])
        per = getattr(ex, "halo_substeps", None)
        self.exchange = max(1, self.depth if per is None else min(int(per), self.depth))
        workers = sorted(self.client.scheduler_info().get("workers", {}))
        if not workers:
            raise SimulationError("the Dask cluster has no workers")
        self.workers = workers
        self.moved = {"client_sent": [], "gathered": [], "interval_wall": [],
                      "split_steps": [], "block_source_s": [], "block_transport_s": [],
                      "rebalanced": [], "place_s": []}
        self._layout(part)

    def _layout(self, part):
        """The blocks of Partition ``part``: labels, operators, cut and workers."""
        from ...transport.halo import block_operators, cut_faces

        self.part = part
        self.labels = np.empty(self.batch.states.shape[0], dtype=np.int64)
        for b, pos in enumerate(part.chunks):
            self.labels[pos] = b
        self.ops = block_operators(self.tr.generator, self.labels, self.exchange)
        self.cut = cut_faces(self.tr.generator, self.labels)
        self.where = {b: self.workers[b % len(self.workers)] for b in range(part.n_chunks)}
        self._spent = np.zeros((part.n_chunks, 2))

    def repartition(self, part):
        """Move the run onto Partition ``part``: drop the blocks on the workers and place the
        new ones from the batch's arrays (the states of the last output time)."""
        start = _time.perf_counter()
        self.release()
        self._layout(part)
        self.moved["rebalanced"][-1]["layout_s"] = round(_time.perf_counter() - start, 4)
        self.place()

    # -- placement --------------------------------------------------------------------
    def _put(self, value, b):
        return self.client.scatter([value], workers=[self.where[b]], hash=False)[0]

    def _submit(self, fn, *args, b):
        return self.client.submit(fn, *args, workers=[self.where[b]],
                                  allow_other_workers=False, pure=False)

    def place(self):
        """Send each block its operator, cell rows, method data and state (once per
        partition)."""
        start = _time.perf_counter()
        self._place()
        self.moved["place_s"].append(round(_time.perf_counter() - start, 4))

    def _place(self):
        b_ = self.batch
        self.shared_f = {w: self.client.scatter([self.shared], workers=[w], hash=False)[0]
                         for w in sorted(set(self.where.values()))}
        self.op_f, self.rows_f, self.idx_f, self.block_f = [], [], {}, []
        for b, (op, pos) in enumerate(zip(self.ops, self.part.chunks)):
            order = sorted(op.sources)
            self.op_f.append(self._put({"m": op.ext.size, "own_in_ext": op.own_in_ext,
                                        "data": op.data, "indices": op.indices,
                                        "indptr": op.indptr,
                                        "piece_pos": [op.sources[a][1] for a in order]}, b))
            cells = b_.cell_ids[pos] if b_.cell_ids is not None else pos
            self.rows_f.append(self._put({"rows": np.ascontiguousarray(b_.rows[pos]),
                                          "cells": np.asarray(cells)}, b))
            for a in order:
                self.idx_f[(a, b)] = self._put(op.sources[a][0], a)
            self.block_f.append(self._put(block_state(
                b_.states[pos], b_.steps[pos], b_.stats_counts[pos], b_.status[pos],
                b_.reached[pos], b_.smoothed[pos]), b))

    # -- one output interval ------------------------------------------------------------
    def _transport_part(self, duration):
        tr = self.tr
        k, dt = _substeps(tr, duration)
        c = tr._count
        if k > 0:
            c["max_courant_used"] = max(c["max_courant_used"], dt * float(tr.out_rate.max()))
        c["substeps"] += k
        c["transport_calls"] += 1
        rounds = [self.exchange] * (k // self.exchange) + (
            [k % self.exchange] if k % self.exchange else [])
        for r, k_r in enumerate(rounds or [0]):
            last = r == max(0, len(rounds) - 1)
            new = []
            for b, op in enumerate(self.ops):
                pieces = [self._submit(halo_take, self.block_f[a], self.idx_f[(a, b)], b=a)
                          for a in sorted(op.sources)] if k_r > 0 else []
                new.append(self._submit(block_transport, self.block_f[b], self.op_f[b],
                                        pieces, float(dt), int(k_r),
                                        last and tr.repair is not None,
                                        self.shared_f[self.where[b]], b=b))
            self.block_f = new

    def _source_part(self, ta, tb):
        self.block_f = [self._submit(block_source, self.block_f[b], self.rows_f[b],
                                     self.shared_f[self.where[b]], float(ta), float(tb),
                                     self.threads, self.ex.fault, b, b=b)
                        for b in range(len(self.ops))]

    def interval(self, t0, t1) -> dict:
        """Submit the interval t0..t1 [s], wait for it (watching for lost workers) and gather
        the blocks' states. Returns the gathered block dicts."""
        start, sent0 = _time.perf_counter(), _client_sent(self.client)
        parts = _interval_parts(self.tr, t0, t1)
        for p in parts:
            if p[0] == "T":
                self._transport_part(p[1])
            else:
                self._source_part(p[1], p[2])
                self.tr._count["split_steps"] += 1
        n_split = sum(p[0] == "S" for p in parts)
        self._wait(t0, t1)
        sent = _client_sent(self.client) - sent0
        blocks = self.client.gather(self.block_f)
        self.moved["client_sent"].append(sent / max(1, n_split))
        self.moved["gathered"].append(sum(blk[a].nbytes for blk in blocks
                                          for a in BLOCK_ARRAYS))
        self.moved["interval_wall"].append(_time.perf_counter() - start)
        self.moved["block_compute_s"] = [float(blk["compute_s"]) for blk in blocks]
        spent = np.array([[float(blk["source_s"]), float(blk["transport_s"])]
                          for blk in blocks])
        step = spent - self._spent
        self._spent = spent
        self.moved["block_source_s"].append([round(x, 4) for x in step[:, 0]])
        self.moved["block_transport_s"].append([round(x, 4) for x in step[:, 1]])
        self.moved["split_steps"].append(n_split)
        return blocks

    def _wait(self, t0, t1):
        from distributed import wait

        while not self._lost():
            try:
                wait(self.block_f, timeout=POLL_S)
                break
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 - cancelled: a worker took data down with it
                break
        lost = self._lost()
        deadline = _time.perf_counter() + 10.0
        while (not lost and any(f.status == "cancelled" for f in self.block_f)
               and _time.perf_counter() < deadline):
            _time.sleep(0.2)                 # the scheduler is removing the lost worker
            lost = self._lost()
        if lost:
            self.client.cancel(self.block_f)
            raise self.ex._failure({b: f"KilledWorker: worker {self.where[b]} lost"
                                    for b in lost}, self.part, at=(t0, t1))
        failed = {}
        for b, f in enumerate(self.block_f):
            if f.status == "cancelled":
                failed[b] = (f"KilledWorker: the states of block {b} were lost with a worker "
                             f"(it ran on {self.where[b]})")
            elif f.status == "error":
                exc = f.exception()
                if isinstance(exc, BlockFailed) and exc.stopped:
                    raise SimulationError(f"{self.batch.source}: "
                                          f"{exc.reason} (block {exc.block})")
                blk = exc.block if isinstance(exc, BlockFailed) else b
                failed[blk] = str(exc) if isinstance(exc, BlockFailed) else \
                    f"{type(exc).__name__}: {exc}"
        if failed:
            raise self.ex._failure(failed, self.part, at=(t0, t1))

    def _lost(self) -> list:
        alive = set(self.client.scheduler_info().get("workers", {}))
        return [b for b, w in self.where.items() if w not in alive]

    def release(self):
        """Drop every future this run holds on the workers."""
        for fs in (self.block_f, self.op_f, self.rows_f, list(self.idx_f.values()),
                   list(getattr(self, "shared_f", {}).values())):
            for f in fs:
                f.release()

    def report(self, k0: int) -> dict:
        """What moved: client bytes per split step, gathered bytes per output time, halos."""
        med = (lambda xs: float(statistics.median(xs)) if xs else 0.0)
        halo = [op.halo_cells for op in self.ops]
        n_state = self.batch.states.shape[1]
        return {"mode": "states on the workers, halo exchange worker to worker",
                "resumed_from_output": int(k0), "blocks": len(self.ops),
                "partition": self.part.kind, "cut_generator_entries": int(self.cut),
                "substeps_per_part": int(self.depth),
                "halo_depth_substeps": int(self.exchange), "halo_cells": halo,
                "block_cells": [int(op.owned.size) for op in self.ops],
                "block_compute_s": self.moved.get("block_compute_s", []),
                "block_source_s_per_interval": self.moved["block_source_s"],
                "block_transport_s_per_interval": self.moved["block_transport_s"],
                "rebalanced": self.moved["rebalanced"],
                "halo_bytes_per_transport_part": int(sum(halo) * n_state * 8),
                "client_sent_bytes_per_split_step": med(self.moved["client_sent"]),
                "gathered_bytes_per_output_time": med(self.moved["gathered"]),
                "interval_wall_s_median": med(self.moved["interval_wall"]),
                "interval_wall_s": [round(x, 4) for x in self.moved["interval_wall"]],
                "place_s": self.moved["place_s"],
                "split_steps": int(sum(self.moved["split_steps"])),
                "workers_of_blocks": [self.where[b] for b in range(len(self.ops))],
                "note": "the client sends task messages only (keys, times, substeps); "
                        "halos move worker to worker; states come to the client once per "
                        "output time"}


def _rebalance(run, k, rhs) -> bool:
    """After output time k: re-partition ``run`` by the measured costs of the interval that
    ended there (``balance``), if its blocks are out of balance. True if it did."""
    from .partition import Partition

    src, trs = run.moved["block_source_s"][-1], run.moved["block_transport_s"][-1]
    weights = cell_costs(rhs, run.labels, src, trs)
    limit = run.ex.balance
    limit = REBALANCE_ABOVE if limit is True else float(limit)
    new, now, after = rebalanced(run.tr.generator, run.labels, weights, limit)
    run.moved["rebalanced"].append({"output": int(k), "predicted_before": round(now, 4),
                                    "predicted_after": round(after, 4),
                                    "moved": new is not None})
    if new is None:
        return False
    blocks = [np.flatnonzero(new == b) for b in range(int(new.max()) + 1)]
    run.repartition(Partition(chunks=blocks, labels=list(run.part.labels),
                              kind=run.part.kind))
    return True


def run_on_workers(ex, part, batch, times, transport, shared, threads, progress) -> list:
    """The transport run of ClusterExecutor ``ex`` with the states on the workers; returns
    the history (states at every output time) and updates ``batch`` like the serial run."""
    states, steps, stats, status, reached = (batch.states, batch.steps, batch.stats_counts,
                                             batch.status, batch.reached)
    from ...io.spool import Spool
    history, k0 = Spool(), 0
    history.append(states)
    store = ex.store
    if store is not None and ex.resume:
        stored = [k for k in store.stored_steps() if k < len(times)]
        k0 = max(stored, default=0)
        for k in stored:
            history.append(store.load_step(k)["states"])
        if k0 > 0:
            z = store.load_step(k0)
            for name, arr in (("states", states), ("steps", steps), ("stats", stats),
                              ("status", status), ("reached", reached)):
                arr[...] = z[name]
            if "smoothed" in z:
                batch.smoothed[...] = z["smoothed"]
            transport._count["repaired_cells"] = int(z.get("repaired", 0))
            transport._count["repair_max_rel_change"] = float(z.get("repair_max", 0.0))
    run = HaloRun(ex, part, batch, times, transport, shared, threads)
    base_repaired = transport._count["repaired_cells"]
    balance = ex.balance is not False and part.kind == "flux graph"
    try:
        run.place()
        for k in range(k0 + 1, len(times)):
            rhs_before = rhs_calls(stats) if balance else None
            blocks = run.interval(float(times[k - 1]), float(times[k]))
            part = run.part
            for pos, blk in zip(part.chunks, blocks):
                states[pos], steps[pos], stats[pos] = blk["states"], blk["steps"], blk["stats"]
                status[pos], reached[pos] = blk["status"], blk["reached"]
                batch.smoothed[pos] = blk["smoothed"]
            repaired = base_repaired + sum(int(b["repaired"]) for b in blocks)
            worst = max([transport._count["repair_max_rel_change"]]
                        + [float(b["repair_max"]) for b in blocks])
            transport._count["repaired_cells"] = repaired
            transport._count["repair_max_rel_change"] = worst
            history.append(states)
            if store is not None:
                store.save_step(k, {"states": states, "steps": steps, "stats": stats,
                                    "status": status, "reached": reached,
                                    "smoothed": batch.smoothed,
                                    "repaired": np.array(repaired),
                                    "repair_max": np.array(worst)})
            if progress is not None:
                progress(times[k] / times[-1], f"t = {times[k]:.4g} s ({part.n_chunks} "
                         "blocks on the workers)")
            if (balance and k < len(times) - 1
                    and _rebalance(run, k, rhs_calls(stats) - rhs_before)):
                base_repaired = repaired          # the new blocks count their repairs anew
    finally:
        ex._report["transport"] = run.report(k0)
        run.release()
    return history

