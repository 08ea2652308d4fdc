"""The output-time watch of the Laguerre ROM's granule number (``MethodEntry.output_watch``).

Aggregation alone can only lower the granule number: for any positive population
d(M00)/dt = -1/2 of the double integral of beta n n <= 0 (beta >= 0). The ROM's RHS applies
the kernel to the signed m-term reconstruction, and where that density's negative part weighs
enough the RHS's aggregation rate of W00 + D0 turns positive: M00 then grows although the
carried moments stay realizable and d43 positive (docs/physics.md 9.2, the bed proxy of
docs/results/laguerre.md). At every output time ``number_rates`` evaluates, per cell, that
rate exactly as ``laguerre_rhs`` does (the cell's own collision-velocity slice blend, weight
blend and kernel multiplier k0 N_ref F_cell; capture moves no granule number and is left
out) together with the sum of the absolute values of its terms, A. A cell is flagged when
rate > (n + 8) eps A: the bound of the round-off of a recursive sum of n products of at most
five factors each (gamma_(n+4) <= (n + 4) eps / (1 - (n + 4) eps) with eps = 2^-52, doubled),
so only a reconstruction whose rate is positive in exact arithmetic is flagged; a positive
population gives rate <= -0 in exact arithmetic and never a flag.

It warns and does not stop: the positive rate is a local flaw of the reconstruction whose
effect on M00 accumulates (the proxy's M00 stays within 6% of QMOM N = 3 at the first
positive rate, ~1000 s, and ends +29% at 1800 s), so the run's other moments (M10, M01 exact
to round-off; d43 within 3.1% of QMOM there) stay answers; the warning says M00 is not.
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.kernels import KTGF, kernel_cell_factor
from .layout import (AUX_NPAIR, AUX_NUMBER_POINTS, AUX_NSLICE, AUX_NWC, AUX_NWD, AUX_OFF_Q,
                     AUX_OFF_QDD, AUX_OFF_XL, AUX_ORDER, N_CORNERS, _corner, weight_corner)
from .position import (_slice_position, _weight_position, binder_shift, laguerre_d43,
                       scale_binder)

#: machine epsilon of float64 [-]
EPS = 2.0 ** -52


@nb.njit(cache=True)
def _pair_sum(state, first, n, aux, base, f):
    """(sum, sum of |terms|) of f sum_{k<=l<n} T[k,l,0] s_k s_l, s = state[first:first+n],
    T the pair-major block at aux[base] (component 0: the number)."""
    r = 0.0
    a = 0.0
    pos = base
    for k in range(n):
        fk = f * state[first + k]
        for l in range(k, n):
            term = fk * state[first + l] * aux[pos]
            r += term
            a += abs(term)
            pos += n
    return r, a


@nb.njit(cache=True)
def number_rate(state, cell, aux, params, config):
    """(rate, A, n) of one cell: the aggregation rate of the granule number W00 + D0 of
    ``laguerre_rhs`` [scaled number per s, N_ref = 1], the sum A of the absolute values of its
    n terms (same units) and n. state: scaled moments; cell: the cell's row (ALPHA [-],
    THETA [m2/s2], COLLISION_VELOCITY [m/s]); aux, params, config: the run's arrays."""
    m = int(aux[AUX_ORDER])
    K = m * m
    wet = False
    dry = False
    for k in range(K):
        wet = wet or state[k] != 0.0
    for k in range(K, K + m):
        dry = dry or state[k] != 0.0
    if not (wet or dry):
        return 0.0, 0.0, 0
    nref = params[P.NUMBER_SCALE]
    if config[P.KERNEL] == KTGF:
        mult = nref * kernel_cell_factor(KTGF, cell[P.ALPHA], cell[P.THETA],
                                         laguerre_d43(state, aux, params, config), params)
    else:
        mult = params[P.RATE] * nref
    if mult == 0.0:
        return 0.0, 0.0, 0
    i0, t = _slice_position(cell, aux)
    wpos = _weight_position(state, aux, m)
    ns = int(aux[AUX_NSLICE])
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    npair = int(aux[AUX_NPAIR])
    npd = m * (m + 1) // 2
    rate = 0.0
    total = 0.0
    n = 0
    for sc in range(2):
        s, ws = _corner(sc, i0, t)
        if ws == 0.0:
            continue
        if dry:
            r, a = _pair_sum(state, K, m, aux, int(aux[AUX_OFF_QDD]) + s * npd * m, mult * ws)
            rate += r
            total += a
            n += npd
        if not wet:
            continue
        for q in range(N_CORNERS):
            w, fw = weight_corner(q, wpos, nwc, nwd)
            f = ws * fw
            if f == 0.0:
                continue
            ws_ = w * ns + s
            r, a = _pair_sum(state, 0, K, aux, int(aux[AUX_OFF_Q]) + ws_ * npair * K,
                             mult * f)
            rate += r
            total += a
            n += npair
            if dry:                       # dry + wet -> wet: D0 loses one (XL, e = 0)
                pl = int(aux[AUX_OFF_XL]) + ws_ * m * K * m
                for k in range(m):
                    dk = mult * f * state[K + k]
                    for l in range(K):
                        term = dk * state[l] * aux[pl + (k * K + l) * m]
                        rate += term
                        total += abs(term)
                n += m * K
    return rate, total, n


