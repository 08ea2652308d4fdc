"""One d43 in the ktgf kernel for every method: the granules' volume-mean diameter, free
droplets excluded (docs/physics.md, "d43").

Where droplets are a population of their own, the right-hand side of a moment method is then
affine in the free-droplet number n_d at a fixed granule state: granule-granule aggregation does
not depend on n_d, droplet capture is proportional to it. If d43 counted the droplets, the
kernel factor d43^(3/2) would change with n_d and the second difference
f(0) - 2 f(x) + f(2x) would not vanish. (The cNMC's d43 is checked against a brute-force
enumeration with the granule-only d43 in test_cnmc_physics.py.)
"""
import dataclasses

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.methods.dispatch import WORK_SIZE, method_rhs
from pbe_cfd.methods.registry import method_of
from pbe_cfd.scene.scene import load_scene

from conftest import make_scene


def rhs_at_droplet_numbers(method_table, binder_fraction=0.15):
    scene = load_scene("study-ktgf")
    scene = dataclasses.replace(scene, method=make_scene(method=method_table).method,
                                initial=dataclasses.replace(scene.initial,
                                                            binder_fraction=binder_fraction))
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    k = arrays.state_names.index("droplet_number_density")
    cell = model.well_mixed_cell(scene)[0]
    out = []
    for scale in (0.0, 1.0, 2.0):
        s = state.copy()
        s[k] = scale * 0.3                          # droplets per granule (scaled units)
        d = np.zeros_like(s)
        method_rhs(s, d, cell, aux, arrays.params, arrays.config, np.zeros(WORK_SIZE))
        out.append(d)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("method", [{"name": "qmom", "nodes": 2, "_replace": True},
                                    {"name": "laguerre", "order": 3, "_replace": True}],
                         ids=["qmom", "laguerre"])
def test_free_droplets_do_not_enter_the_ktgf_d43(method):
    f0, f1, f2 = rhs_at_droplet_numbers(method)
    scale = np.max(np.abs(f2))
    assert scale > 0
    assert np.max(np.abs(f1 - f0)) > 1e-3 * scale            # droplets do matter (capture)
    # affine in n_d: second difference at round-off (a d43 counting 0.3 droplets of 60 um per
    # 100 um granule would change d43 by ~5% and the RHS by ~8% of the capture term)
    assert np.max(np.abs(f0 - 2 * f1 + f2)) <= 1e-12 * scale
