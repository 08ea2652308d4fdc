"""The numba core of the cNMC (``methods.cnmc``): one replica's box (``run_box``), its mass
classes and their majorant tables, and the box's moments. The algorithm and its units are
described in ``methods.cnmc``; all quantities are SI."""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid
from ...physics.breakage import cell_selection_factor
from ...physics.kernels import collision_frequency
from ...physics.rates import aggregation_rate
from .breakage import breakage_trial, breakage_weights
from .droplets import DRIFT_STEP, capture_rate, new_drying_array
from .drying import DRIFT_SHARE, drift_box, drift_due, spray_drying_time
from .slots import C_D as _C_D
from .slots import N_BINS, Particles, Slots
from .slots import d4 as _d4
from .slots import insert_slot as _insert
from .slots import remove_slot as _remove
from .spray import constant_spray, next_change, rate_at, sprayed_mass
from .quantities import (MOMENT_NAMES, N_QUANTITIES, PSD_BINS, PSD_FRACTIONS,  # noqa: F401
                         PSD_LOG10_LO, PSD_PER_DECADE, QUANTITY_NAMES, box_quantities,
                         box_size_classes, store_output)

# run_box status codes
STATUS_OK = 0
STATUS_MAX_TRIALS = 1      # trial budget exhausted before the last output time
STATUS_NONFINITE = 2       # event rate not finite (e.g. alpha >= alpha_max in ktgf)
STATUS_STALLED = 3         # dt below the resolution of t (event rate ~1e16 times 1/t)

MAX_TRIALS = 10 ** 10      # per replica; ~ minutes of work, then simulate_ensemble raises

_BOUND_SAFETY = 1.0 + 1e-12
_D43_MARGIN = 1.02         # majorant tables use d43 * 1.02, rebuilt when d43 leaves the margin


# ---------------------------------------------------------------------------------------------
# numba core
# ---------------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _kernel_d43(s4, ptot, n_free_droplets, dry, rho):
    """d43 [m] the ktgf kernel uses: sum d^4 / sum d^3 of the granules (docs/physics.md
    section 4.3), from the box sums s4 = sum d^4 [m^4] and ptot = sum p [kg] less the free
    droplets at their mean mass dry[4] [kg] and mean d^4 dry[5] [m^4] (``cnmc.droplets``);
    0 if the box holds no granule mass."""
    gran_mass = ptot - n_free_droplets * dry[4]
    if not gran_mass > 0.0:
        return 0.0
    return max(s4 - n_free_droplets * dry[5], 0.0) / (_C_D / rho * gran_mass)


@nb.njit(cache=True)
def pair_rate_bounds(gmin, gmax, n_granules, alpha, theta, d43, params, config):
    """Majorants (B_gg, B_dg) [m3/s] of the granule-granule and droplet-granule pair rates.

    gmin, gmax [kg]: an interval containing the masses of all granules (droplets excluded where
    config[SEPARATE_DROPLETS] == 1); n_granules: their number (0 gives zero bounds);
    alpha [-], theta [m2/s2], d43 [m]: the cell's local values used by the kernel.
    B_gg bounds aggregation_rate of any two granules, B_dg bounds droplet_capture_rate of any
    granule (0 unless droplets are separate). See the module docstring for why.
    """
    if n_granules <= 0:
        return 0.0, 0.0
    bgg = interval_pair_bound(gmin, gmax, gmin, gmax, alpha, theta, d43, params, config)
    bdg = 0.0
    if config[P.SEPARATE_DROPLETS] == 1:
        pd = params[P.DROPLET_MASS]
        bdg = params[P.DROPLET_FACTOR] * interval_pair_bound(gmin, gmax, pd, pd, alpha, theta,
                                                             d43, params, config)
    return bgg, bdg