@nb.njit(cache=True)
def number_rates(states, rows, aux, params, config):
    """Per cell (one row of ``states`` and ``rows`` each): the aggregation rate of the
    granule number over the granule number [1/s] and True where that rate exceeds its
    round-off floor (module doc)."""
    nc = states.shape[0]
    rel = np.zeros(nc)
    flag = np.zeros(nc, dtype=np.bool_)
    m = int(aux[AUX_ORDER])
    K = m * m
    scaled = np.empty(states.shape[1])
    for c in range(nc):
        # as the RHS: a wet class below the lowest tabulated fraction at its scaled state
        shift = binder_shift(states[c], aux, m)
        if shift != 0.0:
            scale_binder(states[c], scaled, aux, m, states.shape[1], shift)
            rate, total, n = number_rate(scaled, rows[c], aux, params, config)
        else:
            rate, total, n = number_rate(states[c], rows[c], aux, params, config)
        m00 = states[c, 0] + states[c, K]
        if m00 > 0.0:
            rel[c] = rate / m00
        flag[c] = rate > (n + 8) * EPS * total
    return rel, flag


class NumberWatch:
    """What the output times found (``update``), for one warning line (``text``) and the
    run's summary (``stats``): the first flagged cell and time, the distinct cells flagged,
    the output times with a flag, the largest relative rate [1/s]."""

    def __init__(self):
        self.first = None               # (time [s], cell name, relative rate [1/s])
        self.cells = set()
        self.times = 0
        self.largest = 0.0
        self.order = 0

    @property
    def count(self) -> int:
        return len(self.cells)

    def update(self, t, states, rows, aux, arrays, cell_ids=None) -> bool:
        """Evaluate the cells at output time t [s]; True if any was flagged. With the wet
        number row on the point measure (aux[AUX_NUMBER_POINTS] = 1) the RHS's rate is not
        positive by construction: nothing to watch."""
        if aux[AUX_NUMBER_POINTS] != 0.0:
            return False
        rel, flag = number_rates(np.ascontiguousarray(states, dtype=np.float64),
                                 np.ascontiguousarray(rows, dtype=np.float64), aux,
                                 arrays.params, arrays.config)
        self.order = int(aux[AUX_ORDER])
        hit = np.flatnonzero(flag)
        if hit.size == 0:
            return False
        ids = hit if cell_ids is None else np.asarray(cell_ids)[hit]
        if self.first is None:
            c = int(hit[0])
            name = "well-mixed" if cell_ids is None else f"cell {int(ids[0])}"
            self.first = (float(t), name, float(rel[c]))
        self.cells.update(int(i) for i in ids)
        self.times += 1
        self.largest = max(self.largest, float(rel[hit].max()))
        return True

    def text(self) -> str:
        t, name, r = self.first
        return (f"laguerre: the aggregation rate of the granule number M00 is positive in "
                f"{self.count} cell(s) at {self.times} output time(s), first in {name} at "
                f"t = {t:.6g} s (+{r:.3g} of M00 per s; largest +{self.largest:.3g} per s): "
                f"the m = {self.order} reconstruction is not a population there (its negative part, "
                "weighted by the collision kernel, makes aggregation create granules), so M00 "
                "is not trustworthy from that time on (the mass moments M10, M01 stay exact); "
                "qmom or cqmom keep the number rate negative (docs/physics.md 9.2)")

    def stats(self) -> dict:
        return {"positive_number_rate_cells": self.count,
                "positive_number_rate_output_times": self.times,
                "positive_number_rate_first_time_s": self.first[0],
                "positive_number_rate_largest_per_s": self.largest}


def output_watch():
    """A new ``NumberWatch`` for one run (``MethodEntry.output_watch``)."""
    return NumberWatch()
