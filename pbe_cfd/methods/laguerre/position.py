"""Where a Laguerre cell state sits on the tabulated grids, and its d43 (numba).

The tensors are tabulated on a log grid of the collision velocity u0 (slices) and, with
adaptive weights, on a log grid of the wet weight's parameters; ``_slice_position`` and
``_weight_position`` give the lower index and the upper point's weight on each axis, which the
RHS (``laguerre_rhs``), breakage, drying and d43 blend with ``layout.weight_corner``.
``laguerre_d43`` [m] is the kinetic-theory kernel's volume-mean diameter of the granules.
"""
import math

import numba as nb

from ...physics import parameters as P
from .layout import (AUX_FOLLOWING, AUX_MASS_SCALE, AUX_NSLICE, AUX_NWC, AUX_NWD, AUX_NWL,
                     AUX_OFF_F43, AUX_OFF_F43D, AUX_OFF_LOGU, AUX_OFF_LOGW, AUX_ORDER,
                     N_CORNERS, weight_corner)

__all__ = ["laguerre_d43"]


@nb.njit(cache=True)
def _log_position(lx, aux, o, n):
    """(lower index, weight of the upper point) of lx on the sorted grid aux[o:o+n], clamped
    at the ends."""
    if n <= 1:
        return 0, 0.0
    if lx <= aux[o]:
        return 0, 0.0
    if lx >= aux[o + n - 1]:
        return n - 2, 1.0
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if aux[o + mid] <= lx:
            lo = mid
        else:
            hi = mid
    return lo, (lx - aux[o + lo]) / (aux[o + lo + 1] - aux[o + lo])


@nb.njit(cache=True)
def _slice_position(cell, aux):
    """(index of the lower u0 slice, interpolation weight of the upper one)."""
    ns = int(aux[AUX_NSLICE])
    if ns <= 1:
        return 0, 0.0
    u0 = cell[P.COLLISION_VELOCITY]
    if not (u0 > 0.0):
        theta = cell[P.THETA]
        if not (theta > 0.0):
            return 0, 0.0
        u0 = 4.0 * math.sqrt(theta / math.pi)
    return _log_position(math.log(u0), aux, int(aux[AUX_OFF_LOGU]), ns)


@nb.njit(cache=True)
def _weight_position(state, aux, m):
    """Adaptive weights: (ic, tc, jd, td, il, tl), the (lower index, upper weight) of the wet
    class's mean mass W10/W00 and mean binder W01/W00 [kg] on the weight grid (following
    support: the mass-weighted mean mass W20 / W10 [kg], the binder fraction W01 / W10 [-]
    and the carried gamma shape W10^2 / (W00 W20 - W10^2) [-], all in logs; the shape index
    is (-1, 0.0) without a shape axis, which ``weight_corner`` reads as bilinear)."""
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    if nwc * nwd <= 1 or not (state[0] > 0.0) or not (state[m] > 0.0):
        return 0, 0.0, 0, 0.0, 0, 0.0
    o = int(aux[AUX_OFF_LOGW])
    pref = aux[AUX_MASS_SCALE]
    il, tl = (0, 0.0) if int(aux[AUX_NWL]) > 1 else (-1, 0.0)
    if aux[AUX_FOLLOWING] == 1.0:          # mass-weighted mean mass W20 / W10
        if not (state[2 * m] > 0.0):
            return 0, 0.0, 0, 0.0, 0, 0.0
        ic, tc = _log_position(math.log(state[2 * m] / state[m] * pref), aux, o, nwc)
        nwl = int(aux[AUX_NWL])
        if nwl > 1:
            var = state[0] * state[2 * m] - state[m] * state[m]
            if var > 0.0:
                il, tl = _log_position(math.log(state[m] * state[m] / var), aux,
                                       o + nwc + nwd, nwl)
            else:                          # a delta: the narrowest shape
                il, tl = nwl - 2, 1.0
    else:
        ic, tc = _log_position(math.log(state[m] / state[0] * pref), aux, o, nwc)
    if not (state[1] > 0.0):
        return ic, tc, 0, 0.0, il, tl
    if aux[AUX_FOLLOWING] == 1.0:          # ratio d / c = W01 / W10
        jd, td = _log_position(math.log(state[1] / state[m]), aux, o + nwc, nwd)
    else:
        jd, td = _log_position(math.log(state[1] / state[0] * pref), aux, o + nwc, nwd)
    return ic, tc, jd, td, il, tl


#: liquid fraction W01 / W10 of a wet class below which, with the following support, its
#: liquid is taken as spread in proportion to the mass (``admissible.laguerre_project``) and
#: its aggregation is that of such a class (``scale_binder``), ours: a moisture of 1e-6
#: kg/kg, far below any a granule holds in a real bed, where W02 ~ y^2 W20 is still above the
#: default absolute tolerance (1e-14 on the scaled state) for the beds' W20 ~ 1e-2 .. 1e2.
#: Below it the falling rate takes the liquid on towards 1e-300 within minutes, and the
#: moments of b^2 lie beneath any tolerance (docs/physics.md section 9.2)
LIQUID_FLOOR = 1e-6


