"""Drying in the Laguerre ROM: a linear operator on the wet moments (docs/physics.md section 15).

A wet granule (p, b) loses liquid at e(p, b) (``physics.drying.drying_rate``), dp/dt = db/dt =
-e. In the wet class's internal coordinates u = p / c, v = b / d (``laguerre_wet``) the moment
M_int_a = int u^i v^j n du dv drifts at

    dM_int_a/dt = - int e (i u^(i-1) v^j / c + j u^i v^(j-1) / d) n du dv,

and with the reconstruction n = sum_k M_int_k phi~_k (linear in the state) this is

    dM~_a/dt = sum_k L[k, a] M~_k,
    L[k, a] = - (r_k / r_a) sum_s W_s e_s (i u_s^(i-1) v_s^j / c + j u_s^i v_s^(j-1) / d)
              phi~_k(s),

over the wet quadrature (nodes s, weights W_s, ``wet_basis``), r_a = p_ref^(i+j) / (c^i d^j)
the state scaling. The evaporated liquid E~ = E / (N_ref p_ref) gains
dE~/dt = sum_k V[k] M~_k, V[k] = (r_k / p_ref) sum_s W_s e_s phi~_k(s): the same sums as the
rows (1, 0) and (0, 1) of L with the opposite sign, so M10 + E and M01 + E are invariants of
the operator to round-off. Everything is a function of the weight (c, d, lambda, gamma) and its
quadrature through the ``bases`` the tables are built from: one block per weight slice of the
adaptive grid, blended at RHS time as the breakage and aggregation tensors are.

The dry class (b = 0 exactly) does not dry, and the falling rate makes e vanish with b, so no
granule crosses from the wet class into the dry one: the drift leaves the dry moments alone.
Free droplets of their own do not dry (as in every method).

The reconstruction is not a positive measure, so V.M~ need not vanish with the wet liquid
M01. For any positive density on the nodes, E = sum_s w_s e_s <= r_max sum_s w_s b_s =
r_max M01 with r_max = max_s e_s / b_s, the fastest relative rate of the slice's nodes. The
drift is therefore scaled by one factor g = min(1, r_max M01 / (V.M~)) (g = 0 where M01 <= 0
or V.M~ <= 0: no liquid, no evaporation, no condensation) on L and V alike, which keeps
M10 + E, M01 + E and the binder solids M10 - M01 exact and gives dM01/dt >= -r_max M01 from
the drying: the wet liquid decays at most exponentially and never crosses zero through it.
Where the reconstruction is a positive measure g = 1 and the operator is the linear one.
The aux block at aux[AUX_OFF_DRYING] holds, per weight slice w, L[w, k, a] (K x K), V[w, k]
(K) then r_max[w] [1/s].
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.drying import drying_rate
from .basis import moment_index
from .breakage import add_laguerre_breakage, add_linear_term
from .layout import (AUX_NWC, AUX_NWD, AUX_OFF_DRYING, AUX_ORDER, N_CORNERS,
                     weight_corner)

#: state entry of the wet liquid M~01: (i, j) = (0, 1) in ``moment_index`` order (order >= 2)
WET_LIQUID = moment_index(2).index((0, 1))


def drying_on(config) -> bool:
    """True if the scene has a [drying] table (config[DRYING] == 1)."""
    return int(config[P.DRYING]) == 1


def node_rates(p, b, params):
    """e [kg/s] at the wet quadrature nodes (masses p, liquid b [kg]) at the scene's slip
    velocity (params[DRY_SLIP] [m/s])."""
    q = np.ascontiguousarray(params, dtype=np.float64)
    slip = float(q[P.DRY_SLIP])
    return np.array([drying_rate(float(pk), float(min(max(bk, 0.0), pk)), slip, q)
                     for pk, bk in zip(p, b)])


def drift_block(basis, rates, m, p_ref):
    """(L[k, a], V[k]) of one weight slice [state units per s] (module docstring). basis:
    ``laguerre_wet.wet_basis`` (nodes u, v, weights W, basis PhiC, scaling r, weight means c,
    d [kg]); rates: e [kg/s] at its nodes; p_ref [kg]."""
    u, v, c, d = basis["u"], basis["v"], basis["c"], basis["d"]
    weighted = basis["PhiC"] * (basis["W"] * rates)[:, None]             # (N, K)
    drift = np.zeros((len(u), m * m))
    for a, (i, j) in enumerate(moment_index(m)):
        if i > 0:
            drift[:, a] += i * u ** (i - 1) * v ** j / c
        if j > 0:
            drift[:, a] += j * u ** i * v ** (j - 1) / d
    T = -(drift.T @ weighted)                                            # T[a, k]
    r = basis["r"]
    L = (T * r[None, :] / r[:, None]).T
    V = weighted.sum(axis=0) * r / p_ref
    return L, V


def fastest_relative_rate(rates, b):
    """r_max = max_s e_s / b_s [1/s] over the nodes with liquid (b_s > 0 [kg], e_s [kg/s]);
    0 without any."""
    wet = np.asarray(b) > 0.0
    return float(np.max(np.asarray(rates)[wet] / np.asarray(b)[wet])) if wet.any() else 0.0


def drying_blocks(params, config, m, bases, p_ref):
    """The flat aux block of the drying term: (L[w], V[w], r_max[w]) for each wet basis of
    ``bases``; an empty array without drying."""
    if not drying_on(config):
        return np.zeros(0)
    blocks = []
    for basis in bases:
        rates = node_rates(basis["p"], basis["b"], params)
        L, V = drift_block(basis, rates, m, p_ref)
        blocks += [L.ravel(), V, np.array([fastest_relative_rate(rates, basis["b"])])]
    return np.concatenate(blocks)


@nb.njit(cache=True)
def add_laguerre_drying(state, out, aux, config, wpos):
    """Add the drying drift [scaled state units per s] of one cell to ``out``: the wet moments
    (entries 0 .. K-1) by L, the evaporated liquid (the last entry) by V, both blended over
    the weight corners wpos (``weight_corner``) of the RHS and scaled by the one factor g of
    the module docstring (evaporation at most r_max M01). Nothing without a drying block."""
    o = int(aux[AUX_OFF_DRYING])
    if o <= 0:
        return
    m = int(aux[AUX_ORDER])
    K = m * m
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    evaporated = config[P.N_STATE] - 1
    stride = K * K + K + 1
    rate = 0.0                                    # V.M~, blended
    r_max = 0.0                                   # r_max, blended
    for q in range(N_CORNERS):
        w, f = weight_corner(q, wpos, nwc, nwd)
        if f == 0.0:
            continue
        pos = o + w * stride
        for k in range(K):
            rate += f * aux[pos + K * K + k] * state[k]
        r_max += f * aux[pos + K * K + K]
    liquid = state[WET_LIQUID]
    if liquid <= 0.0 or rate <= 0.0:
        return
    g = min(1.0, r_max * liquid / rate)
    for q in range(N_CORNERS):
        w, f = weight_corner(q, wpos, nwc, nwd)
        if f == 0.0:
            continue
        pos = o + w * stride
        add_linear_term(state, out, aux, pos, K, 0, 0, f * g)
    out[evaporated] += g * rate


@nb.njit(cache=True)
def add_linear_terms(state, out, cell, aux, params, config, wpos):
    """The linear terms of the ROM's RHS: breakage (``laguerre_breakage``, with a [breakage]
    table) and drying (with a [drying] table), at the weight corners wpos of the RHS."""
    if config[P.BREAKAGE] == 1:
        add_laguerre_breakage(state, out, cell, aux, params, config, wpos)
    if config[P.DRYING] == 1:
        add_laguerre_drying(state, out, aux, config, wpos)
