"""Breakage in the methods beyond the closed forms: the cNMC's constant-number rule, droplets
that never break, the collisional selection per cell, and the scene and plan.

The constant-number rule (methods.cnmc_breakage): the first daughter takes the parent's slot,
the second replaces a particle drawn uniformly among the N + 1 after the split (itself: it is
dropped). Tested by counting the N + 1 outcomes of 60,000 splits of a 5-particle box with a
seed fixed when the test was written: chi-square with N = 5 degrees of freedom, refused above
its 0.999 quantile (20.5), so a correct rule fails once in 1000 seeds.
"""
import math

import numba as nb
import numpy as np
import pytest
from scipy import stats

from pbe_cfd.runs import model
from pbe_cfd.methods.cnmc import box as cnmc_box
from pbe_cfd.methods.cnmc.breakage import split
from pbe_cfd.methods.cnmc.slots import Particles, Slots, d4
from pbe_cfd.methods.dispatch import WORK_SIZE
from pbe_cfd.methods.qmom.qmom import qmom_rhs
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.plan import describe_plan
from pbe_cfd.scene.scene import SceneError
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

N0, P0, Y0 = 1.0e10, 1.0e-9, 0.25


# ---------------------------------------------------------------------------- constant number
@nb.njit(cache=True)
def _split_outcomes(p0, b0, i, trials, seed, config, outcome, errors):
    """Split slot i of fresh copies of the box (p0, b0), once per trial with numba's generator
    seeded to seed + trial. The rule predicts the result from the same two draws (the mass
    share r of the first daughter, then the slot k = randint(N + 1)): slot i holds r p_i, slot
    k the rest p_i - r p_i (k = i: the first daughter is replaced; k = N: the second daughter
    is dropped), every other slot is untouched. outcome[trial] = k; errors: [mispredicted
    trials, largest relative error of the returned total mass and of sum d^4 against the
    box's sums, largest binder-fraction error, largest particle-count error of the classes]."""
    n = p0.size
    rho = 1000.0
    for trial in range(trials):
        np.random.seed(seed + trial)
        r = np.random.random()
        k = np.random.randint(n + 1)
        p1 = r * p0[i]
        p2 = p0[i] - p1
        np.random.seed(seed + trial)
        p = p0.copy()
        b = b0.copy()
        isdrop = np.zeros(n, np.int64)
        cls = cnmc_box._new_classes(n)
        members, bcnt, bpos, bin_of, lo, hi, dirty, table, tabd, dlist, dpos, dcnt = cls[:12]
        m_ref, ptot, s4 = cnmc_box._fill_classes(p, isdrop, False, rho, bin_of, bpos, members,
                                                 bcnt, lo, hi, dirty, dlist, dpos, dcnt)
        ptot, s4 = split(i, Particles(p, b, isdrop, rho, m_ref), ptot, s4,
                         Slots(bin_of, bpos, members, bcnt, lo, hi, dirty, dlist, dpos, dcnt),
                         config)
        expected = p0.copy()
        expected[i] = p1
        if k < n:
            expected[k] = p2
        if not np.array_equal(p, expected):
            errors[0] += 1
        outcome[trial] = k
        total = 0.0
        s4_sum = 0.0
        for q in range(n):
            total += p[q]
            s4_sum += d4(p[q], rho)
            errors[3] = max(errors[3], abs(b[q] / p[q] - 0.1))
        errors[1] = max(errors[1], abs(ptot / total - 1.0))
        errors[2] = max(errors[2], abs(s4 / s4_sum - 1.0))
        errors[4] = max(errors[4], abs(np.sum(bcnt) - n))


