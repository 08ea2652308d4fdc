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
  output time), the step memory, the counters and the status. Data moves once each way.
* **With** ``[transport]`` the transport operator couples all cells every split step, so the
  client keeps the states and runs ``Transport.advance`` (sparse upwind matrix, as in the
  serial run); each source part of each split step is one task per chunk: the chunk's states
  and step memory go out, the integrated states, step memory and counters come back (the
  cell rows and the method data are sent once and stay on the workers). The bytes moved and
  the wall time per split step are measured and reported (``report()["transport"]``).
* **Fault tolerance.** With a chunk store (``DIR.chunks/`` next to the output ``DIR``) every
  finished chunk is written atomically to ``DIR.chunks/chunk_00003.npz`` by the client as soon
  as it arrives. A chunk whose task fails (an exception, or a worker lost more often than the
  scheduler's ``allowed-failures``) is reported by number; the other chunks keep computing and
  are stored. ``--resume DIR`` (same scene) reads the stored chunks and computes only the
  missing ones. The store carries a fingerprint of every numeric input (initial states, cell
  rows, method data, times, tolerances, partition), so a store made by a different problem is
  refused. With transport, the client stores the states at every output time
  (``DIR.chunks/step_00004.npz``) and a resume continues from the last stored output time.
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
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import statistics
import threading
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import integrate
from .physics import parameters as P
from .output import remove_matching
from .scene import SceneError
from .simulate import SimulationError

#: Environment variable for deterministic fault injection: "raise:3,5" makes chunks 3 and 5
#: raise in their task, "exit:3" makes the worker running chunk 3 exit (a lost worker);
#: an optional "@T" ("raise:1@5") fires only for source steps starting at t >= T s.
FAULT_ENV = "PBE_CFD_FAULT"

#: Name of the chunk store next to an output directory DIR: DIR.chunks/.
STORE_SUFFIX = ".chunks"
#: The files a chunk store writes (nothing else in DIR.chunks/ is ever removed).
STORE_FILES = ("manifest.json", "chunk_*.npz", "step_*.npz", ".manifest.json.*.tmp",
               ".chunk_*.tmp", ".step_*.tmp")
MANIFEST = "manifest.json"
STORE_VERSION = 1

_NUMBA_LOCK = threading.Lock()


class ChunksFailed(SimulationError):
    """Some chunks did not finish. ``failed`` maps chunk number -> reason; ``store`` is the
    chunk store holding the finished chunks (or None)."""

    def __init__(self, message, failed: dict, store: Path | None):
        super().__init__(message)
        self.failed = failed
        self.store = store


class ChunkStoreError(SceneError):
    """A chunk store or decomposition that cannot be used for this run (missing, made by
    another problem, stale): bad input, exit code 2. ``ChunkStoreError(path, message)``."""

    def __init__(self, path, message):
        super().__init__(path, None, message)


# ---------------------------------------------------------------------------- partition
@dataclass
class Partition:
    """Chunks of the active cells.

    chunks     list of (n_k,) int arrays: positions into the active-cell list (ascending)
    labels     one name per chunk ("block 3" or "processor1")
    kind       "blocks" or "processors"
    """
    chunks: list
    labels: list
    kind: str = "blocks"

    @property
    def n_chunks(self) -> int:
        """Number of chunks [-]."""
        return len(self.chunks)


def block_partition(n_active: int, n_chunks: int) -> Partition:
    """Split positions 0..n_active-1 into ``n_chunks`` contiguous blocks of near-equal size
    (no empty block; at most n_active blocks)."""
    n_chunks = max(1, min(int(n_chunks), int(n_active)))
    parts = np.array_split(np.arange(n_active, dtype=np.int64), n_chunks)
    return Partition(chunks=list(parts), labels=[f"block {k}" for k in range(n_chunks)])


def processor_partition(decomposition: list, idx: np.ndarray, n_cells: int) -> Partition:
    """One chunk per processor directory: the active cells (positions into ``idx``, the
    global indices of the active cells) that ``decomposition[p]`` (cellProcAddressing of
    processor p: global cell of each local cell) holds. Processors without an active cell
    get no chunk."""
    proc = np.full(n_cells, -1, dtype=np.int64)
    for p, addr in enumerate(decomposition):
        proc[addr] = p
    if np.any(proc < 0):
        raise ChunkStoreError("processor*/constant/polyMesh/cellProcAddressing",
                              f"the decomposition covers {np.count_nonzero(proc >= 0)} of "
                              f"{n_cells} cells; rerun decomposePar -force")
    owner = proc[idx]
    chunks, labels = [], []
    for p in range(len(decomposition)):
        pos = np.flatnonzero(owner == p)
        if pos.size:
            chunks.append(pos)
            labels.append(f"processor{p}")
    return Partition(chunks=chunks, labels=labels, kind="processors")


# ---------------------------------------------------------------------------- decomposed case
def decomposition_dict(n_subdomains: int) -> str:
    """Text of a decomposeParDict splitting the bed into ``n_subdomains`` vertical slabs side
    by side (method simple, n = (N 1 1); y is vertical in the fluid-bed case), so every
    subdomain holds a share of the dense bed at the bottom."""
    return f"""/*--------------------------------*- C++ -*----------------------------------*\\
  Written by pbe_cfd.distributed.decompose_case: {n_subdomains} vertical slabs side by side.
\\*---------------------------------------------------------------------------*/
FoamFile
{{
    version     2.0;
    format      ascii;
    class       dictionary;
    object      decomposeParDict;
}}

numberOfSubdomains {n_subdomains};

method          simple;

simpleCoeffs
{{
    n               ({n_subdomains} 1 1);
    delta           0.001;
}}
"""


def decompose_case(case_dir, n_subdomains: int = 2, time: float | str | None = None) -> list:
    """Run ``decomposePar -force`` on an OpenFOAM case (mesh, and the CFD time ``time`` [s]
    when given, so the processor directories hold alpha and Theta next to written-back
    fields). Uses ``system/decomposeParDict`` when it has ``numberOfSubdomains`` equal to
    ``n_subdomains``, otherwise writes ``system/decomposeParDict.pbe`` and passes it.
    Returns the processor directories. Needs OpenFOAM (``decomposePar``)."""
    import re
    import subprocess

    from .cfd import openfoam as of

    case = Path(case_dir).resolve()
    install = of.find_openfoam(("decomposePar",))
    args = ["decomposePar", "-force"]
    own = case / "system" / "decomposeParDict"
    m = None
    if own.is_file():
        m = re.search(r"^\s*numberOfSubdomains\s+(\d+)\s*;", own.read_text(), flags=re.M)
    if m is None or int(m.group(1)) != int(n_subdomains):
        alt = case / "system" / "decomposeParDict.pbe"
        if alt.exists() and "pbe_cfd.distributed" not in alt.read_text(errors="replace"):
            raise of.OpenFOAMError(f"{alt} exists and was not written by pbe-cfd; move it "
                                   "away to let --decompose write its own")
        alt.write_text(decomposition_dict(int(n_subdomains)))
        args += ["-decomposeParDict", str(alt)]
    if time is not None:
        t = of.pick_time(case, time)
        args += ["-time", of.time_name(case, t)]
    log = case / "log.pbe-cfd-decomposePar"     # never a log of the user's decomposePar
    with open(log, "w") as fh:
        r = subprocess.run(args, cwd=case, env=install.env(), stdout=fh,
                           stderr=subprocess.STDOUT)
    text = log.read_text(errors="replace")
    if r.returncode != 0 or "FOAM FATAL" in text:
        raise of.OpenFOAMError(f"decomposePar failed in {case}", tool="decomposePar",
                               log_path=log, log_tail="\n".join(text.splitlines()[-30:]))
    return processor_dirs(case)


def processor_dirs(case_dir) -> list:
    """The ``processorN`` directories of a case holding cellProcAddressing, by N."""
    case = Path(case_dir)
    out = []
    for p in case.glob("processor*"):
        suffix = p.name[len("processor"):]
        if suffix.isdigit() and (p / "constant" / "polyMesh" / "cellProcAddressing").is_file():
            out.append((int(suffix), p))
    out.sort()
    if out and [n for n, _ in out] != list(range(len(out))):
        raise ChunkStoreError(case, f"processor directories {[n for n, _ in out]} are not "
                              "0..N-1; rerun decomposePar -force")
    return [p for _, p in out]


def read_decomposition(case_dir, n_cells: int | None = None) -> list:
    """cellProcAddressing of every processor directory (the global OpenFOAM cell of each
    local cell, (n_p,) int64), checked to be a partition of the ``n_cells`` cells."""
    from foamlib import FoamFile

    dirs = processor_dirs(case_dir)
    out = [np.asarray(FoamFile(d / "constant" / "polyMesh" / "cellProcAddressing")[None],
                      dtype=np.int64).ravel() for d in dirs]
    if out and n_cells is not None:
        allc = np.concatenate(out)
        if allc.size != n_cells or not np.array_equal(np.sort(allc), np.arange(n_cells)):
            raise ChunkStoreError(
                case_dir, f"processor directories hold {allc.size} cells, the case has "
                f"{n_cells}; the decomposition is stale (rerun decomposePar -force)")
    return out


def write_processor_fields(case_dir, decomposition: list, time_name: str,
                           fields: dict, dimensions: dict | None = None,
                           overwrite: bool = False) -> list:
    """Write cell fields (name -> (n_cells,) global values, SI) back per processor: each
    ``processorN/<time_name>/`` gets the values of its local cells (cellProcAddressing order)
    via ``openfoam.write_foam_fields`` (``dimensions``: name -> SI exponents, default
    dimensionless). ``reconstructPar -time <time_name>`` reassembles them. Returns the
    files."""
    from .cfd.openfoam import write_foam_fields

    written = []
    for d, addr in zip(processor_dirs(case_dir), decomposition):
        local = {k: np.asarray(v, dtype=float)[addr] for k, v in fields.items()}
        written += write_foam_fields(d, time_name, local, dimensions=dimensions,
                                     overwrite=overwrite)
    return written


# ---------------------------------------------------------------------------- chunk store
def store_path(out_dir) -> Path:
    """The chunk store of output directory DIR: the sibling ``DIR.chunks/``."""
    out = Path(out_dir).resolve()
    return out.with_name(out.name + STORE_SUFFIX)


def _atomic_savez(path: Path, **arrays):
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _atomic_write_text(path: Path, text: str):
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


class ChunkStore:
    """Finished chunks of one run, as ``chunk_%05d.npz`` (no transport) or output-time
    checkpoints ``step_%05d.npz`` (transport), plus ``manifest.json`` (fingerprint, layout,
    the scene and output directory, for ``--resume``). Every file is written atomically."""

    def __init__(self, path):
        self.path = Path(path)

    @staticmethod
    def read_manifest(path) -> dict | None:
        """The manifest of a store directory, or None when there is none."""
        f = Path(path) / MANIFEST
        if not f.is_file():
            return None
        try:
            return json.loads(f.read_text())
        except ValueError:
            return None

    def open(self, fingerprint: str, meta: dict, resume: bool) -> "ChunkStore":
        """Prepare the store for a run whose inputs hash to ``fingerprint``. With ``resume``
        the store must exist with that fingerprint (its files are kept); without, an existing
        store is replaced (a fresh run)."""
        manifest = self.read_manifest(self.path)
        if resume:
            if manifest is None:
                raise ChunkStoreError(self.path, "--resume: no chunk store here (it is made by a "
                                      "run with --workers or --scheduler and removed after "
                                      "success)")
            if manifest.get("fingerprint") != fingerprint:
                raise ChunkStoreError(
                    self.path, "--resume: made by a different problem (scene, case, "
                    "partition or method data differ); rerun without --resume to start over")
            return self
        if self.path.exists() and any(self.path.iterdir()):
            if manifest is None:
                raise ChunkStoreError(self.path, "exists and is not a chunk store written by "
                                      "pbe-cfd; nothing was changed: choose another --out "
                                      "or move it away yourself")
            remove_matching(self.path, STORE_FILES)   # only the store's own files
        self.path.mkdir(parents=True, exist_ok=True)
        _atomic_write_text(self.path / MANIFEST, json.dumps(
            {"version": STORE_VERSION, "fingerprint": fingerprint, **meta}, indent=1))
        return self

    def _chunk(self, k: int) -> Path:
        return self.path / f"chunk_{k:05d}.npz"

    def _step(self, k: int) -> Path:
        return self.path / f"step_{k:05d}.npz"

    def finished_chunks(self) -> set:
        """Numbers of the chunks stored complete."""
        out = set()
        for p in self.path.glob("chunk_*.npz"):
            try:
                out.add(int(p.stem.split("_")[1]))
            except ValueError:
                pass
        return out

    def save_chunk(self, k: int, result: dict):
        """Store chunk k's result arrays atomically."""
        _atomic_savez(self._chunk(k), **result)

    def load_chunk(self, k: int) -> dict:
        """Chunk k's stored result arrays."""
        with np.load(self._chunk(k)) as z:
            return {name: z[name] for name in z.files}

    def save_step(self, k: int, arrays: dict):
        """Store the states and counters at output time number k atomically."""
        _atomic_savez(self._step(k), **arrays)

    def stored_steps(self) -> list:
        """Output-time numbers stored, ascending."""
        out = []
        for p in self.path.glob("step_*.npz"):
            try:
                out.append(int(p.stem.split("_")[1]))
            except ValueError:
                pass
        return sorted(out)

    def load_step(self, k: int) -> dict:
        """The arrays stored for output time number k."""
        with np.load(self._step(k)) as z:
            return {name: z[name] for name in z.files}

    def remove(self):
        """Delete the store's own files, and the directory when that empties it (after the
        output was written)."""
        remove_matching(self.path, STORE_FILES)


def fingerprint(*arrays, extra: str = "") -> str:
    """SHA-256 over the bytes, dtypes and shapes of numeric inputs (and a text)."""
    h = hashlib.sha256(extra.encode())
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


# ---------------------------------------------------------------------------- faults
def parse_fault(text: str | None) -> dict | None:
    """Parse ``PBE_CFD_FAULT`` ("raise:3,5", "exit:2", "raise:1@5"): {"mode", "chunks",
    "after" [s]} or None."""
    if not text:
        return None
    mode, _, rest = text.partition(":")
    after = -math.inf
    if "@" in rest:
        rest, _, at = rest.partition("@")
        after = float(at)
    if mode not in ("raise", "exit"):
        raise ValueError(f"{FAULT_ENV}: mode must be 'raise' or 'exit', got {mode!r}")
    chunks = sorted({int(s) for s in rest.split(",") if s.strip()})
    return {"mode": mode, "chunks": chunks, "after": after}


def _maybe_fail(fault, chunk: int, t: float):
    if not fault or chunk not in fault["chunks"] or t < fault.get("after", -math.inf):
        return
    if fault["mode"] == "exit":
        os._exit(70)        # the worker process dies: a lost worker, as a crash would be
    raise RuntimeError(f"injected fault in chunk {chunk} ({FAULT_ENV})")


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
    step memory [s]; shared dict(aux, params, config, rtol, atol, max_steps). Returns
    history (n_times, n, n_state), steps, stats (n, N_STATS), status, reached [s],
    fail_interval (index of the output time at which a cell stopped, -1 if none), compute_s
    (wall time of the integration [s]) and the worker's numba threads. A cell that stops ends
    the chunk (as the serial run stops at the end of that interval)."""
    _maybe_fail(fault, chunk, float(times[0]))
    start = _time.perf_counter()
    states = np.array(states, dtype=np.float64, order="C", copy=True)
    rows = np.ascontiguousarray(rows)
    steps = np.array(steps, dtype=np.float64, copy=True)
    n = states.shape[0]
    hist = np.empty((len(times),) + states.shape)
    hist[0] = states
    stats = np.zeros((n, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(n, dtype=np.int64)
    reached = np.zeros(n)
    fail = np.full(n, -1, dtype=np.int64)
    nthreads = _numba_threads(threads)
    with _NUMBA_LOCK:
        _set_threads(nthreads)
        for k in range(1, len(times)):
            integrate.integrate_cells(states, rows, shared["aux"], shared["params"],
                                      shared["config"], float(times[k - 1]), float(times[k]),
                                      steps, shared["rtol"], shared["atol"],
                                      shared["max_steps"], stats, status, reached)
            hist[k] = states
            new = (status != integrate.OK) & (fail < 0)
            if new.any():
                fail[new] = k
                hist[k + 1:] = states
                break
    return {"history": hist, "steps": steps, "stats": stats, "status": status,
            "reached": reached, "fail_interval": fail,
            "compute_s": np.array(_time.perf_counter() - start),
            "threads": np.array(nthreads)}


def chunk_source(chunk: int, states, rows, steps, shared, t0: float, t1: float, threads,
                 fault=None) -> dict:
    """Task: integrate one chunk's per-cell sources from t0 to t1 [s] (one source part of a
    split step). Returns states, steps [s], stats (increments), status, reached [s] and
    compute_s [s]."""
    _maybe_fail(fault, chunk, t0)
    start = _time.perf_counter()
    states = np.array(states, dtype=np.float64, order="C", copy=True)
    steps = np.array(steps, dtype=np.float64, copy=True)
    n = states.shape[0]
    stats = np.zeros((n, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(n, dtype=np.int64)
    reached = np.zeros(n)
    with _NUMBA_LOCK:
        _set_threads(_numba_threads(threads))
        integrate.integrate_cells(states, rows, shared["aux"], shared["params"],
                                  shared["config"], t0, t1, steps, shared["rtol"],
                                  shared["atol"], shared["max_steps"], stats, status, reached)
    return {"states": states, "steps": steps, "stats": stats, "status": status,
            "reached": reached, "compute_s": _time.perf_counter() - start}


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
    _report: dict = field(default_factory=dict, repr=False)
    store: ChunkStore | None = field(default=None, repr=False)

    # -- the hook of couple.run_coupled ------------------------------------------------
    def run(self, states, times, transport, *, rows, aux, arrays, method, steps, stats,
            status, reached, idx, scene, progress=None) -> list:
        """Advance ``states`` (n_active, n_state) over all output ``times`` [s] like the
        serial loop of ``run_coupled``; update states, steps, stats, status, reached in place
        and return the history (one (n_active, n_state) array per output time)."""
        start = _time.perf_counter()
        n = states.shape[0]
        part = self._partition(n, idx, scene)
        shared = {"aux": np.asarray(aux), "params": np.asarray(arrays.params),
                  "config": np.asarray(arrays.config), "rtol": float(method.rtol),
                  "atol": float(method.atol),
                  "max_steps": int(integrate.MAX_STEPS_PER_INTERVAL)}
        threads = numba_thread_table(self.client)
        layout = np.concatenate([np.r_[len(c), c] for c in part.chunks])
        extra = json.dumps({"method": method.name, "rtol": shared["rtol"],
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
            history = self._run_independent(part, states, times, rows, steps, stats, status,
                                             reached, idx, scene, shared, threads, progress)
        else:
            history = self._run_transport(part, states, times, transport, rows, steps, stats,
                                          status, reached, idx, scene, shared, threads,
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
    def _partition(self, n, idx, scene) -> Partition:
        if isinstance(self.chunks, Partition):
            return self.chunks
        if self.decomposition is not None and self.chunks is None:
            n_cells = sum(len(a) for a in self.decomposition)
            return processor_partition(self.decomposition, np.asarray(idx), n_cells)
        k = self.chunks
        if k is None:
            k = 4 * max(1, len(self.client.scheduler_info().get("workers", {})))
        return block_partition(n, int(k))

    def _run_independent(self, part, states, times, rows, steps, stats, status, reached,
                         idx, scene, shared, threads, progress):
        from distributed import as_completed

        n_t = len(times)
        history = np.empty((n_t,) + states.shape)
        fail_interval = np.full(states.shape[0], -1, dtype=np.int64)
        done = self.store.finished_chunks() if (self.store and self.resume) else set()
        done &= set(range(part.n_chunks))
        total = states.shape[0]
        cells_done = 0

        def accept(k, res):
            nonlocal cells_done
            pos = part.chunks[k]
            history[:, pos, :] = res["history"]
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
            _raise_cell_failure(scene, idx, rows, status, reached,
                                np.flatnonzero(fail_interval == first))
        return [history[k] for k in range(n_t)]

    def _run_transport(self, part, states, times, transport, rows, steps, stats, status,
                       reached, idx, scene, shared, threads, progress):
        from distributed import as_completed

        client = self.client
        history = [states.copy()]
        k0 = 0
        if self.store is not None and self.resume:
            for k in self.store.stored_steps():
                if k >= len(times):
                    continue
                z = self.store.load_step(k)
                history.append(z["states"].copy())
                k0 = k
            if k0 > 0:
                z = self.store.load_step(k0)
                states[...] = z["states"]
                steps[...] = z["steps"]
                stats[...] = z["stats"]
                status[...] = z["status"]
                reached[...] = z["reached"]
            history = history[:k0 + 1]
        shared_f = client.submit(_identity, shared, pure=False)
        rows_f = [client.submit(_identity, np.ascontiguousarray(rows[pos]), pure=False)
                  for pos in part.chunks]
        moved = {"out": [], "back": [], "wall": [], "compute_max": [], "wait": []}

        def source_step(s, ta, tb):
            t_start = _time.perf_counter()
            futs = {}
            out_bytes = 0
            for c, pos in enumerate(part.chunks):
                sc, st = s[pos], steps[pos]
                out_bytes += sc.nbytes + st.nbytes
                f = client.submit(chunk_source, c, sc, rows_f[c], st, shared_f, float(ta),
                                  float(tb), threads, self.fault, pure=False)
                futs[f] = c
            failed, back, cmax = {}, 0, 0.0
            for f in as_completed(list(futs)):
                c = futs[f]
                try:
                    res = f.result()
                except Exception as exc:  # noqa: BLE001
                    failed[c] = f"{type(exc).__name__}: {exc}"
                    continue
                pos = part.chunks[c]
                s[pos] = res["states"]
                steps[pos] = res["steps"]
                stats[pos] += res["stats"]
                status[pos] = res["status"]
                reached[pos] = res["reached"]
                back += sum(res[x].nbytes for x in ("states", "steps", "stats", "status",
                                                    "reached"))
                cmax = max(cmax, float(res["compute_s"]))
            wall = _time.perf_counter() - t_start
            moved["out"].append(out_bytes)
            moved["back"].append(back)
            moved["wall"].append(wall)
            moved["compute_max"].append(cmax)
            moved["wait"].append(wall - cmax)
            if failed:
                raise self._failure(failed, part, at=(ta, tb))
            bad = np.flatnonzero(status != integrate.OK)
            if bad.size:
                _raise_cell_failure(scene, idx, rows, status, reached, bad)

        try:
            for k in range(k0 + 1, len(times)):
                transport.advance(states, times[k - 1], times[k], source_step)
                history.append(states.copy())
                if self.store is not None:
                    self.store.save_step(k, {"states": states, "steps": steps,
                                             "stats": stats, "status": status,
                                             "reached": reached})
                if progress is not None:
                    progress(times[k] / times[-1], f"t = {times[k]:.4g} s "
                             f"({part.n_chunks} chunks per source step)")
        finally:
            for f in rows_f:
                f.release()
            shared_f.release()
            med = (lambda xs: float(statistics.median(xs)) if xs else 0.0)
            self._report["transport"] = {
                "source_steps": len(moved["wall"]),
                "resumed_from_output": int(k0),
                "bytes_out_per_step": med(moved["out"]),
                "bytes_back_per_step": med(moved["back"]),
                "source_step_wall_s_median": med(moved["wall"]),
                "slowest_task_compute_s_median": med(moved["compute_max"]),
                "overhead_s_per_step_median": med(moved["wait"]),
                "note": "transport on the client (scipy.sparse), per-cell sources per chunk "
                        "on the workers; states and step memory go out and back every "
                        "split step, cell rows and method data are sent once"}
        return history

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


def _raise_cell_failure(scene, idx, rows, status, reached, bad):
    """The serial run's error for the first failing cells ``bad`` (positions)."""
    c = int(bad[0])
    raise SimulationError(
        f"{scene.source}: cell {int(idx[c])} (alpha {rows[c, P.ALPHA]:.4g}, Theta "
        f"{rows[c, P.THETA]:.3g} m2/s2) stopped at t = {reached[c]:.6g} s: "
        f"{integrate.STATUS_TEXT[int(status[c])]}; {bad.size} cell(s) affected")


