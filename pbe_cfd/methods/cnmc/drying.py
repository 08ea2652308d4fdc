"""Drying of the cNMC box's granules (docs/physics.md section 15): between events every
granule's liquid drifts at db/dt = dp/dt = -e(p, b) (``physics.drying``), integrated per
particle over the interval (``physics.drying.advance_liquid``: exact in the skeleton period);
the events see the box as dried to the last drift (operator splitting, see ``DRIFT_TRIALS``).
Free droplets of their own dry like every particle (a solution's through its liquid sphere to
its solids; a pure liquid by ``physics.drying.liquid_sphere_after`` to exactly zero mass, when
``cnmc.droplets.refill_vanished`` takes it out of the box). Masses in kg."""
import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.drying import advance_liquid, drying_rate, scene_gas
from ...physics.injection import droplet_liquid
from .droplets import droplet_stats, refill_vanished
from .spray import sprayed_mass

#: the box drifts at every output time and after every N / DRIFT_TRIALS event proposals
#: (N particles), so an event sees a particle dried to within ~1/DRIFT_TRIALS of the mean
#: time between two events of that particle; O(DRIFT_TRIALS) work per proposal
DRIFT_TRIALS = 32
#: and, while droplets of their own are sprayed, at least every DRIFT_SHARE x a sprayed
#: droplet's drying time (``spray_drying_time``): where the box's events are rare against its drying
#: (a small box in a dilute spray), the proposals alone spaced the drifts longer than a
#: droplet's life, and a droplet sprayed between two drifts is dried from the earlier one.
#: Ours: such a droplet dries at most 2% of that time too long; on the sprayed cell of
#: docs/results/laguerre.md steps of 10% and 0.5% give the same within the replicas' band
DRIFT_SHARE = 0.02


@nb.njit(cache=True)
def dry_box(p, b, dt, params):
    """Dry every particle of the box (masses p, liquid b [kg]; granules and free droplets)
    for dt [s] in the scene's air (``physics.drying.scene_gas``: the cNMC is well-mixed, one
    gas for the box), in place; returns the liquid evaporated [kg]."""
    lost = 0.0
    gas = scene_gas(params)
    for k in range(p.size):
        if not b[k] > 0.0:
            continue
        bk = advance_liquid(p[k], b[k], dt, gas, params)
        loss = b[k] - bk
        if p[k] == b[k]:         # pure liquid: stays pure (p = b), 0 once gone
            p[k] = bk
        else:
            p[k] -= loss
        b[k] = bk
        lost += loss
    return lost


@nb.njit(cache=True)
def drift_due(trials_since, n):
    """True if a box of n particles should drift now, between two events: N / DRIFT_TRIALS
    event proposals since its last drift."""
    return trials_since * DRIFT_TRIALS >= n


@nb.njit(cache=True, inline="always")
def drift_box(box, slots, t, conc0, spray, dry, ptot, params):
    """Dry the box (``box``, ``slots``: ``cnmc.slots``) from its last drift (dry[1] [s]) to t
    [s] in its volume at t, V = P / (C0 + S(t) - E) (``methods.cnmc``; S the mass sprayed per
    m3 by t, ``cnmc.spray``; E = dry[0] the evaporated liquid [kg/m3]; P = ptot [kg]); adds
    the loss to E, resets the proposal count dry[2], refills the slots of droplets that
    vanished and refreshes the droplet statistics dry[3:6] (``cnmc.droplets``); returns the
    box's total mass [kg]."""
    p, b = box.p, box.b
    vol = ptot / (conc0 + sprayed_mass(t, spray) - dry[0])
    lost = dry_box(p, b, t - dry[1], params)
    dry[0] += lost / vol
    dry[1] = t
    dry[2] = 0.0
    ptot = refill_vanished(box, slots, ptot - lost)
    droplet_stats(p, slots.dlist, slots.dcnt, params[P.DROPLET_MASS], box.rho, dry)
    return ptot


@nb.njit(cache=True)
def spray_drying_time(injection, params, config):
    """The time [s] a freshly sprayed droplet (p_d, b_d) of its own (``droplet_factor``) would
    take to lose its liquid at its first rate in the scene's air, b_d / e(p_d, b_d)
    (``physics.drying.drying_rate``; 2/3 of the d^2 law's life for a pure liquid); inf
    without a spray (``injection`` [droplets/(m3 s)] = 0), without separate droplets, without
    drying, or when it does not dry."""
    if not (injection > 0.0 and config[P.DRYING] == 1 and config[P.SEPARATE_DROPLETS] == 1):
        return np.inf
    bd = droplet_liquid(params)
    rate = drying_rate(params[P.DROPLET_MASS], bd, scene_gas(params), params)
    if not (bd > 0.0 and rate > 0.0):
        return np.inf
    return bd / rate


def evaporated_columns(evaporated, t_factor, config):
    """{"liquid_evaporated", + "_lo", "_hi"} [kg/m3] of the replicas' rows ``evaporated``
    (replicas, times): their mean -+ t_factor x their standard deviation (the ensemble's 95%
    band); empty without drying (config[DRYING] == 0)."""
    if int(config[P.DRYING]) != 1:
        return {}
    mean = evaporated.mean(axis=0)
    half = t_factor * evaporated.std(axis=0, ddof=1) if len(evaporated) > 1 else 0.0 * mean
    return {"liquid_evaporated": mean, "liquid_evaporated_lo": mean - half,
            "liquid_evaporated_hi": mean + half}
