"""The bed's air balance (docs/physics.md section 15, "The bed's air"; ``physics.air``,
``runs.air``): a well-mixed bed of N0 V monodisperse wet granules (no aggregation: the
quadrature of the drift is exact) in a dry-air flow G.

Closed forms, written out here from the gas balance G (Y_b - Y_in) = E (independent of the
code's): every granule's rate is k f (dY_in - (Y_b - Y_in)) with k = e_c / dY_in its film
conductance (e_c its isolated constant rate) and f its drying-curve factor.

* constant rate (f = 1, K = N0 V k constant): the liquid falls linearly at e_c G / (G + K)
  (well-mixed gas) or G dY_in (1 - exp(-K/G)) / (N0 V) (plug flow): exact for the lagged
  scheme, since K does not change;
* falling rate (f = b / (X_cr m_s), X_eq = 0): the bed's liquid L = N0 V b has K = kappa L,
  kappa = k / (X_cr m_s), and dL/dt = -kappa L dY_in G / (G + kappa L), so
  ln(L / L0) / kappa + (L - L0) / G = -dY_in t. The lagged scheme runs each piece at the
  conductance of the piece before: its error is first order in the interval. A piece of
  length h runs at the conductance of L one piece earlier, L (1 + h r) with r = -dlnL/dt,
  which lowers r by r s h, s = K / (G + K) the share of the air's limit; an error eps of
  ln L lowers r by r s eps in turn, so to first order d eps/dt = r s (eps + r h), eps(0) = 0.
"""
import math

import numpy as np
import pytest

from conftest import make_scene
from pbe_cfd.physics import drying
from pbe_cfd.runs.simulate import run_well_mixed
from pbe_cfd.scene.scene import SceneError

N0 = 1.0e10          # 1/m3
P0 = 1.0e-9          # kg
RHO_S = 1021.0       # kg/m3
VOLUME = 1.0e-3      # m3 of bed
AIR = {"air_temperature": 333.15, "air_humidity": 0.005, "slip_velocity": 0.3}


def _film(y0):
    """(e_c [kg/s], dY_in [kg/kg], T_wb [K]) of a granule of mass P0, liquid fraction y0 at
    the inlet air: pi d Sh D_v rho_g dY_in with the skeleton diameter (section 15)."""
    rho, mu, diff, t_wb, driving = drying.gas_state(AIR["air_temperature"],
                                                    AIR["air_humidity"], 101325.0)
    d = (6.0 * P0 * (1.0 - y0) / (math.pi * RHO_S)) ** (1.0 / 3.0)
    sh = 2.0 + 0.6 * math.sqrt(rho * AIR["slip_velocity"] * d / mu) * (
        mu / (rho * diff)) ** (1.0 / 3.0)
    return math.pi * d * sh * diff * rho * driving, driving, t_wb


def _scene(y0, end, x_cr, flow, balance="well-mixed", interval=0.25, outputs=20):
    return make_scene(scene={"end_time": end, "output_interval": end / outputs},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": y0},
                      drying={**AIR, "critical_moisture": x_cr, "air_balance": balance,
                              "air_mass_flow": flow, "bed_volume": VOLUME,
                              "air_interval": interval},
                      method={"_replace": True, "name": "qmom", "nodes": 3, "rtol": 1e-11,
                              "atol": 1e-16})


@pytest.mark.parametrize("balance", ["well-mixed", "plug-flow"])
def test_constant_rate_drying_is_limited_by_the_air_flow(balance):
    y0, x_cr = 0.3, 0.02
    e_c, d_in, t_wb = _film(y0)
    conductance = N0 * VOLUME * e_c / d_in
    flow = conductance / 3.0                         # the air, not the film, limits
    if balance == "well-mixed":
        rate = e_c * flow / (flow + conductance)
    else:
        rate = flow * d_in * -math.expm1(-conductance / flow) / (N0 * VOLUME)
    ms = P0 * (1.0 - y0)
    end = 0.8 * (y0 * P0 - x_cr * ms) / rate         # stays in the constant-rate period
    res = run_well_mixed(_scene(y0, end, x_cr, flow, balance))
    c = res.columns
    t = c["time_s"]
    b = y0 * P0 - rate * t
    assert np.allclose(c["M01"], N0 * b, rtol=1e-8, atol=0.0)
    assert np.allclose(c["M10"], N0 * (ms + b), rtol=1e-8, atol=0.0)
    bed_rate = N0 * VOLUME * rate
    assert np.allclose(c["evaporation_rate_kg_s"], bed_rate, rtol=1e-8, atol=0.0)
    assert np.allclose(c["outlet_humidity"], AIR["air_humidity"] + bed_rate / flow,
                       rtol=1e-8, atol=0.0)
    # below the air's capacity, and the outlet air between the wet bulb and the inlet
    assert np.all(bed_rate < flow * d_in)
    assert np.all((c["outlet_temperature_K"] > t_wb)
                  & (c["outlet_temperature_K"] < AIR["air_temperature"]))


