"""Free droplets of their own evaporate with [drying] (docs/physics.md section 15, "Free
droplets' evaporation") in every method that carries them: QMOM, CQMOM, EQMOM, the Laguerre
ROM and the cNMC (whose droplets are particles: its own tests below).

Closed forms: an initial charge of N_d free droplets, no capture (droplet_factor = 0), dry
granules (nothing else dries), slip 0 (Sh = 2). All droplets have the same age, so the
class's mean liquid L_d / N_d is every droplet's liquid b(t) and the one-mass closure is exact:

- pure liquid: the liquid sphere's d^2 law, e = 2 pi d D_v rho_g dY with b = rho_l pi d^3 / 6,
  so d(d^2)/dt = -8 D_v rho_g dY / rho_l and b(t) = b0 (1 - t / tau)^(3/2),
  tau = rho_l d0^2 / (8 D_v rho_g dY); the droplets end at zero mass at tau and stay there;
- a solution (s = 0.1): the liquid sphere (diameter from the liquid alone) shrinks by the
  same law until it reaches the skeleton's diameter d_s = (6 s p_d / (pi rho_s))^(1/3), then
  the skeleton's constant rate 2 pi d_s D_v rho_g dY down to X_cr s p_d, then the falling
  rate, exponential with the time X_cr s p_d / e_c.

The liquid held by the droplets is L_d = N_d b(t) (the M01 column, the granules being dry),
the evaporated liquid N_d (b0 - b). Tolerance 1e-8 of N_d b0 (rtol 1e-11 on the scaled state,
as tests/physics/test_drying.py).
"""
import math

import numpy as np
import pytest

from conftest import make_scene
from pbe_cfd.physics import drying
from pbe_cfd.runs.simulate import run_well_mixed

RHO_S = 1021.0       # kg/m3, granules and the solution's skeleton
RHO_L = 1000.0       # kg/m3
D0 = 60e-6           # m, droplet diameter
ND = 1.0e9           # 1/m3 free droplets
AIR = {"air_temperature": 333.15, "air_humidity": 0.005, "slip_velocity": 0.0}
TOL = 1.0e-8
METHODS = {
    "qmom": {"name": "qmom", "nodes": 2},
    "cqmom": {"name": "cqmom", "nodes": 2, "binder_nodes": 2},
    "eqmom": {"name": "eqmom", "nodes": 2},
    "laguerre": {"name": "laguerre", "order": 3},
}


def _k():
    """D_v rho_g (Y_s(T_wb) - Y) [kg/(m s)] of the scene's air."""
    rho, _, diff, _, driving = drying.gas_state(AIR["air_temperature"], AIR["air_humidity"],
                                                101325.0)
    return diff * rho * driving


def _scene(solids, end, x_cr, method, tolerances=True):
    return make_scene(scene={"end_time": end, "output_interval": end / 30},
                      material={"density": RHO_S, "binder_density": RHO_L},
                      initial={"mean_mass": 1e-9, "number_density": 1e10,
                               "binder_fraction": 0.0, "droplet_number_density": ND},
                      aggregation={"kernel": "constant", "rate": 1e-30,
                                   "droplet_factor": 0.0},
                      binder_injection={"rate": 0.0, "droplet_diameter": D0,
                                        "solids_fraction": solids},
                      drying={**AIR, "critical_moisture": x_cr},
                      method={"_replace": True, **method,
                              **({"rtol": 1e-11, "atol": 1e-16} if tolerances else {})})


def _pure_liquid(t):
    """b(t) [kg] of a pure-liquid droplet (module docstring)."""
    b0 = RHO_L * math.pi / 6.0 * D0 ** 3
    tau = RHO_L * D0 ** 2 / (8.0 * _k())
    return b0 * max(1.0 - t / tau, 0.0) ** 1.5, tau


def _solution(t, s, x_cr):
    """b(t) [kg] of a droplet of solution (module docstring) and the times the liquid sphere
    and the constant-rate period end [s]."""
    k = _k()
    pd = RHO_L * math.pi / 6.0 * D0 ** 3
    ms = s * pd
    d_l0 = (6.0 * (1.0 - s) * pd / (math.pi * RHO_L)) ** (1.0 / 3.0)
    d_s = (6.0 * ms / (math.pi * RHO_S)) ** (1.0 / 3.0)
    t1 = RHO_L * (d_l0 ** 2 - d_s ** 2) / (8.0 * k)
    if t <= t1:
        return RHO_L * math.pi / 6.0 * (d_l0 ** 2 - 8.0 * k * t / RHO_L) ** 1.5, t1, None
    b1 = RHO_L * math.pi / 6.0 * d_s ** 3
    ec = 2.0 * math.pi * d_s * k
    t2 = t1 + (b1 - x_cr * ms) / ec
    if t <= t2:
        return b1 - ec * (t - t1), t1, t2
    return x_cr * ms * math.exp(-(t - t2) * ec / (x_cr * ms)), t1, t2