@pytest.mark.slow
def test_split_replaces_a_particle_drawn_uniformly_among_the_n_plus_one():
    """Box p = (1, 2, 3, 4, 5) p0, binder 0.1 p, uniform daughters, slot 2 splits: the result
    is the rule's prediction in every trial, the box's total mass and sum d^4 are carried
    exactly, every particle keeps its binder fraction, the count stays 5, and the 6 outcomes
    are equally frequent (chi-square, module docstring)."""
    p0 = np.arange(1.0, 6.0) * P0
    b0 = 0.1 * p0
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.BREAKAGE] = 1
    config[P.BREAKAGE_DAUGHTERS] = 0            # uniform
    trials = 60000
    outcome = np.zeros(trials, np.int64)
    errors = np.zeros(5)
    _split_outcomes(p0, b0, 2, trials, 16005, config, outcome, errors)
    assert errors[0] == 0
    assert errors[1] < 1e-12 and errors[2] < 1e-12 and errors[3] < 1e-12 and errors[4] == 0
    counts = np.bincount(outcome, minlength=6)
    assert counts.size == 6
    chi2 = float(np.sum((counts - trials / 6) ** 2 / (trials / 6)))
    assert chi2 < stats.chi2.ppf(0.999, 5), counts


# ---------------------------------------------------------------------------- droplets
def droplet_scene(method, end=10.0, s=0.1):
    """Granules (exponential, y0) and free droplets (0.1 N0, 60 um) that are captured at a
    negligible rate (K = 1e-30 m3/s: K n t ~ 1e-19), constant breakage s."""
    return make_scene(scene={"end_time": end, "output_interval": end / 4},
                      initial={"distribution": "exponential", "binder_fraction": Y0,
                               "droplet_number_density": 0.1 * N0},
                      aggregation={"kernel": "constant", "rate": 1e-30, "droplet_factor": 1.0},
                      binder_injection={"rate": 0.0, "droplet_diameter": 60e-6},
                      breakage={"selection": "constant", "rate": s},
                      method=dict(method, _replace=True))


def test_droplets_never_break_qmom():
    """The free droplets stay at 0.1 N0 while the granules multiply as e^(s t) (to the
    integrator's 1e-6; module docstring of test_breakage.py)."""
    res = run_well_mixed(droplet_scene({"name": "qmom", "nodes": 2}))
    c = res.columns
    t = c["time_s"]
    assert np.max(np.abs(c["droplet_number_density"] / (0.1 * N0) - 1.0)) < 1e-12
    granules = c["M00"] - c["droplet_number_density"]
    assert np.max(np.abs(granules / (N0 * np.exp(0.1 * t)) - 1.0)) < 1e-6


def test_droplets_never_break_cnmc():
    """In the box the droplets are thinned with every other particle by the constant-number
    rule, so their density stays 0.1 N0 in the mean; the granules' M00 grows as e^(s t).
    Bonferroni band over 2 quantities x 4 times, family-wise 99% (test_breakage.py)."""
    replicas = 32
    res = run_well_mixed(droplet_scene({"name": "cnmc", "particles": 2000,
                                        "replicas": replicas, "seed": 16006}))
    c = res.columns
    t = c["time_s"]
    t95 = stats.t.ppf(0.975, replicas - 1)
    tq = stats.t.ppf(1.0 - 0.01 / (2 * 8), replicas - 1)
    for k in range(1, 5):
        sem = (c["droplet_number_density_hi"][k] - c["droplet_number_density"][k]) / t95
        assert abs(c["droplet_number_density"][k] - 0.1 * N0) <= tq * sem
        sem = (c["M00_hi"][k] - c["M00"][k]) / t95
        assert abs(c["M00"][k] - (N0 * math.exp(0.1 * t[k]) + 0.1 * N0)) <= tq * sem
    assert res.stats["events_breakage"] > 0


