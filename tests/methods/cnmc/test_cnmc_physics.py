"""An independent check of the physics inside the cNMC: brute-force pair enumeration.

QMOM, the Laguerre ROM and the cNMC share ``physics.rates``, so agreement between them checks
the moment closures only; an error in a kernel or an efficiency factor would be invisible. Here
the rates are written out again in the test, from the formulas of docs/physics.md (seed 000
eq. 4-6 and sec. II, seed 001 eq. 5.3.4-5.3.5, 6.4.1-6.4.2; no call into ``pbe_cfd.physics``),
and enumerated over every pair of a box of 300 particles with unequal sizes and binder
contents. The cNMC is then asked about the same box:

* its first trial from the box is accepted with probability R_true / R_prop, R_prop the
  proposal rate of its majorant table and R_true = (1/V) sum over pairs of beta psi; the trial
  advances time by 1/R_prop (seed 000 eq. 20), so ``accepted / t_reached`` over M one-trial
  runs (``run_box(..., max_trials=1)``, seeds 0..M-1) estimates R_true: the box's aggregation
  event rate [1/s];
* the particle an accepted trial creates tells which pair merged: its mean mass and binder and
  the share of droplet captures among accepted trials must match the rate-weighted means of the
  enumeration.

Bands: the number accepted is Binomial(M, R_true t), exactly; the product's mean mass over n
accepted trials has the standard error sqrt(Var_r / n), Var_r the rate-weighted variance from
the enumeration; every check passes if its two-sided p-value (exact binomial test, or normal for
the means) exceeds 1e-6, so the whole file raises a false alarm with probability below 3e-5.
With M = 12000 and acceptance 0.5-0.9 the rate is resolved to 0.4-1% (1 sigma), so a kernel
or efficiency error above ~5% fails. The droplet-rich box also pins the ktgf d43 to the
granules' (docs/physics.md section 4.3): counting its 250 droplets would lower every rate by 33%.
"""
import math

import numpy as np
import pytest
from scipy import stats

from pbe_cfd.methods.cnmc import ensemble as cnmc
from pbe_cfd.physics import parameters as P

P_VALUE_FLOOR = 1e-6
RUNS = 12000

# Avicel and binder (seed 000 tables I-II); S_max and porosity for the saturation factor
RHO_S, RHO_L, MU = 1021.0, 1000.0, 0.762
B_S, C_S, F_L, G_L, H_A, R_G = 35.1, 0.129, 25.9, 0.327, 6.3e-6, 60e-6
EPS, S_MAX = 0.4, 0.3
ALPHA_MAX = 0.62
D_PRIMARY = 100.4e-6
P_PRIMARY = RHO_S * math.pi / 6 * D_PRIMARY ** 3
PD = RHO_L * math.pi / 6 * (60e-6) ** 3


# ---- the physics, written out from the formulas (docs/physics.md) ---------------------------
def diameters(p):
    """d = (6 p / (pi rho_s))^(1/3) [m] of masses p [kg]; every particle at rho_s."""
    return np.cbrt(6.0 * p / (math.pi * RHO_S))


def kernel_matrix(kind, k0, p1, p2, alpha, theta, d43, d_ref):
    """beta [m3/s] of every pair (p1[:, None], p2[None, :])."""
    a, c = p1[:, None], p2[None, :]
    if kind == "constant":
        return np.full(np.broadcast_shapes(a.shape, c.shape), k0)
    if kind == "sum":
        return k0 * (a + c)
    if kind == "product":
        return k0 * a * c
    da, dc = diameters(a), diameters(c)
    if kind == "eke":                                   # Hounslow 1998, seed 001 eq. 5.3.4
        xa, xc = da / d_ref, dc / d_ref
        return k0 * (xa + xc) ** 2 * np.sqrt(xa ** -3 + xc ** -3)
    g0 = 1.0 / (1.0 - (alpha / ALPHA_MAX) ** (1.0 / 3.0))   # Sinclair-Jackson
    return (k0 * g0 * math.sqrt(theta) * d43 ** 1.5              # seed 001 eq. 5.3.5
            * (da + dc) ** 2 * np.sqrt(da ** -3 + dc ** -3))


