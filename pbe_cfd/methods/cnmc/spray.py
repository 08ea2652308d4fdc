"""The spray of the cNMC box: a piecewise-constant injection rate (the scene's schedule, or one
constant rate from t = 0), as ``Spray(starts [s], rates [droplets/(m3 s)], droplet_mass
[kg])``: rate k holds from starts[k] to starts[k + 1] (the last one for ever), nothing is
sprayed before starts[0]."""
from collections import namedtuple

import numba as nb
import numpy as np

Spray = namedtuple("Spray", "starts rates droplet_mass")


@nb.njit(cache=True)
def constant_spray(rate, droplet_mass):
    """One rate [droplets/(m3 s)] from t = 0 on, droplets of ``droplet_mass`` [kg]."""
    return Spray(np.zeros(1), np.full(1, float(rate)), float(droplet_mass))


def scheduled_spray(segments, droplet_mass):
    """The rates of ``segments`` [(t0 [s], t1 [s], rate [droplets/(m3 s)])] in order
    (``scene.spray.segments``), the last one held past its t1."""
    starts = np.array([float(t0) for t0, _, _ in segments])
    rates = np.array([float(r) for _, _, r in segments])
    return Spray(starts, rates, float(droplet_mass))


@nb.njit(cache=True, inline="always")
def segment_at(t, spray):
    """Index of the segment that holds t [s] (the last start at or before t; -1 before the
    first)."""
    k = -1
    for i in range(spray.starts.size):
        if spray.starts[i] <= t:
            k = i
    return k


@nb.njit(cache=True, inline="always")
def rate_at(t, spray):
    """Injection rate [droplets/(m3 s)] at t [s]."""
    k = segment_at(t, spray)
    return spray.rates[k] if k >= 0 else 0.0


@nb.njit(cache=True, inline="always")
def next_change(t, spray):
    """The first segment start after t [s] (inf if none)."""
    for i in range(spray.starts.size):
        if spray.starts[i] > t:
            return spray.starts[i]
    return np.inf


@nb.njit(cache=True, inline="always")
def sprayed_mass(t, spray):
    """Mass sprayed per m3 from 0 to t [s] [kg/m3]: droplet_mass x the rate's integral."""
    total = 0.0
    n = spray.starts.size
    for i in range(n):
        if t <= spray.starts[i]:
            break
        end = spray.starts[i + 1] if i + 1 < n else np.inf
        total += (spray.rates[i] * spray.droplet_mass) * (min(t, end) - spray.starts[i])
    return total
