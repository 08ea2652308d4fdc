"""The Laguerre ROM's tables with the following support are built on the run's threads, one
node set of weight slices per share (``methods.laguerre.build._slice_tensors``): the tables
must not depend on how many threads build them."""
import numpy as np

from pbe_cfd.methods.laguerre import build
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.methods.laguerre.layout import AUX_NWC, AUX_NWD
from pbe_cfd.runs import model

from conftest import AVICEL, make_scene
from test_breakage import P0


def _tables(monkeypatch, threads):
    """The aux of a following-support scene (3 x 4 weight slices) built on
    ``threads`` threads, without the disk cache."""
    monkeypatch.setattr(build, "run_threads", lambda: threads)
    sc = make_scene(scene={"end_time": 1.0, "output_interval": 1.0}, material=AVICEL,
                    domain={"collision_velocity": 0.3},
                    initial={"distribution": "exponential", "binder_fraction": 0.01},
                    aggregation={"kernel": "constant", "rate": 1.0e-10,
                                 "efficiency": ["geometric", "physical"]},
                    method={"_replace": True, "name": "laguerre", "order": 3,
                            "following_support": True})
    arrays = model.pack(sc)
    weights, support = LT.scene_weights_support(sc)
    spec = dict(following=True, c=(P0, 4.0 * P0), points_c=3, y=(0.01, 1.0), points_y=3,
                y_below=[1e-3], shapes=None)
    return LT.build_aux(arrays.params, arrays.config, 3, weights=weights, support=support,
                        adaptive=spec, collision_velocity=0.3, use_cache=False)


def test_the_tables_do_not_depend_on_the_number_of_threads(monkeypatch):
    node_sets = []
    kernels = build.wet_kernels
    monkeypatch.setattr(build, "wet_kernels", lambda *a: node_sets.append(1) or kernels(*a))
    one = _tables(monkeypatch, 1)
    # the kernel matrices of every node set once: more sets than threads below, so that a
    # share builds more than one
    assert len(node_sets) >= 4, len(node_sets)
    assert int(one[AUX_NWC]) * int(one[AUX_NWD]) > len(node_sets)
    for threads in (2, 3):
        assert np.array_equal(_tables(monkeypatch, threads), one), threads