@nb.njit(cache=True)
def interval_pair_bound(lo1, hi1, lo2, hi2, alpha, theta, d43, params, config):
    """Majorant [m3/s] of the collision frequency over [lo1, hi1] x [lo2, hi2] (masses, kg).

    The maximum of the kernel over the four corners (times 1 + 1e-12): an upper bound for every
    kernel of the registry because each is quasi-convex in each mass (module docstring).
    alpha [-], theta [m2/s2], d43 [m]: the local values passed to the kernel.
    """
    code = config[P.KERNEL]
    m = collision_frequency(code, lo1, lo2, alpha, theta, d43, params)
    m = max(m, collision_frequency(code, lo1, hi2, alpha, theta, d43, params))
    m = max(m, collision_frequency(code, hi1, lo2, alpha, theta, d43, params))
    m = max(m, collision_frequency(code, hi1, hi2, alpha, theta, d43, params))
    return m * _BOUND_SAFETY


@nb.njit(cache=True)
def _bound_row(c, lo, hi, table, tabd, alpha, theta, d43, dlo, params, config):
    """Recompute the majorants of class c against every class with a valid interval (the
    droplets' masses in [dlo, p_d] [kg])."""
    sep = config[P.SEPARATE_DROPLETS] == 1
    for a in range(N_BINS):
        if hi[a] > 0.0 and hi[c] > 0.0:
            bnd = interval_pair_bound(lo[a], hi[a], lo[c], hi[c], alpha, theta, d43, params,
                                      config)
        else:
            bnd = 0.0
        table[a, c] = bnd
        table[c, a] = bnd
    tabd[c] = 0.0
    if sep and hi[c] > 0.0:
        pd = params[P.DROPLET_MASS]
        tabd[c] = params[P.DROPLET_FACTOR] * interval_pair_bound(
            lo[c], hi[c], dlo, pd, alpha, theta, d43, params, config)


@nb.njit(cache=True)
def run_box(p, b, isdrop, volume0, output_times, cell, params, config, rng_seed,
            exponential_dt, max_trials, out):
    """``run_box_with_sizes`` without the size classes and percentiles, at the constant
    injection cell[INJECTION] (arguments and returns as there)."""
    n_out = output_times.size
    spray = constant_spray(cell[P.INJECTION], params[P.DROPLET_MASS])
    return run_box_with_sizes(p, b, isdrop, volume0, output_times, cell, params, config,
                              rng_seed, exponential_dt, max_trials, out,
                              np.zeros((n_out, PSD_BINS, 2)), np.zeros((n_out, 3)),
                              np.zeros(n_out), spray)


