"""Slots and mass classes of the cNMC box (``methods.cnmc_box``): the O(1) bookkeeping that
puts a particle into its mass class (or the droplet list) and takes it out again, shared by
the aggregation, injection and breakage events. Masses in kg, diameters in m."""
import math
from collections import namedtuple

import numba as nb

N_BINS = 64                # mass classes of the granules (factor 2 wide)
C_D = 6.0 / math.pi

#: a box's particles: masses p, b [kg] and droplet flags (arrays), density rho [kg/m3] and
#: the lower mass of class 0, m_ref [kg]
Particles = namedtuple("Particles", "p b isdrop rho m_ref")
#: a box's slot bookkeeping (the arrays of ``insert_slot``/``remove_slot``)
Slots = namedtuple("Slots", "bin_of bpos members bcnt lo hi dirty dlist dpos dcnt")


@nb.njit(cache=True)
def d4(p, rho):
    """Fourth power of the volume-equivalent diameter d = (6 p / (pi rho))^(1/3) [m^4]."""
    d = (C_D * p / rho) ** (1.0 / 3.0)
    return d * d * d * d


@nb.njit(cache=True)
def bin_index(p, m_ref):
    """Mass class of a granule: floor(log2(p / m_ref)) clipped to [0, N_BINS - 1]."""
    if not p > m_ref:
        return 0
    c = int(math.floor(math.log2(p / m_ref)))
    if c >= N_BINS:
        return N_BINS - 1
    return c


@nb.njit(cache=True)
def remove_slot(k, bin_of, bpos, members, bcnt, dlist, dpos, dcnt):
    """Take slot k out of its mass class (or out of the droplet list); O(1)."""
    c = bin_of[k]
    if c >= 0:
        last = members[c, bcnt[c] - 1]
        members[c, bpos[k]] = last
        bpos[last] = bpos[k]
        bcnt[c] -= 1
    else:
        last = dlist[dcnt[0] - 1]
        dlist[dpos[k]] = last
        dpos[last] = dpos[k]
        dcnt[0] -= 1


@nb.njit(cache=True)
def insert_slot(k, droplet, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos,
            dcnt):
    """Put slot k (mass p[k]) into its mass class, widening the class interval if needed
    (and marking the class dirty), or into the droplet list; O(1)."""
    if droplet:
        bin_of[k] = -1
        dlist[dcnt[0]] = k
        dpos[k] = dcnt[0]
        dcnt[0] += 1
        return
    c = bin_index(p[k], m_ref)
    bin_of[k] = c
    members[c, bcnt[c]] = k
    bpos[k] = bcnt[c]
    bcnt[c] += 1
    if p[k] < lo[c]:
        lo[c] = p[k]
        dirty[c] = True
    if p[k] > hi[c]:
        hi[c] = p[k]
        dirty[c] = True
