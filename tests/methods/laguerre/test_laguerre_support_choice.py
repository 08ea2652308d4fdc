"""Which support the Laguerre ROM takes from a scene's [method] table (docs/physics.md 9.2):
the following support at order 3 unless the scene sets support_mass or support_binder,
the seed's fixed support then (with the bounds it sets, the others seed 000's), and
following_support = true / false when the scene says so; summary.json records the choice."""
import pytest

from conftest import make_scene
from pbe_cfd.methods.laguerre.options import SEED_SUPPORT_BINDER, SEED_SUPPORT_MASS
from pbe_cfd.scene.scene import SceneError, describe, load_scene


def options(**keys):
    return make_scene(method={"name": "laguerre", **keys, "_replace": True}).method.options


@pytest.mark.parametrize("keys, follows, p_max, b_max", [
    ({"order": 3}, True, SEED_SUPPORT_MASS, SEED_SUPPORT_BINDER),
    ({"order": 4}, False, SEED_SUPPORT_MASS, SEED_SUPPORT_BINDER),
    ({"order": 4, "following_support": True}, True, SEED_SUPPORT_MASS, SEED_SUPPORT_BINDER),
    ({"order": 2}, False, SEED_SUPPORT_MASS, SEED_SUPPORT_BINDER),
    ({"order": 3, "support_mass": 2e-8}, False, 2e-8, SEED_SUPPORT_BINDER),
    ({"order": 3, "support_binder": 1e-9}, False, SEED_SUPPORT_MASS, 1e-9),
    ({"order": 3, "following_support": False}, False, SEED_SUPPORT_MASS, SEED_SUPPORT_BINDER),
    ({"order": 3, "support_mass": 2e-8, "following_support": True}, True, 2e-8,
     SEED_SUPPORT_BINDER),
])
def test_the_support_a_scene_gets(keys, follows, p_max, b_max):
    m = options(**keys)
    assert m.follows is follows
    assert (m.mass_support, m.binder_support) == (p_max, b_max)
    assert m.dry_weight_shape_mass == 10.0          # the same dry class under both supports


def test_the_same_rule_for_scenes_built_in_code():
    """A scene switched to the ROM in code (``with_method``) gets the same choice as one read
    from a file, and setting a support later turns the following off."""
    scene = load_scene("seed-wurster").with_method(name="laguerre", order=3)
    assert scene.method.options.follows
    assert not scene.with_method(support_mass=2e-8).method.options.follows


def test_the_seed_scenes_keep_the_fixed_support_and_the_summary_says_which():
    for name, follows in (("seed-wurster-laguerre", False), ("study-seed-dry", False),
                          ("fluid-bed-laguerre", True), ("fluid-bed-laguerre-batch", True)):
        scene = load_scene(name)
        assert scene.method.options.follows is follows, name
        described = describe(scene)["method"]
        assert described["following_support"] is follows, name
        assert described["support_mass"] == pytest.approx(SEED_SUPPORT_MASS, rel=0, abs=0)


def test_following_support_with_order_2_is_refused_naming_the_key():
    with pytest.raises(SceneError, match=r"method\.following_support.*order >= 3"):
        options(order=2, following_support=True)


@pytest.mark.parametrize("order", [3, 4])
def test_the_following_support_takes_every_wet_row_from_the_points(order):
    """The rows of aggregation and capture: on the points with the following support at every
    order (at m = 4 "points" stops on the seed scenarios), the tensors with the fixed one."""
    from pbe_cfd.methods.laguerre.tensor import number_closure
    follow = options(order=order, following_support=True)
    fixed = options(order=order, following_support=False)
    assert number_closure(follow.follows, follow.number_closure, order) == "points-all"
    assert number_closure(fixed.follows, fixed.number_closure, order) == "tensor"
