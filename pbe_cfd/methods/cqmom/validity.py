"""Closure validity of the CQMOM's conditional binder quadrature (docs/physics.md section 9.1,
"Closure validity").

The geometric success factor psi_g = 1 - (1 - eta)(1 - eta') is a steep sigmoid in each
partner's binder fraction y (b_s = 35.1: from 0.01 to 0.82 between a dry primary and one that
captured one droplet). Its mean over a size node's binder distribution is what the N2-point
conditional rule integrates, and where the distribution is a few atoms on both sides of the
step (dry granules and wetted ones) that quadrature can be off by tens of per cent with no
sign in the moments (results/hard-cases.md, results/cqmom.md).

The estimate is embedded: the run's rule (Gauss, exact through the conditional moment
2 N2 - 1) against the rule of the same carried moments through 2 N2 - 2 that puts an atom on
the dry state y = 0 (the lower principal representation: N2 - 1 points plus the dry atom).
Both are realizable readings of the moments the closure resolves to one degree less; where
they disagree on the pair rate weighted by psi_g, the carried moments do not determine that
rate. The pair rate is the number's aggregation loss with the size nodes' collision frequency
left out (a constant kernel: beta's size dependence is smooth, eta's step is not):

    R = 1/2 sum_{a, c} w_a w_c [1 - (1 - E_a)(1 - E_c)],   E_a = sum_b r_ab eta(y_ab)

(independent partners: the pair mean of psi_g is that of the node means). The estimate of a
state is |R_gauss - R_dry| / R_gauss [-].

Run after the integration, on its output states (one numba loop over the rows); it reads the
inversion's work array and calls no source term, so it cannot change a result.
"""
import math

import numba as nb
import numpy as np

from ...physics import parameters as P
from .conditional import _principal3
from .cqmom import invert, off_cond, off_counts, off_points, work_size

#: The accuracy the CQMOM aims at on the moments against the cNMC (3%, results/cqmom.md). A
#: relative error e of the aggregation loss rate makes the number lost by aggregation over
#: any interval e off (it is the time integral of that rate), so a state whose rate the
#: closure cannot fix to better than the aim cannot give the aim: the warning threshold.
RATE_ESTIMATE_THRESHOLD = 0.03


@nb.njit(cache=True, error_model="numpy")
def _eta(y, slope, centre):
    """Accessible-binder share eta(y) [-] of a binder fraction y [-] (physics.properties)."""
    return 1.0 / (1.0 + math.exp(-slope * (y - centre)))


@nb.njit(cache=True, error_model="numpy")
def _dry_atom_mean2(mu1, mu2, slope, centre):
    """Mean of eta over the two-point reading of (1, mu1, mu2) with an atom on y = 0 (atoms on 0
    and mu2 / mu1); NaN where (1, mu1, mu2) is not realizable on [0, 1] (mu2 < mu1^2 or
    mu2 > mu1)."""
    if not (mu1 > 0.0) or not (mu2 >= mu1 * mu1) or not (mu2 <= mu1):
        return math.nan
    w_up = mu1 * mu1 / mu2
    return (1.0 - w_up) * _eta(0.0, slope, centre) + w_up * _eta(mu2 / mu1, slope, centre)


@nb.njit(cache=True, error_model="numpy")
def _dry_atom_mean(mu, m, slope, centre, nodes, weights):
    """Mean of eta over the second reading of a node's fraction moments mu[0:2m]: the lower
    principal representation of mu[0:2m-1] (an atom on y = 0 and m - 1 points); where those
    moments are not realizable (the run's rule then reads the nearest realizable set, not the
    carried one), the same reading of fewer moments (m = 3: of mu0 .. mu2), and at the last
    one point at the mean fraction mu1 (the one moment every rule keeps)."""
    if m >= 3:
        n = _principal3(mu, False, nodes, weights)
        if n > 0:
            total = 0.0
            for a in range(n):
                total += weights[a] * _eta(nodes[a], slope, centre)
            return total
    two = _dry_atom_mean2(mu[1], mu[2], slope, centre)
    if math.isfinite(two):
        return two
    return _eta(min(max(mu[1], 0.0), 1.0), slope, centre)


