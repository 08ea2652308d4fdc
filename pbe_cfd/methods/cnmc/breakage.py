"""Breakage in the cNMC box (``methods.cnmc_box``): majorants per mass class, proposals, and
the mass split of an accepted event. All quantities SI (masses in kg, rates in 1/s).

Events: a granule i breaks at S(p_i) [1/s] (``physics.breakage``), so the box's breakage rate
is sum_i S(p_i) over its granules (free droplets never break). It is realised by thinning, like
aggregation: class a (mass interval [lo_a, hi_a]) is proposed at n_a B_a with B_a =
max(S(lo_a), S(hi_a)) (x (1 + 1e-12)), a member uniformly, and the break accepted with
S(p_i) / B_a. B_a bounds S on the class because every selection function of the registry is
monotone in p (constant, or a non-negative power of p; ``tests/physics/test_registries.py`` checks).

The split (constant number, Smith & Matsoukas 1998; Lin, Lee & Matsoukas 2002): the parent
(p, b) becomes the first daughter (u p, u b) in its own slot, u from the daughter rule; the
second daughter ((1 - u) p, (1 - u) b) replaces a particle chosen uniformly among the N + 1
particles the box holds after the split (the N - 1 others and both daughters; when the second
daughter itself is chosen it is dropped). That is a uniform thinning of the N + 1 particles
back to N, so the box stays an unbiased sample of the population; the box volume follows the
removed mass, V = P_box / C(t) (``cnmc``), which keeps M10 exact.
"""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.breakage import daughter_share, selection_function
from .slots import d4, insert_slot, remove_slot

_BOUND_SAFETY = 1.0 + 1e-12


@nb.njit(cache=True)
def selection_bound(lo, hi, factor, params, config):
    """Majorant [1/s] of the selection rate on the mass interval [lo, hi] [kg] (factor: the
    cell factor [1/s]); 0 for an empty interval (hi <= 0)."""
    if hi <= 0.0 or factor == 0.0:
        return 0.0
    code = config[P.BREAKAGE_SELECTION]
    s_lo = selection_function(code, lo, factor, params)
    s_hi = selection_function(code, hi, factor, params)
    return max(s_lo, s_hi) * _BOUND_SAFETY


@nb.njit(cache=True, inline="always")
def breakage_weights(bcnt, lo, hi, occ, n_occ, factor, params, config, bound, brow):
    """Per occupied class a: bound[a] = B_a [1/s] and brow[a] = n_a B_a; returns their sum
    [1/s], the proposal rate of breakage in the box (0 when nothing breaks)."""
    total = 0.0
    if factor == 0.0:
        return total
    for ia in range(n_occ):
        a = occ[ia]
        bound[a] = selection_bound(lo[a], hi[a], factor, params, config)
        brow[a] = bcnt[a] * bound[a]
        total += brow[a]
    return total


@nb.njit(cache=True, inline="always")
def pick_breakage(w_br, n_occ, occ, brow, bcnt, members):
    """Propose a granule to break: class a by n_a B_a, then a member uniformly. Returns
    (slot i, class a)."""
    x = np.random.random() * w_br
    a = -1
    for ia in range(n_occ):
        if x < brow[occ[ia]]:
            a = occ[ia]
            break
        x -= brow[occ[ia]]
    if a < 0:                          # round-off guard: the last class with weight
        for ia in range(n_occ - 1, -1, -1):
            if brow[occ[ia]] > 0.0:
                a = occ[ia]
                break
    return members[a, np.random.randint(bcnt[a])], a


@nb.njit(cache=True, inline="always")
def daughter_masses(p, b, config):
    """The two daughters ((p1, b1), (p2, b2)) [kg] of a granule (p, b): mass share u of the
    daughter rule for a uniform random number in (0, 1), binder in proportion to mass; both
    daughters strictly lighter than the parent (u redrawn otherwise)."""
    code = config[P.BREAKAGE_DAUGHTERS]
    while True:
        r = np.random.random()
        if r <= 0.0:
            continue
        u = daughter_share(code, r)
        p1 = u * p
        p2 = p - p1
        if p1 > 0.0 and p2 > 0.0:
            b1 = u * b
            return p1, b1, p2, b - b1


@nb.njit(cache=True, inline="always")
def breakage_trial(w_br, n_occ, occ, brow, bbound, factor, box, ptot, s4, slots, params, config):
    """Propose a breakage (``cnmc_breakage.pick_breakage``), accept it with S(p_i) / B_a and
    split. ``box``: the ``slots.Particles``, ``slots``: the ``slots.Slots`` of the box. Returns
    (total mass [kg], sum d^4 [m^4], 1 if split, 1 if S exceeded its bound)."""
    i, a = pick_breakage(w_br, n_occ, occ, brow, slots.bcnt, slots.members)
    rate = selection_function(config[P.BREAKAGE_SELECTION], box.p[i], factor, params)
    above = 1 if rate > bbound[a] else 0
    if np.random.random() * bbound[a] < rate:
        ptot, s4 = split(i, box, ptot, s4, slots, config)
        return ptot, s4, 1, above
    return ptot, s4, 0, above


@nb.njit(cache=True, inline="always")
def split(i, box, ptot, s4, slots, config):
    """Accepted breakage of granule i (constant number, ``methods.cnmc_breakage``): the first
    daughter takes slot i, the second replaces a slot chosen uniformly among the N + 1
    particles after the split (dropped when it chooses itself). ``box``, ``slots``: the box's
    ``slots.Particles`` and ``slots.Slots``. Returns the new total mass [kg] and sum d^4
    [m^4]."""
    p, b, isdrop, rho, m_ref = box.p, box.b, box.isdrop, box.rho, box.m_ref
    bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt = slots
    n = p.size
    p1, b1, p2, b2 = daughter_masses(p[i], b[i], config)
    remove_slot(i, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
    s4 += d4(p1, rho) - d4(p[i], rho)
    ptot -= p[i] - p1
    p[i] = p1
    b[i] = b1
    insert_slot(i, False, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
    k = np.random.randint(n + 1)
    if k == n:
        return ptot, s4                  # the second daughter was the one drawn: dropped
    remove_slot(k, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
    s4 += d4(p2, rho) - d4(p[k], rho)
    ptot += p2 - p[k]
    p[k] = p2
    b[k] = b2
    isdrop[k] = 0
    insert_slot(k, False, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
    return ptot, s4
