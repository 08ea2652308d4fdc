"""A partition of the flux graph weighted by each cell's measured cost, for a transport run
with the states on the workers (``halo_run``).

Why: blocks of equal cells are not blocks of equal work. A cell of the spray zone takes more
integrator steps than one outside it (the droplets' capture and the wet granules' growth are
fast), so under a partition of equal cells the run waits at every split step for the block
that holds more of the spray zone. The cost of a cell is known after it has been integrated:
over one output interval each block reports the wall seconds its tasks spent in the sources
and in the transport, and every cell its right-hand-side evaluations (the
``RHS_CALLS`` counter, Jacobian columns included). The cost model is then, for cell c of
block b,

    w_c = S_b * r_c / sum_{c' in b} r_c' + T_b / n_b

with S_b and T_b the source and transport seconds of block b in the interval, r_c the
right-hand-side calls of cell c and n_b the cells of b: each block's measured seconds shared
among its cells by their evaluations (the sources) and evenly (the transport: the same few
operations per cell and substep). The measured seconds, not the calls alone, set the blocks'
totals because a call does not cost the same everywhere: a stiff cell's calls come with
Jacobians and linear solves (on the bundled small case the block holding the spray zone
took 2.6 times the seconds of the other in an interval where the calls predicted 1.7). The
partition is ``weighted_level_partition``: the reverse Cuthill-McKee order of
``transport.halo.level_partition`` (level sets of the flux graph, sections of the bed), cut
into runs of equal summed cost instead of equal cells, so the cut still falls along a section
of the bed.

When: at an output time, where the client holds every cell's counters anyway (nothing extra
crosses the network to measure), if the current blocks' predicted loads (the weights summed
per block) differ by more than ``REBALANCE_ABOVE`` from their mean and the weighted
partition predicts a lower maximum. A re-placement sends every block its cells once (the
bytes of one output time's gather). Results do not depend on the partition (``halo_run``):
the re-partitioned run is bitwise the serial one.
"""
from __future__ import annotations

import numpy as np

from ...integrate import codes

#: Predicted max/mean block load above which an output time re-partitions (ours: a
#: re-placement costs about one output time's gather, a few per cent of an interval's wall).
REBALANCE_ABOVE = 1.05


def weighted_level_partition(generator, n_blocks: int, weights) -> np.ndarray:
    """Block label (0..n_blocks-1) of each cell: the cells in reverse Cuthill-McKee order of
    the symmetrised flux graph (as ``transport.halo.level_partition``) cut into
    ``n_blocks`` contiguous runs of near-equal summed ``weights`` (n,) (a cell's cost, any
    unit, >= 0): each run's sum is within one cell's weight of the even share. Every block
    keeps at least one cell."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = generator.shape[0]
    n_blocks = max(1, min(int(n_blocks), n))
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ValueError(f"weighted_level_partition: weights must be {n} finite values >= 0")
    pattern = abs(generator) + abs(generator).T
    order = np.asarray(reverse_cuthill_mckee(pattern.tocsr(), symmetric_mode=True))
    cum = np.cumsum(w[order])
    total = float(cum[-1]) if n else 0.0
    if total <= 0.0:
        cum, total = np.arange(1.0, n + 1.0), float(n)
    # run b ends where the cumulative weight first reaches (b + 1) / n_blocks of the total
    want = np.searchsorted(cum, total * np.arange(1, n_blocks) / n_blocks, side="left") + 1
    cuts, prev = [], 0
    for j, c in enumerate(want):
        prev = int(min(max(int(c), prev + 1), n - (n_blocks - 1 - j)))
        cuts.append(prev)
    labels = np.empty(n, dtype=np.int64)
    for b, run in enumerate(np.split(order, cuts)):
        labels[run] = b
    return labels


def block_loads(labels, weights, n_blocks: int) -> np.ndarray:
    """Summed weight of each block (the unit of ``weights``)."""
    return np.bincount(np.asarray(labels, dtype=np.int64),
                       weights=np.asarray(weights, dtype=float), minlength=int(n_blocks))


def cell_costs(rhs_calls, labels, source_s, transport_s) -> np.ndarray:
    """Cost of each cell over one interval [s] (see the module): ``rhs_calls`` (n,) the
    right-hand-side evaluations of each cell in the interval, ``labels`` (n,) the block
    that integrated it, ``source_s`` and ``transport_s`` (n_blocks,) the wall seconds [s]
    of each block's source and transport tasks in the interval. Each block's source seconds
    are shared among its cells by their calls (evenly if none made one), its transport
    seconds evenly: the costs of a block sum to its measured seconds."""
    r = np.asarray(rhs_calls, dtype=float)
    labels = np.asarray(labels, dtype=np.int64)
    src = np.asarray(source_s, dtype=float)
    trs = np.asarray(transport_s, dtype=float)
    n_blocks = src.size
    cells = np.bincount(labels, minlength=n_blocks).astype(float)
    calls = np.bincount(labels, weights=r, minlength=n_blocks)
    per_call = np.divide(src, calls, out=np.zeros(n_blocks), where=calls > 0)
    even = np.divide(src, cells, out=np.zeros(n_blocks), where=cells > 0)
    per_cell = np.divide(trs, cells, out=np.zeros(n_blocks), where=cells > 0)
    return np.where(calls[labels] > 0, per_call[labels] * r, even[labels]) + per_cell[labels]


def imbalance(labels, weights, n_blocks: int) -> float:
    """Largest block load over the mean block load [-] (1: balanced)."""
    loads = block_loads(labels, weights, n_blocks)
    mean = float(loads.mean()) if loads.size else 0.0
    return float(loads.max()) / mean if mean > 0.0 else 1.0


def rhs_calls(stats) -> np.ndarray:
    """The right-hand-side calls column (n,) of per-cell counters (n, N_STATS) [-]."""
    return np.array(np.asarray(stats)[:, codes.RHS_CALLS], dtype=np.int64)


def rebalanced(generator, labels, weights, threshold: float = REBALANCE_ABOVE):
    """New block labels balancing ``weights`` (``weighted_level_partition``), or None
    when the current ``labels`` are within ``threshold`` (max/mean) or the weighted
    partition would not lower the largest block load. Returns (labels or None, predicted
    imbalance now, predicted imbalance of the new labels)."""
    labels = np.asarray(labels, dtype=np.int64)
    n_blocks = int(labels.max()) + 1 if labels.size else 0
    now = imbalance(labels, weights, n_blocks) if n_blocks else 1.0
    if n_blocks < 2 or now <= threshold:
        return None, now, now
    new = weighted_level_partition(generator, n_blocks, weights)
    after = imbalance(new, weights, n_blocks)
    if after >= now:
        return None, now, after
    return new, now, after
