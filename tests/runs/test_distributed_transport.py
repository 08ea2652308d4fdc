"""Transport on a Dask cluster with the states on the workers (runs/distributed/halo_run):
on 2 and 3 blocks over a 2-worker local cluster the run equals the serial one bitwise, on the
bundled small case and on a small 3-D bed; the client's traffic per split step does not grow
with the cells; a failed block and a lost worker are named, and --resume from the last stored
output time gives the uninterrupted result."""
import dataclasses

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from pbe_cfd.io.openfoam.bed3d import VTU_NAME, write_bed  # noqa: E402
from pbe_cfd.runs import distributed as D  # noqa: E402
from pbe_cfd.runs.couple import run_coupled  # noqa: E402
from pbe_cfd.runs.domain import load_domain  # noqa: E402
from pbe_cfd.scene.scene import load_scene  # noqa: E402

pytestmark = pytest.mark.slow


def assert_same(ref, res):
    """Bitwise equal cell fields at every output time, bed columns and step counts."""
    assert len(ref.cell_fields) == len(res.cell_fields)
    for a, b in zip(ref.cell_fields, res.cell_fields):
        for k in a:
            assert np.array_equal(a[k], b[k]), k
    for k in ref.bed_columns:
        assert np.array_equal(ref.bed_columns[k], res.bed_columns[k]), k
    for k in ("accepted_steps", "rejected_error", "rejected_realizability", "rhs_calls"):
        assert ref.stats[k] == res.stats[k], k
    assert (ref.stats["transport"]["qmom_binder_repairs"]
            == res.stats["transport"]["qmom_binder_repairs"])


def scene_of(case=None, end=1.0, interval=0.5):
    scene = load_scene("fluid-bed-transport")
    scene = dataclasses.replace(scene, end_time=end, output_interval=interval)
    if case is not None:
        scene = dataclasses.replace(scene, domain=dataclasses.replace(scene.domain,
                                                                      case=str(case)))
    return scene


@pytest.fixture(scope="module")
def client():
    client, cluster = D.start_local_cluster(2)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def problems(tmp_path_factory):
    """(scene, domain, serial result) of the small case and of a 3-D bed of ~700 cells."""
    bed = tmp_path_factory.mktemp("bed3d")
    write_bed(bed, 700)
    out = {}
    for name, case in (("small", None), ("3d", bed / VTU_NAME)):
        scene = scene_of(case)
        domain = load_domain(scene, need_flux=True)
        out[name] = (scene, domain, run_coupled(scene, domain))
    return out


@pytest.mark.parametrize("case", ["small", "3d"])
@pytest.mark.parametrize("blocks", [2, 3])
def test_states_on_the_workers_equal_serial(client, problems, case, blocks):
    scene, domain, ref = problems[case]
    ex = D.ClusterExecutor(client=client, chunks=blocks)
    res = run_coupled(scene, domain, executor=ex)
    assert_same(ref, res)
    rep = res.stats["cluster"]["transport"]
    assert rep["blocks"] == blocks and rep["split_steps"] == 4
    assert len(set(rep["workers_of_blocks"])) == 2          # both workers hold blocks
    # the halo is a fraction of the cells, the client sends task messages only
    n_active = int(ref.stats["active_cells"])
    assert sum(rep["halo_cells"]) < blocks * n_active
    assert rep["gathered_bytes_per_output_time"] >= n_active * 8 * 5   # states once per output


@pytest.mark.parametrize("blocks", [2, 3])
def test_blocks_recut_by_measured_cost_equal_serial(client, problems, blocks):
    """Re-partitioned at the output time by the measured cost of each cell (``balance=1.0``:
    whenever the weighted cut lowers the largest predicted block load): the cells move to
    other blocks and the result is still bitwise the serial run's."""
    scene, domain, ref = problems["3d"]
    res = run_coupled(scene, domain, executor=D.ClusterExecutor(client=client, chunks=blocks,
                                                                balance=1.0))
    assert_same(ref, res)
    rep = res.stats["cluster"]["transport"]
    assert [r["output"] for r in rep["rebalanced"]] == [1]    # the last output time: none
    moved = rep["rebalanced"][0]
    assert moved["moved"] and moved["predicted_after"] < moved["predicted_before"]
    assert len(rep["block_cells"]) == blocks and sum(rep["block_cells"]) == \
        ref.stats["active_cells"]
    assert len(rep["block_source_s_per_interval"]) == 2