@nb.njit(cache=True, error_model="numpy")
def _state_estimate(state, config, slope, centre, work, means):
    """|R_gauss - R_dry| / R_gauss of one scaled state (module docstring); NaN for an empty
    cell or no aggregating pair. ``means``: 2 n_max + 6 floats of scratch."""
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    n = invert(state, config, work)
    if n == 0:
        return math.nan
    op = off_points(n_max)
    npt = n_max * m
    oc = off_counts(n_max, m)
    ocond = off_cond(n_max, m)
    gauss = means[0:n_max]
    dry = means[n_max:2 * n_max]
    rule = means[2 * n_max:]
    total = 0.0
    for a in range(n):
        w_a = work[n_max + a]
        total += w_a
        e = 0.0
        for b in range(int(work[oc + a])):
            i = a * m + b
            y = min(max(work[op + npt + i] / work[op + i], 0.0), 1.0)
            e += work[op + 2 * npt + i] / w_a * _eta(y, slope, centre)
        gauss[a] = e
        dry[a] = e
        if work[oc + n_max + a] == 0.0:             # a free node (not an atom on a bound)
            dry[a] = _dry_atom_mean(work[ocond + a * 2 * m:ocond + (a + 1) * 2 * m], m,
                                    slope, centre, rule[0:3], rule[3:6])
    wet_g = 0.0
    wet_d = 0.0
    for a in range(n):
        wet_g += work[n_max + a] * (1.0 - gauss[a])
        wet_d += work[n_max + a] * (1.0 - dry[a])
    rate = total * total - wet_g * wet_g          # twice the pair rate R
    if not (rate > 0.0):
        return math.nan
    return abs(wet_d * wet_d - wet_g * wet_g) / rate


@nb.njit(cache=True, error_model="numpy")
def _estimates(states, config, slope, centre, out):
    n_max = config[P.ORDER]
    m = config[P.BINDER_NODES]
    work = np.zeros(work_size(n_max, m))
    means = np.zeros(2 * n_max + 6)
    state = np.zeros(states.shape[1])
    for r in range(states.shape[0]):
        finite = True
        for j in range(states.shape[1]):
            state[j] = states[r, j]
            finite = finite and math.isfinite(state[j])
        out[r] = _state_estimate(state, config, slope, centre, work, means) if finite else math.nan


def rate_estimates(states, config, params):
    """The closure-validity estimate [-] of each row of scaled CQMOM states (rows: output
    times of a cell, or cells): |R_gauss - R_dry| / R_gauss of the module docstring; NaN where
    it does not apply (an empty cell, no geometric factor, one binder point per size node, no
    binder transported)."""
    states = np.ascontiguousarray(np.atleast_2d(np.asarray(states, dtype=np.float64)))
    out = np.full(len(states), np.nan)
    if (int(config[P.USE_GEOMETRIC]) != 1 or int(config[P.BINDER_NODES]) < 2
            or int(config[P.BIVARIATE]) != 1):
        return out
    _estimates(states, np.asarray(config, dtype=np.int64), float(params[P.GEO_SLOPE]),
               float(params[P.GEO_CENTRE]), out)
    return out


def validity_report(blocks, config, params, row_name):
    """(stats, warnings) of the estimate over ``blocks`` (a sequence of 2-D arrays of scaled
    states, e.g. one per output time with a row per cell, read one at a time): the largest
    estimate, the share of rows above RATE_ESTIMATE_THRESHOLD, and, if any row is above it,
    one warning line naming the method, the row with the largest estimate
    (``row_name(block, row)``: "cell 12 at t = 300 s"), the estimate and the remedy. The stats
    are None where the estimate does not apply."""
    worst, worst_at, above, counted = -1.0, (0, 0), 0, 0
    for k, block in enumerate(blocks):
        est = rate_estimates(block, config, params)
        valid = np.isfinite(est)
        counted += int(valid.sum())
        if valid.any():
            above += int(np.count_nonzero(est[valid] > RATE_ESTIMATE_THRESHOLD))
            r = int(np.nanargmax(est))
            if est[r] > worst:
                worst, worst_at = float(est[r]), (k, r)
    if counted == 0:
        return {"cqmom_closure_estimate_max": None, "cqmom_closure_share_above": None}, []
    stats = {"cqmom_closure_estimate_max": worst,
             "cqmom_closure_share_above": above / counted,
             "cqmom_closure_threshold": RATE_ESTIMATE_THRESHOLD}
    if above == 0:
        return stats, []
    n2 = int(config[P.BINDER_NODES])
    remedy = (f"set [method] binder_nodes = {n2 + 1}" if n2 < 3 else
              "no more binder nodes exist: check against the cNMC ([method] name = 'cnmc')")
    text = (f"CQMOM {int(config[P.ORDER])} x {n2}: the conditional binder quadrature does not "
            f"resolve the geometric efficiency's step: at {row_name(*worst_at)} the "
            f"aggregation rate is uncertain by {worst:.0%} (above "
            f"{RATE_ESTIMATE_THRESHOLD:.0%} in {above} of {counted} cell outputs); {remedy}")
    return stats, [text]
