"""The Laguerre ROM's free droplets evaporate with [drying] (docs/physics.md section 15, "Free
droplets' evaporation"): the droplet class carries its liquid L_d, every droplet is the class's
mean point (s p_d + l, l), l = L_d / n_d, and a capture hands a granule that point.

The closed forms of the droplets alone (the d^2 law, a solution through its three periods) are
in ``tests/methods/test_methods_droplet_evaporation.py`` for every method. Here:

- the capture at the droplet's point, mapped at the RHS from the capture moments, equals the
  capture tabulated for a sprayed droplet of that very point (constant kernel: the capture rate
  does not depend on the droplet), for the wet and the dry class;
- with a constant kernel the granules' moments, the droplet number and the droplets' liquid
  obey a closed hierarchy (below), solved independently with solve_ivp: the ROM follows it
  from a wet and from a dry start.
"""
import math

import numpy as np
import pytest

from conftest import make_scene
from pbe_cfd.methods.laguerre.rhs import laguerre_rhs
from pbe_cfd.methods.registry import method_of
from pbe_cfd.physics import drying
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs import model
from pbe_cfd.runs.simulate import run_well_mixed

K0 = 1.0e-10          # m3/s
N0 = 1.0e10           # 1/m3
P0 = 1.0e-9           # kg
RATE = 2.0e9          # droplets/(m3 s)
D_DROP = 60e-6        # m
RHO_L = 1000.0        # kg/m3
FACTOR = 2.0          # droplet capture at 2 k0 per granule
END = 6.0             # s
#: slip 0: Sh = 2, the liquid sphere's d^2 law; X_cr = 1e9 puts the granules deep in their
#: falling-rate period (relative drying rate ~1e-9 /s: below TOL over END)
AIR = {"air_temperature": 333.15, "air_humidity": 0.005, "slip_velocity": 0.0,
       "critical_moisture": 1.0e9}
#: the integrator runs at rtol 1e-11 on the scaled state over ~10^2-10^3 steps; 1e-8 leaves
#: a factor >10 for their sum (as tests/methods/test_spray.py)
TOL = 1.0e-8
LAGUERRE = {"_replace": True, "name": "laguerre", "order": 3, "rtol": 1e-11, "atol": 1e-16}


def _scene(y0, solids=0.0, diameter=D_DROP, dry=True, end=END):
    return make_scene(scene={"end_time": end, "output_interval": 0.25},
                      initial={"mean_mass": P0, "number_density": N0, "binder_fraction": y0,
                               "distribution": "exponential"},
                      aggregation={"kernel": "constant", "rate": K0, "droplet_factor": FACTOR},
                      binder_injection={"droplet_diameter": diameter, "rate": RATE,
                                        "solids_fraction": solids},
                      **({"drying": AIR} if dry else {}),
                      method=LAGUERRE)


def _capture_part(scene, state_of):
    """RHS(state with droplets) - RHS(the same state without droplets) of a scene: the capture
    terms alone (linear in the droplet population; drying of the granules and aggregation
    cancel), for the entries before the droplet tail. ``state_of(arrays, y)`` sets the
    droplets of the initial state y (returns (with, without))."""
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    y0 = model.initial_moments(scene, arrays, arrays.state_names)
    with_droplets, without = state_of(arrays, y0)
    cell = model.well_mixed_cell(scene)[0].copy()
    cell[P.INJECTION] = 0.0           # no injection: only the captures differ
    out = []
    for y in (with_droplets, without):
        f = np.zeros(y.size)
        laguerre_rhs(y, f, cell, aux, arrays.params, arrays.config)
        out.append(f)
    m = 3
    return (out[0] - out[1])[:m * m + m], arrays


@pytest.mark.parametrize("y0", [0.1, 0.0], ids=["wet-class", "dry-class"])
def test_the_capture_at_the_droplets_point_is_the_tabulated_capture_of_that_point(y0):
    """Droplets of solution (s = 0.2) that lost half their liquid: (s p_d + b_d / 2, b_d / 2)
    per droplet. The ROM with [drying] maps the capture gain at that point at the RHS; a ROM
    without drying, sprayed with droplets of exactly that mass and liquid, tabulates it. With
    a constant kernel the two give the same capture terms to round-off. Seen red with the
    point's mass in place of its liquid in the gain's binder powers."""
    s, nd = 0.2, 3.0e8
    pd = RHO_L * math.pi / 6.0 * D_DROP ** 3
    liquid = 0.5 * (1.0 - s) * pd
    point = s * pd + liquid                       # the droplet's mass now [kg]
    d_point = (6.0 * point / (math.pi * RHO_L)) ** (1.0 / 3.0)

    def evaporating(arrays, y):
        with_d, without = y.copy(), y.copy()
        with_d[-1] = nd / arrays.number_scale
        with_d[-3] = nd * liquid / (arrays.number_scale * arrays.mass_scale)
        without[-3] = 0.0
        without[-1] = 0.0
        return with_d, without

    def tabulated(arrays, y):
        with_d, without = y.copy(), y.copy()
        with_d[-1] = nd / arrays.number_scale
        without[-1] = 0.0
        return with_d, without

    at_point, a1 = _capture_part(_scene(y0, solids=s), evaporating)
    table, a2 = _capture_part(_scene(y0, solids=s * pd / point, diameter=d_point, dry=False),
                              tabulated)
    assert a1.mass_scale == a2.mass_scale and a1.number_scale == a2.number_scale
    assert np.any(at_point != 0.0)
    scale = np.abs(table).max()
    assert np.allclose(at_point, table, rtol=1e-12, atol=1e-14 * scale)


