"""Dask clusters: the cores of this host, a local cluster of worker processes, and the numba
threads each task may use."""
from __future__ import annotations

import os


# ---------------------------------------------------------------------------- cluster
def host_cores() -> int:
    """Cores this process may run on [-]."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def start_local_cluster(workers: int, cores: int | None = None):
    """A ``LocalCluster`` of ``workers`` processes with one Dask thread each, and a Client.
    Returns (client, cluster); numba threads per task are cores // workers."""
    import logging

    from distributed import Client, LocalCluster

    import dask

    # worker-saturation 1.0: a worker holds only the task it runs, so a lost worker takes no
    # queued chunk down with it; OpenMP (numba's omp layer) may use the worker's share of cores
    share = max(1, (cores or host_cores()) // max(1, int(workers)))
    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0,
                          "distributed.nanny.pre-spawn-environ.OMP_NUM_THREADS": share}):
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR)
    return Client(cluster), cluster


def numba_thread_table(client) -> dict:
    """Worker address -> numba threads per task: the host's cores divided by the worker
    processes on that host (at least 1), so workers x threads <= cores on every host."""
    info = client.scheduler_info().get("workers", {})
    cores = client.run(host_cores)
    per_host = {}
    for addr, w in info.items():
        per_host.setdefault(w.get("host"), []).append(addr)
    table = {}
    for host, addrs in per_host.items():
        c = max(cores.get(a, 1) for a in addrs)
        for a in addrs:
            table[a] = max(1, c // len(addrs))
    return table
