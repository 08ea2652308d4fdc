"""The per-cell solve on a Dask cluster (pbe_cfd.runs.distributed): a local cluster of 2 worker
processes gives the serial run's numbers bitwise, with and without transport and on a
decomposed OpenFOAM case; failed or lost chunks are reported and completed on resume."""
import dataclasses
import os
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from pbe_cfd.runs import distributed as D  # noqa: E402
from pbe_cfd.cli import main  # noqa: E402
from pbe_cfd.runs.couple import run_coupled  # noqa: E402
from pbe_cfd.runs.domain import load_domain  # noqa: E402
from pbe_cfd.io.output import read_columns_csv  # noqa: E402
from pbe_cfd.scene.scene import SceneError, bundled_scenes, load_scene  # noqa: E402


def short(name="fluid-bed", end=10.0, interval=5.0):
    scene = load_scene(name)
    return dataclasses.replace(scene, end_time=end, output_interval=interval)


def assert_same(ref, res):
    """Bitwise equal cell fields at every output time, bed columns and step counts."""
    assert len(ref.cell_fields) == len(res.cell_fields)
    for a, b in zip(ref.cell_fields, res.cell_fields):
        assert a.keys() == b.keys()
        for k in a:
            assert np.array_equal(a[k], b[k]), k
    assert ref.bed_columns.keys() == res.bed_columns.keys()
    for k in ref.bed_columns:
        assert np.array_equal(ref.bed_columns[k], res.bed_columns[k]), k
    for k in ("accepted_steps", "rejected_error", "rejected_realizability", "rhs_calls"):
        assert ref.stats[k] == res.stats[k], k


@pytest.fixture(scope="module")
def client():
    client, cluster = D.start_local_cluster(2)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def serial_short():
    scene = short()
    domain = load_domain(scene)
    return scene, domain, run_coupled(scene, domain)


def test_chunked_history_goes_to_disk_not_memory():
    """13 output times of 1e5 cells x 7 state entries, filled chunk by chunk (10 chunks) as
    the no-transport cluster path fills its history: the peak of the allocations is one
    chunk's result (1/10 of the history) plus slack, not the history; every output time
    reads back what was written into it."""
    n, m, n_t, k = 100_000, 7, 13, 10
    whole = n_t * n * m * 8
    spool = D.ChunkedSpool()
    tracemalloc.start()
    try:
        for _ in range(n_t):
            spool.reserve((n, m))
        for c, rows in enumerate(np.array_split(np.arange(n), k)):
            result = np.empty((n_t, rows.size, m))     # what one chunk's task returns
            result[...] = (np.arange(n_t)[:, None, None] + 100.0 * c)
            for j in range(n_t):
                spool.fill(j, rows, result[j])
            del result
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 0.25 * whole, (peak, whole)
    assert spool.nbytes == whole and len(spool) == n_t
    for j, rows in ((0, slice(0, 10_000)), (12, slice(90_000, None))):
        c = 0 if j == 0 else 9
        assert np.all(spool[j][rows] == j + 100.0 * c)


def test_partitions_cover_the_active_cells():
    part = D.block_partition(10, 3)
    assert [len(c) for c in part.chunks] == [4, 3, 3]
    assert np.array_equal(np.concatenate(part.chunks), np.arange(10))
    assert D.block_partition(2, 5).n_chunks == 2
    decomposition = [np.array([0, 2, 4]), np.array([1, 3, 5])]
    idx = np.array([1, 2, 3])               # active cells (global)
    part = D.processor_partition(decomposition, idx, 6)
    assert part.labels == ["processor0", "processor1"]
    assert [c.tolist() for c in part.chunks] == [[1], [0, 2]]
    with pytest.raises(SceneError):
        D.processor_partition([np.array([0, 1])], idx, 6)
    assert D.parse_fault("raise:3,1@5") == {"mode": "raise", "chunks": [1, 3], "after": 5.0}
    assert D.parse_fault("") is None
    assert D.store_path("/x/run1") == Path("/x/run1.chunks")


