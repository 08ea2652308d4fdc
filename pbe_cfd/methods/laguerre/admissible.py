"""Admissibility, linear invariants and the post-step fix of a Laguerre cell state (numba).

State layout: ``rhs`` (module doc). ``laguerre_realizable`` accepts RK stages,
``laguerre_conserved`` gives the integrator the invariants M10 and M01, ``laguerre_project``
clips the free droplets, merges a vanishing dry class into the wet one and spreads a dried
class's last liquid over its mass.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid
from ..quadrature.drying_sources import set_droplet_invariants
from .layout import AUX_CHECK_LEVEL, AUX_FOLLOWING, droplet_number_entry, evaporated_entry
from .position import LIQUID_FLOOR, mass_moment

__all__ = ["laguerre_realizable", "laguerre_project", "laguerre_conserved",
           "strictly_realizable", "DRY_MERGE_SHARE"]

#: the dry class is merged into the wet one once it holds less than this share of the granules
DRY_MERGE_SHARE = 1e-12
#: round-off floor of a moment relative to the largest carried moment of its total order [-]
ROUND_OFF = 1e-12


@nb.njit(cache=True)
def _order_floors(state, m, K, n):
    """Round-off floors per total order i + j of the moments (ROUND_OFF times the largest
    |W_ij| with i + j = order and |D_order| of the dry class), and of the entries past the
    classes (free droplets, drying): ROUND_OFF times the largest of them and of the number
    and mass scales. The entries span many decades (on the bed W22 ~ 6e12 against
    W00 ~ 2e-4 in state units), so one floor relative to the largest entry would accept any
    sign of W00, W10."""
    floors = np.zeros(2 * m)
    for i in range(m):
        for j in range(m):
            v = abs(state[i * m + j])
            if v > floors[i + j]:
                floors[i + j] = v
    for k in range(m):
        v = abs(state[K + k])
        if v > floors[k]:
            floors[k] = v
    extra = max(floors[0], floors[1])
    for k in range(K + m, n):
        extra = max(extra, abs(state[k]))
    floors[2 * m - 1] = extra
    for k in range(2 * m):
        floors[k] *= ROUND_OFF
    return floors


@nb.njit(cache=True)
def _wet_checks(state, m, top, level, floors, rel):
    """Sign, b <= p and Cauchy-Schwarz conditions on the wet moments (laguerre_realizable);
    floors[n] the round-off floor of the moments of total order n."""
    if state[0] < 0.0:
        return False
    for i in range(m):
        for j in range(m):
            if i + j <= top and state[i * m + j] < -floors[i + j]:
                return False
    if m > 1 and state[1] > state[m] * (1.0 + rel) + floors[1]:     # W01 <= W10
        return False
    if level < 1:
        return True
    # b <= p: W_(i,j+1) <= W_(i+1,j)
    for i in range(m - 1):
        for j in range(m - 1):
            if i + j + 1 > top:
                continue
            if state[i * m + j + 1] > state[(i + 1) * m + j] * (1.0 + rel) + floors[i + j + 1]:
                return False
    # Cauchy-Schwarz W_(e+f)^2 <= W_(2e) W_(2f)
    h = (m - 1) // 2
    for e1 in range(h + 1):
        for e2 in range(h + 1):
            for f1 in range(h + 1):
                for f2 in range(h + 1):
                    if f1 * (h + 1) + f2 <= e1 * (h + 1) + e2:
                        continue
                    s1 = e1 + f1
                    s2 = e2 + f2
                    if s1 >= m or s2 >= m:
                        continue
                    if max(2 * (e1 + e2), 2 * (f1 + f2)) > top:
                        continue
                    mid = state[s1 * m + s2]
                    tol = floors[s1 + s2]
                    if mid * mid > (state[2 * e1 * m + 2 * e2] * state[2 * f1 * m + 2 * f2]
                                    * (1.0 + rel) + tol * tol):
                        return False
    return True


@nb.njit(cache=True)
def _moment_checks(state, config, level):
    """Admissibility of a scaled state at a check level (see laguerre_realizable)."""
    m = config[P.ORDER]
    K = m * m
    n = config[P.N_STATE]
    for i in range(n):
        if not math.isfinite(state[i]):
            return False
    floors = _order_floors(state, m, K, n)
    rel = 1e-10
    for k in range(K + m, n):                   # free droplets
        if state[k] < -floors[2 * m - 1]:
            return False
    top = 2 * (m - 1) if level >= 2 else 2      # highest total order i + j checked
    if not _wet_checks(state, m, top, level, floors, rel):
        return False
    for k in range(m):                          # dry class
        if k <= top and state[K + k] < -floors[k]:
            return False
    if level >= 1:                              # Hankel: D_(e+f)^2 <= D_2e D_2f
        for e in range((m - 1) // 2 + 1):
            for f in range(e + 1, (m - 1) // 2 + 1):
                if max(2 * e, 2 * f) > top:
                    continue
                mid = state[K + e + f]
                tol = floors[e + f]
                if mid * mid > state[K + 2 * e] * state[K + 2 * f] * (1.0 + rel) + tol * tol:
                    return False
    return True


@nb.njit(cache=True)
def laguerre_realizable(state, aux, params, config, work=None):
    """True if the scaled state is admissible for the ROM (used to accept RK stages).

    Level aux[AUX_CHECK_LEVEL] (build_aux(check_level=...)), tol of a moment of total order
    i + j = 1e-12 times the largest |W_ij|, |D_(i+j)| of that order (of the droplets and
    drying entries: 1e-12 times the largest of them, |W00|, |W10|, |D0|, |D1|), relative slack
    1e-10 (an exact monodisperse start with equalities passes):
    0 (default): every entry finite; W00 >= 0; W10, W01, W11, W20, W02 >= -tol (the wet
      moments of total order <= 2); W01 <= W10 (b <= p); D0, D1, D2 >= -tol; free droplets
      n_d >= -tol.
    1: also W02 <= W11 <= W20 and Cauchy-Schwarz W10^2 <= W00 W20, W01^2 <= W00 W02,
      W11^2 <= W20 W02, D1^2 <= D0 D2.
    2: all of these for every carried order (W_(i,j+1) <= W_(i+1,j), W_(e+f)^2 <= W_2e W_2f,
      D_(e+f)^2 <= D_2e D_2f, every entry >= -tol).
    The reconstruction is a signed expansion and is not checked. Why level 0 is the default:
    from the seed scenario's dry delta start (on the Cauchy-Schwarz boundary, variance 0) the
    m = 4 consistent ROM's vector field points outward (its p-variance shrinks at t = 0), so
    level 1 stalls the integrator at t ~ 3e-7 s; W21, W22 go transiently negative for m = 3.
    """
    return _moment_checks(state, config, int(aux[AUX_CHECK_LEVEL]))


def strictly_realizable(state, config, level=2):
    """True if the moment conditions of ``level`` (default: all orders) hold."""
    return bool(_moment_checks(np.asarray(state, float), np.asarray(config, np.int64), level))


@nb.njit(cache=True)
def laguerre_conserved(config, params, pivots, coefs):
    """Linear invariants of the ROM state for the time integrator: rows c of ``coefs``
    (n_inv, N_STATE) with c . d(state)/dt independent of the state (the injection only):
    granule mass M10 = W10 + D1 (wet and dry classes) and binder mass M01 = W01 (the dry
    class holds none), each plus the droplets' x_d n_d and x_l n_d (x_d = p_d / p_ref, x_l =
    b_d / p_ref their liquid; with evaporating droplets their solids x_d - x_l and liquid L_d)
    and drying's E.
    ``pivots[r]`` is the entry with coefficient 1 (W10, W01). Returns the count."""
    m = config[P.ORDER]
    n = config[P.N_STATE]
    K = m * m
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    xl = droplet_liquid(params) / params[P.MASS_SCALE]
    for r in range(2):
        for k in range(n):
            coefs[r, k] = 0.0
        pivots[r] = m if r == 0 else 1          # W10 at (1, 0), W01 at (0, 1)
        coefs[r, pivots[r]] = 1.0
        if r == 0:
            coefs[r, K + 1] = 1.0               # dry D1
        if not set_droplet_invariants(coefs, r, params, config):
            if config[P.SEPARATE_DROPLETS] == 1 and n > K + m:
                coefs[r, droplet_number_entry(config)] = xd if r == 0 else xl
        if config[P.DRYING] == 1:
            coefs[r, evaporated_entry(config)] = 1.0
    return 2


@nb.njit(cache=True)
def spread_dried_liquid(state, m):
    """Set the wet class's liquid moments W_ij (j >= 1, W01 kept) to those of its liquid
    fraction y = W01 / W10 in every granule, y^j M_(i+j) (``position.mass_moment``): the
    post-step fix of a class dried below LIQUID_FLOOR. Invariants (W10, W01) and the mass
    moments kept."""
    y = state[1] / state[m]
    for i in range(m):
        f = 1.0
        for j in range(1, m):
            f *= y
            if i == 0 and j == 1:
                continue
            state[i * m + j] = f * mass_moment(state, m, i + j)


@nb.njit(cache=True)
def laguerre_project(state, aux, params, config, work=None):
    """In-place fix after an accepted step: clips a negative free-droplet density to 0,
    merges a dry class holding less than DRY_MERGE_SHARE of the granules into the wet class
    (W_k0 += D_k, D = 0: mass and number conserved, the dry tensors no longer evaluated), and
    with the following support spreads the liquid of a wet class dried below LIQUID_FLOOR in
    proportion to the mass (``spread_dried_liquid``; W01 and the mass moments kept; a W01 the
    falling rate's last step left a round-off below 0 is returned from the evaporated liquid
    E, so M01 + E is unchanged, and the class holds none).

    The moments themselves are otherwise left untouched (the ROM has no cheaper admissible
    neighbour).
    """
    m = config[P.ORDER]
    K = m * m
    if config[P.SEPARATE_DROPLETS] == 1 and config[P.N_STATE] > K + m:
        d = droplet_number_entry(config)
        if state[d] < 0.0:
            state[d] = 0.0
    d0 = state[K]
    if d0 != 0.0 and abs(d0) <= DRY_MERGE_SHARE * (state[0] + abs(d0)):
        for k in range(m):
            state[k * m] += state[K + k]
            state[K + k] = 0.0
    if (aux[AUX_FOLLOWING] == 1.0 and state[0] > 0.0 and state[m] > 0.0
            and state[1] < LIQUID_FLOOR * state[m]):       # the following support: m >= 3
        if state[1] < 0.0 and config[P.DRYING] == 1:
            # the falling rate's last step took a round-off more liquid than there was:
            # returned from the evaporated liquid, so M01 + E stays what it was
            state[evaporated_entry(config)] += state[1]
            state[1] = 0.0
        spread_dried_liquid(state, m)