@nb.njit(cache=True)
def run_box_with_sizes(p, b, isdrop, volume0, output_times, cell, params, config, rng_seed,
                       exponential_dt, max_trials, out, classes, percentiles, evaporated, spray):
    """One cNMC replica. Mutates p, b, isdrop (the final box) and fills ``out``.

    p, b: float64 [kg], length N (N >= 2 for aggregation); isdrop: int64, 1 = free droplet
    (0 unless config[SEPARATE_DROPLETS] == 1); volume0: box volume [m3]; output_times [s],
    non-decreasing, from 0; cell: ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s]; params,
    config: physics.parameters; rng_seed: numba's seed;
    exponential_dt: 0 = mean waiting time 1/R (seed 000), 1 = exponential; max_trials: budget
    of proposals; out (n_out, N_QUANTITIES) by QUANTITY_NAMES (rows not reached: NaN), classes
    (n_out, PSD_BINS, 2), percentiles (n_out, 3) (``cnmc.quantities``), evaporated (n_out)
    [kg/m3]; spray: the injection (``cnmc.spray``). Returns (trials, accepted, injections,
    violations, status, t_reached [s],
    break_trials, splits): aggregation proposals and aggregations, injections, proposals above
    their majorant (must be 0), a STATUS_* code, breakage proposals and breakages."""
    np.random.seed(rng_seed)
    n, n_out = p.size, output_times.size
    sep, rho, pd = config[P.SEPARATE_DROPLETS] == 1, params[P.DENSITY], params[P.DROPLET_MASS]
    bd = droplet_liquid(params) if config[P.BIVARIATE] == 1 else 0.0
    alpha, theta, u0 = cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY]
    brk_factor = cell_selection_factor(cell, params, config)
    members, bcnt, bpos, bin_of, lo, hi, dirty, table, tabd, dlist, dpos, dcnt, occ, srow, trow, \
        drow = _new_classes(n)[:16]
    bbound, brow, dry = np.zeros(N_BINS), np.zeros(N_BINS), new_drying_array(pd, rho)
    m_ref, ptot, s4 = _fill_classes(p, isdrop, sep, rho, bin_of, bpos, members, bcnt, lo, hi,
                                    dirty, dlist, dpos, dcnt)
    box, slots = Particles(p, b, isdrop, rho, m_ref), Slots(bin_of, bpos, members, bcnt, lo, hi,
                                                            dirty, dlist, dpos, dcnt)
    conc0, inj = ptot / volume0, _spray_now(0.0, spray, dry, params, config)   # kg/m3, 1/(m3 s)
    d43_tab = _initial_bounds(rho, dcnt[0], dry, ptot, s4, lo, hi, dirty, table, tabd, alpha,
                              theta, params, config)
    trials = accepted = injections = violations = break_trials = splits = since_sync = 0
    status, t, w_gg, w_dg, w_br, k_out, n_occ, changed = STATUS_OK, 0.0, 0.0, 0.0, 0.0, 0, 0, True
    drying, hazard = config[P.DRYING] == 1, 0.0         # stops between events if timed:
    timed = drying or spray.starts.size > 1 or spray.starts[0] > 0.0
    while k_out < n_out:
        if drying and drift_due(dry[2], n):      # dry to now, between two events
            ptot, s4, d43_tab = _dried_and_synced(box, slots, t, conc0, spray, dry, ptot,
                                                  s4, d43_tab, table, tabd, alpha, theta,
                                                  params, config)
            since_sync, changed = 0, True
        if changed:
            changed = False
            n_occ, w_gg, w_dg = _pair_weights(bcnt, table, tabd, occ, srow, trow, drow)
            w_br = breakage_weights(bcnt, lo, hi, occ, n_occ, brk_factor, params, config,
                                    bbound, brow)
        vol = ptot / (conc0 + sprayed_mass(t, spray) - dry[0])
        r_gg, r_dg, r_inj = 0.5 * w_gg / vol, dcnt[0] * w_dg / vol, inj * vol
        r = r_gg + r_dg + r_inj + w_br
        if not (r < np.inf):
            status = STATUS_NONFINITE
            break
        t_next, hazard = _next_event(t, r, hazard, timed, exponential_dt)
        stop = max(min(output_times[k_out], dry[1] + dry[DRIFT_STEP], next_change(t, spray)), t)
        if timed and stop < t_next:
            hazard, k_out, ptot, s4, d43_tab = _to_stop(
                stop, t, t_next, hazard, drying, k_out, output_times, box, slots, conc0, spray,
                dry, ptot, s4, d43_tab, table, tabd, alpha, theta, out, classes, percentiles,
                evaporated, params, config)
            t, since_sync, changed = stop, 0 if drying else since_sync, changed or drying
            inj = _spray_now(t, spray, dry, params, config)
            continue
        # without drying the box does not change between events
        k_out = _store_outputs_to(t_next, k_out, output_times, box, conc0, spray, out,
                                  classes, percentiles, evaporated, dry, False)
        dry[2] += 1.0
        hazard = 0.0
        if k_out >= n_out:
            break
        if t_next <= t:
            status = STATUS_STALLED
            break
        t = t_next
        u = np.random.random() * r
        if u < r_inj or (r_gg <= 0.0 and r_dg <= 0.0 and w_br <= 0.0):
            injections, changed = injections + 1, True
            ptot, s4 = _inject(p, b, isdrop, pd, bd, sep, rho, m_ref, ptot, s4, bin_of, bpos,
                               members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
        elif w_br > 0.0 and (u >= r_inj + r_gg + r_dg or (r_gg <= 0.0 and r_dg <= 0.0)):
            break_trials += 1
            ptot, s4, done, above = breakage_trial(w_br, n_occ, occ, brow, bbound, brk_factor, box,
                                                   ptot, s4, slots, params, config)
            splits, violations, changed = splits + done, violations + above, changed or done == 1
        else:
            trials += 1
            granules = (u < r_inj + r_gg and r_gg > 0.0) or r_dg <= 0.0
            ptot, s4, merged, above = _aggregation_trial(
                granules, w_gg, w_dg, n_occ, occ, trow, srow, drow, table, tabd, box, slots,
                ptot, s4, dry, alpha, theta, u0, params, config)
            accepted, violations = accepted + merged, violations + above
            changed = changed or merged == 1
        if trials + break_trials >= max_trials:
            status = STATUS_MAX_TRIALS
            break
        if changed:
            since_sync, ptot, s4, d43_tab = _refresh_bounds(
                since_sync, p, rho, dcnt[0], dry, ptot, s4, d43_tab, bin_of, lo, hi, dirty,
                table, tabd, alpha, theta, params, config)
    out[k_out:] = np.nan
    return trials, accepted, injections, violations, status, t, break_trials, splits


# ---------------------------------------------------------------------------------------------
# the steps of run_box (inlined into it by numba: the compiled loop is the one written out)
# ---------------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _new_classes(n):
    """The box's class structure for n slots: members (N_BINS, n), counts, slot positions,
    class of each slot, class mass intervals [lo, hi] [kg], dirty flags, the majorant tables
    (class pairs, droplet capture) [m3/s], the droplet list, and scratch rows."""
    return (np.empty((N_BINS, n), np.int32), np.zeros(N_BINS, np.int64), np.empty(n, np.int64),
            np.empty(n, np.int64), np.full(N_BINS, np.inf), np.zeros(N_BINS),
            np.zeros(N_BINS, np.bool_), np.zeros((N_BINS, N_BINS)), np.zeros(N_BINS),
            np.empty(n, np.int64), np.empty(n, np.int64), np.zeros(1, np.int64),
            np.empty(N_BINS, np.int64), np.zeros(N_BINS), np.zeros(N_BINS), np.zeros(N_BINS))


@nb.njit(cache=True)
def _fill_classes(p, isdrop, sep, rho, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist,
                  dpos, dcnt):
    """Sort every slot into its class (or the droplet list); returns the class reference mass
    m_ref [kg], the total mass [kg] and sum d^4 [m^4] of the box."""
    n = p.size
    m_ref = np.inf
    for k in range(n):
        m_ref = min(m_ref, p[k])
    m_ref = m_ref * 2.0 ** -8
    ptot = 0.0
    s4 = 0.0
    for k in range(n):
        if not sep:
            isdrop[k] = 0
        if isdrop[k] != 0:
            isdrop[k] = 1
        _insert(k, isdrop[k] == 1, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty,
                dlist, dpos, dcnt)
        ptot += p[k]
        s4 += _d4(p[k], rho)
    return m_ref, ptot, s4


@nb.njit(cache=True, inline="always")
def _initial_bounds(rho, n_free_droplets, dry, ptot, s4, lo, hi, dirty, table, tabd, alpha,
                    theta, params, config):
    """Build every class's majorant row at the box's initial granule d43 x margin (droplet
    statistics ``dry``: ``cnmc.droplets``); returns that d43 [m]."""
    d43_tab = _kernel_d43(s4, ptot, n_free_droplets, dry, rho) * _D43_MARGIN
    for c in range(N_BINS):
        _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, dry[3], params, config)
        dirty[c] = False
    return d43_tab


