"""The cluster study: when does a Dask cluster pay off? Cell-steps per second of the serial
numba run and of local clusters on a synthetic mesh (the small case's cells replicated), Dask's
overhead per task, and the data a transport run moves per split step."""
from __future__ import annotations

import dataclasses
import math
import statistics
import time as _time

import numpy as np

from ..runs import model
from ..runs.batch import CellBatch, output_times
from ..runs.distributed import block_partition, host_cores, numba_thread_table, start_local_cluster
from ..runs.distributed.tasks import _identity, _noop, _set_threads, chunk_history
from ..runs.domain import build_cells, coupled_scales, initial_states, load_domain
from ..methods.registry import method_of
from ..physics import parameters as P
from ..scene.scene import load_scene
from .. import integrate


def synthetic_problem(n_cells: int, scene="fluid-bed", end_time: float = 2.0,
                      output_interval: float = 1.0):
    """A synthetic mesh of ``n_cells`` active cells: the small case's active cells (bundled
    snapshot) replicated. Returns dict(states, rows, steps, shared, times [s], cells_per_copy)."""
    sc = load_scene(scene) if isinstance(scene, str) else scene
    sc = dataclasses.replace(sc, end_time=end_time, output_interval=output_interval)
    domain = load_domain(sc)
    rows, active, _, _ = build_cells(sc, domain.cells)
    idx = np.flatnonzero(active)
    scaled = coupled_scales(sc, rows[idx, P.ALPHA])
    arrays = model.pack(scaled)
    aux = method_of(scaled).aux(scaled, arrays, None)
    st0 = initial_states(sc, arrays, rows[idx, P.ALPHA])
    reps = int(math.ceil(n_cells / idx.size))
    sel = np.tile(np.arange(idx.size), reps)[:n_cells]
    batch = CellBatch.for_scene(sc, arrays, aux, np.ascontiguousarray(rows[idx][sel]),
                                np.ascontiguousarray(st0[sel]))
    return {"states": batch.states, "rows": batch.rows, "steps": batch.steps,
            "shared": batch.shared(), "times": output_times(sc),
            "cells_per_copy": int(idx.size)}


def _serial(prob, threads):
    """(wall [s], accepted steps, final states) of the serial run of a synthetic problem."""
    _set_threads(threads)
    batch = CellBatch.of_chunk(prob["shared"], prob["rows"], prob["states"], prob["steps"])
    t0 = _time.perf_counter()
    times = prob["times"]
    for k in range(1, len(times)):
        batch.advance(times[k - 1], times[k])
    return _time.perf_counter() - t0, batch.stats()["accepted_steps"], batch.states


def _cluster_once(client, prob, n_chunks, threads):
    from distributed import wait

    n = prob["states"].shape[0]
    part = block_partition(n, n_chunks)
    t0 = _time.perf_counter()
    shared_f = client.submit(_identity, prob["shared"], pure=False)
    futs = [client.submit(chunk_history, k, prob["states"][pos], prob["rows"][pos],
                          prob["steps"][pos], shared_f, prob["times"], threads, None,
                          pure=False) for k, pos in enumerate(part.chunks)]
    wait(futs)
    res = client.gather(futs)
    wall = _time.perf_counter() - t0
    steps = sum(int(r["stats"][:, integrate.ACCEPTED].sum()) for r in res)
    compute = [float(r["compute_s"]) for r in res]
    final = np.empty_like(prob["states"])
    for pos, r in zip(part.chunks, res):
        final[pos] = r["history"][-1]
    return wall, steps, compute, final


