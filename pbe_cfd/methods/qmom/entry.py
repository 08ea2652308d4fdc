"""The QMOM's registry entry: its scene keys, state names, populations, plan line and its
numba functions (``methods.registry`` lists it)."""
from ...physics import parameters as P
from ..entry import MethodEntry, no_aux, no_diagnostics, no_hint
from .options import QmomOptions
from .qmom import (qmom_conserved, qmom_on_closure, qmom_project, qmom_realizable,
                   qmom_rhs,
                   quadrature_of as qmom_quadrature_of,
                   quadrature_rows_of as qmom_quadrature_rows_of, state_names as qmom_state_names,
                   work_size as qmom_work_size)

#: config[P.METHOD] of the QMOM
CODE = 0


def _keys(t, defaults):
    return {"nodes": t.number("nodes", defaults.nodes, integer=True, low=1, high=5)}


def _state_names(scene):
    return qmom_state_names(scene.method.options.nodes, scene.bivariate, scene.separate_droplets,
                            getattr(scene, "drying", None) is not None)


def _population(state, aux, arrays):
    x, w, beta = qmom_quadrature_of(state, arrays.config)
    return w * arrays.number_scale, x * arrays.mass_scale, beta * arrays.mass_scale


def _populations(states, aux, arrays):
    x, w, beta, counts = qmom_quadrature_rows_of(states, arrays.config)
    return w * arrays.number_scale, x * arrays.mass_scale, beta * arrays.mass_scale, counts


#: the plan's note where the efficiency reads the binder that QMOM holds one value of per node
BINDER_SPREAD_NOTE = ("\n    note: one binder value per size node, and the efficiency reads "
                      "the binder; where binder differs between granules of one size (a "
                      "spray), CQMOM or the Laguerre ROM carry that spread "
                      "(docs/results/accuracy.md, \"Which method for which question\")")


def _plan(scene):
    m = scene.method
    # an efficiency that reads the binder sees each size node's one binder value
    agg = scene.aggregation
    note = BINDER_SPREAD_NOTE if agg is not None and agg.reads_binder else ""
    return (f"QMOM with {m.options.nodes} nodes; state {', '.join(_state_names(scene))}"
            f"; rtol {m.rtol:g}{note}")


ENTRY = MethodEntry(
    name="qmom", code=CODE, scene_keys=_keys, options=QmomOptions, order_key="nodes", order_label="QMOM N",
    state_names=_state_names, aux=no_aux, tabulates_theta=False, population=_population,
    populations=_populations, failure_hint=no_hint, diagnostics=no_diagnostics, plan_line=_plan,
    repairs_mixture=lambda plan: plan.bivariate,
    rhs=qmom_rhs, realizable=qmom_realizable, project=qmom_project,
    on_closure=qmom_on_closure,
    conserved=qmom_conserved, work_size=lambda config: qmom_work_size(config[P.ORDER]),
    bench_orders=int, bench_scene=lambda scene, order: scene.with_method(nodes=order),
    bench_quick=("2", "3"), bench_full=("2", "3", "4"), bench_ceiling="nodes",
    bench_baseline="3", bench_breakdown="nodes",
    distribution="gamma",
    distributions=("support", "semi-infinite"),
    distribution_text="gamma EQMOM of N - 1 kernels of one width fitted to the carried "
                      "M00 .. M(2N-2)0 (one kernel for N = 2; M(2N-1)0 not used); binder "
                      "fraction per size class interpolated in ln p between the "
                      "nodes' binder values",
    moments_text="from the quadrature nodes (one binder value per size node)",
    accuracy_knobs=lambda quick: tuple((f"N={n}", {"nodes": n})
                                       for n in ((1, 2, 3) if quick else (1, 2, 3, 4))),
    dries=True, evaporates_droplets=True)