@nb.njit(cache=True, inline="always")
def _pair_weights(bcnt, table, tabd, occ, srow, trow, drow):
    """Class-pair majorant weights over the occupied classes, O(K_occ^2): fills occ (the
    occupied classes), srow, trow (ordered granule pairs per class) and drow (droplet
    captures per class); returns (number occupied, total granule weight, total droplet
    weight) [m3/s]."""
    n_occ = 0
    for c in range(N_BINS):
        if bcnt[c] > 0:
            occ[n_occ] = c
            n_occ += 1
    w_gg = 0.0
    w_dg = 0.0
    for ia in range(n_occ):
        a = occ[ia]
        s = (bcnt[a] - 1) * table[a, a]
        for ib in range(n_occ):
            c = occ[ib]
            if c != a:
                s += bcnt[c] * table[a, c]
        srow[a] = s
        trow[a] = bcnt[a] * s          # ordered pairs (i in a, j != i)
        w_gg += trow[a]
        drow[a] = bcnt[a] * tabd[a]
        w_dg += drow[a]
    return n_occ, w_gg, w_dg


@nb.njit(cache=True, inline="always")
def _next_event_time(t, r, exponential_dt):
    """Time [s] of the next event at total event rate r [1/s]: t + 1/r (the mean waiting time,
    seed 000) or an exponential waiting time (exponential_dt == 1); infinity when r = 0."""
    if r <= 0.0:
        return np.inf
    if exponential_dt == 1:
        return t - math.log(1.0 - np.random.random()) / r
    return t + 1.0 / r


