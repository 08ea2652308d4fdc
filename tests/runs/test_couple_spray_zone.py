"""The empty-spray-zone warning explains its cut from the output plan alone: the counts of the
box's cells removed by each criterion of the alpha window, counted here independently."""
from types import SimpleNamespace

import numpy as np
import pytest

from pbe_cfd.runs.domain import spray_zone_cut

# five cells on a line, centres x = 0..4 m; the box [0.5, 3.5] m holds cells 1, 2, 3
CENTRES = np.array([[float(x), 0.0, 0.0] for x in range(5)])
ALPHA = np.array([0.3, 0.05, 0.3, 0.6, 0.3])
ALPHA_MIN = 0.08
ZONE = SimpleNamespace(box_min=(0.5, -1.0, -1.0), box_max=(3.5, 1.0, 1.0),
                       alpha_low=0.1, alpha_high=0.5)
CELLS = SimpleNamespace(cell_centre=CENTRES, alpha=ALPHA)


def test_the_cut_counts_each_criterion_of_the_window_over_the_box():
    active = ALPHA >= ALPHA_MIN
    text = spray_zone_cut(ZONE, ALPHA_MIN, CELLS, active)
    box = (CENTRES[:, 0] >= 0.5) & (CENTRES[:, 0] <= 3.5)
    low = int(np.count_nonzero(ALPHA[box] < ZONE.alpha_low))
    high = int(np.count_nonzero(ALPHA[box] > ZONE.alpha_high))
    inactive = int(np.count_nonzero(~active[box]))
    assert (int(box.sum()), low, high, inactive) == (3, 1, 1, 1)
    assert text == (f"its box holds {int(box.sum())} cells (alpha 0.05..0.6), removed by the "
                    f"alpha window: {low} with alpha < alpha_low = 0.1, {high} with alpha > "
                    f"alpha_high = 0.5, {inactive} with alpha < alpha_min = {ALPHA_MIN:g}")


def test_a_box_without_cells_and_a_scene_without_a_zone_say_so():
    active = ALPHA >= ALPHA_MIN
    far = SimpleNamespace(box_min=(10.0, 10.0, 10.0), box_max=(11.0, 11.0, 11.0),
                          alpha_low=0.1, alpha_high=0.5)
    assert spray_zone_cut(far, ALPHA_MIN, CELLS, active) == (
        "no cell centre lies inside box_min..box_max")
    assert spray_zone_cut(None, ALPHA_MIN, CELLS, active) == "no cell has alpha >= alpha_min"


def test_a_nozzle_flow_reaches_the_bed_whole_in_every_cell_row():
    """fluid-bed-batch gives the nozzle's flow F [kg/s] (rate_unit = "kg/s"): every caller of
    the cell rows (``runs.domain.build_cells``: the run, transport's plan, the cluster bench)
    gets droplets/(m3 s), the same in each spray cell, and the zone receives F:
    sum(rate x volume) x p_d = F."""
    from pbe_cfd.physics import parameters as P
    from pbe_cfd.physics.injection import droplet_mass
    from pbe_cfd.runs.domain import build_cells, load_domain
    from pbe_cfd.scene.scene import load_scene
    sc = load_scene("fluid-bed-batch")
    inj = sc.binder_injection
    assert inj.rate_unit == "kg/s"
    cells = load_domain(sc).cells
    rows, active, spray, _ = build_cells(sc, cells)
    rate = rows[spray, P.INJECTION]
    assert spray.any() and np.all(rate == rate[0]) and np.all(rows[~spray, P.INJECTION] == 0.0)
    volume = np.asarray(cells.cell_volume, float)[spray]
    flow = float(np.sum(rate * volume)) * droplet_mass(inj.droplet_diameter,
                                                       sc.material.binder_density)
    assert flow == pytest.approx(inj.rate, rel=1e-12, abs=0.0)
