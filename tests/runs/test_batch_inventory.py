"""The bed's liquid and binder-solids inventory of ``fluid-bed-batch`` (docs/physics.md
section 15, "Inventory"), on the bundled bed with transport, shortened: spraying 0-16 s, drying
16-24 s (the batch's physics; a real batch sprays 20 min), with the batch's QMOM and with the
Laguerre ROM.

The sprayed amounts are the schedule's integral times the spray cells' rates and volumes, the
held ones sums of the states: independent sides. The integrator keeps M10 + E and M01 + E
invariant (their derivatives are state-free) and transport moves every moment conservatively,
so the liquid balance holds to the step control's round-off, ~1e-16 x the steps (~1e4 per cell
here), well inside 1e-8 of the sprayed liquid; the binder solids (M10 - M01 gains s p_d per
captured droplet, exactly) to 1e-10.
"""
import dataclasses

import numpy as np
import pytest

from pbe_cfd.runs.couple import run_coupled
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene

SPRAY_STOP = 16.0
END = 24.0


#: the batch's own QMOM N = 2, and the Laguerre ROM (m = 3, its support following the wet
#: class, as fluid-bed-laguerre-batch, with its fixed weight shape: the shape axis is nine
#: times the tables to build and adds nothing to a balance): its droplets of their own
#: evaporate too, and its wet class dries below the tables' lowest binder fraction from
#: ~22 s on (docs/physics.md section 9.2, "Below the lowest binder fraction")
METHODS = {"qmom": {}, "laguerre": {"name": "laguerre", "order": 3, "following_support": True,
                                    "following_shape": False}}


@pytest.fixture(scope="module", params=sorted(METHODS))
def batch(request):
    scene = load_scene("fluid-bed-batch")
    if METHODS[request.param]:
        scene = scene.with_method(**METHODS[request.param])
    inj = scene.binder_injection
    scene = dataclasses.replace(
        scene, end_time=END, output_interval=4.0,
        binder_injection=dataclasses.replace(inj, schedule=((0.0, inj.rate),
                                                            (SPRAY_STOP, 0.0))))
    domain = load_domain(scene, need_flux=True)
    return run_coupled(scene, domain, threads=1).bed_columns


@pytest.mark.slow
def test_sprayed_liquid_is_held_or_evaporated(batch):
    c = batch
    held = c["liquid_granules_kg"] + c["liquid_droplets_kg"] + c["liquid_evaporated_kg"]
    sprayed = c["liquid_sprayed_kg"]
    assert sprayed[-1] > 0 and c["liquid_evaporated_kg"][-1] > 0
    assert np.allclose(held, sprayed, rtol=0.0, atol=1e-8 * sprayed[-1])
    # the schedule: nothing sprayed after its stop, linear before
    t = c["time_s"]
    assert np.allclose(sprayed[t >= SPRAY_STOP], sprayed[-1], rtol=1e-15, atol=0.0)
    on = t <= SPRAY_STOP
    assert np.allclose(sprayed[on], sprayed[-1] * t[on] / SPRAY_STOP, rtol=1e-12, atol=0.0)
    # the scene's nozzle flow F [kg/s] of solution (rate_unit = "kg/s"), spread over the
    # spray zone's cells, reaches the bed whole: liquid (1 - s) F t
    inj = load_scene("fluid-bed-batch").binder_injection
    assert inj.rate_unit == "kg/s"
    assert sprayed[-1] == pytest.approx((1.0 - inj.solids_fraction) * inj.rate * SPRAY_STOP,
                                        rel=1e-12, abs=0.0)


@pytest.mark.slow
def test_binder_solids_are_conserved(batch):
    c = batch
    assert c["solids_sprayed_kg"][-1] > 0
    assert np.allclose(c["solids_held_kg"], c["solids_sprayed_kg"], rtol=0.0,
                       atol=1e-10 * c["solids_sprayed_kg"][-1])
    # solution at s = 0.1: solids s / (1 - s) of the liquid
    assert np.allclose(c["solids_sprayed_kg"], c["liquid_sprayed_kg"] / 9.0, rtol=1e-12,
                       atol=0.0)


@pytest.mark.slow
def test_the_air_limits_the_drying_and_the_moisture_is_physical(batch):
    c = batch
    # never above the air's capacity, the outlet air between the wet bulb and the inlet
    scene = load_scene("fluid-bed-batch")
    dry = scene.drying
    from pbe_cfd.physics import drying
    _, _, _, t_wb, d_in = drying.gas_state(dry.air_temperature, dry.air_humidity, dry.pressure)
    assert np.all(c["evaporation_rate_kg_s"] <= dry.air_mass_flow * d_in * (1 + 1e-12))
    assert np.all(c["outlet_temperature_K"] >= t_wb - 1e-9)
    assert np.all(c["outlet_temperature_K"] <= dry.air_temperature + 1e-9)
    assert np.all(c["moisture_content"] >= 0.0) and np.all(c["moisture_content"] < 1.0)
    # after the spray stops the granules' liquid only falls
    t = c["time_s"]
    after = t >= SPRAY_STOP
    assert np.all(np.diff(c["liquid_granules_kg"][after]) < 0)