def _falling_liquid(t, l0, kappa, flow, d_in):
    """L(t) [kg] of ln(L/L0)/kappa + (L - L0)/G = -dY_in t (module docstring), by Newton in
    u = ln(L/L0)."""
    u = 0.0
    for _ in range(100):
        f = u / kappa + l0 * (math.exp(u) - 1.0) / flow + d_in * t
        step = f / (1.0 / kappa + l0 * math.exp(u) / flow)
        u -= step
        if abs(step) < 1e-15:
            break
    return l0 * math.exp(u)


def test_falling_rate_lag_is_first_order_in_the_interval():
    y0, x_cr = 0.05, 0.2                             # falling from the start
    e_c, d_in, _ = _film(y0)
    ms = P0 * (1.0 - y0)
    l0 = N0 * VOLUME * y0 * P0
    kappa = (e_c / d_in) / (x_cr * ms)               # K = kappa L
    flow = kappa * l0 / 2.0                          # K0 / G = 2
    tau = x_cr * ms / e_c * (1.0 + kappa * l0 / flow)    # the initial decay time
    end = 3.0 * tau
    errors = []
    intervals = (end / 40, end / 80, end / 160)
    for interval in intervals:
        c = run_well_mixed(_scene(y0, end, x_cr, flow, interval=interval, outputs=4)).columns
        exact = _falling_liquid(end, l0, kappa, flow, d_in)
        errors.append(math.log(c["M01"][-1] * VOLUME / exact))
    # first order: halving the interval halves the error (1.7-2.3: the O(h^2) remainder)
    assert 1.7 < errors[0] / errors[1] < 2.3 and 1.7 < errors[1] / errors[2] < 2.3
    # and its size is the lag's (module docstring), to its O(h^2) remainder
    grid = np.linspace(0.0, end, 4001)
    liquid = np.array([_falling_liquid(t, l0, kappa, flow, d_in) for t in grid])
    cond = kappa * liquid
    r = cond * d_in * flow / (flow + cond) / liquid
    rs = r * cond / (flow + cond)
    eps, h = 0.0, intervals[2]
    for k in range(len(grid) - 1):                   # Heun on the linear error equation
        dt = grid[k + 1] - grid[k]
        f0 = rs[k] * (eps + r[k] * h)
        f1 = rs[k + 1] * (eps + dt * f0 + r[k + 1] * h)
        eps += 0.5 * dt * (f0 + f1)
    assert errors[2] == pytest.approx(eps, rel=0.1, abs=0.0)


@pytest.mark.parametrize("drying, key", [
    ({"air_balance": "well-mixed", "air_mass_flow": 1e-3}, "drying.bed_volume"),
    ({"air_balance": "well-mixed", "bed_volume": 1e-3}, "drying.air_mass_flow"),
    ({"air_balance": "stirred", "air_mass_flow": 1e-3, "bed_volume": 1e-3},
     "drying.air_balance"),
    ({"air_balance": "well-mixed", "air_mass_flow": 1e-3, "superficial_velocity": 1.0,
      "bed_volume": 1e-3}, "drying.superficial_velocity"),
    ({"air_balance": "well-mixed", "air_mass_flow": -1.0, "bed_volume": 1e-3},
     "drying.air_mass_flow"),
    ({"air_balance": "well-mixed", "air_mass_flow": 1e-3, "bed_volume": 1e-3,
      "air_interval": 0.0}, "drying.air_interval"),
])
def test_bad_air_balance_input_names_the_key(drying, key):
    with pytest.raises(SceneError) as err:
        make_scene(initial={"binder_fraction": 0.1},
                   drying={**AIR, "critical_moisture": 0.1, **drying})
    assert err.value.key == key
