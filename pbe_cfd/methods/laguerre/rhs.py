"""Bivariate Laguerre reduced-order model (seed 000 section III): numba RHS and helpers.

State of one cell (float64, non-dimensional; contract with ``integrate.py``), m the order,
K = m*m, N_ref = params[NUMBER_SCALE] [1/m3], p_ref = params[MASS_SCALE] [kg]:
``state[i*m + j] = W_ij / (N_ref p_ref^(i+j))`` for i, j < m, the mixed moments of the wet
granules (binder b > 0; binder mass on the same scale as p);
``state[K + k] = D_k / (N_ref p_ref^k)`` for k < m, the moments in p of the dry granules (b = 0
exactly: wet granulation starts dry, see ``laguerre_dry``); with drying the evaporated liquid
E, and, if config[SEPARATE_DROPLETS] == 1, ``state[N_STATE - 1] = n_d / N_ref`` (free binder
droplets of mass p_d = params[DROPLET_MASS], liquid b_d; with drying they evaporate and their
liquid L_d is the entry before E: ``laguerre_layout``). The population's moments are M_ij =
W_ij + D_i delta_j0 (+ free droplets n_d p_d^i b_d^j in the output columns).

dW~_a/dt = mult [sum_{k<=l} Q[k,l,a] W~_k W~_l + sum_{k,l} X[k,l,a] D~_k W~_l
                 + n~_d sum_k Cd[k,a] W~_k + sum_e CAPMAP[e,a] L~_e]          (+ injection),
dD~_e/dt = mult [sum_{k<=l} Qdd[k,l,e] D~_k D~_l + sum_{k,l} XL[k,l,e] D~_k W~_l] - L~_e,
dn~_d/dt = -mult n~_d sum_k Cd0[k] W~_k - L~_0 + INJECTION / N_ref,
L~_e = mult n~_d sum_k Cdd[k,e] D~_k   (droplets captured by dry granules),

and with evaporating droplets (drying) the droplet's point (s p_d + l, l), l = L_d / n_d, in
the capture gains (Cd then holds the capture moments, ``capture_gain``) and the droplet
class's liquid balance (``quadrature.drying_sources.add_droplet_class_terms``),

with aux[AUX_NUMBER_POINTS] = 1 (``[method] number_closure = "points"``) the Q form's rows of
order 0 and 2 (W00, W20, W11, W02), the X, XL, Cd and Cdd rows of order <= 2 and the droplets
lost replaced by pair sums over the classes' point measures (``number_points``), and with
aux[AUX_NUMBER_POINTS] = EVERY_ROW_ON_POINTS (``"points-all"``) every wet row of Q, X and Cd,

mult = k0 N_ref F_cell, F_cell = g0(alpha) sqrt(Theta) d43^(3/2) for the ktgf kernel (1
otherwise); d43 [m] from the reconstruction: d43 = (6 / (pi rho_s))^(1/3) int p^(4/3) n /
int p n of the granules of both classes, free droplets excluded as in every method
(docs/physics.md, "d43"), falling back to the log-convex moment estimate
M_(4/3) = M_1^(2/3) M_2^(1/3) (or M_1 (M_1/M_0)^(1/3) for m = 2) if the reconstruction gives a non-positive value. All tensors
are tabulated in ln(u0) when the physical efficiency is on and the tensor was built on a Theta
grid (grid u0 = 4 sqrt(Theta / pi)); at RHS time u0 = cell[COLLISION_VELOCITY] [m/s], or
4 sqrt(cell[THETA] / pi) if that is not positive; linear interpolation in ln u0, clamped at the
grid ends. Otherwise one slice (fixed u0). With adaptive weights the wet tensors (Q, Cd, Cd0,
X, XL, F43) are also tabulated on a log grid of the wet weight means (c, d), and the terms are
blended bilinearly in (ln c, ln d) at c = p_ref W~10/W~00, d = p_ref W~01/W~00 (the wet
class's mean mass and binder [kg]; clamped at the grid ends). Every blend weight multiplies a
complete closure, so exactness for the constant kernel and the exact mass bookkeeping hold for
the blend. Formulas: ``laguerre_wet``, ``laguerre_dry``; the aux layout: ``laguerre_layout``.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.drying import cell_gas
from ...physics.kernels import KTGF, kernel_cell_factor
from ..quadrature.drying_sources import add_droplet_class_terms, droplet_point
from .admissible import (DRY_MERGE_SHARE, laguerre_conserved, laguerre_project,  # noqa: F401
                         laguerre_realizable, strictly_realizable)
from .linear_terms import add_linear_terms
from .layout import (AUX_CAPTURE_MOMENTS, AUX_NPAIR, AUX_NSLICE, AUX_NWC, AUX_NWD,
                     AUX_OFF_CAPMAP, AUX_OFF_CD, AUX_OFF_CD0, AUX_OFF_CDD, AUX_OFF_Q,
                     AUX_NUMBER_POINTS, AUX_OFF_QDD, AUX_OFF_X, AUX_OFF_XL, AUX_ORDER,
                     EVERY_ROW_ON_POINTS,
                     AUX_SEPARATE, _corner,
                     droplet_number_entry, state_names, state_size,  # noqa: F401
                     N_CORNERS, weight_corner)
from .moments import (moments_from_state, reconstruct, reconstruct_dry,  # noqa: F401
                      reconstructed_moment, support_share)
from .capture import capture_gain
from .number_points import DRY_POINT_ORDERS, add_point_terms
from .position import (_log_position, _slice_position, _weight_position,  # noqa: F401
                       LIQUID_FLOOR, binder_shift, laguerre_d43, scale_binder,
                       unscale_binder_rates)
from .tensor import build_aux, escaped_mass_share, initial_state, theta_to_u0  # noqa: F401

__all__ = ["laguerre_rhs", "laguerre_realizable", "laguerre_project", "laguerre_conserved",
           "build_aux",
           "moments_from_state", "escaped_mass_share", "reconstruct", "reconstructed_moment",
           "initial_state", "state_size", "state_names", "strictly_realizable", "theta_to_u0"]


# ---- numba core: aggregation, capture, injection -------------------------------------------
@nb.njit(cache=True)
def _any_nonzero(state, start, stop):
    for k in range(start, stop):
        if state[k] != 0.0:
            return True
    return False


@nb.njit(cache=True)
def _quadratic_form(state, first, n, out, out_first, aux, base, mult, skip=0):
    """out[out_first + a] += mult sum_{k<=l<n} T[k,l,a] s_k s_l for a < n, s =
    state[first:first+n], T the pair-major block at aux[base]; the rows a whose bit is set in
    ``skip`` are left out (``points_rows``)."""
    pos = base
    for k in range(n):
        mk = mult * state[first + k]
        for l in range(k, n):
            prod = mk * state[first + l]
            for a in range(n):
                if (skip >> a) & 1 == 0:
                    out[out_first + a] += prod * aux[pos + a]
            pos += n


@nb.njit(cache=True)
def points_rows(m):
    """Bit mask of the wet rows a = i m + j of order i + j = 0 and 2 (W00, W20, W11, W02),
    which ``number_points`` gives for the wet-wet aggregation (m <= 7: K < 63 bits)."""
    mask = 0
    for i in range(m):
        for j in range(m):
            if i + j == 0 or i + j == 2:
                mask |= 1 << (i * m + j)
    return mask


@nb.njit(cache=True)
def low_rows(m):
    """Bit mask of the wet rows a = i m + j of order i + j <= 2, which ``number_points``
    gives for the dry-wet aggregation and the droplet capture (m <= 7)."""
    mask = 0
    for i in range(m):
        for j in range(m):
            if i + j <= 2:
                mask |= 1 << (i * m + j)
    return mask


@nb.njit(cache=True)
def _dry_wet_aggregation(state, out, aux, m, px, pl, mult, skip, dry_low):
    """Dry + wet -> wet: out[a] += mult X D W (a with i >= 1), out[K + e] += mult XL D W, X
    and XL of one (weight, slice) at aux[px], aux[pl]; the wet rows whose bit is set in
    ``skip`` and the dry rows e < dry_low are left out (``low_rows``)."""
    K = m * m
    for k in range(m):
        dk = mult * state[K + k]
        if dk == 0.0:
            px += K * K
            pl += K * m
            continue
        for l in range(K):
            prod = dk * state[l]
            for a in range(m, K):
                if (skip >> a) & 1 == 0:
                    out[a] += prod * aux[px + a]
            for e in range(dry_low, m):
                out[K + e] += prod * aux[pl + e]
            px += K
            pl += m


@nb.njit(cache=True)
def _wet_capture(state, out, aux, m, c0, d0, w, skip):
    """Droplets captured by wet granules: out[a] += w sum_k Cd[k, a] W_k for the rows a whose
    bit is not set in ``skip``; returns w sum_k Cd0[k] W_k, the droplets lost (0 with a
    ``skip``: then the points give it), w = mult n~_d times the corner weight."""
    K = m * m
    loss = 0.0
    for k in range(K):
        wk = w * state[k]
        pos = c0 + k * K
        for a in range(K):
            if (skip >> a) & 1 == 0:
                out[a] += wk * aux[pos + a]
        if skip == 0:
            loss += wk * aux[d0 + k]
    return loss


@nb.njit(cache=True)
def _wet_capture_at(state, out, aux, m, c0, d0, w, xd, xl, skip):
    """Droplets of the point (xd, xl) (scaled) captured by wet granules, with the capture
    moments Cd[k, f] (AUX_CAPTURE_MOMENTS): the gain ``capture_gain`` of w sum_k Cd[k, f] W_k
    for each f, in the rows whose bit is not set in ``skip``; returns w sum_k Cd0[k] W_k,
    the droplets lost (0 with a ``skip``)."""
    K = m * m
    loss = 0.0
    if skip == 0:
        for k in range(K):
            loss += w * state[k] * aux[d0 + k]
    for f in range(K):
        moment = 0.0
        for k in range(K):
            moment += state[k] * aux[c0 + k * K + f]
        if moment != 0.0:
            capture_gain(out, w * moment, f, m, xd, xl, skip)
    return loss


@nb.njit(cache=True)
def _dry_capture(state, out, aux, m, c0, w, at_point, xd, xl, dry_low):
    """Droplets captured by dry granules: L_e = w sum_k Cdd[k, e] D_k (e >= dry_low: the
    points give the others) leaves the dry class and enters the wet one as (p + p_d)^i b_d^j,
    through the tabulated CAPMAP of the sprayed droplet, or with ``at_point``
    (AUX_CAPTURE_MOMENTS) at the droplet's scaled point (xd, xl) (the granule's own moment e
    plus ``capture_gain``); returns L_0, the droplets lost (0 with dry_low > 0)."""
    K = m * m
    cap = int(aux[AUX_OFF_CAPMAP])
    loss = 0.0
    for e in range(dry_low, m):
        acc = 0.0
        for k in range(m):
            acc += state[K + k] * aux[c0 + k * m + e]
        lost = w * acc
        out[K + e] -= lost
        if at_point:
            out[e * m] += lost
            capture_gain(out, lost, e * m, m, xd, xl, 0)
        else:
            for a in range(K):
                out[a] += aux[cap + e * K + a] * lost
        if e == 0:
            loss = lost
    return loss


#: which terms ``_aggregation_and_capture`` adds (bit flags)
AGGREGATION_TERMS = 1
CAPTURE_TERMS = 2
ALL_TERMS = AGGREGATION_TERMS | CAPTURE_TERMS
#: leave out the wet-wet aggregation's rows of order 0 and 2 (W00, W20, W11, W02), which
#: ``number_points`` then gives
WITHOUT_POINT_ROWS = 4
#: also leave out the dry-wet aggregation's and the capture's wet rows of order <= 2, dry rows
#: e < DRY_POINT_ORDERS and droplets lost, which ``number_points`` then gives
WITHOUT_CROSS_ROWS = 8
#: with both above: leave out every wet row of these terms (the points give them all)
WITHOUT_ANY_WET_ROW = 16


@nb.njit(cache=True)
def _aggregation_and_capture(state, out, aux, m, mult, nd, wet, dry, wpos, i0, t, xd, xl,
                             terms=ALL_TERMS):
    """Every aggregation and capture term (``terms``: AGGREGATION_TERMS, CAPTURE_TERMS or
    both), blended over the slice (u0) and weight corners; returns the droplets captured per
    unit time (scaled). (xd, xl): the droplet's scaled point where the capture tensors hold
    the capture moments (AUX_CAPTURE_MOMENTS); else the sprayed droplet's gain is
    tabulated."""
    K = m * m
    ns = int(aux[AUX_NSLICE])
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    npair = int(aux[AUX_NPAIR])
    capture = nd != 0.0 and aux[AUX_SEPARATE] == 1.0 and (terms & CAPTURE_TERMS) != 0
    aggregation = (terms & AGGREGATION_TERMS) != 0
    skip = points_rows(m) if (terms & WITHOUT_POINT_ROWS) != 0 else 0
    low = low_rows(m) if (terms & WITHOUT_CROSS_ROWS) != 0 else 0
    if (terms & WITHOUT_ANY_WET_ROW) != 0:
        skip = (1 << (m * m)) - 1
        low = skip
    dry_low = min(m, DRY_POINT_ORDERS) if low != 0 else 0
    at_point = aux[AUX_CAPTURE_MOMENTS] == 1.0
    loss = 0.0
    for sc in range(2):
        s, ws = _corner(sc, i0, t)
        if ws == 0.0:
            continue
        if dry:
            npd = m * (m + 1) // 2
            if aggregation:
                _quadratic_form(state, K, m, out, K, aux,
                                int(aux[AUX_OFF_QDD]) + s * npd * m, mult * ws)
            if capture:
                loss += _dry_capture(state, out, aux, m, int(aux[AUX_OFF_CDD]) + s * m * m,
                                     mult * ws * nd, at_point, xd, xl, dry_low)
        if not wet or (low == (1 << K) - 1 and dry_low >= m):
            continue                    # the points give every wet row (and the dry ones)
        for q in range(N_CORNERS):
            w, fw = weight_corner(q, wpos, nwc, nwd)
            f = ws * fw
            if f == 0.0:
                continue
            ws_ = w * ns + s
            if aggregation:
                _quadratic_form(state, 0, K, out, 0, aux,
                                int(aux[AUX_OFF_Q]) + ws_ * npair * K, mult * f, skip)
            if dry and aggregation:
                _dry_wet_aggregation(state, out, aux, m,
                                     int(aux[AUX_OFF_X]) + ws_ * m * K * K,
                                     int(aux[AUX_OFF_XL]) + ws_ * m * K * m, mult * f, low,
                                     dry_low)
            if capture and at_point:
                loss += _wet_capture_at(state, out, aux, m, int(aux[AUX_OFF_CD]) + ws_ * K * K,
                                        int(aux[AUX_OFF_CD0]) + ws_ * K, mult * f * nd, xd,
                                        xl, low)
            elif capture:
                loss += _wet_capture(state, out, aux, m, int(aux[AUX_OFF_CD]) + ws_ * K * K,
                                     int(aux[AUX_OFF_CD0]) + ws_ * K, mult * f * nd, low)
    return loss


@nb.njit(cache=True)
def _below_lowest_fraction(state, out, aux, m, mult, nd, dry, i0, t, xd, xl, shift,
                           scratch, skip=0):
    """The aggregation and capture terms of a wet class whose liquid fraction lies below the
    following tables' lowest (``position.binder_shift``: shift = ln(y_lo / y) > 0): evaluated
    on the state with the binder coordinate scaled up to y_lo in ``scratch`` (length >= K +
    m; ``position.scale_binder``) and scaled back. The droplet's liquid xl scales with it, so
    the capture gains at the droplet's point scale back exactly; a tabulated capture (the
    sprayed droplet's gain, which cannot scale), and any capture below LIQUID_FLOOR, is
    evaluated on the state itself. ``skip``: WITHOUT_POINT_ROWS and WITHOUT_CROSS_ROWS, or
    0. Returns the droplets lost."""
    K = m * m
    scale_binder(state, scratch, aux, m, K + m, shift)
    # the capture at the droplet's point scales with the class above LIQUID_FLOOR (below it
    # the class holds no liquid to speak of, and exp(shift) may overflow)
    scaled_capture = (aux[AUX_CAPTURE_MOMENTS] == 1.0
                      and state[1] >= LIQUID_FLOOR * state[m])
    loss = _aggregation_and_capture(scratch, out, aux, m, mult, nd, True, dry,
                                    _weight_position(scratch, aux, m), i0, t, xd,
                                    xl * math.exp(shift) if scaled_capture else xl,
                                    (ALL_TERMS if scaled_capture else AGGREGATION_TERMS)
                                    | skip)
    unscale_binder_rates(out, m, shift)
    if not scaled_capture:
        loss += _aggregation_and_capture(state, out, aux, m, mult, nd, True, dry,
                                         _weight_position(state, aux, m), i0, t, xd, xl,
                                         CAPTURE_TERMS | skip)
    return loss


@nb.njit(cache=True)
def laguerre_rhs(state, out, cell, aux, params, config, work=None):
    """d(state)/dt [scaled state units per s] of one cell; writes ``out`` (length N_STATE).

    state: scaled moments (module doc); cell: (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY
    [m/s], INJECTION [droplets/(m3 s)]); aux: from build_aux; params, config: physics arrays;
    work: the integrator's scratch array (K + m entries used, only where the wet class's
    liquid fraction lies below the following tables' lowest; without it that case allocates
    them).
    """
    m = int(aux[AUX_ORDER])
    K = m * m
    n = config[P.N_STATE]
    for a in range(n):
        out[a] = 0.0
    nref = params[P.NUMBER_SCALE]
    d43 = 0.0
    if config[P.KERNEL] == KTGF:
        d43 = laguerre_d43(state, aux, params, config)
        mult = nref * kernel_cell_factor(KTGF, cell[P.ALPHA], cell[P.THETA], d43, params)
    else:
        mult = params[P.RATE] * nref
    separate = config[P.SEPARATE_DROPLETS] == 1
    droplets = droplet_number_entry(config)
    nd = state[droplets] if separate else 0.0
    # one droplet now [kg]: (p_d, b_d), or the class's mean point (s p_d + l, l) with drying
    pd, bd = droplet_point(state, params, config)
    if not pd > 0.0:
        nd = 0.0                        # droplets of no mass left: nothing to capture
    wet = _any_nonzero(state, 0, K)
    dry = _any_nonzero(state, K, K + m)
    loss = 0.0
    if mult != 0.0 and (wet or dry):
        i0, t = _slice_position(cell, aux)
        xd = pd / params[P.MASS_SCALE]
        xl = bd / params[P.MASS_SCALE]
        skip = 0
        if aux[AUX_NUMBER_POINTS] != 0.0 and m >= 3:
            skip = WITHOUT_POINT_ROWS | WITHOUT_CROSS_ROWS
            if aux[AUX_NUMBER_POINTS] == EVERY_ROW_ON_POINTS:
                skip |= WITHOUT_ANY_WET_ROW
        shift = binder_shift(state, aux, m) if wet else 0.0
        if shift == 0.0:
            loss = _aggregation_and_capture(state, out, aux, m, mult, nd, wet, dry,
                                            _weight_position(state, aux, m), i0, t, xd, xl,
                                            ALL_TERMS | skip)
        elif work is None:
            loss = _below_lowest_fraction(state, out, aux, m, mult, nd, dry, i0, t, xd, xl,
                                          shift, np.empty(K + m), skip)
        else:
            loss = _below_lowest_fraction(state, out, aux, m, mult, nd, dry, i0, t, xd, xl,
                                          shift, work, skip)
        if skip != 0:
            loss += add_point_terms(state, out, cell, aux, params, config, d43, nd, pd, bd,
                                    True, (skip & WITHOUT_ANY_WET_ROW) != 0)
        if separate:
            out[droplets] = -loss
    if config[P.BREAKAGE] == 1 or config[P.DRYING] == 1:     # laguerre_breakage, _drying
        add_linear_terms(state, out, cell, aux, params, config,
                         _weight_position(state, aux, m))
    inj = cell[P.INJECTION]
    if separate:
        out[droplets] += inj / nref
        add_droplet_class_terms(state, out, inj / nref, loss, bd / params[P.MASS_SCALE],
                                cell_gas(cell, params, config), params, config)
    elif inj != 0.0:
        x = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
        xl = params[P.DROPLET_MASS] * (1.0 - params[P.DROPLET_SOLIDS]) / params[P.MASS_SCALE]
        for i in range(m):
            for j in range(m):
                out[i * m + j] += inj / nref * (x ** (i + j) if xl == x else x ** i * xl ** j)