@pytest.mark.parametrize("per_exchange", [1, 4])
def test_shallow_halo_exchanged_per_round_equals_serial(client, problems, per_exchange):
    """Halos exchanged every ``per_exchange`` substeps (a halo that many hops deep) instead
    of once per transport part: still bitwise the serial run, with a halo no deeper than
    asked and smaller than the one-exchange-per-part halo."""
    scene, domain, ref = problems["3d"]
    deep = run_coupled(scene, domain, executor=D.ClusterExecutor(client=client, chunks=2))
    res = run_coupled(scene, domain, executor=D.ClusterExecutor(
        client=client, chunks=2, halo_substeps=per_exchange))
    assert_same(ref, res)
    rep, rep_deep = (r.stats["cluster"]["transport"] for r in (res, deep))
    assert rep_deep["substeps_per_part"] > per_exchange       # the split is a real one
    assert rep["halo_depth_substeps"] == per_exchange
    assert sum(rep["halo_cells"]) < sum(rep_deep["halo_cells"])


def test_client_traffic_does_not_grow_with_the_cells(client, tmp_path):
    write_bed(tmp_path, 3000)
    sent = {}
    cells = {}
    for case in ("small", "3d"):
        scene = scene_of(tmp_path / VTU_NAME if case == "3d" else None)
        domain = load_domain(scene, need_flux=True)
        res = run_coupled(scene, domain, executor=D.ClusterExecutor(client=client, chunks=2))
        sent[case] = res.stats["cluster"]["transport"]["client_sent_bytes_per_split_step"]
        cells[case] = res.stats["active_cells"]
    assert cells["3d"] > 1.5 * cells["small"]
    # same number of blocks: the same task messages (keys and floats), whatever the cells;
    # the states alone would be cells * n_state * 8 bytes
    assert sent["3d"] < 1.1 * sent["small"]
    assert sent["3d"] < 0.5 * cells["3d"] * 8 * 5


def test_failed_block_is_named_and_resumed(client, problems, tmp_path):
    scene, domain, ref = problems["small"]
    store = tmp_path / "tr.chunks"
    ex = D.ClusterExecutor(client=client, chunks=2, store_dir=store,
                           fault=D.parse_fault("raise:1@0.5"))
    with pytest.raises(D.ChunksFailed, match=r"source step 0\.5.*1 \(block 1"):
        run_coupled(scene, domain, executor=ex)
    assert ex.store.stored_steps() == [1]
    again = D.ClusterExecutor(client=client, chunks=2, store_dir=store, resume=True)
    res = run_coupled(scene, domain, executor=again)
    assert res.stats["cluster"]["transport"]["resumed_from_output"] == 1
    assert_same(ref, res)


def test_lost_worker_is_named_and_resume_gives_the_uninterrupted_run(problems, tmp_path):
    scene, domain, ref = problems["3d"]
    store = tmp_path / "lost.chunks"
    client, cluster = D.start_local_cluster(2)
    try:
        ex = D.ClusterExecutor(client=client, chunks=2, store_dir=store,
                               fault=D.parse_fault("exit:1@0.5"))
        with pytest.raises(D.ChunksFailed) as err:
            run_coupled(scene, domain, executor=ex)
        assert set(err.value.failed) == {1}
        assert "KilledWorker: worker tcp://" in err.value.failed[1] and "lost" in str(err.value)
        assert ex.store.stored_steps() == [1]
    finally:
        client.close()
        cluster.close()
    client, cluster = D.start_local_cluster(2)
    try:
        again = D.ClusterExecutor(client=client, chunks=2, store_dir=store, resume=True)
        res = run_coupled(scene, domain, executor=again)
        assert res.stats["cluster"]["transport"]["resumed_from_output"] == 1
        assert_same(ref, res)
    finally:
        client.close()
        cluster.close()
