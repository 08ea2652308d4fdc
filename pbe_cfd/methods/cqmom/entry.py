"""The CQMOM's registry entry: its scene keys, state names, populations, plan line and its
numba functions (``methods.registry`` lists it)."""
from ...physics import parameters as P
from ..entry import MethodEntry, no_aux, no_diagnostics, no_hint
from .cqmom import (MAX_BINDER_NODES, MAX_SIZE_NODES, cqmom_conserved, cqmom_project,
                    cqmom_realizable, quadrature_of as cqmom_quadrature_of,
                    state_names as cqmom_state_names, work_size as cqmom_work_size)
from .options import CqmomOptions
from .sources import cqmom_rhs
from .validity import validity_report

#: config[P.METHOD] of the CQMOM
CODE = 2


def _keys(t, defaults):
    return {"nodes": t.number("nodes", defaults.nodes, integer=True, low=1,
                              high=MAX_SIZE_NODES),
            "binder_nodes": t.number("binder_nodes", defaults.binder_nodes, integer=True, low=1,
                                     high=MAX_BINDER_NODES)}


def _state_names(scene):
    m = scene.method.options
    return cqmom_state_names(m.nodes, m.binder_nodes, scene.bivariate, scene.separate_droplets,
                             getattr(scene, "drying", None) is not None)


def _population(state, aux, arrays):
    x, w, b = cqmom_quadrature_of(state, arrays.config)
    return w * arrays.number_scale, x * arrays.mass_scale, b * arrays.mass_scale


def _plan(scene):
    m = scene.method.options
    return (f"CQMOM with {m.nodes} size nodes x {m.binder_nodes} binder-fraction nodes; "
            f"state {', '.join(_state_names(scene))}; rtol {scene.method.rtol:g}")


def _closure_check(blocks, arrays, row_name):
    return validity_report(blocks, arrays.config, arrays.params, row_name)


def _bench_orders(text):
    """'2x2' -> (2, 2): size nodes x binder-fraction nodes."""
    n1, _, n2 = text.partition("x")
    return int(n1), int(n2)


ENTRY = MethodEntry(
    name="cqmom", code=CODE, scene_keys=_keys, options=CqmomOptions, order_key="nodes", order_label="CQMOM N1",
    state_names=_state_names, aux=no_aux, tabulates_theta=False, population=_population,
    failure_hint=no_hint, diagnostics=no_diagnostics, plan_line=_plan,
    repairs_mixture=lambda plan: plan.bivariate,
    config_slots=lambda scene: {P.BINDER_NODES: scene.method.options.binder_nodes},
    rhs=cqmom_rhs, realizable=cqmom_realizable, project=cqmom_project,
    conserved=cqmom_conserved,
    work_size=lambda config: cqmom_work_size(config[P.ORDER], config[P.BINDER_NODES]),
    bench_orders=_bench_orders,
    bench_scene=lambda scene, order: scene.with_method(nodes=order[0], binder_nodes=order[1]),
    bench_quick=("2x2",), bench_full=("2x2", "3x2", "3x3"), bench_ceiling="points",
    bench_versus_baseline=True,
    distribution="gamma",
    distributions=("support", "semi-infinite"),
    distribution_text="gamma EQMOM of N - 1 kernels of one width fitted to the carried "
                      "M00 .. M(2N-2)0 (one kernel for N = 2; M(2N-1)0 not used); binder "
                      "fraction per size class interpolated in ln p between the "
                      "size nodes' mass-mean binder fractions",
    moments_text="from the quadrature nodes (one binder value per size node)",
    accuracy_knobs=lambda quick: tuple(
        (f"N1={n1} N2={n2}", {"nodes": n1, "binder_nodes": n2})
        for n1, n2 in (((2, 2),) if quick else ((2, 2), (3, 2), (3, 3), (4, 2)))),
    closure_check=_closure_check,
    dries=True, evaporates_droplets=True)