@nb.njit(cache=True, inline="always")
def _to_stop(stop, t, t_next, hazard, drying, k_out, output_times, box, slots, conc0, spray,
             dry, ptot, s4, d43_tab, table, tabd, alpha, theta, out, classes, percentiles,
             evaporated, params, config):
    """The box, whose next event would come at t_next [s] after t [s], goes to ``stop`` [s]
    (an output time, a change of the spray or its longest drift step, before t_next): with
    ``drying`` it dries to it with its majorants rebuilt (``_dried_and_synced``); it is
    stored at an output time there (``_store_outputs_to``); the rest of the waiting hazard
    runs on at the rates after the stop. Returns (hazard left, next output row, total mass
    [kg], sum d^4 [m^4], d43 of the tables [m])."""
    if t_next < np.inf:
        hazard *= (t_next - stop) / (t_next - t)
    if drying:
        ptot, s4, d43_tab = _dried_and_synced(box, slots, stop, conc0, spray, dry, ptot, s4,
                                              d43_tab, table, tabd, alpha, theta, params,
                                              config)
    k_out = _store_outputs_to(stop, k_out, output_times, box, conc0, spray, out, classes,
                              percentiles, evaporated, dry, True)
    return hazard, k_out, ptot, s4, d43_tab


@nb.njit(cache=True, inline="always")
def _spray_now(t, spray, dry, params, config):
    """The injection rate [droplets/(m3 s)] at t [s] (``cnmc.spray``); sets the box's longest
    drift step (dry[DRIFT_STEP]) to DRIFT_SHARE of a sprayed droplet's drying time while it
    is sprayed (inf otherwise: ``cnmc.drying.spray_drying_time``)."""
    inj = rate_at(t, spray)
    dry[DRIFT_STEP] = DRIFT_SHARE * spray_drying_time(inj, params, config)
    return inj


@nb.njit(cache=True, inline="always")
def _store_outputs_to(t, k_out, output_times, box, conc0, spray, out, classes, percentiles,
                      evaporated, dry, including):
    """Store the box (``store_output``) at every output time before t [s] (``including``: up
    to t itself) from row k_out on, at the mass concentration of that time; returns the next
    row."""
    while k_out < output_times.size and (output_times[k_out] < t
                                          or (including and output_times[k_out] <= t)):
        store_output(k_out, box, conc0 + sprayed_mass(output_times[k_out], spray) - dry[0], out,
                     classes, percentiles, evaporated, dry)
        k_out += 1
    return k_out


@nb.njit(cache=True, inline="always")
def _aggregation_trial(granules, w_gg, w_dg, n_occ, occ, trow, srow, drow, table, tabd, box,
                       slots, ptot, s4, dry, alpha, theta, u0, params, config):
    """One aggregation proposal (``_propose``: a granule pair, or a droplet capture), accepted
    with probability rate / majorant and then merged. Returns (total mass [kg], sum d^4
    [m^4], 1 if merged, 1 if the rate exceeded its majorant)."""
    p, b, rho, nd = box.p, box.b, box.rho, slots.dcnt[0]
    d43 = _kernel_d43(s4, ptot, nd, dry, rho)
    i, j, rate, bound = _propose(granules, w_gg, w_dg, n_occ, occ, trow, srow, drow,
                                 slots.bcnt, table, tabd, slots.members, slots.dlist, nd, p, b,
                                 alpha, theta, u0, d43, params, config)
    above = 1 if rate > bound else 0
    if not np.random.random() * bound < rate:
        return ptot, s4, 0, above
    ptot, s4 = _merge(i, j, p, b, box.isdrop, rho, box.m_ref, ptot, s4, slots.bin_of,
                      slots.bpos, slots.members, slots.bcnt, slots.lo, slots.hi, slots.dirty,
                      slots.dlist, slots.dpos, slots.dcnt)
    return ptot, s4, 1, above


