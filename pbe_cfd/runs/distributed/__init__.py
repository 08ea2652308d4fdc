"""The per-cell source integration of ``pbe-cfd couple`` on a Dask cluster.

``run_coupled(..., executor=ClusterExecutor(...))`` hands the integration of the per-cell
sources to a ``dask.distributed`` cluster (a running scheduler, or a ``LocalCluster`` of
worker processes) with the same numba kernel (``integrate.integrate_cells``) inside each task.
All times are in s, all fields SI; the states are the scaled moments of ``couple.run_coupled``.

Design
------
* **Partition.** The active cells (alpha >= alpha_min, in ``couple``'s order) are split into
  chunks: contiguous blocks (``--chunks K``), or, for a decomposed OpenFOAM case
  (``processor*/constant/polyMesh/cellProcAddressing``), one chunk per processor directory.
  Per-cell integration is independent of every other cell, so any partition gives results
  bitwise equal to the serial run (the same cell sees the same floating-point operations).
* **Without transport** chunks are independent over the whole run: one task per chunk
  integrates its cells over *all* output intervals and returns the history (states at every
  output time), the step memory, the counters and the status. Data moves once each way; the
  client writes each chunk's history into a spool on disk as it arrives (``ChunkedSpool``).
* **With** ``[transport]`` the states stay on the workers (``halo_run``). Each block of cells
  (one per processor directory of a decomposed case, else ``--chunks K`` or one per worker
  blocks of the flux graph, ``transport.halo.level_partition``, re-cut at an output time into
  blocks of equal measured cost when out of balance: ``balance``) lives on one worker. Per
  transport part a block reads, worker to worker through Dask's dependency transfer, only the
  states of its halo (the cells within k upwind hops in other blocks, k the CFL substeps of the
  part) and advances its own cells through the k substeps; per source part it integrates its
  own cells. The client submits each output interval's task graph (control messages only) and
  gathers the states once per output time. Results are bitwise the serial run's (the local
  rows of the step matrix keep the global rows' entries in order; the rest is per cell). The
  bytes the client sends per split step, the halo sizes and the gathered bytes per output time
  are reported (``report()["transport"]``).
* **Fault tolerance.** With a chunk store (``DIR.chunks/`` next to the output ``DIR``) every
  finished chunk is written atomically to ``DIR.chunks/chunk_00003.npz`` by the client as soon
  as it arrives. A chunk whose task fails (an exception, or a worker lost more often than the
  scheduler's ``allowed-failures``) is reported by number; the other chunks keep computing and
  are stored. ``--resume DIR`` (same scene) reads the stored chunks and computes only the
  missing ones. The store carries a fingerprint of every numeric input (initial states, cell
  rows, method data, times, tolerances, partition), so a store made by a different problem is
  refused. With transport, the client stores the states at every output time
  (``DIR.chunks/step_00004.npz``) and a resume continues from the last stored output time; a
  worker lost during an interval is found by polling the scheduler and named with its blocks.
  The output directory itself is written atomically (``output.atomic_directory``) only after
  the whole run succeeded; the chunk store is removed after that.
* **Threads.** A ``LocalCluster`` of N worker processes has one Dask thread per worker (one
  task at a time per process) and numba threads = cores // N inside each task, so workers x
  threads <= cores. On an external scheduler the numba threads of a task are the host's cores
  divided by the number of worker processes on that host; tasks in one worker process take a
  process-wide lock around the numba call, so a worker with several Dask threads never runs
  two parallel numba regions at once.
* **Progress** across workers comes from ``distributed.as_completed`` on the client, reported
  through the ``progress(fraction, text)`` callback (the CLI's tqdm bar).

Modules: ``partition`` (chunks), ``decompose`` (decomposePar, processor directories), ``store``
(the chunk store), ``faults`` (fault injection), ``tasks`` (what a worker runs), ``halo_run``
and ``halo_tasks`` (transport with the states on the workers), ``balance`` (blocks of equal
measured cost), ``cluster``
(local clusters, threads), ``executor`` (``ClusterExecutor``), ``launch`` (an executor from the
command-line options).
"""
from .cluster import host_cores, numba_thread_table, start_local_cluster
from .decompose import (decompose_case, decomposition_dict, processor_dirs, read_decomposition,
                        write_processor_fields)
from .executor import ChunkedSpool, ChunksFailed, ClusterExecutor
from .faults import FAULT_ENV, parse_fault
from .launch import check_store, make_executor, resume_manifest
from .partition import Partition, block_partition, processor_partition
from .store import STORE_SUFFIX, ChunkStore, ChunkStoreError, fingerprint, store_path
from .tasks import chunk_history

__all__ = ["host_cores", "numba_thread_table", "start_local_cluster", "decompose_case",
           "decomposition_dict", "processor_dirs", "read_decomposition",
           "write_processor_fields", "ChunkedSpool", "ChunksFailed", "ClusterExecutor",
           "FAULT_ENV", "parse_fault", "check_store", "make_executor", "resume_manifest",
           "Partition", "block_partition", "processor_partition", "STORE_SUFFIX", "ChunkStore",
           "ChunkStoreError", "fingerprint", "store_path", "chunk_history"]
