"""Blocks of the transport operator (pbe_cfd.transport.halo): k substeps of a block over its
depth-k halo give bitwise the rows of k global substeps; a halo one hop short does not; the
partitions cover the cells in near-equal blocks and cut fewer upwind reads than a random
split. The reference here is the global product (I + dt L)^k S that Transport.transport
applies, on the bundled small case's own transport generator."""
import numpy as np
import pytest
import scipy.sparse as sp

from pbe_cfd.runs.domain import build_cells, load_domain
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.transport.halo import (advance_block, block_operators, cut_faces, halo_closure,
                                    level_partition, rcb_partition)
from pbe_cfd.transport.operator import transport_of_scene


@pytest.fixture(scope="module")
def small_transport():
    scene = load_scene("fluid-bed-transport")
    domain = load_domain(scene, need_flux=True)
    rows, active, _, _ = build_cells(scene, domain.cells)
    tr = transport_of_scene(scene, domain, active, rows)
    centres = np.asarray(domain.cells.cell_centre)[np.flatnonzero(active)]
    return tr, centres


def _global(tr, states, dt, k):
    mat = (sp.identity(tr.n, format="csr") + dt * tr.generator).tocsr()
    work = np.ascontiguousarray(states)
    for _ in range(k):
        work = mat @ work
    return work


@pytest.mark.parametrize("n_blocks", [2, 3])
def test_block_substeps_equal_the_global_ones_bitwise(small_transport, n_blocks):
    tr, _ = small_transport
    rng = np.random.default_rng(7)
    states = rng.uniform(0.5, 2.0, size=(tr.n, 5))
    k, dt = tr.substeps(0.125)
    assert k >= 2                       # several substeps: the halo depth matters
    ref = _global(tr, states, dt, k)
    labels = level_partition(tr.generator, n_blocks)
    for op in block_operators(tr.generator, labels, k):
        ext = states[op.ext]
        got = advance_block(ext, op.matrix(), dt, k)[op.own_in_ext]
        assert np.array_equal(got, ref[op.owned])
        # the halo pieces name cells of other blocks only, and fill the halo exactly
        filled = np.zeros(op.ext.size, dtype=bool)
        filled[op.own_in_ext] = True
        for a, (src, pos) in op.sources.items():
            assert a != labels[op.owned[0]]
            assert np.all(labels[op.ext[pos]] == a)
            filled[pos] = True
        assert filled.all()


def test_a_halo_one_hop_short_is_wrong(small_transport):
    tr, _ = small_transport
    rng = np.random.default_rng(8)
    states = rng.uniform(0.5, 2.0, size=(tr.n, 3))
    k, dt = tr.substeps(0.125)
    ref = _global(tr, states, dt, k)
    labels = level_partition(tr.generator, 2)
    ops = block_operators(tr.generator, labels, k - 1)
    worst = max(np.abs(advance_block(states[op.ext], op.matrix(), dt, k)[op.own_in_ext]
                       - ref[op.owned]).max() for op in ops)
    assert worst > 1e-12                # information from k hops away is missing


def test_closure_depth_grows_by_upwind_hops(small_transport):
    tr, _ = small_transport
    owned = np.array([int(np.argmax(tr.out_rate))])
    one = halo_closure(tr.generator, owned, 1)
    upwind = tr.generator[owned[0]].indices
    assert np.array_equal(one, np.union1d(owned, upwind))
    assert halo_closure(tr.generator, owned, 2).size > one.size


@pytest.mark.parametrize("kind", ["level", "rcb"])
def test_partitions_balance_and_cut_less_than_random(small_transport, kind):
    tr, centres = small_transport
    for n_blocks in (2, 3, 4):
        labels = (level_partition(tr.generator, n_blocks) if kind == "level"
                  else rcb_partition(centres, n_blocks))
        sizes = np.bincount(labels, minlength=n_blocks)
        assert sizes.sum() == tr.n and sizes.min() > 0
        assert sizes.max() - sizes.min() <= n_blocks   # near-equal source work
        rng = np.random.default_rng(n_blocks)
        random = rng.permutation(labels)
        assert cut_faces(tr.generator, labels) < 0.25 * cut_faces(tr.generator, random)