@nb.njit(cache=True, inline="always")
def _next_event(t, r, hazard, timed, exponential_dt):
    """The next event's time [s] after t [s] at the total majorant rate r [1/s], and its
    waiting hazard. Without stops between events (``timed`` False: no drying and a spray at
    one rate from t = 0) ``_next_event_time`` (hazard 0). With them the event comes when the
    rate integrated since the last event reaches the hazard, 1 (exponential_dt == 0, the mean
    waiting time) or an exponential draw, drawn anew where ``hazard`` is spent (<= 0); what a
    stop between two events leaves of it is kept (the box's majorants change at a drift or a
    change of the spray, the hazard runs on at the new ones)."""
    if not timed:
        return _next_event_time(t, r, exponential_dt), 0.0
    if not hazard > 0.0:
        hazard = 1.0 if exponential_dt == 0 else -math.log(1.0 - np.random.random())
    return (t + hazard / r if r > 0.0 else np.inf), hazard


@nb.njit(cache=True, inline="always")
def _dried_and_synced(box, slots, t, conc0, spray, dry, ptot, s4, d43_tab, table, tabd,
                      alpha, theta, params, config):
    """The box dried to t [s] (``drift_box``), then its sums and class intervals recomputed
    and its majorant tables rebuilt at once (``_refresh_bounds`` at a sync): a drift can move
    a particle below the mass interval the majorants were built for. Returns (total mass
    [kg], sum d^4 [m^4], d43 of the tables [m])."""
    ptot = drift_box(box, slots, t, conc0, spray, dry, ptot, params)
    _, ptot, s4, d43_tab = _refresh_bounds(box.p.size - 1, box.p, box.rho, slots.dcnt[0], dry,
                                           ptot, s4, d43_tab, slots.bin_of, slots.lo, slots.hi,
                                           slots.dirty, table, tabd, alpha, theta, params,
                                           config)
    return ptot, s4, d43_tab


@nb.njit(cache=True, inline="always")
def _propose(granules, w_gg, w_dg, n_occ, occ, trow, srow, drow, bcnt, table, tabd, members,
             dlist, nd, p, b, alpha, theta, u0, d43, params, config):
    """Propose an aggregation: a granule-granule pair (``granules``) or a droplet capture.
    Returns (slot i, slot j, its rate [m3/s], the majorant it was proposed with [m3/s])."""
    if granules:
        i, j, a, c = _pick_granule_pair(w_gg, n_occ, occ, trow, srow, bcnt, table, members)
        rate = aggregation_rate(p[i], b[i], p[j], b[j], alpha, theta, u0, d43, params, config)
        return i, j, rate, table[a, c]
    i, j, a = _pick_capture(w_dg, n_occ, occ, drow, bcnt, members, dlist, nd)
    rate = capture_rate(i, j, p, b, alpha, theta, u0, d43, params, config)
    return i, j, rate, tabd[a]