def _hierarchy(y0, times):
    """The constant kernel's closed hierarchy with pure-liquid droplets of their own that
    evaporate: granules M00, M10, M01, M20, M11, M02, droplets n_d and L_d at ``times``. A
    droplet of liquid l is a sphere of diameter d = (6 l / (pi rho_l))^(1/3) evaporating at
    2 pi d K (Sh = 2, K = D_v rho_g (Y_s - Y)); granules capture droplets at c = f k0 n_d each
    and gain the class's mean droplet (l, l), l = L_d / n_d:

        dn/dt = -k0 n^2 / 2,  dM10/dt = c l n,  dM01/dt = c l n,
        dM20/dt = k0 M10^2 + c (2 l M10 + l^2 n),  dM11/dt = k0 M10 M01 + c (l M01 + l M10 +
        l^2 n),  dM02/dt = k0 M01^2 + c (2 l M01 + l^2 n),
        dn_d/dt = R - c n,  dL_d/dt = R b_d - c L_d - n_d 2 pi d(l) K.

    solve_ivp (DOP853, rtol 1e-13); from an exponential start of binder fraction y0."""
    from scipy.integrate import solve_ivp
    rho, _, diff, _, driving = drying.gas_state(AIR["air_temperature"], AIR["air_humidity"],
                                                101325.0)
    k = diff * rho * driving
    bd = RHO_L * math.pi / 6.0 * D_DROP ** 3
    kc = FACTOR * K0

    def rates(t, y):
        n, m10, m01, m20, m11, m02, nd, ld = y
        c = kc * nd
        liq = max(ld, 0.0) / nd if nd > 0.0 else bd
        e = 2.0 * math.pi * (6.0 * liq / (math.pi * RHO_L)) ** (1.0 / 3.0) * k
        return [-0.5 * K0 * n * n, c * liq * n, c * liq * n,
                K0 * m10 * m10 + c * (2 * liq * m10 + liq * liq * n),
                K0 * m10 * m01 + c * (liq * m01 + liq * m10 + liq * liq * n),
                K0 * m01 * m01 + c * (2 * liq * m01 + liq * liq * n),
                RATE - c * n, RATE * bd - c * n * liq - nd * e]
    y0v = [N0, N0 * P0, y0 * N0 * P0, 2 * N0 * P0 ** 2, 2 * y0 * N0 * P0 ** 2,
           2 * y0 ** 2 * N0 * P0 ** 2, 0.0, 0.0]
    scale = N0 * np.array([1.0, P0, P0, P0 ** 2, P0 ** 2, P0 ** 2, 1.0, P0])
    sol = solve_ivp(rates, (0.0, times[-1]), y0v, t_eval=times, rtol=1e-13,
                    atol=1e-16 * scale, method="DOP853")
    assert sol.success, sol.message
    return sol.y, bd, k


@pytest.mark.parametrize("y0", [0.1, 0.0], ids=["wet-start", "dry-start"])
def test_laguerre_droplets_evaporate_and_hand_their_point_to_the_granules(y0):
    """Pure-liquid droplets sprayed at RATE, captured at 2 k0 per granule (kappa tau ~ 1-2:
    about a third of the liquid evaporates before capture), constant aggregation: every
    carried moment of the population (free droplets at (l, l) included), n_d and the droplets'
    liquid follow the closed hierarchy to TOL; the liquid inventory balances (sprayed = held
    by granules + held by droplets + evaporated)."""
    c = run_well_mixed(_scene(y0)).columns
    t = np.asarray(c["time_s"])
    (n, m10, m01, m20, m11, m02, nd, ld), bd, _ = _hierarchy(y0, t)
    assert np.allclose(c["droplet_number_density"], nd, rtol=TOL, atol=TOL * nd.max())
    assert np.allclose(c["liquid_droplets"], ld, rtol=TOL, atol=TOL * ld.max())
    liq = np.where(nd > 0.0, ld / np.where(nd > 0.0, nd, 1.0), bd)
    for name, granule, (i, j) in (("M00", n, (0, 0)), ("M10", m10, (1, 0)),
                                  ("M01", m01, (0, 1)), ("M20", m20, (2, 0)),
                                  ("M11", m11, (1, 1)), ("M02", m02, (0, 2))):
        expected = granule + nd * liq ** i * liq ** j
        assert np.allclose(c[name], expected, rtol=TOL, atol=TOL * np.abs(expected).max()), \
            name
    sprayed = RATE * bd * t
    evaporated = sprayed - (m01 - y0 * N0 * P0) - ld
    assert evaporated[-1] > 0.2 * sprayed[-1]          # the droplets' evaporation matters
    assert np.allclose(c["liquid_evaporated"], evaporated, rtol=0.0, atol=TOL * sprayed[-1])
    held = c["liquid_granules"] + c["liquid_droplets"] - y0 * N0 * P0
    assert np.allclose(held + c["liquid_evaporated"], sprayed, rtol=0.0,
                       atol=1e-10 * sprayed[-1])