def efficiency_matrix(factors, width, u0, p1, b1, p2, b2):
    """psi [-] of every pair: product of the factors named."""
    a, c = p1[:, None], p2[None, :]
    ba, bc = b1[:, None], b2[None, :]
    ya, yc = ba / a, bc / c
    psi = np.ones(np.broadcast_shapes(a.shape, c.shape))
    if "geometric" in factors:                          # seed 000 sec. II, seed 001 eq. 5.3.7
        eta_a = 1.0 / (1.0 + np.exp(-B_S * (ya - C_S)))
        eta_c = 1.0 / (1.0 + np.exp(-B_S * (yc - C_S)))
        psi = psi * (1.0 - (1.0 - eta_a) * (1.0 - eta_c))
    if "physical" in factors:                           # seed 000 eq. 4-6
        da, dc = diameters(a), diameters(c)
        st = 4 * RHO_S * u0 * da * dc * (da + dc) ** 2 / (9 * MU * (da ** 3 + dc ** 3))
        lam = R_G * (np.exp(F_L * (ya - G_L) / 3) + np.exp(F_L * (yc - G_L) / 3))
        st_c = 2 * np.log(lam / H_A)
        if width > 0:
            phys = np.where(st_c > 0, 0.5 * (1 - np.tanh((st - st_c) / (width * np.abs(st_c)))),
                            (st <= st_c) * 1.0)
        else:
            phys = (st <= st_c) * 1.0
        psi = psi * phys
    if "saturation" in factors:                         # seed 001 eq. 6.4.1-6.4.2
        h = (ba + bc) / (a + c - ba - bc)
        s = h * RHO_S * (1 - EPS) / (RHO_L * EPS)
        psi = psi * np.minimum(1.0, s / S_MAX)
    return psi


def brute_force(case, p, b, isdrop, volume):
    """Event rate R_true [1/s] of the box and the rate-weighted statistics of the product.

    Returns (rate, mean product mass, its variance, mean product binder, its variance,
    share of droplet captures)."""
    gran = isdrop == 0
    pg, bg = p[gran], b[gran]
    dg = diameters(pg)
    d43 = np.sum(dg ** 4) / np.sum(dg ** 3)             # granules only (docs/physics.md)
    beta = kernel_matrix(case["kernel"], case["k0"], pg, pg, case["alpha"], case["theta"], d43,
                         D_PRIMARY)
    psi = efficiency_matrix(case["efficiency"], case["width"], case["u0"], pg, bg, pg, bg)
    iu = np.triu_indices(pg.size, 1)                    # unordered pairs i < j
    r_gg = (beta * psi)[iu]
    m_gg = (pg[:, None] + pg[None, :])[iu]
    q_gg = (bg[:, None] + bg[None, :])[iu]
    n_drop = int(np.count_nonzero(~gran))
    if n_drop:
        pd_arr, bd_arr = np.array([PD]), np.array([PD])
        beta_d = kernel_matrix(case["kernel"], case["k0"], pg, pd_arr, case["alpha"],
                               case["theta"], d43, D_PRIMARY)[:, 0]
        psi_d = efficiency_matrix(case["efficiency"], case["width"], case["u0"], pg, bg,
                                  pd_arr, bd_arr)[:, 0]
        r_dg = n_drop * case["droplet_factor"] * beta_d * psi_d   # every droplet alike
        m_dg, q_dg = pg + PD, bg + PD
    else:
        r_dg = m_dg = q_dg = np.zeros(0)
    r = np.concatenate([r_gg, r_dg])
    m = np.concatenate([m_gg, m_dg])
    q = np.concatenate([q_gg, q_dg])
    total = r.sum()
    mean_m, mean_q = (r @ m) / total, (r @ q) / total
    var_m, var_q = (r @ (m - mean_m) ** 2) / total, (r @ (q - mean_q) ** 2) / total
    return total / volume, mean_m, var_m, mean_q, var_q, r_dg.sum() / total


