"""The cost-weighted partition of a transport run on the workers (runs/distributed/balance):
the cost model shares the measured source seconds by right-hand-side calls and the transport
seconds evenly (the seconds are conserved); blocks out of balance under the measured costs are
re-cut into blocks of equal cost, blocks in balance are left alone. The reference for the
loads is a direct sum over the cells of each block."""
import numpy as np
import pytest

from pbe_cfd.runs.distributed.balance import (REBALANCE_ABOVE, block_loads, cell_costs,
                                              imbalance, rebalanced, weighted_level_partition)
from pbe_cfd.runs.domain import build_cells, load_domain
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.transport.halo import cut_faces, level_partition
from pbe_cfd.transport.operator import transport_of_scene


@pytest.fixture(scope="module")
def transport():
    scene = load_scene("fluid-bed-transport")
    domain = load_domain(scene, need_flux=True)
    rows, active, _, _ = build_cells(scene, domain.cells)
    return transport_of_scene(scene, domain, active, rows)


@pytest.fixture(scope="module")
def generator(transport):
    return transport.generator


def test_costs_share_each_blocks_measured_seconds():
    rhs = np.array([10, 30, 0, 60, 0, 0])
    labels = np.array([0, 0, 1, 1, 2, 2])
    w = cell_costs(rhs, labels, source_s=[2.0, 3.0, 1.0], transport_s=[0.4, 0.2, 0.6])
    # each block's costs sum to its measured seconds
    assert np.allclose(np.bincount(labels, weights=w), [2.4, 3.2, 1.6], atol=1e-12)
    # block 0: sources by the calls (0.5, 1.5 s); block 1: all to the cell with calls;
    # block 2 made no call: its sources evenly; the transport evenly in each block
    assert np.allclose(w, [0.7, 1.7, 0.1, 3.1, 0.8, 0.8], atol=1e-12)


def test_loads_against_a_direct_sum():
    labels = np.array([0, 1, 1, 0, 2])
    w = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    direct = [sum(w[c] for c in range(5) if labels[c] == b) for b in range(3)]
    assert imbalance(labels, w, 3) == pytest.approx(max(direct) / np.mean(direct), abs=1e-12)


@pytest.mark.parametrize("n_blocks", [2, 3])
def test_out_of_balance_blocks_are_recut_balanced_ones_kept(generator, n_blocks):
    n = generator.shape[0]
    equal = level_partition(generator, n_blocks)
    # costly cells in the first block of the equal-cell split (as the spray zone may be)
    w = np.where(equal == 0, 3.0, 1.0)
    new, before, after = rebalanced(generator, equal, w)
    assert before > REBALANCE_ABOVE and new is not None
    assert np.bincount(new, minlength=n_blocks).min() > 0 and new.size == n
    # the weighted cut moves at most one cell's weight per block boundary
    assert after <= 1.0 + n_blocks * w.max() / w.sum() + 1e-12
    assert after == pytest.approx(imbalance(new, w, n_blocks), abs=1e-12)
    # blocks already in balance under the costs are not moved
    kept, now, _ = rebalanced(generator, equal, np.ones(n))
    assert kept is None and now <= 1.0 + n_blocks / n


@pytest.mark.parametrize("n_blocks", [2, 3, 4])
def test_weighted_level_partition_balances_the_weights(transport, n_blocks):
    """Cut at the cumulative weight's quantiles, each block's summed weight is within one
    cell's weight of the even share (a cut moves at most the cell it falls on); the cut of
    the flux graph stays far below a random split's; equal weights give the unweighted
    blocks."""
    tr = transport
    rng = np.random.default_rng(11 + n_blocks)
    w = rng.uniform(0.5, 1.0, tr.n)
    w[: tr.n // 5] *= 4.0                  # a costly region, like the spray zone
    labels = weighted_level_partition(tr.generator, n_blocks, w)
    loads = block_loads(labels, w, n_blocks)
    assert np.bincount(labels, minlength=n_blocks).min() > 0
    assert loads.sum() == pytest.approx(w.sum(), abs=1e-9 * w.sum())
    assert np.abs(loads - w.sum() / n_blocks).max() <= w.max()
    equal = level_partition(tr.generator, n_blocks)
    # the equal-cell blocks are out of balance under these weights, the weighted are not
    assert np.abs(block_loads(equal, w, n_blocks) - w.sum() / n_blocks).max() > w.max()
    random = rng.permutation(labels)
    assert cut_faces(tr.generator, labels) < 0.25 * cut_faces(tr.generator, random)
    assert np.array_equal(weighted_level_partition(tr.generator, n_blocks, np.ones(tr.n)),
                          equal)


def test_weighted_partition_refuses_bad_weights(transport):
    tr = transport
    with pytest.raises(ValueError, match="weights"):
        weighted_level_partition(tr.generator, 2, -np.ones(tr.n))
