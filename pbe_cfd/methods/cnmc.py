"""Constant-number Monte Carlo (cNMC) reference for the two-component population (p, b).

Smith & Matsoukas (1998), Lin, Lee & Matsoukas (2002), seed 000 section IV. The physics is the
registry's: ``physics.rates.aggregation_rate`` for granule-granule pairs and
``physics.rates.droplet_capture_rate`` for droplet-granule pairs (DESIGN section 3). All
quantities are SI: masses p, b in kg, volumes in m3, times in s, rates in m3/s (pair rates) or
1/s (event rates of the box), number densities in 1/m3.

Entry points: ``simulate_ensemble`` (plain Python: replicas, seeds, 95% band), ``run_box``
(numba: one replica), ``seed_scenario_benchmark`` (seed 000 scenario timing, not a test).

Algorithm (one replica, ``run_box``)
------------------------------------
N particles (arrays p, b and a droplet flag) sit in a box of volume V [m3]. Granules are sorted
into mass classes a = floor(log2(p / m_ref)) (N_BINS = 64 classes, factor 2 wide, m_ref = the
smallest initial mass / 256, the ends open); each class keeps an interval [lo_a, hi_a] that
contains the masses of its members. Events, with their proposal rates [1/s]:

* granule-granule pairs of classes (a, c): rate_ij = aggregation_rate(i, j) <= B[a, c],
  proposed at n_a n_c B[a, c] / V (a != c) and n_a (n_a - 1) B[a, a] / (2V);
* droplet-granule pairs (only if config[SEPARATE_DROPLETS] == 1): rate = droplet_capture_rate
  of the granule <= B_d[a], proposed at n_a N_d B_d[a] / V; droplet-droplet pairs never
  aggregate;
* injection of one binder droplet (p_d = params[DROPLET_MASS], b = p_d, or b = 0 in a
  univariate scene) at  R_inj = cell[INJECTION] * V.

The box's true aggregation rate is (1/(2V)) sum_{i != j} rate_ij. A trial picks an event class
by its rate, then a pair uniformly within the class pair, and accepts it with probability
rate_ij / B (thinning); this realises exactly the true rate whatever the majorant, as long as it
is one. Every trial advances time by the mean waiting time dt = 1/R, R the sum of all proposal
rates, as seed 000 eq. 20 does (``run_box(..., exponential_dt=1)`` draws dt ~ Exp(R) instead);
with the mean the process lags half a trial on average behind the Poisson clock, which matters
only when trials are rare (a box fed by injection alone gains up to one droplet less by t).
The class table costs O(K_occ) per trial and O(K_occ^2) per accepted event (K_occ = occupied
classes, ~10-30), so trials stay cheap while acceptance stays high for broad distributions:
with one global bound from the smallest and largest particle the sum kernel at k0 M1 t = 5
accepted 1 trial in 175, with the classes 3 in 4.

* Accepted aggregation: particle i becomes (p_i + p_j, b_i + b_j) (for a droplet-granule pair i
  is the granule), slot j is refilled with a copy of a particle k != j chosen uniformly among
  the other N - 1 slots (a copy of a droplet is a droplet).
* Injection: a uniformly chosen slot is overwritten by a droplet (its particle is removed, as
  in seed 000). Removing among the N + 1 (droplet included) instead would be biased: the box's
  droplet fraction f must grow at cell[INJECTION] V (1 - f) / N, which is what removal among
  the N old particles gives.
* Volume: aggregation conserves mass and injection adds p_d * cell[INJECTION] kg per m3 per s,
  so the exact mass concentration is C(t) = M10(0) + cell[INJECTION] p_d t. The box volume is
  V(t) = P_box / C(t), P_box the total mass in the box. After a refill this is the seed's
  eq. 18, V -> V (P + p_k) / P; for injection it is eq. 19 with the injected mass entering as its
  expectation instead of in Poisson jumps (the number of droplets put into the box stays
  random). Hence M10 is exact to round-off with and without injection.
  M01 is conserved to round-off only where every particle has the same binder fraction (no
  droplets, uniform initial binder fraction): copying particle k changes the box's binder/mass
  ratio by (b_k - y_box p_k) / P, which averages to zero over the choice of k but is not zero
  per event. Otherwise M01 is unbiased (measured: mean deviation from M01(0) + rate p_d t below
  0.04% +- 0.04% over 1280 replicas) with O(1/sqrt(N)) scatter that the ensemble band covers.

Why the majorants are upper bounds
----------------------------------
Every efficiency factor of ``physics.efficiency`` lies in [0, 1] (geometric: 1 - (1-eta)(1-eta')
with eta in (0, 1); physical: a step or 0.5 (1 - tanh) in [0, 1]; saturation: min(1, S/S_max)),
so rate <= beta (collision frequency) and capture rate <= droplet_factor * beta(p, p_d).
Every kernel beta(p, p') of the registry is, for fixed p', quasi-convex in p (non-increasing
then non-decreasing, or monotone), so on an interval its maximum lies at an end point, and the
maximum over a rectangle [lo1, hi1] x [lo2, hi2] lies at one of its four corners:

* constant: beta = k0, constant;
* sum: k0 (p + p'), increasing; product: k0 p p', increasing (p, p' >= 0);
* eke: with u = x^(1/3), x = p / (rho_s v_ref), beta = k0 f(u, u'),
  f = (u + u')^2 sqrt(u^-3 + u'^-3); d ln f / du has the sign of 2 r^4 + r/2 - 3/2, r = u/u',
  which is increasing in r with a single zero: f decreases, then increases in u (so the
  largest rates are between the smallest and the largest granule, or two of the largest);
* ktgf: beta = k0 g0(alpha) sqrt(Theta) d43^(3/2) f(d, d') with the same f of the diameters;
  g0 and Theta are common to all pairs; it increases with the box's d43.

So B[a, c] = max of beta over the corners of [lo_a, hi_a] x [lo_c, hi_c] and
B_d[a] = droplet_factor * max(beta(lo_a, p_d), beta(hi_a, p_d)) (``interval_pair_bound``,
times 1 + 1e-12 against round-off) bound every pair of the classes. The kernels that use d43
(ktgf) are evaluated for the table at d43_tab = 1.02 d43 and the table is rebuilt when the
current d43 rises above d43_tab (or falls 6% below it), which is a bound because every kernel
is non-decreasing in d43. Intervals are kept cheaply: a granule entering a class widens its
interval (and its row of the table, K kernel calls, is recomputed), a copy lands inside an
existing interval, a removal leaves a stale, wider interval, which is still a bound; every N
accepted events or injections an O(N) pass resets the intervals to the exact ranges (and
re-sums P and sum d^4 against round-off drift): O(1) amortised per event, no O(N^2) scan.
A proposal with rate above its bound is counted in ``violations`` and makes
``simulate_ensemble`` raise (never seen; the tests check every pair of random populations).
``pair_rate_bounds`` gives the same bound for one class spanning [gmin, gmax].

ktgf needs d43 = sum d^4 / sum d^3 [m] of the granules of the box (free droplets excluded
where they are a population of their own, as in every method: docs/physics.md, "d43"; with
d = (6 p / (pi rho_s))^(1/3)); sum d^3 follows from P and sum d^4 is updated per event, the
free droplets (all of mass p_d) are subtracted (``_kernel_d43``).

Finite-N bias (why the band can be trusted, and when it cannot)
---------------------------------------------------------------
Pairs are proposed over the N (N - 1) / 2 distinct pairs and the refill copies one of the
N - 1 others, whose mean mass is P / (N - 1); so per event M0 = N / V drops on average by the
factor E[P / (P + p_k)] = 1 - 1/(N-1) + E[p_k^2] / P^2 + ...: the leading terms reproduce
Smoluchowski's dM0/dt exactly and the Jensen term of the copy leaves a relative bias of the
decay rate of about S2 / P^2 = M20 M00 / (M10^2 N) (S2 = sum p^2). The missing self-pairs bias
dM20/dt by about - k0 M20 / V for the constant kernel and by - 2 k0 M30 / V for the sum kernel,
relative size S3 / (P S2) = M30 M00 / (M10 M20 N). For the constant kernel all of these are
O((1 + cv^2)/N) (cv the coefficient of variation of p), ~1e-3 at N = 2000, far inside the band
of a few replicas (measured coverage of the 95% band of 16 replicas of N = 2000 at tau = 1
and 5: 92.5-97.5% over 40
ensembles). For the sum kernel (monodisperse start, T = k0 M1 t) M30 M00 / (M10 M20) =
3 e^T - 2, so d ln M20/dT = 2 (1 - (3 e^T - 2)/N) and M20(T = 5) is low by about
2 * int_0^5 (3 e^s - 2) ds / N = 864/N, and M20 of one replica is heavy-tailed (its value
rests on the few largest particles), which also thins the coverage of a t-band. Coverage of
the 95% band of 8 replicas at T = 5, over 40 ensembles each: N = 2000: M20 35% (mean -28%),
M00 80% (mean +8.6%, predicted +(e^5 - 1)/N = +7%); N = 20000: M20 75% (mean -5.8% +- 1.9%),
M00 85%; N = 50000: M20 95% (mean -3.3% +- 1.3%), M00 92.5% (+0.8%). So the sum kernel at
T = 5 needs N ~ 5e4; at T = 1 the biases are -2 (3 (e - 1) - 2)/N = -6.3/N (M20)
and +(e - 1)/N = +1.7/N (M00).
"""
import math
import time