# ---------------------------------------------------------------------------- collisional
def test_qmom_collisional_selection_per_cell():
    """dM00/dt of a two-node QMOM state under collisional breakage is sum_a w_a S_a (F(0) = 2
    daughters: one more granule per break), with S = s0 g0(alpha) sqrt(Theta / Theta_ref)
    (p / p_ref)^a from each cell's own row, and 0 where the Stokes deformation gate is shut
    (St_def = rho u0^2 / (2 Y) <= 0.2 at Y = 1000 Pa, rho = 1000 kg/m3: Theta = 0.09
    m2/s2 opens it, 0.04 does not)."""
    scene = make_scene(domain={"type": "well-mixed", "solids_fraction": 0.3,
                               "granular_temperature": 0.05, "alpha_max": 0.62,
                               "alpha_min_friction": 0.5},
                       breakage={"selection": "collisional", "rate": 0.05, "exponent": 1.5,
                                 "reference_granular_temperature": 0.01,
                                 "yield_strength": 1000.0, "critical_deformation_number": 0.2},
                       method={"name": "qmom", "nodes": 2})
    arrays = model.pack(scene)
    x = np.array([0.5, 2.0])           # scaled masses (p0 = 1e-9 kg)
    w = np.array([0.6, 0.4])           # scaled number
    state = np.array([np.sum(w * x ** k) for k in range(4)])
    out = np.zeros(4)
    for alpha, theta in ((0.31, 0.09), (0.55, 0.09), (0.55, 0.04), (0.12, 0.02)):
        u0 = 4.0 * math.sqrt(theta / math.pi)
        cell = np.array([alpha, theta, u0, 0.0])
        qmom_rhs(state, out, cell, np.zeros(1), arrays.params, arrays.config,
                 np.zeros(WORK_SIZE))
        g0 = 1.0 / (1.0 - (min(alpha, 0.5) / 0.62) ** (1.0 / 3.0))
        s = 0.05 * g0 * math.sqrt(theta / 0.01) * x ** 1.5
        gate = 1000.0 * u0 ** 2 / (2.0 * 1000.0) > 0.2      # rho_g = the scene's 1000 kg/m3
        expected = float(np.sum(w * s)) if gate else 0.0
        assert out[0] == pytest.approx(expected, rel=1e-10, abs=0.0), (alpha, theta)
        assert out[1] == 0.0
        assert out[2] == pytest.approx(-float(np.sum(w * s * x ** 2)) / 3.0 if gate else 0.0,
                                       rel=1e-10, abs=0.0)


# ---------------------------------------------------------------------------- scene and plan
def test_absent_table_builds_nothing_and_plan_says_so():
    scene = make_scene()
    arrays = model.pack(scene)
    assert arrays.config[P.BREAKAGE] == 0
    assert not np.any(arrays.params[P.BREAKAGE_RATE:P.CRITICAL_DEFORMATION + 1])
    assert "breakage (no [breakage] table)" in describe_plan(scene)


def test_plan_lists_breakage():
    scene = make_scene(breakage={"selection": "power", "rate": 0.02, "exponent": 2.0,
                                 "daughters": "equal"})
    text = describe_plan(scene)
    assert "breakage: selection power, S = s0 (p / p_ref)^a, s0 = 0.02 1/s" in text
    assert "a = 2, p_ref = 1e-09 kg (the initial mean granule mass)" in text
    assert "two equal halves" in text and "left out: nothing" not in text
    arrays = model.pack(scene)
    assert arrays.params[P.BREAKAGE_REFERENCE_MASS] == scene.initial.mean_mass
    assert arrays.config[P.BREAKAGE] == 1


@pytest.mark.parametrize("table,key", [
    ({"selection": "constant", "rate": 0.1, "exponent": 1.0}, "breakage.exponent"),
    ({"selection": "power", "rate": -0.1}, "breakage.rate"),
    ({"selection": "shear", "rate": 0.1}, "breakage.selection"),
    ({"selection": "power", "rate": 0.1, "daughters": "three"}, "breakage.daughters"),
    ({"selection": "power", "rate": 0.1, "exponent": -1.0}, "breakage.exponent"),
    ({"selection": "collisional", "rate": 0.1}, "breakage.reference_granular_temperature"),
    ({"selection": "collisional", "rate": 0.1, "reference_granular_temperature": 0.01,
      "yield_strength": 1e3}, "breakage.critical_deformation_number"),
])
def test_scene_refuses_a_bad_breakage_table(table, key):
    with pytest.raises(SceneError, match=key.replace(".", r"\.")):
        make_scene(domain={"type": "well-mixed", "solids_fraction": 0.3,
                           "granular_temperature": 0.01},
                   breakage=table)


def test_collisional_selection_needs_the_cell_fields_of_a_well_mixed_domain():
    with pytest.raises(SceneError, match="granular_temperature"):
        make_scene(breakage={"selection": "collisional", "rate": 0.1,
                             "reference_granular_temperature": 0.01})
