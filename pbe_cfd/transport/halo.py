"""The transport operator cut into blocks of cells: a partition of the active cells that keeps
the cut of the flux graph small, and for each block the rows of the upwind generator over the
block and its halo, so that a block advances its own cells through k explicit substeps from
its own states and the states of its halo alone.

Why a halo of depth k. One substep is S <- B S with B = I + dt L (``Transport.step_matrix``);
row c of B reads the cells upwind of c. After k substeps cell c depends on the cells within k
upwind hops of it. A block therefore holds the extended set E_k = its cells plus every cell
within k hops (``halo_closure``); applying the restriction of B to E_k k times leaves the rows
at depth j in E_k correct after k - j substeps, so the block's own cells (depth 0) are exact
after k. Each row of the local matrix keeps the entries of the global row in the same order
(the column map is monotone), so every owned cell sees the same floating-point operations as
in the global product: the block result is bitwise the serial one.

Partition. Where the case has a processor decomposition, its blocks are used as they are
(``runs.distributed.processor_partition``). Otherwise a partition of our own, with no
dependency and deterministic: ``rcb_partition`` (recursive coordinate bisection of the cell
centres, each cut normal to the longest extent at the median: equal numbers of cells, so equal
source work per block) where centres are known, and ``level_partition`` (contiguous runs of a
reverse Cuthill-McKee order of the flux graph) where only the operator is. On the box-like
beds here both cut along a section of the bed, the smallest cut a balanced split can have,
which is what a graph partitioner such as METIS finds on such meshes too; ``cut_faces``
reports the cut of the partition used.

All sizes are counts; the generator is in 1/s; substeps dt in s.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .substeps import apply_substeps


# ---------------------------------------------------------------------------- partition
def rcb_partition(centres, n_blocks: int) -> np.ndarray:
    """Block label (0..n_blocks-1) of each of the n cells with centres ``centres`` (n, 3) [m]:
    recursive coordinate bisection, blocks of near-equal size (differ by at most one cell
    per level). Labels are numbered in the order of the cuts (deterministic)."""
    centres = np.asarray(centres, dtype=float)
    n = centres.shape[0]
    n_blocks = max(1, min(int(n_blocks), n))
    labels = np.zeros(n, dtype=np.int64)

    def split(cells, first, count):
        if count == 1:
            labels[cells] = first
            return
        ext = np.ptp(centres[cells], axis=0)
        axis = int(np.argmax(ext))
        left_count = count // 2
        n_left = int(round(cells.size * left_count / count))
        order = cells[np.argsort(centres[cells, axis], kind="stable")]
        split(np.sort(order[:n_left]), first, left_count)
        split(np.sort(order[n_left:]), first + left_count, count - left_count)

    split(np.arange(n), 0, n_blocks)
    return labels


def level_partition(generator: sp.csr_matrix, n_blocks: int) -> np.ndarray:
    """Block label (0..n_blocks-1) of each cell from the flux graph alone: the cells in reverse
    Cuthill-McKee order (breadth-first level sets of the symmetrised upwind graph, from a
    peripheral cell) cut into ``n_blocks`` contiguous runs of near-equal size. Each cut falls
    inside one level set, a section of the bed, so the cut stays near the smallest section
    the breadth-first fronts cross; used where neither a processor decomposition nor cell
    centres are at hand."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = generator.shape[0]
    n_blocks = max(1, min(int(n_blocks), n))
    pattern = abs(generator) + abs(generator).T
    order = np.asarray(reverse_cuthill_mckee(pattern.tocsr(), symmetric_mode=True))
    labels = np.empty(n, dtype=np.int64)
    for b, run in enumerate(np.array_split(order, n_blocks)):
        labels[run] = b
    return labels


def cut_faces(generator: sp.csr_matrix, labels) -> int:
    """Number of nonzero off-diagonal entries of the generator that join two blocks (the
    upwind reads that cross a block boundary) [-]."""
    coo = generator.tocoo()
    off = coo.row != coo.col
    labels = np.asarray(labels)
    return int(np.count_nonzero(labels[coo.row[off]] != labels[coo.col[off]]))


