"""The Laguerre ROM's registry entry: its scene keys, state names, tables, populations, plan
line and its numba functions (``methods.registry`` lists it)."""
from ...physics import parameters as P
from ..entry import MethodEntry
from .build import FOLLOWING_SPAN
from .guard import output_check
from .number_watch import output_watch
from .options import LaguerreOptions
from .tensor import (aux_for_scene, escaped_share_report, failure_hint, number_closure,
                     population_for_output, plan_columns, scene_initial_state, scene_keys,
                     state_names, table_bytes)
from .rhs import laguerre_conserved, laguerre_project, laguerre_realizable, laguerre_rhs

#: config[P.METHOD] of the Laguerre ROM
CODE = 1


def laguerre_state_names(order, separate_droplets, drying=False):
    """State entry names of the Laguerre ROM (wet moments, dry moments, free droplets, the
    evaporated liquid)."""
    return state_names(order, separate_droplets, drying)


def _names(scene):
    return laguerre_state_names(scene.method.options.order, scene.separate_droplets,
                                getattr(scene, "drying", None) is not None)


def _keys(t, defaults):
    kw = {"order": t.number("order", defaults.order, integer=True, low=2, high=5),
          "consistent": t.boolean("consistent", defaults.consistent)}
    for key, unit in (("weight_mean_mass", "kg"), ("weight_mean_binder", "kg"),
                      ("weight_shape_mass", ""), ("weight_shape_binder", ""),
                      ("support_mass", "kg"), ("support_binder", "kg")):
        kw[key] = t.number(key, getattr(defaults, key), positive=True, unit=unit)
    for key in ("grid_mass", "grid_binder"):
        kw[key] = t.number(key, getattr(defaults, key), integer=True, low=4, high=400)
    kw["grid_spacing"] = t.choice("grid_spacing", ("fraction", "uniform"), defaults.grid_spacing)
    kw.update(scene_keys(t, defaults))
    if kw.get("following_support") and kw["order"] < 3:
        t.fail("following_support", "the following support needs order >= 3 (its weight "
                                    f"follows W20 / W10), got order = {kw['order']}")
    if kw.get("number_closure") not in (None, "tensor") and kw["order"] < 3:
        t.fail("number_closure", f'"{kw["number_closure"]}" needs order >= 3 (it gives W20, '
                                 f'W11, W02), got order = {kw["order"]}')
    return kw


def _aux(scene, arrays, theta_grid=None):
    return aux_for_scene(scene, arrays, theta_grid=theta_grid)


def _hint(plan, arrays, state, aux):
    return failure_hint(state, aux, arrays)


def _diagnostics(states, aux, arrays):
    share, text = escaped_share_report(states, aux, arrays)
    return {"escaped_mass_share": share}, ([text] if text else [])


def _plan(scene):
    m = scene.method.options
    n_state = len(_names(scene))
    return (f"Laguerre ROM of order {m.order} "
            f"({'moment-consistent' if m.consistent else 'plain projection'}"
            f"{', dry class' if m.dry_class else ''}"
            f"{', adaptive weights' if m.adaptive_weights else ''}, aggregation and capture "
            f"rows: {number_closure(m.follows, m.number_closure, m.order)}), "
            f"{_support_text(scene)}, grid {m.grid_mass} x {m.grid_binder}; {n_state} states")


def _support_text(scene):
    """The plan's words for the ROM's support (docs/physics.md 9.2)."""
    m = scene.method.options
    if m.follows:
        c_dry = m.dry_weight_mean_mass or scene.initial.mean_mass
        return (f"support following the wet class (up to {m.following_growth:g} x the initial "
                f"mean mass), dry class p <= {max(m.mass_support, FOLLOWING_SPAN * c_dry):.3g} kg")
    return f"fixed support p <= {m.mass_support:g} kg, b <= {m.binder_support:g} kg"


def _accuracy_knobs(quick):
    """The accuracy study's settings: order x tensor grid (coarse, fine) x consistent or
    plain projection (the quick study leaves out the fine plain ones), on the seed's fixed
    support, whose tensors the grid resolves (the seed scenes set it)."""
    grids = {"coarse": 8, "fine": 12} if quick else {"coarse": 20, "fine": 40}
    out = []
    for m in ((2, 3) if quick else (2, 3, 4)):
        for gname, g in grids.items():
            for consistent in (True, False):
                if quick and gname == "fine" and not consistent:
                    continue
                kind = "consistent" if consistent else "plain"
                out.append((f"m={m} {gname} {kind}", {"order": m, "consistent": consistent,
                                                      "grid_mass": g, "grid_binder": g,
                                                      "following_support": False}))
    return tuple(out)


_BUILDER_WARM = []


def _table_build_seconds(scene, pack, cell):
    """Seconds to build the scene's tensors from scratch (no disk cache); ``pack(scene)`` its
    packed arrays, ``cell(scene)`` its well-mixed cell row. The tensor builder is compiled
    beforehand on a 4 x 4 grid (once per process)."""
    import time

    from .tensor import build_aux, scene_weights_support

    def build(sc):
        arrays = pack(sc)
        weights, support = scene_weights_support(sc)
        u0 = float(cell(sc)[0, P.COLLISION_VELOCITY])
        t0 = time.perf_counter()
        build_aux(arrays.params, arrays.config, sc.method.options.order, weights=weights,
                  support=support, consistent=sc.method.options.consistent,
                  collision_velocity=u0 if u0 > 0 else None, use_cache=False)
        return time.perf_counter() - t0

    if not _BUILDER_WARM:
        build(scene.with_method(grid_mass=4, grid_binder=4))
        _BUILDER_WARM.append(True)
    return build(scene)


ENTRY = MethodEntry(
    name="laguerre", code=CODE, scene_keys=_keys, options=LaguerreOptions, order_key="order",
    order_label="Laguerre m", state_names=lambda s: _names(s),
    aux=_aux, tabulates_theta=True, population=population_for_output,
    failure_hint=_hint, diagnostics=_diagnostics, plan_line=_plan,
    initial_state=scene_initial_state, columns=plan_columns,
    table_bytes=table_bytes,
    table_keys=("grid_mass", "grid_binder", "dry_grid_mass"),
    rhs=laguerre_rhs, realizable=laguerre_realizable, project=laguerre_project,
    conserved=laguerre_conserved, work_size=lambda config: int(config[P.N_STATE]),
    bench_orders=int, bench_scene=lambda scene, order: scene.with_method(order=order),
    bench_quick=("2", "3"), bench_full=("2", "3", "4"), bench_ceiling="contraction",
    bench_breakdown="contraction",
    distribution="laguerre_density",
    distributions=("support", "semi-infinite", "expansion"),
    distribution_text="the Laguerre ROM's own density (wet and dry classes) integrated per "
                      "size class",
    moments_text="integral of the Laguerre density over its support",
    accuracy_knobs=_accuracy_knobs, table_build=_table_build_seconds,
    solute_droplets=True, dries=True, evaporates_droplets=True, output_check=output_check,
    output_watch=output_watch)