import numba as nb
import numpy as np
from scipy import stats

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
def _kernel_d43(s4, ptot, n_free_droplets, pd, rho):
    """d43 [m] the ktgf kernel uses: sum d^4 / sum d^3 of the granules, from the box sums
    s4 = sum d^4 [m^4] and ptot = sum p [kg] less the free droplets (mass pd [kg] each);
    0 if the box holds no granule mass."""
    gran_mass = ptot - n_free_droplets * pd
    if not gran_mass > 0.0:
        return 0.0
    return max(s4 - n_free_droplets * _d4(pd, rho), 0.0) / (_C_D / rho * gran_mass)


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
    droplet (ignored, set to 0, unless config[SEPARATE_DROPLETS] == 1); volume0: initial box
    volume [m3]; output_times [s], non-decreasing, from 0; cell: float64 row (ALPHA [-],
    THETA [m2/s2], COLLISION_VELOCITY [m/s], INJECTION [droplets/(m3 s)]); params, config:
    the arrays of physics.parameters; rng_seed: seed of numba's generator; exponential_dt: 0 =
    mean waiting time 1/R per trial (seed 000), 1 = exponential; max_trials: trial budget.
    out: float64 (len(output_times), N_QUANTITIES), rows in the order of QUANTITY_NAMES.

    Returns (trials, accepted, injections, violations, status, t_reached [s]); trials counts
    aggregation proposals, accepted the aggregations done, violations the proposals whose rate
    exceeded the majorant (must be 0), status one of the STATUS_* codes (rows not reached are
    NaN when status != 0).
    """
    np.random.seed(rng_seed)
    n = p.size
    n_out = output_times.size
    sep = config[P.SEPARATE_DROPLETS] == 1
    biv = config[P.BIVARIATE] == 1
    rho = params[P.DENSITY]
    pd = params[P.DROPLET_MASS]
    bd = pd if biv else 0.0
    alpha = cell[P.ALPHA]
    theta = cell[P.THETA]
    u0 = cell[P.COLLISION_VELOCITY]
    inj = cell[P.INJECTION]

    # mass classes of the granules, the droplet list
    members = np.empty((N_BINS, n), np.int32)
    bcnt = np.zeros(N_BINS, np.int64)
    bpos = np.empty(n, np.int64)
    bin_of = np.empty(n, np.int64)
    lo = np.full(N_BINS, np.inf)
    hi = np.zeros(N_BINS)
    dirty = np.zeros(N_BINS, np.bool_)
    table = np.zeros((N_BINS, N_BINS))
    tabd = np.zeros(N_BINS)
    dlist = np.empty(n, np.int64)
    dpos = np.empty(n, np.int64)
    dcnt = np.zeros(1, np.int64)
    occ = np.empty(N_BINS, np.int64)
    srow = np.zeros(N_BINS)
    trow = np.zeros(N_BINS)
    drow = np.zeros(N_BINS)

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
    conc0 = ptot / volume0
    mass_rate = inj * pd                     # kg/(m3 s) added by injection
    d43 = _kernel_d43(s4, ptot, dcnt[0], pd, rho)
    d43_tab = d43 * _D43_MARGIN
    for c in range(N_BINS):
        _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, params, config)
        dirty[c] = False

    trials = 0
    accepted = 0
    injections = 0
    violations = 0
    status = STATUS_OK
    since_sync = 0
    t = 0.0
    k_out = 0
    changed = True
    w_gg = 0.0
    w_dg = 0.0
    n_occ = 0
    while k_out < n_out:
        if changed:
            # class-pair majorant weights over the occupied classes, O(K_occ^2)
            changed = False
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
        conc = conc0 + mass_rate * t
        vol = ptot / conc
        nd = dcnt[0]
        r_gg = 0.5 * w_gg / vol
        r_dg = nd * w_dg / vol
        r_inj = inj * vol
        r = r_gg + r_dg + r_inj
        if not (r < np.inf):
            status = STATUS_NONFINITE
            break
        if r <= 0.0:
            t_next = np.inf
        elif exponential_dt == 1:
            t_next = t - math.log(1.0 - np.random.random()) / r
        else:
            t_next = t + 1.0 / r
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
            # injection: overwrite a random slot with a droplet
            injections += 1
            k = np.random.randint(n)
            ptot -= p[k]
            s4 -= _d4(p[k], rho)
            _remove(k, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
            p[k] = pd
            b[k] = bd
            isdrop[k] = 1 if sep else 0
            _insert(k, sep, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty, dlist,
                    dpos, dcnt)
            ptot += pd
            s4 += _d4(pd, rho)
            changed = True
        else:
            trials += 1
            d43 = _kernel_d43(s4, ptot, dcnt[0], pd, rho)
            if (u < r_inj + r_gg and r_gg > 0.0) or r_dg <= 0.0:
                # granule-granule: class a by its share of ordered pairs, then class c
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
                rate = aggregation_rate(p[i], b[i], p[j], b[j], alpha, theta, u0, d43,
                                        params, config)
                bound = table[a, c]
            else:
                # droplet-granule: granule class a by n_a * B_d(a), a random droplet
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
                rate = droplet_capture_rate(p[i], b[i], alpha, theta, u0, d43, params, config)
                bound = tabd[a]
            if rate > bound:
                violations += 1
            if np.random.random() * bound < rate:
                accepted += 1
                # merge j into i (i is a granule)
                _remove(i, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
                _remove(j, bin_of, bpos, members, bcnt, dlist, dpos, dcnt)
                s4 -= _d4(p[i], rho) + _d4(p[j], rho)
                p[i] += p[j]
                b[i] += b[j]
                s4 += _d4(p[i], rho)
                _insert(i, False, p, m_ref, bin_of, bpos, members, bcnt, lo, hi, dirty,
                        dlist, dpos, dcnt)
                # refill j with a copy of a particle k != j
                k = np.random.randint(n - 1)
                if k >= j:
                    k += 1
                p[j] = p[k]
                b[j] = b[k]
                isdrop[j] = isdrop[k]
                _insert(j, isdrop[k] == 1, p, m_ref, bin_of, bpos, members, bcnt, lo, hi,
                        dirty, dlist, dpos, dcnt)
                ptot += p[j]
                s4 += _d4(p[j], rho)
                changed = True
            if trials >= max_trials:
                status = STATUS_MAX_TRIALS
                break
        if changed:
            since_sync += 1
            rebuild = False
            if since_sync >= n:
                # O(N) pass every N changes: exact sums and tight class intervals
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
            d43 = _kernel_d43(s4, ptot, dcnt[0], pd, rho)
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
                        _bound_row(c, lo, hi, table, tabd, alpha, theta, d43_tab, params,
                                   config)
                        dirty[c] = False

    for k in range(k_out, n_out):
        for q in range(out.shape[1]):
            out[k, q] = np.nan
    return trials, accepted, injections, violations, status, t


# ---------------------------------------------------------------------------------------------
# Python wrapper
# ---------------------------------------------------------------------------------------------
def initial_box(params, config, initial, particles, rng):
    """Sample one replica's initial box.

    params, config: arrays of physics.parameters; initial: dict of simulate_ensemble;
    particles: N; rng: numpy Generator. Returns (p [kg], b [kg], isdrop (int64 flags),
    volume [m3]). The box holds N_d droplets (p_d, b = p_d) and N - N_d granules with
    N_d = N nd0 / (n0 + nd0) rounded stochastically (unbiased over replicas), and
    V = N / (n0 + nd0).
    """
    n0 = float(initial["number_density"])
    nd0 = float(initial.get("droplet_number_density", 0.0))
    p0 = float(initial["mean_mass"])
    y0 = float(initial.get("binder_fraction", 0.0))
    dist = initial.get("distribution", "monodisperse")
    biv = int(config[P.BIVARIATE]) == 1
    sep = int(config[P.SEPARATE_DROPLETS]) == 1
    pd = float(params[P.DROPLET_MASS])

    expected_drops = particles * nd0 / (n0 + nd0)
    n_drop = int(math.floor(expected_drops))
    if rng.random() < expected_drops - n_drop:
        n_drop += 1
    n_gran = particles - n_drop
    if dist == "monodisperse":
        pg = np.full(n_gran, p0)
    elif dist == "exponential":
        pg = rng.exponential(p0, n_gran)
    else:
        raise ValueError(f"initial distribution {dist!r}: expected 'monodisperse' or "
                         "'exponential'")
    p = np.empty(particles)
    b = np.zeros(particles)
    isdrop = np.zeros(particles, np.int64)
    p[:n_gran] = pg
    p[n_gran:] = pd
    if biv:
        b[:n_gran] = y0 * pg
        b[n_gran:] = pd
    if sep:
        isdrop[n_gran:] = 1
    return p, b, isdrop, particles / (n0 + nd0)


def _validate(params, config, cell, initial, output_times, particles, replicas):
    if params.shape != (P.N_PARAMS,):
        raise ValueError(f"params: expected a float array of length {P.N_PARAMS}")
    if config.shape != (P.N_CONFIG,):
        raise ValueError(f"config: expected an int array of length {P.N_CONFIG}")
    if cell.shape != (P.N_CELL,):
        raise ValueError(f"cell: expected one row of length {P.N_CELL}")
    if particles < 2:
        raise ValueError(f"particles = {particles}: expected at least 2")
    if replicas < 1:
        raise ValueError(f"replicas = {replicas}: expected at least 1")
    if output_times.ndim != 1 or output_times.size == 0 or output_times[0] != 0.0:
        raise ValueError("output_times: expected a 1-D array starting at 0 s")
    if not np.all(np.isfinite(output_times)) or np.any(np.diff(output_times) < 0):
        raise ValueError("output_times: expected finite, non-decreasing times [s]")
    n0 = float(initial["number_density"])
    nd0 = float(initial.get("droplet_number_density", 0.0))
    if n0 < 0 or nd0 < 0 or n0 + nd0 <= 0:
        raise ValueError("initial number_density + droplet_number_density: expected > 0 1/m3")
    if not float(initial["mean_mass"]) > 0:
        raise ValueError("initial mean_mass: expected > 0 kg")
    y0 = float(initial.get("binder_fraction", 0.0))
    if not 0.0 <= y0 <= 1.0:
        raise ValueError(f"initial binder_fraction = {y0}: expected in [0, 1]")
    if cell[P.INJECTION] < 0:
        raise ValueError("cell INJECTION: expected >= 0 droplets/(m3 s)")
    if (cell[P.INJECTION] > 0 or nd0 > 0) and not params[P.DROPLET_MASS] > 0:
        raise ValueError("params DROPLET_MASS: expected > 0 kg with droplets present")
    if not params[P.DENSITY] > 0:
        raise ValueError("params DENSITY: expected > 0 kg/m3")


def simulate_ensemble(params, config, cell, initial, output_times, particles, replicas, seed,
                      progress=None):
    """cNMC ensemble: mean and 95% confidence band of the moments at ``output_times``.

    params (float64, N_PARAMS), config (int64, N_CONFIG): arrays of physics.parameters;
    cell: float64 row (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s],
    INJECTION [droplets/(m3 s)]); initial: {"distribution": "monodisperse" | "exponential",
    "number_density": n0 [1/m3], "mean_mass": p0 [kg], "binder_fraction": y0 [-],
    "droplet_number_density": nd0 [1/m3]}; output_times [s]: 1-D, from 0, non-decreasing;
    particles: N per box; replicas: R independent boxes; seed: int (same seed, same numbers);
    progress: optional callable(fraction_done) called after each replica.

    Returns a dict of numpy arrays: "time_s" [s]; for each name in QUANTITY_NAMES (M00 [1/m3],
    M10 [kg/m3], M01 [kg/m3], M20 [kg2/m3], M11 [kg2/m3], M02 [kg2/m3] of the whole population
    incl. free droplets, droplet_number_density [1/m3], d32_m [m], d43_m [m],
    binder_fraction [-] = M01/M10 of each replica) the ensemble mean under the name and the
    95% band mean -+ t_{0.975, R-1} std / sqrt(R) under name + "_lo" / "_hi" (zero width when
    R = 1); "trials", "accepted", "events_injection": totals over the ensemble (int64).
    Raises RuntimeError if a replica exhausts MAX_TRIALS trials (e.g. a product kernel past
    gelation), FloatingPointError for an infinite event rate (alpha >= alpha_max).
    """
    params = np.ascontiguousarray(params, dtype=np.float64)
    config = np.ascontiguousarray(config, dtype=np.int64)
    cell = np.ascontiguousarray(cell, dtype=np.float64).reshape(-1)
    output_times = np.ascontiguousarray(output_times, dtype=np.float64)
    particles = int(particles)
    replicas = int(replicas)
    _validate(params, config, cell, initial, output_times, particles, replicas)

    n_out = output_times.size
    data = np.empty((replicas, n_out, N_QUANTITIES))
    totals = np.zeros(3, np.int64)
    children = np.random.SeedSequence(int(seed)).spawn(replicas)
    for r, child in enumerate(children):
        rng = np.random.default_rng(child)
        p, b, isdrop, volume0 = initial_box(params, config, initial, particles, rng)
        box_seed = int(rng.integers(0, 2 ** 31 - 1))
        trials, accepted, injections, violations, status, t_reached = run_box(
            p, b, isdrop, volume0, output_times, cell, params, config, box_seed, 0,
            MAX_TRIALS, data[r])
        if violations:
            raise RuntimeError(f"cNMC replica {r}: {violations} pair rates exceeded the "
                               "majorant (bound bug)")
        if status == STATUS_MAX_TRIALS:
            raise RuntimeError(f"cNMC replica {r}: {trials} trials reached at t = "
                               f"{t_reached:.6g} s before the end time "
                               f"{output_times[-1]:.6g} s; the event rate is running away "
                               "(gelation?)")
        if status == STATUS_NONFINITE:
            raise FloatingPointError(f"cNMC replica {r}: event rate not finite at t = "
                                     f"{t_reached:.6g} s (overflow, or alpha >= alpha_max in ktgf)")
        if status == STATUS_STALLED:
            raise RuntimeError(f"cNMC replica {r}: time step below the resolution of t at "
                               f"t = {t_reached:.6g} s (event rate too high)")
        totals += (trials, accepted, injections)
        if progress is not None:
            progress((r + 1) / replicas)

    mean = data.mean(axis=0)
    if replicas > 1:
        half = (stats.t.ppf(0.975, replicas - 1) * data.std(axis=0, ddof=1)
                / math.sqrt(replicas))
    else:
        half = np.zeros_like(mean)
    result = {"time_s": output_times.copy()}
    for q, name in enumerate(QUANTITY_NAMES):
        result[name] = mean[:, q]
        result[name + "_lo"] = mean[:, q] - half[:, q]
        result[name + "_hi"] = mean[:, q] + half[:, q]
    result["trials"] = np.int64(totals[0])
    result["accepted"] = np.int64(totals[1])
    result["events_injection"] = np.int64(totals[2])
    return result


# ---------------------------------------------------------------------------------------------
# seed 000 scenario (benchmark, not a test)
# ---------------------------------------------------------------------------------------------
def seed_scenario_setup():
    """params, config, cell, initial of the seed 000 Wurster scenario (tables I-II), SI, taken
    from the bundled ``seed-wurster-cnmc`` scene (the one place those values are written)."""
    import dataclasses

    from .. import model
    from ..scene import load_scene

    scene = load_scene("seed-wurster-cnmc")
    arrays = model.pack(scene)
    initial = dataclasses.asdict(scene.initial)     # the keys simulate_ensemble reads
    return arrays.params, arrays.config, model.well_mixed_cell(scene)[0], initial


def seed_scenario_benchmark(particles=10_000, replicas=1, seed=0, end_time=600.0,
                            output_interval=1.0, verbose=True):
    """Run the seed 000 scenario (see seed_scenario_setup) on one core and time it.

    particles: N per box; replicas: R; seed: int; end_time, output_interval [s].
    Returns {"result": simulate_ensemble's dict, "wall_s_per_replica" [s],
    "trials_per_s", "accepted_per_s" [1/s of wall time], "report": printable summary}.
    The first call includes numba compilation unless the cache is warm (it warms it with a
    tiny run first).
    """
    params, config, cell, initial = seed_scenario_setup()
    times = np.arange(0.0, end_time + 0.5 * output_interval, output_interval)
    simulate_ensemble(params, config, cell, initial, times[:3], 50, 1, seed)   # compile/warm
    t0 = time.perf_counter()
    res = simulate_ensemble(params, config, cell, initial, times, particles, replicas, seed)
    wall = time.perf_counter() - t0
    lines = [f"seed scenario: N = {particles}, R = {replicas}, {end_time:g} s, "
             f"wall {wall / replicas:.2f} s per replica",
             f"trials {int(res['trials'])} ({res['trials'] / wall:.3g}/s), accepted "
             f"{int(res['accepted'])} ({res['accepted'] / wall:.3g}/s), injections "
             f"{int(res['events_injection'])}"]
    for tq in (0.0, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0):
        if tq > end_time:
            continue
        k = int(np.argmin(np.abs(times - tq)))
        lines.append(f"t = {times[k]:6.1f} s  M00 = {res['M00'][k]:.4e} "
                     f"[{res['M00_lo'][k]:.4e}, {res['M00_hi'][k]:.4e}] 1/m3  "
                     f"n_d = {res['droplet_number_density'][k]:.3e}  "
                     f"M10 = {res['M10'][k]:.5e}  M01 = {res['M01'][k]:.5e}  "
                     f"M20 = {res['M20'][k]:.4e}  d43 = {res['d43_m'][k] * 1e6:.1f} um")
    report = "\n".join(lines)
    if verbose:
        print(report)
    return {"result": res, "wall_s_per_replica": wall / replicas,
            "trials_per_s": res["trials"] / wall, "accepted_per_s": res["accepted"] / wall,
            "report": report}
