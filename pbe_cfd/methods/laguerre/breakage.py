"""Breakage in the Laguerre ROM: a linear term in the carried moments (docs/physics.md section 8).

With the reconstruction n = sum_k M_k phi~_k (``laguerre_wet``; the dry class has its own
univariate basis psi~_k, ``laguerre_dry``), the breakage source of moment a = (i, j)
(``physics.breakage``; binary daughters, each keeping its parent's binder fraction) is

    dM_a/dt = int_S S(p) (F(i + j) - 1) p^i b^j n = F_cell sum_k L[k, a] M_k,
    L[k, a] = int_S S_unit(p) (F(i + j) - 1) p^i b^j phi~_k,

S = F_cell S_unit: every selection of the registry is a cell factor F_cell [1/s] (s0, or
s0 g0(alpha) sqrt(Theta / Theta_ref) x the Stokes deformation gate) times a particle part
S_unit [-] (1, or (p / p_ref)^a), so the matrices do not depend on the cell: F_cell is evaluated
per cell at RHS time and nothing is tabulated on the Theta grid. The wet class's matrix depends
on its weight (one per slice of the adaptive weight grid, blended as the other wet tensors);
the dry class's is one m x m matrix (under the following support at m = 3 the dry rows are
taken on the Gauss rule of the dry class's own gamma instead: ``linear_terms``). Dry granules
break into dry daughters (b = 0 stays 0) and wet ones into wet daughters (b > 0 stays > 0): no
cross terms. Free droplets never break.

The integrals use each class's quadrature on the support; with the consistent reconstruction
(int_S p^i b^j phi~_k = delta_ak) L is exact for a constant selection (L = diag(F - 1)).
F(1) = 1 exactly for every daughter rule, so the mass and binder rows (i + j = 1) are exactly
zero and M10, M01 stay exact.

Units: the wet quadrature works in internal coordinates u = p / c, v = b / d (moments M_int =
M~ r, ``laguerre_wet``); ``linear_block`` returns L in state units (M~ = M / (N_ref
p_ref^(i+j))), laid out [k, a] like the droplet-capture matrices. The aux block at
aux[AUX_OFF_BREAK] holds L_wet[w, k, a] for every weight slice w, then L_dry[k, e].
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.breakage import (cell_selection_factor, daughter_moment_factor,
                                 selection_function)
from .basis import moment_index
from .layout import (AUX_NWC, AUX_NWD, AUX_NWL, AUX_OFF_BREAK, AUX_ORDER, N_CORNERS,
                     weight_corner)


def breakage_on(config) -> bool:
    """True if the scene has a [breakage] table (config[BREAKAGE] == 1)."""
    return int(config[P.BREAKAGE]) == 1


def unit_selection(p_nodes, params, config):
    """S_unit(p) [-] at the granule masses p_nodes [kg]: the selection function with a unit
    cell factor (the cell's factor [1/s] multiplies at RHS time)."""
    code = int(config[P.BREAKAGE_SELECTION])
    q = np.ascontiguousarray(params, dtype=np.float64)
    return np.array([selection_function(code, float(p), 1.0, q) for p in p_nodes])


def daughter_gains(exponents, config):
    """F(i + j) - 1 [-] for each moment (i, j) of ``exponents`` (state order); exactly 0 for
    i + j = 1 (F(1) = 1: the daughters keep the parent's mass and binder)."""
    code = int(config[P.BREAKAGE_DAUGHTERS])
    gains = np.array([daughter_moment_factor(code, float(i + j)) - 1.0 for i, j in exponents])
    gains[[i + j == 1 for i, j in exponents]] = 0.0
    return gains


def linear_block(monomials, weighted_basis, selection, gains, scale):
    """L[k, a] [state units, per unit cell factor] of one class.

    monomials: (N, K) u^i v^j (or x^e) at the N quadrature nodes; weighted_basis: (N, K)
    phi~_k times the quadrature weight; selection: (N,) S_unit; gains: (K,) F(i + j) - 1;
    scale: (K,) r_a with M_int = M~ r (ones for the dry class, already in state units).
    """
    T = (monomials * selection[:, None]).T @ weighted_basis          # T[a, k]
    T *= gains[:, None]
    return (T * scale[None, :] / scale[:, None]).T


def breakage_blocks(params, config, m, bases, dry):
    """The flat aux block of the breakage term: L_wet[w, k, a] for each wet basis of ``bases``
    (``laguerre_wet.wet_basis``: nodes u, v, masses p [kg], weights W, basis PhiC, scaling r),
    then L_dry[k, e] (``laguerre_dry.dry_class``: nodes x = p / p_ref, weights w, state-unit
    basis psi, masses p [kg]). An empty array without breakage."""
    if not breakage_on(config):
        return np.zeros(0)
    idx = moment_index(m)
    gains = daughter_gains(idx, config)
    blocks = []
    for basis in bases:
        mon = np.stack([basis["u"] ** i * basis["v"] ** j for (i, j) in idx], axis=1)
        sel = unit_selection(basis["p"], params, config)
        blocks.append(linear_block(mon, basis["PhiC"] * basis["W"][:, None], sel, gains,
                                   basis["r"]))
    mon_d = dry["x"][:, None] ** np.arange(m)[None, :]
    gains_d = daughter_gains([(e, 0) for e in range(m)], config)
    blocks.append(linear_block(mon_d, dry["psi"] * dry["w"][:, None],
                               unit_selection(dry["p"], params, config), gains_d, np.ones(m)))
    return np.concatenate([b.ravel() for b in blocks])


@nb.njit(cache=True, inline="always")
def add_linear_term(state, out, aux, offset, n, first_in, first_out, factor):
    """out[first_out + a] += factor sum_k L[k, a] state[first_in + k], a, k < n, L the
    [k, a] block at aux[offset] (``linear_block``); nothing when factor == 0."""
    if factor == 0.0:
        return
    pos = offset
    for k in range(n):
        w = factor * state[first_in + k]
        if w != 0.0:
            for a in range(n):
                out[first_out + a] += w * aux[pos + a]
        pos += n


@nb.njit(cache=True)
def add_laguerre_breakage(state, out, cell, aux, params, config, wpos, dry_rows):
    """Add the breakage sources [scaled state units per s] of one cell to ``out``: the wet
    class's L blended over the weight corners wpos (``weight_corner``) of the RHS and, where
    ``dry_rows`` is True, the dry class's L_dry, both times the cell factor F_cell [1/s] of the
    cell row (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s]). Returns F_cell [1/s] (0
    without a breakage block); free droplets are untouched."""
    o = int(aux[AUX_OFF_BREAK])
    if o <= 0:
        return 0.0
    factor = cell_selection_factor(cell, params, config)
    if factor == 0.0:
        return 0.0
    m = int(aux[AUX_ORDER])
    K = m * m
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    for q in range(N_CORNERS):
        w, f = weight_corner(q, wpos, nwc, nwd)
        if f != 0.0:
            add_linear_term(state, out, aux, o + w * K * K, K, 0, 0, factor * f)
    if dry_rows:
        add_dry_breakage_matrix(state, out, aux, factor)
    return factor


@nb.njit(cache=True)
def add_dry_breakage_matrix(state, out, aux, factor):
    """Add the dry class's breakage rows of its fixed weight, F_cell L_dry D~ [scaled per s]
    (factor = F_cell [1/s]), to ``out``; nothing without a breakage block."""
    o = int(aux[AUX_OFF_BREAK])
    if o <= 0:
        return
    m = int(aux[AUX_ORDER])
    K = m * m
    n_weights = int(aux[AUX_NWC]) * int(aux[AUX_NWD]) * max(1, int(aux[AUX_NWL]))
    add_linear_term(state, out, aux, o + n_weights * K * K, m, K, K, factor)
