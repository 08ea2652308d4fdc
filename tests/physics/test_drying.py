"""Drying of the liquid binder (docs/physics.md section 15).

Closed forms (QMOM; no aggregation, a monodisperse wet population is one node, so the
quadrature of the drift is exact): every granule has the dry mass m_s = p0 (1 - y0) and the
liquid b(t), with the skeleton diameter d (constant) the constant rate e_c is constant, so
    b(t) = b0 - e_c t                                   while b >= X_cr m_s,
    b(t) = X_eq m_s + (b_c - X_eq m_s) exp(-e_c (t - t_c) / ((X_cr - X_eq) m_s))   after,
and M_ij = N0 (m_s + b)^i b^j, the evaporated liquid E = N0 (b0 - b).
"""
import math

import numpy as np
import pytest

from conftest import make_scene
from pbe_cfd.physics import drying
from pbe_cfd.runs.simulate import run_well_mixed
from pbe_cfd.scene.scene import SceneError

N0 = 1.0e10          # 1/m3
P0 = 1.0e-9          # kg (granule mass, liquid included)
RHO_S = 1021.0       # kg/m3
AIR = {"air_temperature": 333.15, "air_humidity": 0.005, "slip_velocity": 0.3}
#: the integrator runs at rtol 1e-11 on the scaled state over ~10^2 steps (module docstring
#: of test_spray): 1e-8 leaves a factor > 10 for the sum of the local errors
TOL = 1.0e-8


def _constant_rate(p0, y0, air=AIR):
    """e_c [kg/s] of a granule of mass p0 [kg], liquid fraction y0, by the formula of section
    14 written out here: pi d Sh D_v rho_g (Y_s(T_wb) - Y), d the skeleton diameter."""
    rho, mu, diff, _, driving = drying.gas_state(air["air_temperature"], air["air_humidity"],
                                                 air.get("pressure", 101325.0))
    d = (6.0 * p0 * (1.0 - y0) / (math.pi * RHO_S)) ** (1.0 / 3.0)
    sh = 2.0 + 0.6 * math.sqrt(rho * air["slip_velocity"] * d / mu) * (mu / (rho * diff)) ** (
        1.0 / 3.0)
    return math.pi * d * sh * diff * rho * driving


def _scene(y0, end, x_cr, x_eq=0.0, method=None):
    return make_scene(scene={"end_time": end, "output_interval": end / 20},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": y0},
                      drying={**AIR, "critical_moisture": x_cr, "equilibrium_moisture": x_eq},
                      method={"_replace": True, "rtol": 1e-11, "atol": 1e-16,
                              **(method or {"name": "qmom", "nodes": 3})})


def _liquid(t, b0, ms, ec, x_cr, x_eq):
    """b(t) [kg] of the closed form (module docstring)."""
    b_c = x_cr * ms
    if b0 > b_c:
        t_c = (b0 - b_c) / ec
        if t <= t_c:
            return b0 - ec * t
        t, b0 = t - t_c, b_c
    tau = (x_cr - x_eq) * ms / ec
    return x_eq * ms + (b0 - x_eq * ms) * math.exp(-t * ec / ((x_cr - x_eq) * ms) * 1.0) \
        if tau > 0 else b0


def _check(res, y0, x_cr, x_eq):
    t = res.columns["time_s"]
    ms = P0 * (1.0 - y0)
    # the rate is that of the granule as it is: its skeleton, so e_c does not change
    ec = _constant_rate(P0, y0)
    b = np.array([_liquid(tk, y0 * P0, ms, ec, x_cr, x_eq) for tk in t])
    p = ms + b
    assert np.allclose(res.columns["M01"], N0 * b, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["M10"], N0 * p, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["M20"], N0 * p * p, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["M11"], N0 * p * b, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["M00"], N0, rtol=TOL, atol=0.0)
    assert np.allclose(res.columns["liquid_evaporated"], N0 * (y0 * P0 - b), rtol=TOL,
                       atol=TOL * N0 * y0 * P0)
    assert np.allclose(res.columns["moisture_content"], b / ms, rtol=TOL, atol=0.0)
    return b, ms


def test_constant_rate_drying_is_linear_then_falls_exponentially():
    y0, x_cr = 0.2, 0.05                          # X0 = 0.25 > X_cr
    ec = _constant_rate(P0, y0)
    t_c = (y0 * P0 - x_cr * P0 * (1 - y0)) / ec
    res = run_well_mixed(_scene(y0, 3.0 * t_c, x_cr))
    b, ms = _check(res, y0, x_cr, 0.0)
    t = res.columns["time_s"]
    linear = t < t_c
    assert linear.sum() >= 5 and (~linear).sum() >= 5      # both periods are sampled
    assert np.all(np.diff(b) < 0)