# ---------------------------------------------------------------------------- halos
def halo_closure(generator: sp.csr_matrix, owned: np.ndarray, depth: int) -> np.ndarray:
    """Ascending positions of the cells within ``depth`` upwind hops of the cells ``owned``
    (positions into the generator's rows), the owned cells included."""
    n = generator.shape[0]
    mask = np.zeros(n, dtype=bool)
    mask[owned] = True
    pattern = generator.copy()
    pattern.data = np.ones_like(pattern.data)
    reads = pattern.T.tocsr()         # column j of row c -> row j of the transpose
    for _ in range(int(depth)):
        grown = mask | (reads @ mask.astype(np.float64) > 0.0)
        if np.array_equal(grown, mask):
            break
        mask = grown
    return np.flatnonzero(mask)


@dataclass
class BlockOperator:
    """The generator over one block and its halo.

    owned       (n_b,) positions (into the active cells) this block advances, ascending
    ext         (m,) positions of the block and its halo, ascending (owned is a subset)
    own_in_ext  (n_b,) where the owned cells sit in ``ext``
    data, indices, indptr  the CSR rows of the generator [1/s] over ``ext`` (local columns)
    sources     {block a: (positions into a's owned cells, positions into ext)} the halo
    """
    owned: np.ndarray
    ext: np.ndarray
    own_in_ext: np.ndarray
    data: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    sources: dict

    @property
    def halo_cells(self) -> int:
        """Cells of the halo [-]."""
        return int(self.ext.size - self.owned.size)

    def matrix(self) -> sp.csr_matrix:
        """The local generator [1/s] as a CSR matrix over ``ext``."""
        m = self.ext.size
        return sp.csr_matrix((self.data, self.indices, self.indptr), shape=(m, m))


def block_operators(generator: sp.csr_matrix, labels, depth: int) -> list:
    """One BlockOperator per block label (0..max) for substep counts up to ``depth``.
    ``generator``: the transport generator L [1/s] (CSR with sorted indices); ``labels`` (n,)
    the block of each active cell."""
    gen = generator.tocsr()
    if not gen.has_sorted_indices:
        gen = gen.copy()
        gen.sort_indices()
    labels = np.asarray(labels, dtype=np.int64)
    n_blocks = int(labels.max()) + 1 if labels.size else 0
    owned_of = [np.flatnonzero(labels == b) for b in range(n_blocks)]
    local_of = np.full(labels.size, -1, dtype=np.int64)
    for owned in owned_of:
        local_of[owned] = np.arange(owned.size)
    out = []
    for b, owned in enumerate(owned_of):
        ext = halo_closure(gen, owned, depth)
        glob2loc = np.full(labels.size, -1, dtype=np.int64)
        glob2loc[ext] = np.arange(ext.size)
        sub = gen[ext]                              # rows keep their column order
        cols = glob2loc[sub.indices]
        keep = cols >= 0
        row = np.repeat(np.arange(ext.size), np.diff(sub.indptr))
        counts = np.bincount(row[keep], minlength=ext.size)
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        halo = ext[labels[ext] != b]
        sources = {}
        for a in np.unique(labels[halo]):
            cells = halo[labels[halo] == a]
            sources[int(a)] = (local_of[cells], glob2loc[cells])
        out.append(BlockOperator(owned=owned, ext=ext, own_in_ext=glob2loc[owned],
                                 data=sub.data[keep].copy(), indices=cols[keep].copy(),
                                 indptr=indptr, sources=sources))
    return out


def advance_block(ext_states: np.ndarray, local_generator: sp.csr_matrix, dt: float,
                  k: int) -> np.ndarray:
    """k substeps of length dt [s] of S <- (I + dt L) S on the states of a block and its halo
    (m, n_state), as ``Transport.transport`` applies them to all cells. Returns the new
    (m, n_state) array; only the rows within depth 0 of the block are exact after k."""
    m = local_generator.shape[0]
    mat = (sp.identity(m, format="csr") + float(dt) * local_generator).tocsr()
    return apply_substeps(mat, ext_states, k)
