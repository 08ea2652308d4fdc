"""Drying (docs/physics.md section 15) in every method that carries it: CQMOM, EQMOM and the
cNMC, beside QMOM (tests/physics/test_drying.py).

Closed forms: no aggregation, a monodisperse wet population is one point of every quadrature
(one size node, one conditional point, one degenerate gamma kernel) and a box of identical
particles in the cNMC, so the drift's quadrature is exact and the moments follow the liquid
b(t) of one granule (linear in the constant-rate period, exponential in the falling-rate
period): M_ij = N0 (m_s + b)^i b^j, E = N0 (b0 - b). Tolerance 1e-8 as there (rtol 1e-11
over ~10^2 steps); the cNMC integrates each particle in closed form (skeleton period), so its
moments are exact to round-off of the box sums.
"""
import numpy as np
import pytest

from conftest import make_scene
from test_drying import AIR, N0, P0, RHO_S, TOL, _constant_rate, _liquid, _scene
from pbe_cfd.runs.simulate import run_well_mixed

METHODS = {
    "cqmom": {"name": "cqmom", "nodes": 2, "binder_nodes": 2},
    "eqmom": {"name": "eqmom", "nodes": 2},
    "cnmc": {"name": "cnmc", "particles": 64, "replicas": 2, "seed": 3},
}


def _check(res, y0, x_cr, x_eq, rtol):
    c = res.columns
    ms = P0 * (1.0 - y0)
    ec = _constant_rate(P0, y0)
    b = np.array([_liquid(t, y0 * P0, ms, ec, x_cr, x_eq) for t in c["time_s"]])
    p = ms + b
    for name, expected in (("M00", N0 + 0 * b), ("M10", N0 * p), ("M01", N0 * b),
                           ("M20", N0 * p * p), ("M11", N0 * p * b), ("M02", N0 * b * b)):
        if name in c:
            assert np.allclose(c[name], expected, rtol=rtol, atol=0.0), name
    assert np.allclose(c["liquid_evaporated"], N0 * (y0 * P0 - b), rtol=rtol,
                       atol=rtol * N0 * y0 * P0)
    return b


@pytest.mark.parametrize("method", sorted(METHODS))
def test_constant_rate_then_falling_rate_closed_form(method):
    y0, x_cr = 0.2, 0.05                          # X0 = 0.25 > X_cr: both periods
    ec = _constant_rate(P0, y0)
    t_c = (y0 * P0 - x_cr * P0 * (1 - y0)) / ec
    res = run_well_mixed(_scene(y0, 3.0 * t_c, x_cr, method=METHODS[method]))
    # the cNMC's moments are box sums of identical particles: round-off of N additions
    b = _check(res, y0, x_cr, 0.0, 1e-12 if method == "cnmc" else TOL)
    t = res.columns["time_s"]
    assert (t < t_c).sum() >= 5 and (t > t_c).sum() >= 5
    assert np.all(np.diff(b) < 0)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_falling_rate_is_first_order_and_dry_stays_dry(method):
    y0, x_cr, x_eq = 0.05, 0.2, 0.01              # falling from the start
    ms = P0 * (1 - y0)
    tau = (x_cr - x_eq) * ms / _constant_rate(P0, y0)
    res = run_well_mixed(_scene(y0, 8.0 * tau, x_cr, x_eq, method=METHODS[method]))
    b = _check(res, y0, x_cr, x_eq, 1e-12 if method == "cnmc" else TOL)
    assert np.all(b >= x_eq * ms) and np.all(res.columns["M01"] >= N0 * x_eq * ms * (1 - TOL))


def _spray_dry(method):
    """Spray a solution (s = 0.1) for 20 s, dry for 2 s, constant-kernel aggregation, droplets
    as ordinary particles (the scene of tests/physics/test_drying.py's balance test)."""
    return make_scene(scene={"end_time": 22.0, "output_interval": 0.5},
                      material={"density": RHO_S, "binder_density": 1000.0},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": 0.02},
                      aggregation={"kernel": "constant", "rate": 2.0e-11},
                      binder_injection={"rate": 8.8e7, "droplet_diameter": 60e-6,
                                        "solids_fraction": 0.1, "start": 0.0, "stop": 20.0},
                      drying={**AIR, "critical_moisture": 0.05},
                      method={"_replace": True, "rtol": 1e-8, **METHODS[method]})


@pytest.mark.parametrize("method", ["cqmom", "eqmom"])
def test_liquid_and_binder_solids_balance(method):
    """Sprayed liquid = held + evaporated to 1e-8, the binder solids M10 - M01 = s p_d I(t)
    (plus their start) to 1e-10: the invariants M10 + E and M01 + E have state-free
    derivatives (the spray), kept by the integrator to round-off."""
    c = run_well_mixed(_spray_dry(method)).columns
    total = c["M01"][0] + c["liquid_sprayed"]
    assert np.allclose(c["M01"] + c["liquid_evaporated"], total, rtol=1e-8, atol=0.0)
    solids = (c["M10"] - c["M01"]) - (c["M10"][0] - c["M01"][0])
    expected = c["liquid_sprayed"] * 0.1 / 0.9
    assert np.allclose(solids, expected, rtol=1e-10, atol=1e-10 * expected[-1])
    after = (c["time_s"] >= 20.0) & (c["M01"] > 1e-6 * c["M01"].max())
    assert c["liquid_evaporated"][-1] > 0.5 * c["liquid_sprayed"][-1]
    assert after.sum() >= 2 and np.all(np.diff(c["M01"][after]) < 0)
    assert np.all(c["M01"] >= 0)