def _check(c, b, b0):
    scale = ND * b0
    assert np.allclose(c["liquid_droplets"], ND * b, rtol=0.0, atol=TOL * scale)
    assert np.allclose(c["M01"], ND * b, rtol=0.0, atol=TOL * scale)
    assert np.allclose(c["liquid_evaporated"], ND * (b0 - b), rtol=0.0, atol=TOL * scale)
    assert np.allclose(c["droplet_number_density"], ND, rtol=1e-14, atol=0.0)
    assert np.all(c["liquid_droplets"] >= 0.0)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_pure_liquid_droplets_evaporate_by_the_d2_law_to_zero_mass(method):
    _, tau = _pure_liquid(0.0)
    res = run_well_mixed(_scene(0.0, 1.5 * tau, 0.05, METHODS[method]))
    c = res.columns
    t = c["time_s"]
    b = np.array([_pure_liquid(x)[0] for x in t])
    b0 = b[0]
    _check(c, b, b0)
    after = t > tau
    assert after.sum() >= 5 and (t < 0.9 * tau).sum() >= 15
    # at zero mass the droplets stay: no liquid left, none negative, all of it evaporated
    assert np.all(c["liquid_droplets"][after] == 0.0)
    assert np.allclose(c["liquid_evaporated"][after], ND * b0, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("method", ["qmom", "cqmom", "laguerre"])
def test_solution_droplets_shrink_then_dry_on_their_skeleton(method):
    s, x_cr = 0.1, 0.5
    _, t1, t2 = _solution(1e9, s, x_cr)
    ms = s * RHO_L * math.pi / 6.0 * D0 ** 3
    d_s = (6.0 * ms / (math.pi * RHO_S)) ** (1.0 / 3.0)
    tail = x_cr * ms / (2.0 * math.pi * d_s * _k())          # the falling-rate time
    res = run_well_mixed(_scene(s, t2 + 3.0 * tail, x_cr, METHODS[method]))
    c = res.columns
    t = c["time_s"]
    b = np.array([_solution(x, s, x_cr)[0] for x in t])
    _check(c, b, b[0])
    # every period is sampled
    assert (t < t1).sum() >= 5 and ((t > t1) & (t < t2)).sum() >= 2 and (t > t2).sum() >= 5


#: the cNMC's box: 110 particles of which 10 droplets (N nd0 / (n0 + nd0) = 10)
CNMC = {"name": "cnmc", "particles": 110, "replicas": 2, "seed": 7}


def _cnmc_check(c, b, b0):
    """The cNMC's droplets are particles of the box: its liquid is nd(0) b(t) (the box's own
    droplet density; its volume stays V0 while only the liquid leaves, section 15)."""
    nd = c["droplet_number_density"][0]
    assert nd == pytest.approx(ND, rel=0.0, abs=1e-6 * ND)
    scale = nd * b0
    assert np.allclose(c["M01"], nd * b, rtol=0.0, atol=TOL * scale)
    assert np.allclose(c["liquid_evaporated"], nd * (b0 - b), rtol=0.0, atol=TOL * scale)
    assert np.all(c["M01"] >= 0.0)
    return nd


def test_cnmc_pure_liquid_droplets_end_at_exactly_zero_mass_and_leave_the_box():
    """The cNMC's pure-liquid droplets follow the d^2 law (``physics.drying.liquid_sphere_after``,
    exact) to exactly zero mass at tau; then they have left the population: no droplet, no
    liquid, the number density the granules' (the vanished slots take copies of granules)."""
    _, tau = _pure_liquid(0.0)
    c = run_well_mixed(_scene(0.0, 1.5 * tau, 0.05, CNMC, tolerances=False)).columns
    t = c["time_s"]
    b = np.array([_pure_liquid(x)[0] for x in t])
    nd = _cnmc_check(c, b, b[0])
    after = t > tau
    assert after.sum() >= 5 and (t < 0.9 * tau).sum() >= 15
    assert np.all(c["M01"][after] == 0.0)
    assert np.all(c["droplet_number_density"][after] == 0.0)
    assert np.allclose(c["M00"][after], c["M00"][0] - nd, rtol=1e-12, atol=0.0)
    assert np.allclose(c["liquid_evaporated"][after], nd * b[0], rtol=1e-12, atol=0.0)


def test_cnmc_solution_droplets_shrink_then_dry_on_their_skeleton():
    s, x_cr = 0.1, 0.5
    _, t1, t2 = _solution(1e9, s, x_cr)
    ms = s * RHO_L * math.pi / 6.0 * D0 ** 3
    d_s = (6.0 * ms / (math.pi * RHO_S)) ** (1.0 / 3.0)
    tail = x_cr * ms / (2.0 * math.pi * d_s * _k())
    c = run_well_mixed(_scene(s, t2 + 3.0 * tail, x_cr, CNMC, tolerances=False)).columns
    t = c["time_s"]
    b = np.array([_solution(x, s, x_cr)[0] for x in t])
    nd = _cnmc_check(c, b, b[0])
    assert np.allclose(c["droplet_number_density"], nd, rtol=1e-12, atol=0.0)
    assert (t < t1).sum() >= 5 and ((t > t1) & (t < t2)).sum() >= 2 and (t > t2).sum() >= 5


def test_a_method_whose_droplets_do_not_evaporate_is_refused_with_drying_and_free_droplets():
    """Every registered method evaporates its free droplets; the scene's check still refuses a
    method that would not (here the Laguerre ROM's entry with the flag cleared), naming the
    key and the methods that do."""
    from pbe_cfd.methods import registry
    from pbe_cfd.scene.drying import drying_refusals
    scene = _scene(0.0, 1.0, 0.05, METHODS["laguerre"], tolerances=False)
    assert drying_refusals(scene, registry.METHOD_REGISTRY) == []
    methods = [m._replace(evaporates_droplets=False) if m.name == "laguerre" else m
               for m in registry.METHOD_REGISTRY]
    (key, text), = drying_refusals(scene, methods)
    assert key == "aggregation.droplet_factor"
    assert "laguerre method's free droplets do not evaporate" in text and "'qmom'" in text


def _steady_share(eps):
    """Share of the sprayed liquid the droplet class evaporates at a constant spray in the
    one-mass closure (docs/physics.md section 15), slip 0: the steady state of
    dL_d/dt = R b0 - kappa L_d - n_d e(l), n_d = R / kappa, e(l) = e(b0) (l / b0)^(1/3) and
    e(b0) = 3 b0 / (2 tau), so x = l / b0 solves x = 1 - (3 eps / 2) x^(1/3), eps = 1 /
    (kappa tau), and the share is (3 eps / 2) x^(1/3). Bisection."""
    lo, hi = 0.0, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid - 1.0 + 1.5 * eps * mid ** (1.0 / 3.0) > 0.0:
            hi = mid
        else:
            lo = mid
    return 1.5 * eps * (0.5 * (lo + hi)) ** (1.0 / 3.0)


def _age_share(eps, n=200000):
    """The share of an age-resolved droplet population (n(a) = R exp(-kappa a)): 1 - kappa
    int_0^tau exp(-kappa a) (1 - a / tau)^(3/2) da, by the midpoint rule in a / tau."""
    s = (np.arange(n) + 0.5) / n
    return 1.0 - np.sum(np.exp(-s / eps) * (1.0 - s) ** 1.5) / (n * eps)


@pytest.mark.parametrize("method", ["qmom", "laguerre"])
def test_sprayed_droplets_evaporate_the_closure_share_before_capture(method):
    """A constant spray of pure-liquid droplets captured at a constant rate kappa (constant
    kernel, no efficiency, granules that hardly aggregate among themselves and hardly dry:
    X_cr = 1e9 puts them deep in the falling-rate period): at steady state the droplets
    evaporate the share of ``_steady_share`` of the sprayed liquid, kappa = R / n_d from the
    run's own droplet number. The inventory balances (sprayed = held by granules + held by
    droplets + evaporated, 1e-8). The closure's share differs from the age-resolved one by
    (3/8) eps^3 (both series: 3/2 eps - 3/4 eps^2, then 0 against -3/8 eps^3)."""
    rate, factor, k0, n0 = 1.0e8, 1.0e12, 1.0e-20, 1.0e10      # kappa = f k0 N0 = 100 /s
    _, tau = _pure_liquid(0.0)
    scene = make_scene(scene={"end_time": 0.6, "output_interval": 0.05},
                       material={"density": RHO_S, "binder_density": RHO_L},
                       initial={"mean_mass": 1e-9, "number_density": n0,
                                "binder_fraction": 0.0},
                       aggregation={"kernel": "constant", "rate": k0, "droplet_factor": factor},
                       binder_injection={"rate": rate, "droplet_diameter": D0},
                       drying={**AIR, "critical_moisture": 1.0e9},
                       method={"_replace": True, **METHODS[method], "rtol": 1e-11,
                               "atol": 1e-16})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    late = t >= 0.4
    kappa = rate / c["droplet_number_density"][late]
    assert np.allclose(kappa, factor * k0 * n0, rtol=1e-6, atol=0.0)
    eps = 1.0 / (kappa[-1] * tau)
    b0 = RHO_L * math.pi / 6.0 * D0 ** 3
    slope = np.diff(c["liquid_evaporated"][late]) / np.diff(t[late])
    assert np.allclose(slope / (rate * b0), _steady_share(eps), rtol=1e-6, atol=0.0)
    gap = _steady_share(eps) - _age_share(eps)
    assert abs(gap - 0.375 * eps ** 3) < 0.1 * 0.375 * eps ** 3
    held = c["liquid_granules"] + c["liquid_droplets"]
    assert np.allclose(held + c["liquid_evaporated"], c["liquid_sprayed"], rtol=1e-8,
                       atol=1e-8 * c["liquid_sprayed"][-1])
    assert c["liquid_droplets"][-1] > 0.0 and c["liquid_evaporated"][-1] > 0.0


def test_cnmc_sprayed_droplets_dry_from_their_own_spraying():
    """A constant spray of pure-liquid droplets, none captured, in a box where they are 1% of
    the particles (n_box = R tau V ~ 40 droplets per box: 40 events per droplet life, against
    the N / 32 = 125 proposals between two drifts that count events). Each droplet lives
    the d^2 law from its own spraying, so with ages uniform over [0, min(t, tau)]:
    n_d = R min(t, tau), L_d = R b0 tau (2/5) (1 - (1 - min(t, tau)/tau)^(5/2)).

    Bounds: the box drifts at least every delta = DRIFT_SHARE b0 / e(b0) = DRIFT_SHARE (2/3)
    tau (``cnmc.drying``; e(b0) = 3 b0 / (2 tau) by the d^2 law), and a droplet sprayed within
    a step is dried from the step's start, at most delta too long: L_d falls short by at most
    R int_0^delta b(a) da <= R b0 delta (relative to the steady L_d: delta / (0.4 tau)), n_d by
    at most R delta; one droplet more or less in a box is
    1 / n_box of n_d and at most b0 / (0.4 b0 n_box) of L_d. The mean over the outputs after
    tau must lie within the sum. (A drift only every 125 events dried every droplet from the
    last drift, more than its life here: L_d 55% short, n_d 50%.)"""
    from pbe_cfd.methods.cnmc.drying import DRIFT_SHARE
    _, tau = _pure_liquid(0.0)
    b0 = RHO_L * math.pi / 6.0 * D0 ** 3
    n0, rate, particles = 1.0e11, 1.0e9 / tau, 4000
    scene = make_scene(scene={"end_time": 4.0 * tau, "output_interval": tau / 4},
                       material={"density": RHO_S, "binder_density": RHO_L},
                       initial={"mean_mass": 1e-9, "number_density": n0,
                                "binder_fraction": 0.0},
                       aggregation={"kernel": "constant", "rate": 1e-30,
                                    "droplet_factor": 1e-30},
                       binder_injection={"rate": rate, "droplet_diameter": D0},
                       drying={**AIR, "critical_moisture": 0.05},
                       method={"_replace": True, "name": "cnmc", "particles": particles,
                               "replicas": 16, "seed": 11})
    c = run_well_mixed(scene).columns
    t = c["time_s"]
    u = np.minimum(t, tau) / tau
    liquid = rate * b0 * tau * 0.4 * (1.0 - (1.0 - u) ** 2.5)
    number = rate * np.minimum(t, tau)
    n_box = particles * number[-1] / (n0 + number[-1])
    late = t >= tau
    assert late.sum() >= 12
    held = np.mean(c["M01"][late] / liquid[late]) - 1.0
    share = DRIFT_SHARE * 2.0 / 3.0                 # delta / tau
    assert abs(held) <= share / 0.4 + 1.0 / (0.4 * n_box)
    count = np.mean(c["droplet_number_density"][late] / number[late]) - 1.0
    assert abs(count) <= share + 1.0 / n_box