# ---- the boxes ------------------------------------------------------------------------------
def make_box(n_drop, seed):
    """300 particles: granules lognormal around the primary mass (sigma 0.8) with binder
    fractions uniform in [0, 0.45], plus n_drop free droplets (p_d, b = p_d)."""
    rng = np.random.default_rng(seed)
    n = 300
    p = P_PRIMARY * rng.lognormal(0.0, 0.8, n)
    b = p * rng.uniform(0.0, 0.45, n)
    isdrop = np.zeros(n, np.int64)
    p[n - n_drop:] = PD
    b[n - n_drop:] = PD
    isdrop[n - n_drop:] = 1
    return p, b, isdrop


def arrays(case, separate):
    params = np.zeros(P.N_PARAMS)
    config = np.zeros(P.N_CONFIG, np.int64)
    values = {P.RATE: case["k0"], P.DENSITY: RHO_S, P.BINDER_DENSITY: RHO_L,
              P.BINDER_VISCOSITY: MU, P.REFERENCE_VOLUME: math.pi / 6 * D_PRIMARY ** 3,
              P.ALPHA_MAX: ALPHA_MAX, P.GEO_SLOPE: B_S, P.GEO_CENTRE: C_S, P.PHI_SLOPE: F_L,
              P.PHI_CENTRE: G_L, P.ASPERITY: H_A, P.GYRATION_RADIUS: R_G,
              P.STOKES_WIDTH: case["width"], P.POROSITY: EPS, P.SATURATION_MAX: S_MAX,
              P.DROPLET_MASS: PD,
              P.DROPLET_FACTOR: case["droplet_factor"] if separate else 0.0}
    for slot, value in values.items():
        params[slot] = value
    config[P.KERNEL] = {"constant": 0, "sum": 1, "product": 2, "eke": 3, "ktgf": 4}[case["kernel"]]
    config[P.USE_GEOMETRIC] = int("geometric" in case["efficiency"])
    config[P.USE_PHYSICAL] = int("physical" in case["efficiency"])
    config[P.USE_SATURATION] = int("saturation" in case["efficiency"])
    config[P.SEPARATE_DROPLETS] = int(separate)
    config[P.BIVARIATE] = 1
    cell = np.zeros(P.N_CELL)
    cell[P.ALPHA] = case["alpha"]
    cell[P.THETA] = case["theta"]
    cell[P.COLLISION_VELOCITY] = case["u0"]
    return params, config, cell


CASES = {
    # seed 000 physics: eke, geometric x sharp Stokes step at u0 = 5.5 m/s, droplets separate
    "eke-seed": dict(kernel="eke", k0=2.5e-14, efficiency=("geometric", "physical"), width=0.0,
                     u0=5.5, alpha=0.0, theta=0.0, droplet_factor=100.0, n_drop=3),
    # the fluid bed's physics: ktgf, every factor, smooth switch where St ~ St*
    "ktgf-bed": dict(kernel="ktgf", k0=1e-5, efficiency=("geometric", "physical", "saturation"),
                     width=0.2, u0=3.0, alpha=0.45, theta=7.8e-5, droplet_factor=100.0,
                     n_drop=3),
    # a box of mostly free droplets: counting them in d43 would lower every ktgf rate by 33%
    "ktgf-droplet-rich": dict(kernel="ktgf", k0=1e-5, efficiency=("geometric",), width=0.0,
                              u0=1.0, alpha=0.3, theta=1e-4, droplet_factor=1.0, n_drop=250,
                              captures_dominate=True),
    # ktgf with droplets as ordinary particles (they count in d43 then)
    "ktgf-ordinary": dict(kernel="ktgf", k0=1e-5, efficiency=("geometric",), width=0.0,
                          u0=1.0, alpha=0.3, theta=1e-4, droplet_factor=0.0, n_drop=30),
    # the validation kernels, with one factor each
    "sum-saturation": dict(kernel="sum", k0=1e-3, efficiency=("saturation",), width=0.0, u0=1.0,
                           alpha=0.0, theta=0.0, droplet_factor=0.0, n_drop=0),
    "product-physical": dict(kernel="product", k0=1e6, efficiency=("physical",), width=0.5,
                             u0=8.0, alpha=0.0, theta=0.0, droplet_factor=0.0, n_drop=0),
    "constant-geometric": dict(kernel="constant", k0=1e-12, efficiency=("geometric",),
                               width=0.0, u0=1.0, alpha=0.0, theta=0.0, droplet_factor=0.0,
                               n_drop=0),
}


