"""Where a large transport run's memory and time go, measured apart from the outputs: the
setup of the 3-D bed (``case make --3d``) stage by stage (peak resident memory [MiB] after
each, and the bytes per cell of the arrays), and the solve phase of the bed under halo
variants (serial; blocks x substeps per halo exchange on a local 2-worker cluster) in one
process. Numbers are measured, never asserted; state the machine's load with them.

python -c "from pbe_cfd.bench.cluster_memory import setup_memory; print(setup_memory(100_000))"
python -c "from pbe_cfd.bench.cluster_memory import halo_variants; halo_variants(20_000, 0.5)"
(a script that starts a cluster must run under ``if __name__ == '__main__'``).
"""
from __future__ import annotations

import dataclasses
import json
import resource
import tempfile
import time
from pathlib import Path

import numpy as np


def _bed_scene(n_cells, end_time, interval, directory):
    from ..io.openfoam.bed3d import VTU_NAME, write_bed
    from ..scene.scene import load_scene
    d = Path(directory) / f"bed{n_cells}"
    if not (d / VTU_NAME).exists():
        d.mkdir(parents=True, exist_ok=True)
        write_bed(d, n_cells)
    scene = load_scene("fluid-bed-transport")
    return dataclasses.replace(scene, end_time=end_time, output_interval=interval,
                               domain=dataclasses.replace(scene.domain, case=str(d / VTU_NAME)))


def setup_memory(n_cells: int, directory=None, log=print) -> dict:
    """Peak resident memory [MiB] after each setup stage of a serial run with transport (60 s,
    13 output times) on the n_cells bed, and the bytes of its arrays per active or mesh cell
    [bytes]; the seconds of one transport part [s]."""
    from ..runs.batch import CellBatch
    from ..runs.domain import load_domain
    from ..runs.problem import problem_of
    from ..transport.operator import build_transport

    t0, stages = time.perf_counter(), {}

    def stage(name):
        stages[name] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        log(f"{time.perf_counter() - t0:7.1f} s  {name}: peak {stages[name]:.0f} MiB")

    with tempfile.TemporaryDirectory(prefix="pbe-bench-memory-") as tmp:
        scene = _bed_scene(n_cells, 60.0, 5.0, directory or tmp)
        stage("bed written")
        dom = load_domain(scene, need_flux=True)
        stage("domain loaded")
        prob = problem_of(scene, dom)
        batch = CellBatch.for_problem(prob)
        stage("problem and batch")
        tr = build_transport(prob.transport, dom, prob.active, prob.mesh_rows,
                             arrays=prob.arrays, aux=prob.aux)
        stage("transport built")
        k, _ = tr.substeps(0.5 * tr.split_step)
        start = time.perf_counter()
        tr.transport(batch.states.copy(), 0.5 * tr.split_step)
        part_s = time.perf_counter() - start
    g, n_act, n_mesh = tr.generator, batch.states.shape[0], dom.cells.n_cells
    work = (batch.steps.nbytes + batch.stats_counts.nbytes + batch.status.nbytes
            + batch.reached.nbytes)
    return {"mesh_cells": int(n_mesh), "active_cells": int(n_act),
            "peak_mib_after": stages, "states_B_per_active": batch.states.nbytes / n_act,
            "rows_B_per_active": batch.rows.nbytes / n_act, "work_B_per_active": work / n_act,
            "generator_B_per_active": (g.data.nbytes + g.indices.nbytes + g.indptr.nbytes)
            / n_act,
            "flux_B_per_mesh": sum(np.asarray(getattr(dom.flux, a)).nbytes
                                   for a in ("owner", "neighbour", "flux")) / n_mesh,
            "substeps_per_part": int(k), "transport_part_s": part_s,
            "correction_l1_rel": tr.flux_stats["correction_l1_rel"],
            "divergence_after_rel": tr.flux_stats["divergence_after_rel"]}


def halo_variants(n_cells: int, end_time: float, variants=("serial", (2, None), (2, 1),
                  (2, 4), (4, None)), repeats: int = 2, directory=None, log=print) -> list:
    """The solve phase (``executor.run``, no outputs) of the bed with transport for each
    variant: "serial", or (blocks, substeps per halo exchange or None) on one local cluster
    of 2 workers; ``repeats`` rounds (the first loads the workers' kernels). Per run: wall
    [s], cell-steps/s, bitwise equal to the first serial run, halo cells, block compute [s],
    the client's bytes per split step."""
    from ..runs import distributed as D
    from ..runs.air import coupled_air
    from ..runs.batch import CellBatch
    from ..runs.domain import load_domain
    from ..runs.executor import SerialExecutor
    from ..runs.problem import problem_of
    from ..transport.operator import build_transport

    out, ref = [], None
    with tempfile.TemporaryDirectory(prefix="pbe-bench-halo-") as tmp:
        scene = _bed_scene(n_cells, end_time, end_time / 2, directory or tmp)
        dom = load_domain(scene, need_flux=True)
        prob = problem_of(scene, dom)
        client, cluster = D.start_local_cluster(2)
        try:
            for v in list(variants) * repeats:
                batch = CellBatch.for_problem(prob)
                batch.air = coupled_air(prob.air, prob.arrays, None)
                tr = build_transport(prob.transport, dom, prob.active, prob.mesh_rows,
                                     arrays=prob.arrays, aux=prob.aux)
                batch.compile()
                tr.compile(batch.states.shape[1])
                ex = SerialExecutor() if v == "serial" else D.ClusterExecutor(
                    client=client, chunks=v[0], halo_substeps=v[1])
                start = time.perf_counter()
                hist = ex.run(batch, prob.times, tr)
                wall = time.perf_counter() - start
                last = np.array(hist[-1])
                ref = last if ref is None else ref
                rep = (ex.report() or {}).get("transport", {})
                row = {"variant": v, "wall_s": wall,
                       "cell_steps_per_s": batch.stats()["accepted_steps"] / wall,
                       "same_as_serial": bool(np.array_equal(last, ref)),
                       "halo_cells": rep.get("halo_cells"),
                       "block_compute_s": rep.get("block_compute_s"),
                       "client_B_per_split_step": rep.get("client_sent_bytes_per_split_step")}
                log(json.dumps(row))
                out.append(row)
        finally:
            client.close()
            cluster.close()
    return out