def test_cluster_run_equals_serial(client, serial_short, tmp_path):
    scene, domain, ref = serial_short
    ex = D.ClusterExecutor(client=client, chunks=3, store_dir=tmp_path / "out.chunks")
    res = run_coupled(scene, domain, executor=ex)
    assert_same(ref, res)
    rep = res.stats["cluster"]
    assert rep["workers"] == 2 and rep["chunks"] == 3
    assert rep["computed_chunks"] == [0, 1, 2] and rep["failed_chunks"] == []
    # two processes on this host: numba threads per task = cores // 2 (at least 1)
    assert rep["numba_threads_per_task"] == [max(1, D.host_cores() // 2)]
    assert sorted(p.name for p in (tmp_path / "out.chunks").glob("chunk_*.npz")) == [
        "chunk_00000.npz", "chunk_00001.npz", "chunk_00002.npz"]
    ex.finish()
    assert not (tmp_path / "out.chunks").exists()


def test_failed_chunk_is_reported_and_completed_on_resume(client, serial_short, tmp_path):
    scene, domain, ref = serial_short
    store = tmp_path / "run.chunks"
    ex = D.ClusterExecutor(client=client, chunks=3, store_dir=store,
                           fault=D.parse_fault("raise:1"))
    with pytest.raises(D.ChunksFailed) as err:
        run_coupled(scene, domain, executor=ex)
    assert set(err.value.failed) == {1}
    assert "1 of 3 chunk(s) failed" in str(err.value) and "--resume" in str(err.value)
    assert ex.store.finished_chunks() == {0, 2}
    again = D.ClusterExecutor(client=client, chunks=3, store_dir=store, resume=True)
    res = run_coupled(scene, domain, executor=again)
    assert res.stats["cluster"]["computed_chunks"] == [1]
    assert res.stats["cluster"]["reused_chunks"] == [0, 2]
    assert_same(ref, res)
    # a store made by another problem is refused
    other = dataclasses.replace(scene, end_time=5.0)
    with pytest.raises(SceneError, match="different problem"):
        run_coupled(other, domain, executor=D.ClusterExecutor(
            client=client, chunks=3, store_dir=store, resume=True))


@pytest.mark.slow
def test_killed_worker_chunk_is_reported_and_resumed(serial_short, tmp_path):
    """A worker process that dies (os._exit) while running chunk 0: the scheduler gives up
    on the chunk (allowed-failures 0), the run names it, the resume completes it."""
    import dask

    scene, domain, ref = serial_short
    store = tmp_path / "killed.chunks"
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        client, cluster = D.start_local_cluster(2)
    try:
        ex = D.ClusterExecutor(client=client, chunks=3, store_dir=store,
                               fault=D.parse_fault("exit:0"))
        with pytest.raises(D.ChunksFailed) as err:
            run_coupled(scene, domain, executor=ex)
        failed = set(err.value.failed)
        assert 0 in failed and "KilledWorker" in err.value.failed[0]
        assert ex.store.finished_chunks() == {0, 1, 2} - failed
        again = D.ClusterExecutor(client=client, chunks=3, store_dir=store, resume=True)
        res = run_coupled(scene, domain, executor=again)
        assert res.stats["cluster"]["computed_chunks"] == sorted(failed)
        assert_same(ref, res)
    finally:
        client.close()
        cluster.close()


def _short_scene_file(tmp_path, case=None, end=10.0, interval=5.0) -> Path:
    text = bundled_scenes()["fluid-bed"].read_text()
    text = text.replace("end_time = 60.0", f"end_time = {end}")
    text = text.replace("output_interval = 5.0", f"output_interval = {interval}")
    if case is not None:
        text = text.replace('case = "bundled:fluid_bed_small"', f'case = "{case}"')
    path = tmp_path / "short.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_cli_workers_failure_and_resume(serial_short, tmp_path, monkeypatch):
    _, _, ref = serial_short
    scene_file = _short_scene_file(tmp_path)
    out = tmp_path / "run"
    monkeypatch.setenv(D.FAULT_ENV, "raise:2")
    code = main(["couple", str(scene_file), "--workers", "2", "--chunks", "3",
                 "--out", str(out)])
    assert code == 1
    assert not out.exists()                              # no output unless all succeeded
    assert sorted(p.name for p in Path(f"{out}.chunks").glob("chunk_*")) == [
        "chunk_00000.npz", "chunk_00001.npz"]
    monkeypatch.delenv(D.FAULT_ENV)
    code = main(["couple", "--resume", str(out), "--workers", "2"])  # scene, chunks: stored
    assert code == 0
    assert not Path(f"{out}.chunks").exists()
    cols = read_columns_csv(out / "bed_moments.csv")
    for k, v in ref.bed_columns.items():
        assert np.array_equal(cols[k], v), k
    assert len(list((out / "vtk").glob("*.vtu"))) == len(ref.times)
    # resume without a store is bad input
    assert main(["couple", "--resume", str(tmp_path / "nothing"), "--workers", "2"]) == 2


# ---------------------------------------------------------------------------- OpenFOAM
@pytest.mark.openfoam
def test_decomposed_case_one_task_per_processor(tmp_path):
    if shutil.which("blockMesh") is None or shutil.which("decomposePar") is None:
        pytest.skip("OpenFOAM (blockMesh, decomposePar) not installed")
    from pbe_cfd.io import openfoam as of

    os.environ.setdefault("WM_PROJECT_DIR", "/usr/share/openfoam")
    case = tmp_path / "bed"
    of.copy_case(of.default_case_dir(), case)
    of.run_case(case, end_time=0.3, avg_start=0.1)
    scene_file = _short_scene_file(tmp_path, case=str(case))
    scene = load_scene(str(scene_file))
    domain = load_domain(scene)
    ref = run_coupled(scene, domain)

    before = {p for p in case.rglob("*") if p.is_file()}
    out = tmp_path / "out"
    code = main(["couple", str(scene_file), "--workers", "2", "--decompose", "2",
                 "--foam-fields", "--out", str(out)])
    assert code == 0
    procs = D.processor_dirs(case)
    assert [p.name for p in procs] == ["processor0", "processor1"]
    decomposition = D.read_decomposition(case, domain.cells.n_cells)
    cols = read_columns_csv(out / "bed_moments.csv")
    for k, v in ref.bed_columns.items():
        assert np.array_equal(cols[k], v), k
    import json
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stats"]["cluster"]["partition"] == "processors"
    # side-by-side slabs: both processors hold bed cells, one task each
    assert summary["stats"]["cluster"]["chunks"] == 2
    # every field written into the case root is also in each processor, on its local cells
    from foamlib import FoamFieldFile
    root_new = [p for p in case.rglob("*") if p.is_file() and p not in before
                and p.parent.parent == case
                and p.relative_to(case).parts[0] not in ("system", "constant", "VTK")
                and not p.relative_to(case).parts[0].startswith("processor")]
    assert root_new, "--foam-fields wrote nothing into the case"
    for path in root_new:
        glob = np.asarray(FoamFieldFile(path).internal_field, dtype=float)
        for proc, addr in zip(procs, decomposition):
            local = proc / path.parent.name / path.name
            assert local.is_file(), local
            vals = np.asarray(FoamFieldFile(local).internal_field, dtype=float)
            assert np.array_equal(vals, glob[addr]), local

    # the API on the decomposed case: one task per processor, bitwise equal to serial
    client, cluster = D.start_local_cluster(2)
    try:
        ex = D.ClusterExecutor(client=client, decomposition=decomposition, case_dir=case)
        res = run_coupled(scene, domain, executor=ex)
        assert res.stats["cluster"]["partition"] == "processors"
        assert_same(ref, res)
    finally:
        client.close()
        cluster.close()
