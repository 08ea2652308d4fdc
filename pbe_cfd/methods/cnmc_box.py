"""The numba core of the cNMC (``methods.cnmc``): one replica's box (``run_box``), its mass
classes and their majorant tables, and the box's moments. The algorithm and its units are
described in ``methods.cnmc``; all quantities are SI."""
import math

import numba as nb
import numpy as np

from ..physics import parameters as P
from ..physics.kernels import collision_frequency
from ..physics.rates import aggregation_rate, droplet_capture_rate

MOMENT_NAMES = ("M00", "M10", "M01", "M20", "M11", "M02")
QUANTITY_NAMES = MOMENT_NAMES + ("droplet_number_density", "d32_m", "d43_m", "binder_fraction")
N_QUANTITIES = len(QUANTITY_NAMES)

# run_box status codes
STATUS_OK = 0
STATUS_MAX_TRIALS = 1      # trial budget exhausted before the last output time
STATUS_NONFINITE = 2       # event rate not finite (e.g. alpha >= alpha_max in ktgf)
STATUS_STALLED = 3         # dt below the resolution of t (event rate ~1e16 times 1/t)

MAX_TRIALS = 10 ** 10      # per replica; ~ minutes of work, then simulate_ensemble raises

_BOUND_SAFETY = 1.0 + 1e-12
_D43_MARGIN = 1.02         # majorant tables use d43 * 1.02, rebuilt when d43 leaves the margin
N_BINS = 64                # mass classes of the granules (factor 2 wide)
_C_D = 6.0 / math.pi


# ---------------------------------------------------------------------------------------------
# numba core
# ---------------------------------------------------------------------------------------------
@nb.njit(cache=True)
def _d4(p, rho):
    """Fourth power of the volume-equivalent diameter d = (6 p / (pi rho))^(1/3) [m^4]."""
    d = (_C_D * p / rho) ** (1.0 / 3.0)
    return d * d * d * d


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
def _bin_index(p, m_ref):
    """Mass class of a granule: floor(log2(p / m_ref)) clipped to [0, N_BINS - 1]."""
    if not p > m_ref:
        return 0
    c = int(math.floor(math.log2(p / m_ref)))
    if c >= N_BINS:
        return N_BINS - 1
    return c


@nb.njit(cache=True)
def _remove(k, bin_of, bpos, members, bcnt, dlist, dpos, dcnt):
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
def _insert(k, droplet, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos,
            dcnt):
    """Put slot k (mass p[k]) into its mass class, widening the class interval if needed
    (and marking the class dirty), or into the droplet list; O(1)."""
    if droplet:
        bin_of[k] = -1
        dlist[dcnt[0]] = k
        dpos[k] = dcnt[0]
        dcnt[0] += 1
        return
    c = _bin_index(p[k], m_ref)
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


@nb.njit(cache=True)
def _bound_row(c, lo, hi, table, tabd, alpha, theta, d43, params, config):
    """Recompute the majorants of class c against every class with a valid interval."""
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
            lo[c], hi[c], pd, pd, alpha, theta, d43, params, config)


@nb.njit(cache=True)
def box_quantities(p, b, isdrop, conc, rho, row):
    """Fill ``row`` (length N_QUANTITIES, order QUANTITY_NAMES) from the box.

    p, b [kg]; isdrop 1 for a free droplet; conc the box's mass concentration M10 [kg/m3],
    which sets the volume V = sum p / conc [m3]; rho the particle density [kg/m3].
    Moments are SI per m3 of the whole population (free droplets included).
    """
    n = p.size
    sp = 0.0
    sb = 0.0
    spp = 0.0
    spb = 0.0
    sbb = 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    nd = 0
    for k in range(n):
        pk = p[k]
        bk = b[k]
        sp += pk
        sb += bk
        spp += pk * pk
        spb += pk * bk
        sbb += bk * bk
        d = (_C_D * pk / rho) ** (1.0 / 3.0)
        d2 = d * d
        s2 += d2
        s3 += d2 * d
        s4 += d2 * d2
        if isdrop[k] != 0:
            nd += 1
    vol = sp / conc
    row[0] = n / vol
    row[1] = sp / vol
    row[2] = sb / vol
    row[3] = spp / vol
    row[4] = spb / vol
    row[5] = sbb / vol
    row[6] = nd / vol
    row[7] = s3 / s2
    row[8] = s4 / s3
    row[9] = sb / sp


