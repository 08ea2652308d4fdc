"""``pbe-cfd bench cluster``: the 3-D bed (``case make --3d``) with and without ``[transport]``,
QMOM N = 2, serial, 1 and 2 workers; per run cell-steps/s, the client's bytes per split step,
the peak memory of the client and of each worker, and wall time. Each run is a child process
(its peak resident memory is its own). Numbers are measured, never asserted; the load of the
machine is recorded next to them. Ends with a model of the multi-machine case built from the
measured parts (``multi_machine_model``)."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from .common import machine_info

#: Network rate assumed between machines for the model [bytes/s] (ours: 1 Gbit/s Ethernet).
NETWORK_BYTES_PER_S = 125e6
#: Latency of one Dask task hop assumed between machines [s] (ours: the measured local no-op
#: round trip is of this order; a LAN adds well under a millisecond).
TASK_HOP_S = 0.01
#: Latency of one neighbour exchange by message passing assumed between machines [s] (ours:
#: an order of magnitude for MPI over Ethernet; no such exchange is built here).
MESSAGE_LATENCY_S = 5e-5


def _child(spec: dict) -> dict:
    """One run (in a child process): spec {vtu, end_time [s], interval [s], transport,
    workers (0: serial), balance (re-partition by measured cost, default True)}. Returns the
    measured numbers."""
    import dataclasses
    import resource
    import time

    import numpy as np

    from ..runs.couple import run_coupled
    from ..runs.domain import load_domain
    from ..scene.scene import load_scene

    scene = load_scene("fluid-bed-transport")
    scene = dataclasses.replace(scene, end_time=spec["end_time"],
                                output_interval=spec["interval"],
                                domain=dataclasses.replace(scene.domain, case=spec["vtu"]))
    if not spec["transport"]:
        scene = dataclasses.replace(scene, transport=None)
    domain = load_domain(scene, need_flux=spec["transport"])
    executor, client, cluster = None, None, None
    if spec["workers"]:
        from ..runs import distributed as D
        client, cluster = D.start_local_cluster(spec["workers"])
        chunks = spec.get("blocks") or spec["workers"] if spec["transport"] else None
        halo, balance = spec.get("halo_substeps"), spec.get("balance", True)
        # warm-up: every worker loads the numba kernels (from the cache) before the timing,
        # on the bundled small case (the same kernels, a fraction of the setup)
        warm = dataclasses.replace(load_scene("fluid-bed-transport"), end_time=0.1,
                                   output_interval=0.1)
        if not spec["transport"]:
            warm = dataclasses.replace(warm, transport=None)
        run_coupled(warm, load_domain(warm, need_flux=spec["transport"]),
                    executor=D.ClusterExecutor(client=client, chunks=chunks,
                                               halo_substeps=halo))
        executor = D.ClusterExecutor(client=client, chunks=chunks, halo_substeps=halo,
                                     balance=balance)
    t0 = time.perf_counter()
    try:
        res = run_coupled(scene, domain, executor=executor)
        wall = time.perf_counter() - t0
        workers_mem = {}
        if client is not None:
            from ..runs.distributed.halo_tasks import worker_memory
            workers_mem = client.run(worker_memory)
    finally:
        if client is not None:
            client.close()
            cluster.close()
    cl = res.stats.get("cluster", {})
    tr = cl.get("transport", {})
    final = np.ascontiguousarray(res.cell_fields[-1]["M00"]) if "M00" in res.cell_fields[-1] \
        else np.zeros(0)
    import hashlib
    return {"cells": int(res.stats["cells"]), "active_cells": int(res.stats["active_cells"]),
            "accepted_steps": int(res.stats["accepted_steps"]),
            "solve_wall_s": float(res.wall_time_s), "process_wall_s": wall,
            "cell_steps_per_s": float(res.stats["cell_steps_per_second"]),
            "client_peak_rss": int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024),
            "worker_peak_rss": sorted(int(v["peak_rss"]) for v in workers_mem.values()),
            "client_sent_bytes_per_split_step": tr.get("client_sent_bytes_per_split_step"),
            "gathered_bytes_per_output_time": tr.get("gathered_bytes_per_output_time"),
            "halo_cells": tr.get("halo_cells"), "halo_depth": tr.get("halo_depth_substeps"),
            "substeps_per_part": tr.get("substeps_per_part"),
            "block_compute_s": tr.get("block_compute_s"),
            "block_source_s_per_interval": tr.get("block_source_s_per_interval"),
            "block_transport_s_per_interval": tr.get("block_transport_s_per_interval"),
            "interval_wall_s": tr.get("interval_wall_s"), "place_s": tr.get("place_s"),
            "block_cells": tr.get("block_cells"), "rebalanced": tr.get("rebalanced"),
            "phases": {k: float(v) for k, v in res.phases.items()},
            "transport_wall_s": res.stats.get("transport", {}).get("transport_wall_s"),
            "source_wall_s": res.stats.get("transport", {}).get("source_wall_s"),
            "halo_bytes_per_transport_part": tr.get("halo_bytes_per_transport_part"),
            "substeps_per_split_step": res.stats.get("transport", {}).get(
                "substeps_per_split_step"),
            "final_hash": hashlib.sha256(json.dumps(
                {k: np.asarray(v).tolist() for k, v in res.bed_columns.items()}).encode()
                                         ).hexdigest()[:16],
            "m00_final_sum": float(final.sum())}


def _run_child(spec: dict, log) -> dict:
    env = dict(os.environ)
    code = ("import json,sys; from pbe_cfd.bench.cluster_3d import _child; "
            "print('RESULT ' + json.dumps(_child(json.loads(sys.argv[1]))))")
    r = subprocess.run([sys.executable, "-c", code, json.dumps(spec)], capture_output=True,
                       text=True, env=env)
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]
    if r.returncode != 0 or not line:
        tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"bench cluster run {spec} failed: {tail}")
    out = json.loads(line[0][len("RESULT "):])
    log(f"  {'transport' if spec['transport'] else 'no transport'}, "
        f"{spec['workers'] or 'serial'}{' worker(s)' if spec['workers'] else ''}"
        f"{'' if spec.get('balance', True) else ' (equal cells)'}: "
        f"{out['accepted_steps']} cell-steps in {out['solve_wall_s']:.1f} s -> "
        f"{out['cell_steps_per_s']:.3g} cell-steps/s; client peak "
        f"{out['client_peak_rss'] / 2**20:.0f} MiB"
        + (f", workers {[round(m / 2**20) for m in out['worker_peak_rss']]} MiB"
           if out["worker_peak_rss"] else "")
        + (f"; client sent {out['client_sent_bytes_per_split_step']:.0f} B per split step"
           if out["client_sent_bytes_per_split_step"] else ""))
    return out


def cluster_study(out_dir, quick: bool = False, cells=None, end_time=None, log=print,
                  transports=(True, False), workers_list=(0, 1, 2), outputs: int = 2,
                  balances=(True,)) -> dict:
    """The study (see the module docstring). ``cells``: list of bed sizes (default 1e5;
    quick 2000); ``end_time`` [s] of process per run (default 2 s, quick 0.5 s: the 60 s the
    issue names does not fit a shared 2-core machine; the rates are per cell-step);
    ``outputs`` output intervals per run; ``transports`` and ``workers_list`` (0: serial)
    the runs made; ``balances``: with transport on 2 or more workers, one run per entry
    (True: re-partitioned by the measured cost after the first output time; False: blocks
    of equal cells). Runs of one bed are made back to back. Writes cluster.json,
    cluster.csv and cluster.md into ``out_dir``."""
    from ..io.openfoam.bed3d import VTU_NAME, write_bed

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cells = cells or ([2000] if quick else [100_000])
    end_time = float(end_time or (0.5 if quick else 2.0))
    res = {"machine": machine_info(), "end_time_s": end_time, "outputs": int(outputs),
           "runs": []}
    with tempfile.TemporaryDirectory(prefix="pbe-bench-cluster-") as tmp:
        for n in cells:
            bed = Path(tmp) / f"bed{n}"
            bed.mkdir()
            info = write_bed(bed, n)
            log(f"bed of {info['cells']} cells ({info['grid']})")
            for transport in transports:
                for workers, balance in ((w, b) for w in workers_list
                                         for b in (balances if transport and w > 1
                                                   else (True,))):
                    spec = {"vtu": str(bed / VTU_NAME), "end_time": end_time,
                            "interval": end_time / int(outputs), "transport": transport,
                            "workers": workers, "balance": bool(balance)}
                    r = _run_child(spec, log)
                    res["runs"].append({**spec, **r, "bed_cells": info["cells"],
                                        "grid": info["grid"]})
    res["machine_after"] = machine_info()
    res["model"] = multi_machine_model(res["runs"])
    (out_dir / "cluster.json").write_text(json.dumps(res, indent=1))
    _write_csv(out_dir / "cluster.csv", res["runs"])
    (out_dir / "cluster.md").write_text(cluster_markdown(res))
    return res


def _write_csv(path, runs):
    cols = ["bed_cells", "active_cells", "transport", "workers", "accepted_steps",
            "solve_wall_s", "cell_steps_per_s", "client_peak_rss", "worker_peak_rss",
            "client_sent_bytes_per_split_step", "gathered_bytes_per_output_time",
            "halo_depth", "halo_cells", "final_hash"]
    lines = [",".join(cols)]
    for r in runs:
        lines.append(",".join(json.dumps(r.get(c)).replace(",", ";") for c in cols))
    Path(path).write_text("\n".join(lines) + "\n")


def multi_machine_model(runs, n_cells=1e7, sim_time=1800.0, split_step=0.25,
                        network=NETWORK_BYTES_PER_S, hop=TASK_HOP_S,
                        per_exchange=None) -> dict:
    """Machines for ``n_cells`` over ``sim_time`` [s] of process to finish in an hour, from
    the largest measured transport runs: the serial rate per machine [cell-steps/s], the
    accepted steps per cell per process second, the halo (cells, depth in substeps) per block
    boundary scaled to the bed of ``n_cells`` (section ~ n^(2/3), substeps ~ 1/cell size),
    ``network`` [bytes/s] and ``hop`` [s] per dependent task hop (4 per split step: two
    transport parts, each a halo hop and a block task, per exchange round). ``per_exchange``:
    substeps per halo exchange (None: one exchange per transport part); the bytes are the
    same either way (k layers of the cut per part), the rounds, and so the hops, are
    k / per_exchange. Where the serial run timed its sources and its transport apart, the
    sources scale with the cells and divide between the machines, the transport scales with
    the cells times the substeps and does not divide (each block advances its extended set,
    the whole bed at these depths). ``one_layer``: the same batch with a one-layer halo
    exchanged at every substep (``one_layer_model``). An estimate, not a measurement."""
    tr = [r for r in runs if r["transport"]]
    if not tr:
        return {}
    n_meas = max(r["active_cells"] for r in tr)
    ser = [r for r in tr if r["workers"] == 0 and r["active_cells"] == n_meas]
    two = [r for r in tr if r["workers"] == 2 and r["active_cells"] == n_meas
           and r.get("balance", True)]
    if not ser or not two:
        return {}   # the model needs the serial and the 2-worker run of one bed
    ser, two = ser[0], two[0]
    rate = _solve_rate(ser)
    steps_per_cell_s = ser["accepted_steps"] / ser["active_cells"] / ser["end_time"]
    scale = (n_cells / n_meas) ** (1.0 / 3.0)
    depth = two.get("halo_depth") or 1
    k_meas = two.get("substeps_per_part") or depth
    # the measured halo per boundary is `depth` layers; a part moves k layers of the cut
    halo_one = ((two["halo_cells"][0] if two.get("halo_cells") else 0) * k_meas / depth
                * scale ** 2 * scale)
    k_big = k_meas * scale
    rounds = 1 if per_exchange is None else math.ceil(k_big / per_exchange)
    n_state = two["halo_bytes_per_transport_part"] / max(1, sum(two["halo_cells"])) / 8
    bytes_split = 2 * 2 * halo_one * n_state * 8   # 2 sides, 2 transport parts
    n_split = sim_time / split_step
    comm = n_split * (bytes_split / network + 4 * rounds * hop)
    if ser.get("transport_wall_s"):
        # as built, the sources divide between the blocks and the transport does not: each
        # block advances its extended set (block + k layers), at these depths the whole bed
        sources, transport_whole = _scaled_parts(ser, n_cells, sim_time, scale)
        compute = sources + transport_whole
    else:
        sources, transport_whole = n_cells * sim_time * steps_per_cell_s / rate, None
        compute = sources
    machines = None
    for m in range(1, 4097):
        if sources / m + (transport_whole or 0.0) + comm <= 3600.0:
            machines = m
            break
    return {"n_cells": n_cells, "sim_time_s": sim_time, "rate_per_machine": rate,
            "transport_whole_bed_s": transport_whole,
            "one_layer": [one_layer_model(ser, n_cells, sim_time, split_step, k_big, n_state,
                                          network=net, latency=lat)
                          for lat in (hop, MESSAGE_LATENCY_S)
                          for net in (network, 10 * network)]
            if ser.get("transport_wall_s") else [],
            "steps_per_cell_per_s": steps_per_cell_s, "halo_cells_per_boundary": halo_one,
            "halo_bytes_per_split_step_per_boundary": bytes_split,
            "compute_s_one_machine": compute, "comm_s": comm, "machines_for_1_h": machines,
            "network_bytes_per_s": network, "task_hop_s": hop,
            "substeps_per_part": k_big, "exchange_rounds_per_part": rounds,
            "measured_at_active_cells": n_meas}


def _scaled_parts(ser, n_cells, sim_time, scale):
    """(sources, transport) seconds of one machine for the bed of ``n_cells`` over
    ``sim_time`` [s], from the serial run ``ser``: the sources scale with the cells, the
    transport with the cells times the substeps (``scale``: the cell size ratio)."""
    per = n_cells / ser["active_cells"] * sim_time / ser["end_time"]
    return ser["source_wall_s"] * per, ser["transport_wall_s"] * per * scale


def one_layer_model(ser, n_cells, sim_time, split_step, substeps, n_state,
                    network=NETWORK_BYTES_PER_S, latency=TASK_HOP_S) -> dict:
    """Machines for the batch if the halo were one layer exchanged at every substep (not how
    the transport is built): cubic blocks of n/m cells, each receiving its 6 faces
    (n/m)^(2/3) cells x ``n_state`` float64 per substep, two transport parts of ``substeps``
    substeps per ``split_step`` [s], each exchange costing ``latency`` [s] plus its bytes at
    ``network`` [bytes/s]; sources and transport divide between the machines. An estimate."""
    scale = (n_cells / ser["active_cells"]) ** (1.0 / 3.0)
    sources, transport = _scaled_parts(ser, n_cells, sim_time, scale)
    exchanges = sim_time / split_step * 2 * substeps
    machines, wall = None, None
    for m in range(1, 100_001):
        face_bytes = 6 * (n_cells / m) ** (2.0 / 3.0) * n_state * 8
        t = (sources + transport) / m + exchanges * (latency + face_bytes / network)
        if t <= 3600.0:
            machines, wall = m, t
            break
    return {"network_bytes_per_s": network, "latency_s": latency,
            "exchanges": exchanges, "latency_floor_s": exchanges * latency,
            "machines_for_1_h": machines, "wall_s": wall}


def _solve_rate(run) -> float:
    """Accepted cell-steps per second of the solve phase [1/s]."""
    solve = float(run["phases"].get("solve_s") or 0.0)
    return run["accepted_steps"] / solve if solve > 0 else 0.0


def cluster_markdown(res) -> str:
    """The study's report (markdown)."""
    m0, m1 = res["machine"], res["machine_after"]
    lines = [f"3-D bed (`pbe-cfd case make --3d`), QMOM N = 2, {res['end_time_s']:g} s of "
             f"process per run, {res.get('outputs', 2)} output intervals. Machine: "
             f"{m0.get('logical_cores')} cores, load {m0.get('load_average_1_5_15min')} "
             f"before, {m1.get('load_average_1_5_15min')} after (shared).", "",
             "Rates: accepted cell-steps over the solve phase (the executor's run, after the "
             "setup), and in brackets over setup + solve (the run's own "
             "`cell_steps_per_second`).", "",
             "| cells (active) | transport | run | cell-steps/s | x serial | client B/split "
             "step | client peak MiB | worker peak MiB | solve s (setup s) | same as serial |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["runs"]:
        ser = ([s for s in res["runs"] if s["transport"] == r["transport"]
                and s["bed_cells"] == r["bed_cells"] and s["workers"] == 0] or [None])[0]
        run = "serial" if not r["workers"] else f"{r['workers']} worker(s)" + (
            "" if r.get("balance", True) or not r["transport"] else ", equal cells")
        sent = r["client_sent_bytes_per_split_step"]
        rate = _solve_rate(r)
        ratio = "- (no serial run)" if ser is None else (
            f"{rate / _solve_rate(ser):.2f} "
            f"({r['cell_steps_per_s'] / ser['cell_steps_per_s']:.2f})")
        lines.append(
            f"| {r['bed_cells']} ({r['active_cells']}) | {'yes' if r['transport'] else 'no'} "
            f"| {run} | {rate:.3g} ({r['cell_steps_per_s']:.3g}) | {ratio} | "
            f"{'-' if sent is None else f'{sent:.0f}'} | {r['client_peak_rss'] / 2**20:.0f} | "
            f"{', '.join(str(round(x / 2**20)) for x in r['worker_peak_rss']) or '-'} | "
            f"{r['phases']['solve_s']:.1f} ({r['phases']['setup_s']:.1f}) | "
            f"{'-' if ser is None else 'yes' if r['final_hash'] == ser['final_hash'] else 'NO'} |")
    mod = res.get("model") or {}
    if mod:
        lines += ["", f"Model (an estimate from the measured parts): {mod['n_cells']:.0e} cells, "
                  f"{mod['sim_time_s']:g} s of process; {mod['steps_per_cell_per_s']:.3g} "
                  f"accepted steps per cell per s and {mod['rate_per_machine']:.3g} cell-steps/s "
                  f"per machine (serial, measured here under the load above) give "
                  f"{mod['compute_s_one_machine'] / 3600:.3g} h of compute on one machine"
                  + (f" ({mod['transport_whole_bed_s'] / 3600:.3g} h of it the transport, "
                     f"which every block does for the whole bed)"
                     if mod.get("transport_whole_bed_s") else "") + "; "
                  f"halo {mod['halo_cells_per_boundary']:.3g} cells per block boundary "
                  f"({mod['halo_bytes_per_split_step_per_boundary'] / 1e6:.3g} MB per split "
                  f"step at {mod['network_bytes_per_s'] / 1e6:g} MB/s) and "
                  f"{mod['task_hop_s'] * 1e3:g} ms per task hop add {mod['comm_s'] / 60:.3g} min; "
                  f"machines to finish in 1 h: {mod['machines_for_1_h']}."]
        if mod.get("one_layer"):
            lines.append("")
        for o in mod.get("one_layer") or []:
            lines.append(
                f"- With a one-layer halo exchanged at every substep (not built; "
                f"{o['exchanges']:.3g} exchanges) at {o['latency_s'] * 1e3:g} ms per "
                f"exchange and {o['network_bytes_per_s'] / 1e6:g} MB/s: machines to finish "
                f"in 1 h: {o['machines_for_1_h']} (latency alone "
                f"{o['latency_floor_s'] / 3600:.3g} h).")
    return "\n".join(lines) + "\n"