def test_falling_rate_drying_is_first_order():
    y0, x_cr, x_eq = 0.05, 0.2, 0.01              # X0 = 0.0526 < X_cr: falling from the start
    ms = P0 * (1 - y0)
    tau = (x_cr - x_eq) * ms / _constant_rate(P0, y0)
    res = run_well_mixed(_scene(y0, 8.0 * tau, x_cr, x_eq))
    b, _ = _check(res, y0, x_cr, x_eq)
    # dry granules stay dry: the liquid tends to X_eq m_s from above and never crosses it
    assert np.all(b >= x_eq * ms) and b[-1] < x_eq * ms * 1.01


@pytest.mark.parametrize("drying, key", [
    ({"critical_moisture": 0.0}, "drying.critical_moisture"),
    ({"critical_moisture": 0.1, "equilibrium_moisture": 0.1}, "drying.equilibrium_moisture"),
    ({"critical_moisture": 0.1, "air_temperature": 100.0}, "drying.air_temperature"),
    ({"critical_moisture": 0.1, "slip_velocity": -1.0}, "drying.slip_velocity"),
    ({"critical_moisture": 0.1, "wind": 1.0}, "drying.wind"),
])
def test_bad_drying_input_names_the_key(drying, key):
    with pytest.raises(SceneError) as err:
        make_scene(initial={"binder_fraction": 0.1}, drying={**AIR, **drying})
    assert err.value.key == key


def test_drying_needs_a_liquid_and_a_method_that_carries_it():
    with pytest.raises(SceneError) as err:
        make_scene(drying={**AIR, "critical_moisture": 0.1})        # dry start, no spray
    assert err.value.key == "drying"
    # every registered method carries the drift; one that does not is refused by name
    from pbe_cfd.methods.registry import METHOD_REGISTRY
    from pbe_cfd.scene.drying import drying_refusals
    for entry in METHOD_REGISTRY:
        scene = make_scene(initial={"binder_fraction": 0.1},
                           drying={**AIR, "critical_moisture": 0.1},
                           method={"_replace": True, "name": entry.name})
        assert entry.dries and drying_refusals(scene, METHOD_REGISTRY) == []
        others = [e._replace(dries=e.name != entry.name) for e in METHOD_REGISTRY]
        assert [k for k, _ in drying_refusals(scene, others)] == ["drying"]
    with pytest.raises(SceneError) as err:                   # pure droplets among particles
        make_scene(initial={"binder_fraction": 0.1}, drying={**AIR, "critical_moisture": 0.1},
                   binder_injection={"rate": 1e8, "droplet_diameter": 60e-6})
    assert err.value.key == "binder_injection.solids_fraction"


def test_gas_state_against_reference_data():
    # steam tables (IAPWS-95): p_s(20 C) = 2339.2 Pa, p_s(50 C) = 12352 Pa; the Magnus form
    # is stated to 0.4% over -40..50 C
    assert drying.saturation_pressure(293.15) == pytest.approx(2339.2, rel=4e-3, abs=0.0)
    assert drying.saturation_pressure(323.15) == pytest.approx(12352.0, rel=4e-3, abs=0.0)
    # air at 300 K: mu = 1.846e-5 Pa s (Incropera, table A.4), rho = 1.177 kg/m3 at 1 atm
    assert drying.air_viscosity(300.0) == pytest.approx(1.846e-5, rel=5e-3, abs=0.0)
    assert drying.air_density(300.0, 101325.0) == pytest.approx(1.177, rel=3e-3, abs=0.0)
    # water vapour in air at 298 K: 2.5e-5 to 2.6e-5 m2/s (Massman 1998: 2.55e-5)
    assert 2.45e-5 < drying.vapour_diffusivity(298.15, 101325.0) < 2.65e-5
    # the wet bulb solves the psychrometric balance, lies between the dew point and T, and
    # is T for saturated air
    t, y, pres = 333.15, 0.005, 101325.0
    t_wb = drying.wet_bulb_temperature(t, y, pres)
    gap = (drying.latent_heat(t_wb) * (drying.saturation_humidity(t_wb, pres) - y)
           - drying.humid_heat(y) * (t - t_wb))
    assert abs(gap) < 1e-6 * drying.humid_heat(y) * (t - t_wb)
    assert drying.saturation_humidity(t_wb, pres) > y and t_wb < t
    y_sat = drying.saturation_humidity(t, pres)
    assert drying.wet_bulb_temperature(t, y_sat, pres) == t


def _spray_dry_scene(nodes, separate):
    """Spray (a solution, s = 0.1) for 20 s, dry for 2 s; constant-kernel aggregation, with
    droplets a population of their own (``separate``) or ordinary particles. A granule's
    falling-rate time X_cr m_s / e_c is ~0.1 s here (the isolated-granule Ranz-Marshall rate
    at 60 C dries fast), so the drying phase is sampled every 0.1 s."""
    aggregation = {"kernel": "constant", "rate": 2.0e-11}
    if separate:
        aggregation["droplet_factor"] = 100.0
    return make_scene(scene={"end_time": 22.0, "output_interval": 0.1},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": 0.02},
                      aggregation=aggregation,
                      binder_injection={"rate": 8.8e7, "droplet_diameter": 60e-6,
                                        "solids_fraction": 0.1, "start": 0.0, "stop": 20.0},
                      drying={**AIR, "critical_moisture": 0.05},
                      method={"_replace": True, "name": "qmom", "nodes": nodes,
                              "rtol": 1e-8})


