"""Where one cell-RHS evaluation spends its time, from the functions the RHS itself calls
(``pbe-cfd bench throughput`` writes it as breakdown.md / breakdown.csv).

QMOM: the Wheeler recurrence with its closed-form eigen-solve (``wheeler_nodes``), the bounded
binder solve (``invert`` less Wheeler), the node and droplet property rows with the kernel's
cell factor (``particle_properties``, ``kernel_cell_factor``), the registry pair rates on those
rows (the kernel-only ceiling's loop), and the rest of the RHS (moment recurrences, droplet
terms, writes) as the full RHS less those parts. The Laguerre ROM: the tensor positions and
d43 (weight and slice interpolation, ``laguerre_d43``), the wet quadratic forms (one corner's
contraction times the corners the cells blend), and the rest (dry class, dry-wet and capture
tensors, injection). Every part is a sweep over the same cells and states as the RHS rate, one
thread, nanoseconds per cell-RHS (medians of repeats).
"""
from __future__ import annotations

import statistics
import time

import numba as nb
import numpy as np

from ..methods.dispatch import WORK_SIZE
from ..methods.laguerre.position import _slice_position, _weight_position, laguerre_d43
from ..methods.laguerre.layout import (AUX_NSLICE, AUX_NWC, AUX_NWD, N_CORNERS,
                                      weight_corner)
from ..methods.qmom.qmom import invert as qmom_invert
from ..methods.quadrature.gauss import wheeler_nodes
from ..physics import parameters as P
from ..physics.properties import N_PROPS
from .sweeps import (laguerre_contraction_sweep, node_property_rows, qmom_kernel_sweep,
                     qmom_node_properties, rhs_sweep)


@nb.njit(cache=True)
def _qmom_part_sweep(states, cells, params, config, reps, out, part):
    """The first ``part`` of the QMOM RHS per cell and repetition: 0 the Wheeler recurrence
    with its eigen-solve, 1 the whole inversion (with the binder solve), 2 the inversion with
    the property rows and the cell factor."""
    n_max = config[P.ORDER]
    nodes = np.zeros(n_max)
    weights = np.zeros(n_max)
    binder = np.zeros(n_max)
    work = np.empty(WORK_SIZE)
    props = np.zeros((n_max + 1, N_PROPS))
    n = states.shape[0]
    for c in range(n):
        for r in range(reps):
            state = states[(c + 7919 * r) % n]
            if part == 0:
                out[c] += wheeler_nodes(state, n_max, nodes, weights, work)
            elif part == 1:
                out[c] += qmom_invert(state, config, nodes, weights, binder, work)
            else:
                out[c] += node_property_rows(state, cells[c], params, config, nodes, weights,
                                             binder, work, props)[1]


@nb.njit(cache=True)
def _laguerre_position_sweep(states, cells, aux, params, config, reps, out):
    """Tensor positions and d43 of the Laguerre RHS; out[c] also counts the wet corners the
    RHS blends (slices with weight > 0 times weight-grid corners with weight > 0)."""
    m = int(aux[1])
    n = states.shape[0]
    for c in range(n):
        for r in range(reps):
            st = states[(c + 7919 * r) % n]
            i0, t = _slice_position(cells[c], aux)
            wpos = _weight_position(st, aux, m)
            d43 = laguerre_d43(st, aux, params, config)
            if r == 0:
                slices = (1.0 if t < 1.0 else 0.0) + (1.0 if t > 0.0 else 0.0)
                corners = 0.0
                for q in range(N_CORNERS):
                    if weight_corner(q, wpos, int(aux[AUX_NWC]), int(aux[AUX_NWD]))[1] != 0.0:
                        corners += 1.0
                out[c] = slices * corners
            elif d43 < 0.0 or i0 < 0:
                out[c] = -1.0                  # keeps the position work live


def _median_ns(fn, n_evals, repeats):
    fn(1)
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(None)
        walls.append(time.perf_counter() - t0)
    return 1e9 * statistics.median(walls) / n_evals


def rhs_breakdown(case, cells, states, reps=20, repeats=5, kind="nodes") -> dict:
    """ns per cell-RHS of each part (module doc) on one thread for a ThroughputCase and cell
    rows / states as the throughput study draws them; ``kind``: its method entry's
    ``bench_breakdown``, "nodes" (the QMOM's parts) or "contraction" (the Laguerre ROM's)."""
    nb.set_num_threads(1)
    params, config, aux = case.arrays.params, case.arrays.config, case.aux
    n = states.shape[0]
    evals = n * reps
    out = np.zeros_like(states)
    acc = np.zeros(n)

    def timed(call):
        return _median_ns(lambda k: call(1 if k == 1 else reps), evals, repeats)

    full = _median_ns(lambda k: rhs_sweep(states, cells, aux, params, config,
                                          1 if k == 1 else reps, out), evals, repeats)
    if kind == "nodes":
        wheeler = timed(lambda r: _qmom_part_sweep(states, cells, params, config, r, acc, 0))
        inversion = timed(lambda r: _qmom_part_sweep(states, cells, params, config, r, acc, 1))
        props = timed(lambda r: _qmom_part_sweep(states, cells, params, config, r, acc, 2))
        n_max = int(config[P.ORDER])
        rows = np.zeros((n, n_max + 1, N_PROPS))
        counts = np.zeros(n, dtype=np.int64)
        factors = np.zeros(n)
        qmom_node_properties(states, cells, params, config, rows, counts, factors)
        pairs = timed(lambda r: qmom_kernel_sweep(rows, counts, cells, factors, params, config,
                                                  r, acc))
        parts = {"Wheeler + eigen-solve": wheeler,
                 "binder solve": max(inversion - wheeler, 0.0),
                 "properties + cell factor": max(props - inversion, 0.0),
                 "pair rates": pairs}
    else:
        position = timed(lambda r: _laguerre_position_sweep(states, cells, aux, params, config,
                                                            r, acc))
        corners = float(np.mean(acc))
        one_corner = timed(lambda r: laguerre_contraction_sweep(states, aux, r, out))
        parts = {"positions + d43": position,
                 f"wet quadratic forms ({corners:.1f} corners)": corners * one_corner}
        if int(aux[AUX_NSLICE]) * int(aux[AUX_NWC]) * int(aux[AUX_NWD]) <= 1:
            parts = {"positions + d43": position, "wet quadratic form": one_corner}
    parts["rest (moment terms, droplets, writes)"] = max(full - sum(parts.values()), 0.0)
    return {"label": case.label, "full_ns": full, "parts": parts}


def breakdown_markdown(results) -> list:
    """A table per method: ns per cell-RHS and share of each part."""
    out = ["**Where one cell-RHS goes** (one thread, ns per evaluation, medians; "
           "`bench/breakdown.py`):", ""]
    for res in results:
        out += [f"*{res['label']}*: {res['full_ns']:.0f} ns per RHS", "",
                "| part | ns | share |", "|---|---|---|"]
        for name, ns in res["parts"].items():
            out.append(f"| {name} | {ns:.0f} | {100 * ns / res['full_ns']:.0f}% |")
        out.append("")
    return out
