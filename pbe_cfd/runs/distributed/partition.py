"""Chunks of the active cells of a coupled run: contiguous blocks, or one chunk per processor
directory of a decomposed OpenFOAM case."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .store import ChunkStoreError

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