@pytest.mark.parametrize("nodes, separate", [(3, True), (2, True), (3, False)])
def test_liquid_and_binder_solids_balance_over_spraying_and_drying(nodes, separate):
    """Sprayed liquid = held (granules and free droplets) + evaporated, to 1e-8 of what was
    there; the binder solids, M10 - M01 less its start, = s p_d I(t) to 1e-10 (the invariants
    M10 + x_d n_d + E and M01 + x_l n_d + E have state-free derivatives, which the explicit
    and implicit steps keep to round-off: 1e-16 x ~1e3 steps)."""
    res = run_well_mixed(_spray_dry_scene(nodes, separate))
    c = res.columns
    liquid0 = c["M01"][0]
    total = liquid0 + c["liquid_sprayed"]
    held = c["liquid_granules"] + c["liquid_droplets"]
    assert np.allclose(held + c["liquid_evaporated"], total, rtol=1e-8, atol=0.0)
    assert np.allclose(held, c["M01"], rtol=1e-14, atol=0.0)
    solids = (c["M10"] - c["M01"]) - (c["M10"][0] - c["M01"][0])
    expected = c["liquid_sprayed"] * 0.1 / 0.9             # s p_d I over (1 - s) p_d I
    assert np.allclose(solids, expected, rtol=1e-10, atol=1e-10 * expected[-1])
    # the drying does its work: something evaporated while spraying, and after the spray stops
    # the liquid only falls; moisture stays between 0 and its largest value while spraying
    t = c["time_s"]
    after = (t >= 20.0) & (c["M01"] > 1e-6 * c["M01"].max())   # above the tolerance's floor
    assert c["liquid_evaporated"][-1] > 0.5 * c["liquid_sprayed"][-1]
    assert after.sum() >= 2 and np.all(np.diff(c["M01"][after]) < 0)
    assert np.all(c["moisture_content"] >= 0) and np.all(c["liquid_granules"] >= 0)


@pytest.mark.parametrize("slip", [0.3, 3.0])
def test_a_liquid_sphere_in_a_slip_flow_follows_ranz_marshall(slip):
    """The exact liquid sphere (``liquid_sphere_after``: the cNMC's pure-liquid droplets and the
    sphere period of its wet particles) against the rate e = pi d Sh K with the Ranz-Marshall
    Sh = 2 + 0.6 Re^(1/2) Sc^(1/3), Re = rho_g slip d / mu_g, written out here and integrated
    with scipy's DOP853 (rtol 1e-12): at slip 0 the two agree whatever the Re term says, so
    the slip is on. A 60 um water droplet in the scene's air, to 99% of its lifetime. Measured:
    they agree to 1e-12 of b0 with the reference at rtol 1e-12 and to 5e-11 at rtol 1e-10 (the
    reference's own error), so 1e-9 of b0 leaves a factor 20 over a ten times looser reference;
    a Re term 10% off moves b by ~1e-2 b0."""
    from scipy.integrate import solve_ivp

    from pbe_cfd.physics import parameters as P

    rho, mu, diff, _, driving = drying.gas_state(AIR["air_temperature"], AIR["air_humidity"],
                                                 101325.0)
    k = diff * rho * driving
    schmidt = mu / (rho * diff)
    rho_l = 1000.0
    gas = (slip, k, rho / mu, schmidt)
    params = np.zeros(P.N_PARAMS)
    params[P.BINDER_DENSITY] = rho_l
    params[P.DENSITY] = RHO_S

    def rate(_, y):
        d = (6.0 * max(y[0], 0.0) / (math.pi * rho_l)) ** (1.0 / 3.0)
        sh = 2.0 + 0.6 * math.sqrt(rho * slip * d / mu) * schmidt ** (1.0 / 3.0)
        return [-math.pi * d * sh * k]

    b0 = rho_l * math.pi / 6.0 * 60e-6 ** 3
    life = drying.liquid_sphere_time(b0, 0.0, gas, params)
    times = np.linspace(0.0, 0.99 * life, 12)[1:]
    ref = solve_ivp(rate, (0.0, times[-1]), [b0], method="DOP853", t_eval=times, rtol=1e-12,
                    atol=1e-12 * b0)
    got = [drying.liquid_sphere_after(b0, t, gas, params, 0.0) for t in times]
    assert np.allclose(got, ref.y[0], rtol=0.0, atol=1e-9 * b0)
    # and the moment methods' rate of the same sphere is the same Ranz-Marshall rate
    for b in (b0, 0.3 * b0, 1e-3 * b0):
        assert drying.drying_rate(b, b, gas, params) == pytest.approx(
            -rate(0.0, [b])[0], rel=1e-12, abs=0.0)