@nb.njit(cache=True)
def run_box(p, b, isdrop, volume0, output_times, cell, params, config, rng_seed,
            exponential_dt, max_trials, out):
    """One cNMC replica. Mutates p, b, isdrop (the final box) and fills ``out``.

    p, b: float64 [kg], length N (N >= 2 for aggregation); isdrop: int64 flags, 1 = free
    droplet (set to 0 unless config[SEPARATE_DROPLETS] == 1); volume0: initial box volume
    [m3]; output_times [s], non-decreasing, from 0; cell: ALPHA [-], THETA [m2/s2],
    COLLISION_VELOCITY [m/s], INJECTION [droplets/(m3 s)]; params, config: physics.parameters;
    rng_seed: seed of numba's generator; exponential_dt: 0 = mean waiting time 1/R per trial
    (seed 000), 1 = exponential; max_trials: trial budget; out: (len(output_times),
    N_QUANTITIES) in the order of QUANTITY_NAMES (rows not reached: NaN).
    Returns (trials, accepted, injections, violations, status, t_reached [s]): aggregation
    proposals, aggregations done, injections, proposals above their majorant (must be 0), a
    STATUS_* code.
    """
    np.random.seed(rng_seed)
    n = p.size
    n_out = output_times.size
    sep = config[P.SEPARATE_DROPLETS] == 1
    rho = params[P.DENSITY]
    pd = params[P.DROPLET_MASS]
    bd = pd if config[P.BIVARIATE] == 1 else 0.0
    alpha, theta, u0, inj = (cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY],
                             cell[P.INJECTION])
    cls = _new_classes(n)
    members, bcnt, bpos, bin_of, lo, hi, dirty, table, tabd, dlist, dpos, dcnt = cls[:12]
    occ, srow, trow, drow = cls[12:]
    m_ref, ptot, s4 = _fill_classes(p, isdrop, sep, rho, bin_of, bpos, members, bcnt, lo, hi,
                                    dirty, dlist, dpos, dcnt)
    conc0 = ptot / volume0
    mass_rate = inj * pd                     # kg/(m3 s) added by injection
    s3_factor = _C_D / rho                   # sum d^3 = s3_factor * ptot
    d43_tab = s4 / (s3_factor * ptot) * _D43_MARGIN
    for c in range(N_BINS):
        _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, params, config)
        dirty[c] = False

    trials = accepted = injections = violations = 0
    status = STATUS_OK
    since_sync = 0
    t = w_gg = w_dg = 0.0
    k_out = n_occ = 0
    changed = True
    while k_out < n_out:
        if changed:
            changed = False
            n_occ, w_gg, w_dg = _pair_weights(bcnt, table, tabd, occ, srow, trow, drow)
        vol = ptot / (conc0 + mass_rate * t)
        nd = dcnt[0]
        r_gg = 0.5 * w_gg / vol
        r_dg = nd * w_dg / vol
        r_inj = inj * vol
        r = r_gg + r_dg + r_inj
        if not (r < np.inf):
            status = STATUS_NONFINITE
            break
        t_next = _next_event_time(t, r, exponential_dt)
        while k_out < n_out and output_times[k_out] < t_next:
            box_quantities(p, b, isdrop, conc0 + mass_rate * output_times[k_out], rho,
                           out[k_out])
            k_out += 1
        if k_out >= n_out:
            break
        if t_next <= t:
            status = STATUS_STALLED
            break
        t = t_next

        u = np.random.random() * r
        if u < r_inj or (r_gg <= 0.0 and r_dg <= 0.0):
            injections += 1
            ptot, s4 = _inject(p, b, isdrop, pd, bd, sep, rho, m_ref, ptot, s4, bin_of, bpos,
                               members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
            changed = True
        else:
            trials += 1
            d43 = s4 / (s3_factor * ptot)
            granules = (u < r_inj + r_gg and r_gg > 0.0) or r_dg <= 0.0
            i, j, rate, bound = _propose(granules, w_gg, w_dg, n_occ, occ, trow, srow, drow,
                                         bcnt, table, tabd, members, dlist, nd, p, b, alpha,
                                         theta, u0, d43, params, config)
            if rate > bound:
                violations += 1
            if np.random.random() * bound < rate:
                accepted += 1
                ptot, s4 = _merge(i, j, p, b, isdrop, rho, m_ref, ptot, s4, bin_of, bpos,
                                  members, bcnt, lo, hi, dirty, dlist, dpos, dcnt)
                changed = True
            if trials >= max_trials:
                status = STATUS_MAX_TRIALS
                break
        if changed:
            since_sync, ptot, s4, d43_tab = _refresh_bounds(
                since_sync, p, rho, s3_factor, ptot, s4, d43_tab, bin_of, lo, hi, dirty,
                table, tabd, alpha, theta, params, config)

    for k in range(k_out, n_out):
        for q in range(out.shape[1]):
            out[k, q] = np.nan
    return trials, accepted, injections, violations, status, t


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
def _propose(granules, w_gg, w_dg, n_occ, occ, trow, srow, drow, bcnt, table, tabd, members,
             dlist, nd, p, b, alpha, theta, u0, d43, params, config):
    """Propose an aggregation: a granule-granule pair (``granules``) or a droplet capture.
    Returns (slot i, slot j, its rate [m3/s], the majorant it was proposed with [m3/s])."""
    if granules:
        i, j, a, c = _pick_granule_pair(w_gg, n_occ, occ, trow, srow, bcnt, table, members)
        rate = aggregation_rate(p[i], b[i], p[j], b[j], alpha, theta, u0, d43, params, config)
        return i, j, rate, table[a, c]
    i, j, a = _pick_capture(w_dg, n_occ, occ, drow, bcnt, members, dlist, nd)
    rate = droplet_capture_rate(p[i], b[i], alpha, theta, u0, d43, params, config)
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
def _refresh_bounds(since_sync, p, rho, s3_factor, ptot, s4, d43_tab, bin_of, lo, hi, dirty,
                    table, tabd, alpha, theta, params, config):
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
    d43 = s4 / (s3_factor * ptot)
    if d43 > d43_tab or d43 * _D43_MARGIN ** 3 < d43_tab:
        rebuild = True
    if rebuild:
        d43_tab = d43 * _D43_MARGIN
        for c in range(N_BINS):
            _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, params, config)
            dirty[c] = False
    else:
        for c in range(N_BINS):
            if dirty[c]:
                _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, params, config)
                dirty[c] = False
    return since_sync, ptot, s4, d43_tab