@nb.njit(cache=True, inline="always")
def _inject(p, b, isdrop, pd, bd, sep, rho, m_ref, ptot, s4, bin_of, bpos, members, bcnt, lo,
            hi, dirty, dlist, dpos, dcnt):
    """Injection: overwrite a random slot with a droplet (p_d, b_d); returns the box's new
    total mass [kg] and sum d^4 [m^4]."""
    k = np.random.randint(p.size)
    ptot -= p[k]
    s4 -= _d4(p[k], rho)
    _remove(k, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
    p[k] = pd
    b[k] = bd
    isdrop[k] = 1 if sep else 0
    _insert(k, sep, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
    ptot += pd
    s4 += _d4(pd, rho)
    return ptot, s4


@nb.njit(cache=True, inline="always")
def _pick_granule_pair(w_gg, n_occ, occ, trow, srow, bcnt, table, members):
    """Propose a granule-granule pair: class a by its share of ordered pairs, then class c,
    then a member of each (distinct slots). Returns (i, j, a, c)."""
    x = np.random.random() * w_gg
    a = occ[n_occ - 1]
    for ia in range(n_occ):
        if x < trow[occ[ia]]:
            a = occ[ia]
            break
        x -= trow[occ[ia]]
    while trow[a] <= 0.0:          # round-off guard: a class with pairs
        a = occ[np.random.randint(n_occ)]
    x = np.random.random() * srow[a]
    c = -1
    for ib in range(n_occ):
        cc = occ[ib]
        wc = (bcnt[cc] - 1 if cc == a else bcnt[cc]) * table[a, cc]
        if x < wc:
            c = cc
            break
        x -= wc
    if c < 0:
        for ib in range(n_occ - 1, -1, -1):
            cc = occ[ib]
            if (bcnt[cc] - 1 if cc == a else bcnt[cc]) * table[a, cc] > 0.0:
                c = cc
                break
    ia = np.random.randint(bcnt[a])
    i = members[a, ia]
    if c == a:
        ja = np.random.randint(bcnt[a] - 1)
        if ja >= ia:
            ja += 1
        j = members[a, ja]
    else:
        j = members[c, np.random.randint(bcnt[c])]
    return i, j, a, c


@nb.njit(cache=True, inline="always")
def _pick_capture(w_dg, n_occ, occ, drow, bcnt, members, dlist, nd):
    """Propose a droplet capture: granule class a by n_a B_d(a), a member of it and a random
    droplet. Returns (granule slot i, droplet slot j, a)."""
    x = np.random.random() * w_dg
    a = -1
    for ia in range(n_occ):
        if x < drow[occ[ia]]:
            a = occ[ia]
            break
        x -= drow[occ[ia]]
    if a < 0:
        for ia in range(n_occ - 1, -1, -1):
            if drow[occ[ia]] > 0.0:
                a = occ[ia]
                break
    i = members[a, np.random.randint(bcnt[a])]
    j = dlist[np.random.randint(nd)]
    return i, j, a


@nb.njit(cache=True, inline="always")
def _merge(i, j, p, b, isdrop, rho, m_ref, ptot, s4, bin_of, bpos, members, bcnt, lo, hi,
           dirty, dlist, dpos, dcnt):
    """Accepted aggregation: merge slot j into granule i, refill j with a copy of a random
    other slot (constant number). Returns the new total mass [kg] and sum d^4 [m^4]."""
    n = p.size
    _remove(i, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
    _remove(j, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
    s4 -= _d4(p[i], rho) + _d4(p[j], rho)
    p[i] += p[j]
    b[i] += b[j]
    s4 += _d4(p[i], rho)
    _insert(i, False, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
    k = np.random.randint(n - 1)
    if k >= j:
        k += 1
    p[j] = p[k]
    b[j] = b[k]
    isdrop[j] = isdrop[k]
    _insert(j, isdrop[k] == 1, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist,
            dpos, dcnt)
    ptot += p[j]
    s4 += _d4(p[j], rho)
    return ptot, s4


@nb.njit(cache=True, inline="always")
def _refresh_bounds(since_sync, p, rho, n_free_droplets, dry, ptot, s4, d43_tab, bin_of, lo, hi,
                    dirty, table, tabd, alpha, theta, params, config):
    """After a change of the box: every N changes an exact O(N) pass over the sums and class
    intervals; the majorant tables rebuilt when d43 leaves their margin (else only the dirty
    classes). Returns (since_sync, total mass [kg], sum d^4 [m^4], d43 of the tables [m])."""
    n = p.size
    since_sync += 1
    rebuild = False
    if since_sync >= n:
        since_sync = 0
        ptot = 0.0
        s4 = 0.0
        for c in range(N_BINS):
            lo[c] = np.inf
            hi[c] = 0.0
        for k in range(n):
            ptot += p[k]
            s4 += _d4(p[k], rho)
            c = bin_of[k]
            if c >= 0:
                lo[c] = min(lo[c], p[k])
                hi[c] = max(hi[c], p[k])
        rebuild = True
    d43 = _kernel_d43(s4, ptot, n_free_droplets, dry, rho)
    if d43 > d43_tab or d43 * _D43_MARGIN ** 3 < d43_tab:
        rebuild = True
    if rebuild:
        d43_tab = d43 * _D43_MARGIN
        for c in range(N_BINS):
            _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, dry[3], params, config)
            dirty[c] = False
    else:
        for c in range(N_BINS):
            if dirty[c]:
                _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, dry[3], params, config)
                dirty[c] = False
    return since_sync, ptot, s4, d43_tab