def bench_cluster(n_cells: int = 100_000, workers=(1, 2), end_time: float = 2.0,
                  output_interval: float = 1.0, chunks_per_worker: int = 4,
                  repeats: int = 3, overhead_tasks: int = 200, scene="fluid-bed",
                  log=print) -> dict:
    """Benchmark the cluster path on a synthetic mesh of ``n_cells`` (small-case cells
    replicated): cell-steps per second [1/s] of the serial numba run (all cores) and of a
    LocalCluster of each ``workers`` count (chunks_per_worker blocks per worker), medians of
    ``repeats`` runs over ``end_time`` [s] of granulation; Dask's overhead per task [s]
    (round trip of one no-op task, and throughput of ``overhead_tasks`` no-op tasks); and
    the data moved per split step with transport [bytes]. Returns a dict (also logged)."""
    cores = host_cores()
    prob = synthetic_problem(n_cells, scene=scene, end_time=end_time,
                             output_interval=output_interval)
    out = {"n_cells": n_cells, "cores": cores, "end_time_s": end_time,
           "output_interval_s": output_interval, "repeats": repeats}
    # serial, after a warm-up on a few cells (numba cache load)
    small = {**prob, "states": prob["states"][:64].copy(), "rows": prob["rows"][:64].copy(),
             "steps": prob["steps"][:64].copy()}
    _serial(small, cores)
    walls, ref = [], None
    for _ in range(repeats):
        w, steps, final = _serial(prob, cores)
        walls.append(w)
        ref = final
    w = statistics.median(walls)
    out["serial"] = {"threads": cores, "wall_s": w, "wall_s_all": walls, "cell_steps": steps,
                     "cell_steps_per_s": steps / w,
                     "steps_per_cell_per_sim_s": steps / n_cells / end_time}
    log(f"serial numba ({cores} threads): {n_cells} cells, {steps} cell-steps, median "
        f"{w:.2f} s -> {steps / w:.3g} cell-steps/s")
    out["cluster"] = {}
    for nw in workers:
        client, cluster = start_local_cluster(nw)
        try:
            threads = numba_thread_table(client)
            # warm-up: every worker loads the numba cache
            _cluster_once(client, small, nw, threads)
            walls, comp = [], []
            for _ in range(repeats):
                w, st, compute, final = _cluster_once(client, prob, nw * chunks_per_worker,
                                                      threads)
                walls.append(w)
                comp.append(sum(compute))
                if not np.array_equal(final, ref):
                    raise AssertionError("cluster result differs from the serial run")
            w = statistics.median(walls)
            # Dask overhead: one no-op round trip, and no-op throughput
            lat = []
            for i in range(20):
                t = _time.perf_counter()
                client.submit(_noop, i, pure=False).result()
                lat.append(_time.perf_counter() - t)
            t = _time.perf_counter()
            client.gather(client.map(_noop, range(overhead_tasks), pure=False))
            thr = (_time.perf_counter() - t) / overhead_tasks
            n_chunks = nw * chunks_per_worker
            rate = st / w
            ideal = statistics.median(comp) / nw
            out["cluster"][nw] = {
                "workers": nw, "numba_threads_per_task": sorted(set(threads.values())),
                "chunks": n_chunks, "wall_s": w, "wall_s_all": walls, "cell_steps": st,
                "cell_steps_per_s": rate, "speedup_vs_serial": out["serial"]["wall_s"] / w,
                "task_compute_s_sum_median": statistics.median(comp),
                "overhead_s_per_chunk": max(0.0, (w - ideal)) / max(1, n_chunks / nw),
                "noop_round_trip_s_median": statistics.median(lat),
                "noop_task_s_throughput": thr, "identical_to_serial": True}
            log(f"{nw} worker(s) x {sorted(set(threads.values()))} numba threads, "
                f"{n_chunks} chunks: median {w:.2f} s -> {rate:.3g} cell-steps/s "
                f"(x{out['serial']['wall_s'] / w:.2f} of serial); no-op task round trip "
                f"{statistics.median(lat) * 1e3:.2f} ms, throughput {thr * 1e3:.2f} ms/task")
        finally:
            client.close()
            cluster.close()
    ns = prob["states"].shape[1]
    out["transport_bytes_per_split_step"] = int(2 * n_cells * (ns + 1) * 8
                                                + n_cells * (integrate.N_STATS + 2) * 8)
    return out


def estimate_wall_time(n_cells: float, sim_time: float, machines: int,
                       cell_steps_per_s_machine: float, steps_per_cell_per_sim_s: float,
                       overhead_s: float = 0.0) -> float:
    """Wall time [s] of ``n_cells`` cells over ``sim_time`` [s] of granulation on
    ``machines`` machines, each delivering ``cell_steps_per_s_machine`` [1/s], with
    ``steps_per_cell_per_sim_s`` accepted steps per cell per simulated s [1/s] (measured),
    plus a fixed ``overhead_s`` [s] (cluster start, data movement)."""
    return (n_cells * sim_time * steps_per_cell_per_sim_s
            / (machines * cell_steps_per_s_machine) + overhead_s)