# ---------------------------------------------------------------------------- CLI glue
def wants_cluster(args) -> bool:
    """True when the ``couple`` arguments ask for a cluster run."""
    return bool(getattr(args, "scheduler", None) or getattr(args, "workers", None)
                or getattr(args, "resume", None))


def prepare_args(args):
    """``--resume DIR``: set ``--out DIR`` and, when not given, SCENE and ``--chunks`` as
    recorded in ``DIR.chunks/manifest.json``. Call before the scene is loaded."""
    resume = getattr(args, "resume", None)
    if not resume:
        store = store_path(args.out)
        cluster = wants_cluster(args) or getattr(args, "decompose", None)
        if cluster and store.exists() and not getattr(args, "overwrite", False):
            raise ChunkStoreError(store, f"holds chunks of an earlier cluster run; "
                                  f"`--resume {args.out}` completes that run, --overwrite "
                                  "starts over (only the store's own files are removed)")
        return args
    args.out = resume
    manifest = ChunkStore.read_manifest(store_path(resume))
    if manifest is None:
        raise SceneError(str(store_path(resume)), None,
                         f"--resume {resume}: no chunk store {store_path(resume)} (made by a "
                         "cluster run with --out DIR and removed after its output was written)")
    if not args.scene and manifest.get("scene"):
        args.scene = manifest["scene"]
    if getattr(args, "chunks", None) is None and manifest.get("partition") == "blocks":
        args.chunks = manifest.get("chunks")      # the same blocks as the first run
    return args


