"""Constant-number Monte Carlo (cNMC) reference for the two-component population (p, b).

Smith & Matsoukas (1998), Lin, Lee & Matsoukas (2002), seed 000 section IV. The physics is the
registry's: ``physics.rates.aggregation_rate`` for granule-granule pairs and
``physics.rates.droplet_capture_rate`` for droplet-granule pairs (docs/physics.md section 7). All
quantities are SI: masses p, b in kg, volumes in m3, times in s, rates in m3/s (pair rates) or
1/s (event rates of the box), number densities in 1/m3.

Entry points: ``simulate_ensemble`` (plain Python: replicas, seeds, 95% band), ``run_box``
(numba: one replica, in ``methods.cnmc_box``); the seed 000 scenario timing is
``pbe_cfd.bench.cnmc.seed_scenario_benchmark``.

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
* injection of one binder droplet (p_d = params[DROPLET_MASS], b = params[DROPLET_LIQUID],
  or b = 0 in a univariate scene) at  R_inj = cell[INJECTION] * V;
* breakage of a granule (only with a [breakage] table): proposed per mass class at n_a B_a,
  B_a the largest selection rate S [1/s] on the class interval, accepted with S(p_i) / B_a;
  an accepted break keeps the particle count by the constant-number rule of
  ``methods.cnmc_breakage`` (first daughter in the parent's slot, the second replaces a
  particle drawn uniformly among the N + 1 after the split, the volume follows the mass).

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
* Drying (a [drying] table): between events every particle's liquid drifts, free droplets
  too (``methods.cnmc.drying``, ``methods.cnmc.droplets``); the box dries at each output
  time, after every N / DRIFT_TRIALS proposals and at least every DRIFT_SHARE of its
  drying time, and the evaporated liquid E [kg/m3]
  leaves the mass concentration below.
* Volume: aggregation conserves mass and injection adds p_d * cell[INJECTION] kg per m3 per s
  (with a schedule, p_d times its rate at t: ``cnmc.spray``), so the exact mass concentration
  is C(t) = M10(0) + cell[INJECTION] p_d t (- E with drying). The box volume is
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
where they are a population of their own, as in every method: docs/physics.md section 4.3;
with d = (6 p / (pi rho_s))^(1/3)); sum d^3 follows from P and sum d^4 is updated per event,
the free droplets are subtracted at their mean mass and mean d^4 (all p_d without drying;
with drying refreshed at every drift: ``cnmc.droplets``, ``cnmc_box._kernel_d43``).

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

import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid
from ..entry import RateNotFinite, RunStopped
from .drying import evaporated_columns
from .spray import constant_spray, scheduled_spray
from .box import (MAX_TRIALS, MOMENT_NAMES, N_QUANTITIES, PSD_BINS, QUANTITY_NAMES,
                  STATUS_MAX_TRIALS, STATUS_NONFINITE, STATUS_OK, STATUS_STALLED,
                  interval_pair_bound, pair_rate_bounds, run_box, run_box_with_sizes)

__all__ = ["simulate_ensemble", "initial_box", "run_box", "pair_rate_bounds",
           "interval_pair_bound", "MOMENT_NAMES", "QUANTITY_NAMES", "N_QUANTITIES",
           "STATUS_OK", "STATUS_MAX_TRIALS", "STATUS_NONFINITE", "STATUS_STALLED", "MAX_TRIALS"]


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
        b[n_gran:] = float(droplet_liquid(params))
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


class _ClassSums:
    """Running sums over the replicas of the granule mass fraction per size class (mean and
    band without keeping every replica) and of the binder and granule mass per class."""

    def __init__(self, n_out):
        self.classes = np.zeros((n_out, PSD_BINS, 2))    # run_box fills it per replica
        self.sum = np.zeros((n_out, PSD_BINS))
        self.sum_sq = np.zeros((n_out, PSD_BINS))
        self.mass = np.zeros((n_out, PSD_BINS))
        self.binder = np.zeros((n_out, PSD_BINS))

    def add(self):
        mass = self.classes[:, :, 0]
        total = mass.sum(axis=1, keepdims=True)
        frac = mass / np.where(total > 0, total, 1.0)
        self.sum += frac
        self.sum_sq += frac * frac
        self.mass += mass
        self.binder += self.classes[:, :, 1]

    def result(self, replicas, t_factor):
        mean = self.sum / replicas
        if replicas > 1:
            var = np.maximum(self.sum_sq - replicas * mean * mean, 0.0) / (replicas - 1)
            half = t_factor * np.sqrt(var)
        else:
            half = np.zeros_like(mean)
        binder = np.where(self.mass > 0, self.binder / np.where(self.mass > 0, self.mass, 1.0),
                          0.0)
        return {"psd_mass_fraction": mean, "psd_mass_fraction_lo": mean - half,
                "psd_mass_fraction_hi": mean + half, "psd_binder_fraction": binder}


def _check_replica(r, violations, status, trials, t_reached, t_end):
    """Raise RunStopped (RateNotFinite) naming replica r and why it stopped at t_reached
    [s] before t_end [s] (its ``run_box_with_sizes`` status and counts), if it did."""
    if violations:
        raise RunStopped(f"cNMC replica {r}: {violations} pair rates exceeded their "
                         "majorant (a defect of the cNMC's bounds: please report it)")
    if status == STATUS_MAX_TRIALS:
        raise RunStopped(f"cNMC replica {r}: {trials} trials reached at t = {t_reached:.6g} s "
                         f"before the end time {t_end:.6g} s; the event rate is running away "
                         "(gelation?)")
    if status == STATUS_NONFINITE:
        raise RateNotFinite(f"cNMC replica {r}: event rate not finite at t = "
                            f"{t_reached:.6g} s (overflow, or alpha >= alpha_max in ktgf)")
    if status == STATUS_STALLED:
        raise RunStopped(f"cNMC replica {r}: time step below the resolution of t at "
                         f"t = {t_reached:.6g} s (event rate too high)")


def _spray_of(cell, params, segments):
    """The box's ``cnmc.spray.Spray``: the schedule's ``segments`` [(t0 [s], t1 [s], rate
    [droplets/(m3 s)])], or cell[INJECTION] from t = 0 (segments None)."""
    if segments is None:
        return constant_spray(cell[P.INJECTION], params[P.DROPLET_MASS])
    spray = scheduled_spray(segments, params[P.DROPLET_MASS])
    if np.any(spray.rates < 0) or (np.any(spray.rates > 0) and not params[P.DROPLET_MASS] > 0):
        raise ValueError("segments: expected rates >= 0 droplets/(m3 s) and, with any spray, "
                         "params[DROPLET_MASS] > 0")
    return spray


def simulate_ensemble(params, config, cell, initial, output_times, particles, replicas, seed,
                      progress=None, segments=None):
    """cNMC ensemble: mean and 95% confidence band of the moments at ``output_times``.

    params (float64, N_PARAMS), config (int64, N_CONFIG): arrays of physics.parameters;
    cell: float64 row (ALPHA [-], THETA [m2/s2], COLLISION_VELOCITY [m/s],
    INJECTION [droplets/(m3 s)]); initial: {"distribution": "monodisperse" | "exponential",
    "number_density": n0 [1/m3], "mean_mass": p0 [kg], "binder_fraction": y0 [-],
    "droplet_number_density": nd0 [1/m3]}; output_times [s]: 1-D, from 0, non-decreasing;
    particles: N per box; replicas: R independent boxes; seed: int (same seed, same numbers);
    progress: optional callable(fraction_done) called after each replica; segments: the spray
    schedule [(t0 [s], t1 [s], rate [droplets/(m3 s)])] (``scene.spray.segments``; None: the
    constant cell[INJECTION] from t = 0).

    Returns a dict of numpy arrays: "time_s" [s]; for each name in QUANTITY_NAMES (M00 [1/m3],
    M10 [kg/m3], M01 [kg/m3], M20 [kg2/m3], M11 [kg2/m3], M02 [kg2/m3] of the whole population
    incl. free droplets, droplet_number_density [1/m3], d32_m [m], d43_m [m],
    binder_fraction [-] = M01/M10 of each replica) the ensemble mean under the name and the
    95% band mean -+ t_{0.975, R-1} std / sqrt(R) under name + "_lo" / "_hi" (zero width when
    R = 1); the same for the granules' mass-based "d10_m", "d50_m", "d90_m" [m] (exact
    percentiles of each replica's particle list, free droplets excluded) and "span" [-];
    "psd_mass_fraction" (+ "_lo", "_hi"): shape (times, PSD_BINS), each replica's granule mass
    fraction per class of the size lattice (``cnmc.quantities``), its ensemble mean and band;
    "psd_binder_fraction": the pooled binder mass / granule mass per class (0 if empty); with
    drying "liquid_evaporated" [kg/m3] (+ "_lo", "_hi"); "trials", "accepted",
    "events_injection": totals (int64), with breakage "trials_breakage", "events_breakage".
    Raises RunStopped if a replica cannot finish (MAX_TRIALS trials, e.g. a product kernel
    past gelation; RateNotFinite for an infinite event rate, alpha >= alpha_max)."""
    params = np.ascontiguousarray(params, dtype=np.float64)
    config = np.ascontiguousarray(config, dtype=np.int64)
    cell = np.ascontiguousarray(cell, dtype=np.float64).reshape(-1)
    output_times = np.ascontiguousarray(output_times, dtype=np.float64)
    particles = int(particles)
    replicas = int(replicas)
    _validate(params, config, cell, initial, output_times, particles, replicas)
    spray = _spray_of(cell, params, segments)

    n_out = output_times.size
    data = np.empty((replicas, n_out, N_QUANTITIES))
    evaporated = np.zeros((replicas, n_out))
    sizes = np.zeros((replicas, n_out, 4))           # d10, d50, d90 [m], span
    psd = _ClassSums(n_out)
    totals = np.zeros(5, np.int64)
    children = np.random.SeedSequence(int(seed)).spawn(replicas)
    for r, child in enumerate(children):
        rng = np.random.default_rng(child)
        pct = np.zeros((n_out, 3))
        p, b, isdrop, volume0 = initial_box(params, config, initial, particles, rng)
        box_seed = int(rng.integers(0, 2 ** 31 - 1))
        (trials, accepted, injections, violations, status, t_reached, break_trials,
         splits) = run_box_with_sizes(p, b, isdrop, volume0, output_times, cell, params, config,
                                      box_seed, 0, MAX_TRIALS, data[r], psd.classes, pct,
                                      evaporated[r], spray)
        _check_replica(r, violations, status, trials, t_reached, output_times[-1])
        totals += (trials, accepted, injections, break_trials, splits)
        psd.add()
        sizes[r, :, :3] = pct
        d50 = sizes[r, :, 1]
        sizes[r, :, 3] = np.where(d50 > 0, (sizes[r, :, 2] - sizes[r, :, 0])
                                  / np.where(d50 > 0, d50, 1.0), 0.0)
        if progress is not None:
            progress((r + 1) / replicas)

    t_factor = 0.0
    if replicas > 1:
        from scipy import stats    # here: scipy loads only for the confidence band
        t_factor = float(stats.t.ppf(0.975, replicas - 1)) / math.sqrt(replicas)
    mean = data.mean(axis=0)
    half = t_factor * data.std(axis=0, ddof=1) if replicas > 1 else np.zeros_like(mean)
    result = {"time_s": output_times.copy()}
    for q, name in enumerate(QUANTITY_NAMES):
        result[name] = mean[:, q]
        result[name + "_lo"] = mean[:, q] - half[:, q]
        result[name + "_hi"] = mean[:, q] + half[:, q]
    result.update(evaporated_columns(evaporated, t_factor, config))
    s_mean = sizes.mean(axis=0)
    s_half = t_factor * sizes.std(axis=0, ddof=1) if replicas > 1 else np.zeros_like(s_mean)
    for q, name in enumerate(("d10_m", "d50_m", "d90_m", "span")):
        result[name] = s_mean[:, q]
        result[name + "_lo"] = s_mean[:, q] - s_half[:, q]
        result[name + "_hi"] = s_mean[:, q] + s_half[:, q]
    result.update(psd.result(replicas, t_factor))
    result["trials"] = np.int64(totals[0])
    result["accepted"] = np.int64(totals[1])
    result["events_injection"] = np.int64(totals[2])
    if int(config[P.BREAKAGE]) == 1:
        result["trials_breakage"] = np.int64(totals[3])
        result["events_breakage"] = np.int64(totals[4])
    return result