@nb.njit(cache=True)
def mass_moment(state, m, n):
    """M_n [scaled] of the wet class in p: W_n0 where carried (n < m), beyond it the gamma of
    the carried W00, W10, W20 (M_(k+1) = M_k theta (shape + k), the following weight's own
    shape), or the delta at W10 / W00 where that variance is not positive (m >= 3)."""
    if n < m:
        return state[n * m]
    mean = state[m] / state[0]
    var = state[2 * m] / state[0] - mean * mean
    out = state[(m - 1) * m]
    if not var > 0.0:
        for k in range(m - 1, n):
            out *= mean
        return out
    theta = var / mean
    shape = mean / theta
    for k in range(m - 1, n):
        out *= theta * (shape + k)
    return out


@nb.njit(cache=True)
def _lowest_log_fraction(aux):
    """ln y_lo, the lowest binder fraction of the following weight's grid [-]."""
    return aux[int(aux[AUX_OFF_LOGW]) + int(aux[AUX_NWC])]


@nb.njit(cache=True)
def binder_shift(state, aux, m):
    """0.0, or ln(y_lo / y) > 0 (inf for y = 0) where the wet class's liquid fraction
    y = W01 / W10 lies below the lowest binder fraction y_lo of the following weight's tables
    (drying takes it there). The aggregation and capture of such a class are evaluated on its
    state with the binder coordinate scaled up to y_lo (``scale_binder``) and scaled back
    (``unscale_binder_rates``): the tables' quadrature is the same in b / y at every low
    fraction (``build.FRACTION_SPAN``), so this is exact where the kernel and efficiencies do
    not depend on the binder, and otherwise evaluates them at y_lo (docs/physics.md 9.2)."""
    if aux[AUX_FOLLOWING] != 1.0 or not (state[0] > 0.0) or not (state[m] > 0.0):
        return 0.0
    if not state[1] > 0.0:
        return math.inf
    lowest = _lowest_log_fraction(aux)
    ly = math.log(state[1] / state[m])
    if ly >= lowest:
        return 0.0
    return lowest - ly


@nb.njit(cache=True)
def scale_binder(state, out, aux, m, n, shift):
    """out[:n] = state[:n] with the wet class's binder coordinate scaled by exp(shift)
    (``binder_shift``): W_ij exp(j shift); a class below LIQUID_FLOOR (its liquid spread in
    proportion to the mass, or none) as that class at y_lo, y_lo^j M_(i+j) (``mass_moment``),
    which no overflow of exp(j shift) reaches."""
    for k in range(n):
        out[k] = state[k]
    uniform = not (state[1] >= LIQUID_FLOOR * state[m])
    y_lo = math.exp(_lowest_log_fraction(aux))
    for i in range(m):
        for j in range(1, m):
            if uniform:
                out[i * m + j] = y_lo ** j * mass_moment(state, m, i + j)
            else:
                out[i * m + j] = state[i * m + j] * math.exp(j * shift)


@nb.njit(cache=True)
def unscale_binder_rates(out, m, shift):
    """Rates of the scaled state back to the state's: out[i m + j] *= exp(-j shift) for the
    wet moments (0 for shift = inf; the moments of b^0 are unchanged by the scaling)."""
    for i in range(m):
        for j in range(1, m):
            out[i * m + j] = out[i * m + j] * math.exp(-j * shift)


@nb.njit(cache=True)
def laguerre_d43(state, aux, params, config):
    """Volume-mean diameter d43 [m] of the cell's granules, the ktgf kernel's d43 (free
    droplets excluded, docs/physics.md "d43")."""
    m = int(aux[AUX_ORDER])
    K = m * m
    pref = params[P.MASS_SCALE]
    wpos = _weight_position(state, aux, m)
    nwc = int(aux[AUX_NWC])
    nwd = int(aux[AUX_NWD])
    m43 = 0.0
    for q in range(N_CORNERS):
        w, f = weight_corner(q, wpos, nwc, nwd)
        if f == 0.0:
            continue
        o = int(aux[AUX_OFF_F43]) + w * K
        acc = 0.0
        for k in range(K):
            acc += aux[o + k] * state[k]
        m43 += f * acc
    od = int(aux[AUX_OFF_F43D])
    for k in range(m):
        m43 += aux[od + k] * state[K + k]
    m0 = state[0] + state[K]
    m1 = state[m] + state[K + 1] if m > 1 else 0.0
    m2 = state[2 * m] + state[K + 2] if m > 2 else 0.0
    if not (m1 > 0.0):
        return 0.0
    if aux[AUX_FOLLOWING] == 1.0 and m > 2 and m0 > 0.0 and m2 > 0.0:
        # the signed reconstruction of a broad population can put M_(4/3) anywhere: keep it
        # within the bounds of any positive measure with these M0, M1, M2 (ln M_s convex in s)
        lo = m1 * (m1 / m0) ** (1.0 / 3.0)
        hi = m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
        m43 = min(max(m43, lo), hi)
    if not (m43 > 0.0):
        if m > 2 and m2 > 0.0:
            m43 = m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
        elif m0 > 0.0:
            m43 = m1 * (m1 / m0) ** (1.0 / 3.0)
        else:
            return 0.0
    return (6.0 * pref / (math.pi * params[P.DENSITY])) ** (1.0 / 3.0) * m43 / m1