def executor_from_args(args, scene, domain):
    """A ClusterExecutor for the ``couple`` arguments (--scheduler ADDRESS | --workers N,
    --chunks K, --resume DIR, --decompose N), or None when none asks for a cluster."""
    if not (wants_cluster(args) or getattr(args, "decompose", None)):
        return None
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise SceneError(scene.source, None, "--workers/--scheduler need dask.distributed: "
                         "pip install \"pbe_cfd[dask]\"") from None
    case_dir, decomposition = None, None
    case = scene.domain.case
    if not case.startswith("bundled:") and Path(case).is_dir():
        case_dir = Path(case).resolve()
        if getattr(args, "decompose", None):
            from .cfd.openfoam import OpenFOAMError
            if any(case_dir.glob("processor*")):  # decomposePar -force would delete them
                raise SceneError(scene.source, "domain.case", f"--decompose: {case_dir} is "
                                 "already decomposed (processor* directories, which "
                                 "decomposePar -force would delete); drop --decompose to use "
                                 "that decomposition")
            try:
                decompose_case(case_dir, args.decompose, time=domain.cells.time)
            except OpenFOAMError as exc:
                raise SceneError(scene.source, "domain.case", f"--decompose: {exc}") from None
        if processor_dirs(case_dir):
            decomposition = read_decomposition(case_dir, domain.cells.n_cells)
    elif getattr(args, "decompose", None):
        raise SceneError(scene.source, "domain.case", "--decompose needs an OpenFOAM case "
                         "directory (not a snapshot)")
    fault = parse_fault(os.environ.get(FAULT_ENV))
    if getattr(args, "scheduler", None):
        from distributed import Client
        client, cluster = Client(args.scheduler), None
    else:
        n = getattr(args, "workers", None) or host_cores()
        client, cluster = start_local_cluster(n)
    out = Path(args.out).resolve()
    scene_arg = args.scene
    if scene_arg and Path(scene_arg).is_file():
        scene_arg = str(Path(scene_arg).resolve())
    return ClusterExecutor(
        client=client, chunks=getattr(args, "chunks", None), decomposition=decomposition,
        store_dir=store_path(out), resume=bool(getattr(args, "resume", None)),
        meta={"scene": scene_arg, "out": str(out)}, fault=fault, cluster=cluster,
        case_dir=case_dir)