def first_trials(case, separate, p0, b0, d0, volume):
    """Run RUNS one-trial replicas from the same box; return (accepted flags, t_reached [s],
    product masses, product binders, capture flags) of the accepted ones."""
    params, config, cell = arrays(case, separate)
    times = np.array([0.0, 1e30])
    out = np.empty((2, cnmc.N_QUANTITIES))
    accepted = np.zeros(RUNS, bool)
    t_first = np.empty(RUNS)
    masses, binders, captures = [], [], []
    old = set(p0.tolist())
    gran_masses = p0[d0 == 0]
    for seed in range(RUNS):
        p, b, isdrop = p0.copy(), b0.copy(), d0.copy()
        trials, acc, inj, viol, status, t, *_ = cnmc.run_box(p, b, isdrop, volume, times, cell,
                                                              params, config, seed, 0, 1, out)
        assert trials == 1 and viol == 0 and inj == 0
        t_first[seed] = t
        if acc:
            accepted[seed] = True
            new = [k for k in range(p.size) if p[k] not in old]
            assert new, "an accepted trial must create a particle of a new mass"
            k = new[0]
            masses.append(p[k])
            binders.append(b[k])
            captures.append(separate and bool(np.any(gran_masses + PD == p[k])))
    return accepted, t_first, np.array(masses), np.array(binders), np.array(captures)


def normal_p_value(z):
    return 2.0 * stats.norm.sf(abs(z))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_cnmc_event_rate_and_pair_choice_match_the_enumeration(name):
    case = CASES[name]
    separate = case["droplet_factor"] > 0
    p0, b0, d0 = make_box(case["n_drop"], seed=1)
    if not separate:
        d0[:] = 0
    volume = p0.size / 1e10
    rate, mean_m, var_m, mean_q, var_q, capture_share = brute_force(case, p0, b0, d0, volume)

    accepted, t_first, masses, binders, captures = first_trials(case, separate, p0, b0, d0,
                                                                volume)
    # every run proposes from the same table: the same 1/R_prop
    assert np.ptp(t_first) <= 1e-12 * t_first[0]
    acceptance = rate * t_first[0]                      # R_true / R_prop
    assert 0.02 < acceptance <= 1.0 + 1e-12, acceptance  # a useful, valid majorant
    n_acc = int(accepted.sum())
    p_rate = stats.binomtest(n_acc, RUNS, min(acceptance, 1.0)).pvalue
    assert p_rate > P_VALUE_FLOOR, (
        f"{name}: cNMC event rate {n_acc / RUNS / t_first[0]:.4g} 1/s against the enumeration's "
        f"{rate:.4g} 1/s (acceptance {n_acc / RUNS:.4f} vs {acceptance:.4f}, p = {p_rate:.2g})")
    # which pairs merged
    z_m = (masses.mean() - mean_m) / math.sqrt(var_m / n_acc)
    z_q = (binders.mean() - mean_q) / math.sqrt(max(var_q, 1e-300) / n_acc)
    assert normal_p_value(z_m) > P_VALUE_FLOOR, (name, masses.mean(), mean_m, z_m)
    assert normal_p_value(z_q) > P_VALUE_FLOOR, (name, binders.mean(), mean_q, z_q)
    if separate:
        p_cap = stats.binomtest(int(captures.sum()), n_acc, capture_share).pvalue
        assert p_cap > P_VALUE_FLOOR, (name, captures.mean(), capture_share)
        if not case.get("captures_dominate"):
            assert 0.05 < capture_share < 0.95           # both kinds of pair are exercised
    else:
        assert not captures.any()
