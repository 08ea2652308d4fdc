"""Free droplets of the cNMC box that dry (docs/physics.md section 15, "Free droplets in the
cNMC"): a droplet is a particle (p, b) [kg] of its own, sprayed at (p_d, b_d) and drying like
a granule between events (``cnmc.drying``), so the droplets of a box have many masses.

* Capture: a granule i captures droplet j at droplet_factor x the pair rate of (p_i, b_i) with
  (p_j, b_j) (``capture_rate``), under the majorant over the droplets' mass interval
  [smallest droplet, p_d] (a droplet only shrinks after it is sprayed at p_d).
* A pure-liquid droplet ends at exactly zero mass (``physics.drying.liquid_sphere_after``):
  it has left the population, and its slot takes a copy of a random particle of mass
  (``refill_vanished``, the constant-number step of Smith and Matsoukas 1998 for a loss; the
  volume P / C follows from the mass balance).
* The kernel's d43 (granules only) takes the droplets out of the box sums by their mean mass
  and mean d^4, refreshed at every drift (``droplet_stats``; between drifts the droplets
  sprayed or captured are counted at that mean).

The droplet statistics live in the box's drying array: dry[3] the smallest droplet mass [kg],
dry[4] the mean droplet mass [kg], dry[5] the mean droplet d^4 [m^4]; without drying they stay
p_d, p_d, d4(p_d) (every droplet is (p_d, b_d)). Masses in kg."""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.rates import aggregation_rate, droplet_capture_rate
from .slots import d4
from .slots import insert_slot as _insert
from .slots import remove_slot as _remove

#: entries of the box's drying array: evaporated, last drift, proposals, droplet statistics,
#: then the longest step between two drifts [s] (``cnmc.drying.DRIFT_SHARE``)
DRY_ENTRIES = 7
DRIFT_STEP = 6


@nb.njit(cache=True)
def new_drying_array(pd, rho):
    """The box's drying array (module docstring) at the start: nothing evaporated, no drift,
    every droplet (p_d [kg]) at density rho [kg/m3]."""
    dry = np.zeros(DRY_ENTRIES)
    dry[3] = pd
    dry[4] = pd
    dry[5] = d4(pd, rho)
    dry[DRIFT_STEP] = np.inf
    return dry


@nb.njit(cache=True)
def droplet_stats(p, dlist, dcnt, pd, rho, dry):
    """Refresh dry[3:6] (module docstring) from the box's droplets (slots dlist[:dcnt[0]],
    masses p [kg]); p_d [kg] and d4(p_d) while there are none."""
    nd = dcnt[0]
    lo, mean, mean4 = pd, pd, d4(pd, rho)
    if nd > 0:
        s = 0.0
        s4 = 0.0
        for i in range(nd):
            k = dlist[i]
            lo = min(lo, p[k])
            s += p[k]
            s4 += d4(p[k], rho)
        mean, mean4 = s / nd, s4 / nd
    dry[3] = lo
    dry[4] = mean
    dry[5] = mean4


@nb.njit(cache=True)
def refill_vanished(box, slots, ptot):
    """Every slot of no mass (a pure-liquid droplet dried to exactly zero) takes a copy of a
    random slot of mass; returns the box's total mass [kg] (ptot [kg] plus the copies). A box
    with no mass left is returned as it is."""
    p, b, isdrop = box.p, box.b, box.isdrop
    n = p.size
    for k in range(n):
        if p[k] > 0.0:
            continue
        j = -1
        for _ in range(64 * n):
            cand = np.random.randint(n)
            if p[cand] > 0.0:
                j = cand
                break
        if j < 0:
            return ptot
        _remove(k, slots.bin_of, slots.bpos, slots.members, slots.bcnt, slots.dlist,
                slots.dpos, slots.dcnt)
        p[k] = p[j]
        b[k] = b[j]
        isdrop[k] = isdrop[j]
        _insert(k, isdrop[k] == 1, p, box.m_ref, slots.bin_of, slots.bpos, slots.members,
                slots.bcnt, slots.lo, slots.hi, slots.dirty, slots.dlist, slots.dpos, slots.dcnt)
        ptot += p[k]
    return ptot


@nb.njit(cache=True, inline="always")
def capture_rate(i, j, p, b, alpha, theta, u0, d43, params, config):
    """Rate [m3/s] at which granule i captures droplet j (slots; masses p, b [kg]): with
    drying droplet_factor x the pair rate with the droplet's own (p_j, b_j); without, the
    sprayed droplet's (``physics.rates.droplet_capture_rate``, every droplet being (p_d, b_d))."""
    if config[P.DRYING] == 1:
        return params[P.DROPLET_FACTOR] * aggregation_rate(p[i], b[i], p[j], b[j], alpha, theta,
                                                           u0, d43, params, config)
    return droplet_capture_rate(p[i], b[i], alpha, theta, u0, d43, params, config)