# ---------------------------------------------------------------------------- benchmark
def synthetic_problem(n_cells: int, scene="fluid-bed", end_time: float = 2.0,
                      output_interval: float = 1.0):
    """A synthetic mesh of ``n_cells`` active cells: the small case's active cells (bundled
    snapshot) replicated. Returns dict(states, rows, steps, shared, times [s], cells_per_copy)."""
    import dataclasses

    from . import couple, model
    from .scene import load_scene
    from .simulate import method_aux, output_times

    sc = load_scene(scene) if isinstance(scene, str) else scene
    sc = dataclasses.replace(sc, end_time=end_time, output_interval=output_interval)
    domain = couple.load_domain(sc)
    rows, active, _, _ = couple.build_cells(sc, domain.cells)
    idx = np.flatnonzero(active)
    scaled = couple.coupled_scales(sc, rows[idx, P.ALPHA])
    arrays = model.pack(scaled)
    aux, _ = method_aux(scaled, arrays)
    st0 = couple.initial_states(sc, arrays, rows[idx, P.ALPHA])
    reps = int(math.ceil(n_cells / idx.size))
    sel = np.tile(np.arange(idx.size), reps)[:n_cells]
    times = output_times(sc)
    return {"states": np.ascontiguousarray(st0[sel]),
            "rows": np.ascontiguousarray(rows[idx][sel]),
            "steps": np.full(n_cells, sc.output_interval * 1e-3),
            "shared": {"aux": aux, "params": arrays.params, "config": arrays.config,
                       "rtol": float(sc.method.rtol), "atol": float(sc.method.atol),
                       "max_steps": int(integrate.MAX_STEPS_PER_INTERVAL)},
            "times": times, "cells_per_copy": int(idx.size)}


def _serial(prob, threads):
    _set_threads(threads)
    s = prob["states"].copy()
    steps = prob["steps"].copy()
    n = s.shape[0]
    stats = np.zeros((n, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(n, dtype=np.int64)
    reached = np.zeros(n)
    sh = prob["shared"]
    t0 = _time.perf_counter()
    times = prob["times"]
    for k in range(1, len(times)):
        integrate.integrate_cells(s, prob["rows"], sh["aux"], sh["params"], sh["config"],
                                  times[k - 1], times[k], steps, sh["rtol"], sh["atol"],
                                  sh["max_steps"], stats, status, reached)
    return _time.perf_counter() - t0, int(stats[:, integrate.ACCEPTED].sum()), s


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
