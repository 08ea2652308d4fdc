"""What a method declares to the rest of the program (``MethodEntry``), and the shared
defaults of its fields. Each method package builds its entry from its own modules; the
registry (``methods.registry``) lists the entries."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

#: config[P.METHOD] of a method that the per-cell integrator does not run (the cNMC)
NOT_INTEGRATED = -1

#: length of the per-cell float work array handed to every method function
WORK_SIZE = 2048


class RunStopped(RuntimeError):
    """A method's own run (``MethodEntry.ensemble``: the cNMC) could not reach its end time;
    the message says which replica, when and why."""


class RateNotFinite(RunStopped, FloatingPointError):
    """A method's own run stopped on an event rate that is not finite."""


class MethodEntry(NamedTuple):
    """One method of the registry (see the module docstring for who calls what).

    name            the scene's ``[method] name``
    code            config[P.METHOD] (unique); NOT_INTEGRATED for a method with a run of its
                    own (cNMC)
    scene_keys      f(table, defaults) -> dict of its ``options`` fields, read from the
                    ``[method]`` table by the scene's table reader (``t.number``,
                    ``t.boolean``, ...); defaults: the ``options`` class (its field defaults)
    options         its frozen options dataclass (``methods/<m>/options.py``): the
                    ``[method]`` keys only it reads; the scene holds one as
                    ``scene.method.options`` (``NoOptions``: none)
    order_key       the ``options`` field of its accuracy order (config[P.ORDER]): "nodes",
                    "order", or None (0)
    order_label     how studies name that order ("QMOM N")
    state_names     f(scene) -> names of the state entries ("M{i}{j}", then
                    "droplet_number_density")
    aux             f(scene, arrays, theta_grid) -> float array of method data (theta_grid
                    [m2/s2]: the cells' granular temperatures to tabulate over, or None)
    tabulates_theta True if a coupled run hands ``aux`` a grid of the cells' Theta
    population      f(state, aux, arrays) -> (w [1/m3], p [kg], b [kg]): the granules of one
                    scaled state as weighted particles (for SI columns and mean diameters)
    populations     f(states, aux, arrays) -> (w [1/m3], p [kg], b [kg], counts): every
                    row's ``population`` in one pass, each (rows, n) zero beyond the row's
                    count of particles; None: ``population`` row by row
    failure_hint    f(plan, arrays, state, aux) -> text appended to a stopped cell's message
                    (plan: the run's ``MethodPlan``)
    diagnostics     f(states, aux, arrays) -> (stats dict, warnings list) after a run
    closure_check   f(blocks, arrays, row_name) -> (stats dict, warnings list) after a run:
                    the method's own estimate of its closure's error (CQMOM:
                    ``cqmom.validity``) over blocks of scaled states (2-D arrays, one per
                    output time with a row per cell, or one with a row per output time),
                    row_name(block, row) naming a row ("cell 12 at t = 300 s"); None: none
    output_check    f(states, aux, arrays) -> None or (row, text): the first row of scaled
                    states (one per cell, at an output time) that is no answer, and why;
                    the run stops there (None: no check)
    output_watch    f() -> a watcher of one run, or None: ``update(t [s], states, rows, aux,
                    arrays, cell_ids)`` at every output time that passed ``output_check``
                    (True: it found something), then ``text()`` (one warning line) and
                    ``stats()`` (summary entries) if it found anything (Laguerre ROM: a
                    positive aggregation rate of the granule number)
    plan_line       f(scene) -> the method's line of ``pbe-cfd plan``
    repairs_mixture f(plan) -> True if a mixture of realizable states (transport) may need
                    the method's projection before the next source step (plan: the
                    scene's ``MethodPlan``)
    initial_state   f(scene, arrays, granule_moment) -> the scaled initial state, or None for
                    the generic one (state entries "M{i}{j}" and "droplet_number_density";
                    granule_moment(i, j) [kg^(i+j)/m3] of the initial granules)
    columns         f(plan, arrays, states, aux, populations) -> SI output columns, or None
                    for the generic ones (``model.moment_outputs``; plan: the run's
                    ``MethodPlan``)
    ensemble        a method that is not integrated per cell: f(plan, arrays, cell, times
                    [s], progress) (plan: the run's ``MethodPlan``) -> dict of result columns and statistics (cNMC:
                    ``cnmc.simulate_ensemble``)
    config_slots    f(scene) -> {config slot: value} of further knobs (CQMOM: BINDER_NODES)
    table_bytes     f(options) -> peak memory [bytes] its tables take to build (``aux``), from
                    the scene's ``method.options``; table_keys the ``[method]`` keys that set it
    rhs, realizable, project, conserved
                    its numba functions (``methods.dispatch`` calls them; None if not
                    integrated): rhs(state, out, cell, aux, params, config, work),
                    realizable/project(state, aux, params, config, work),
                    conserved(config, params, pivots, coefs) -> number of invariants
    on_closure      numba function realizable(state, aux, params, config, work) -> True if the
                    state is also on the method's closure (QMOM, EQMOM: the binder moments
                    reproduced by the bounded per-node binder), the test that picks the cells
                    the repair after transport re-projects; None: ``realizable``
    work_size       f(config) -> floats of the per-cell ``work`` array it needs (at most
                    WORK_SIZE; ``model.pack`` checks)
    bench_orders    f(text) -> the order of ``pbe-cfd bench throughput --methods name:text``
                    (QMOM "3" -> 3, CQMOM "2x2" -> (2, 2)); None: not in that study
    bench_scene     f(scene, order) -> the scene with that order (the throughput study)
    bench_quick, bench_full
                    the order texts (``bench_orders``) of the quick and the full throughput
                    study; () : not in it by default
    bench_ceiling   the throughput study's kernel-only sweep of its aggregation rates
                    (``bench.throughput.measure_ceiling``): "nodes" (pair rates of the
                    quadrature nodes), "points" (of the N1 N2 conditional points),
                    "contraction" (the Laguerre tensor contraction), None (no ceiling: NaN)
    bench_baseline  the order text of the study's reference row, which the plain NumPy/SciPy
                    baseline (``bench.numpy_baseline``) reimplements; None: not the baseline
    bench_breakdown how the study breaks its RHS into parts (``bench.breakdown``): "nodes"
                    (QMOM's Wheeler, binder solve, properties, pair rates), "contraction" (the
                    Laguerre positions and quadratic forms), None (no breakdown)
    bench_versus_baseline
                    True if the study reports its RHS rate against the baseline row
    distribution    how ``distribution.tables`` reconstructs the size distribution: "gamma"
                    (from the populations), "laguerre_density" (its own), "kernel_mixture"
                    (EQMOM's gamma kernels, ``distribution.kernel_mixture``), None (none)
    distribution_text   that reconstruction in words (columns.json, docs/physics.md 11.1)
    distributions   the reconstructions ``[method] size_distribution`` may name, the first
                    the default: "support" (gamma kernels on the granules' support [p_min,
                    inf), ``distribution.tables``), "semi-infinite" (on [0, inf): the
                    quadrature nodes' fit, EQMOM's own kernels), "expansion" (the Laguerre
                    ROM's own density); () : none to choose
    moments_text    how the moments it does not carry are reconstructed (columns.json)
    accuracy_knobs  f(quick) -> ((label, {options field: value}), ...): the settings of its
                    accuracy knob the accuracy study runs (``bench.accuracy``; quick: the
                    short study's); None: not in that study
    table_build     f(scene, pack, cell) -> seconds to build its tables (``aux``) from
                    scratch, without the disk cache (the accuracy study reports them apart);
                    pack(scene) -> its packed arrays, cell(scene) -> its well-mixed cell row;
                    None: no tables
    dries           True if it carries the drying drift of a [drying] table (docs/physics.md
                    section 15) and its evaporated-liquid entry
    solute_droplets True if its free droplets of their own may carry binder solids
                    ([binder_injection] solids_fraction > 0: liquid b_d < mass p_d)
    evaporates_droplets
                    True if its free droplets of their own evaporate with [drying] (their
                    liquid a state entry "droplet_liquid", docs/physics.md section 15)
    """
    name: str
    code: int
    scene_keys: Callable
    order_key: str | None
    order_label: str
    state_names: Callable
    aux: Callable
    tabulates_theta: bool
    population: Callable
    failure_hint: Callable
    diagnostics: Callable
    plan_line: Callable

    options: type | None = None
    populations: Callable | None = None
    repairs_mixture: Callable = lambda plan: False
    ensemble: Callable | None = None
    config_slots: Callable = lambda scene: {}
    initial_state: Callable | None = None
    columns: Callable | None = None
    table_bytes: Callable = lambda method: 0
    table_keys: tuple = ()
    rhs: Callable | None = None
    realizable: Callable | None = None
    project: Callable | None = None
    conserved: Callable | None = None
    on_closure: Callable | None = None
    work_size: Callable = lambda config: 0
    bench_orders: Callable | None = None
    bench_scene: Callable | None = None
    bench_quick: tuple = ()
    bench_full: tuple = ()
    bench_ceiling: str | None = None
    bench_baseline: str | None = None
    bench_breakdown: str | None = None
    bench_versus_baseline: bool = False
    distribution: str | None = None
    distribution_text: str = ""
    distributions: tuple = ()
    moments_text: str = ""
    accuracy_knobs: Callable | None = None
    closure_check: Callable | None = None
    table_build: Callable | None = None
    dries: bool = False
    solute_droplets: bool = True
    evaporates_droplets: bool = False
    output_check: Callable | None = None
    output_watch: Callable | None = None

    def order(self, method) -> int:
        """config[P.ORDER] of the scene's ``Method`` (its options' nodes, order; 0)."""
        return int(getattr(method.options, self.order_key)) if self.order_key else 0

    @property
    def options_class(self) -> type:
        """The dataclass of its ``[method]`` keys (``NoOptions`` if it declares none)."""
        return self.options or NoOptions

    @property
    def closure_test(self) -> Callable | None:
        """The test of a state on its closure (``on_closure``), or ``realizable`` where the
        method has none: what the repair after transport asks."""
        return self.on_closure if self.on_closure is not None else self.realizable

    @property
    def integrated(self) -> bool:
        """True if the per-cell integrator runs it (a moment method)."""
        return self.code != NOT_INTEGRATED


@dataclass(frozen=True)
class MethodPlan:
    """What a method's hooks called after the one pass (``runs.problem.problem_of``) read of
    the scene: ``columns``, ``failure_hint``, ``repairs_mixture``, ``ensemble``, and the
    generic output columns (``runs.model.moment_outputs``). Built by
    ``methods.registry.method_plan``.

    method          the method's registry entry
    options         its ``[method]`` options (the scene's ``method.options``)
    bivariate       True if the granules carry binder (the binder coordinate b)
    separate_droplets  True if free droplets are a population of their own
    density         granule material density [kg/m3] (mean diameters)
    initial         the scene's ``[initial]`` table (SI; a method with a run of its own
                    starts its particles from it)
    spray           the spray schedule's segments [(t0 [s], t1 [s], rate [droplets/(m3
                    s)])] (``scene.spray.segments``), empty without a schedule (a method
                    with a run of its own sprays cell[INJECTION] from t = 0 then)
    """
    method: "MethodEntry"
    options: object
    bivariate: bool
    separate_droplets: bool
    density: float
    initial: object = None
    spray: tuple = ()


@dataclass(frozen=True)
class NoOptions:
    """A method without ``[method]`` keys of its own."""


def no_keys(t, defaults):
    """Reads no ``[method]`` key of its own."""
    return {}


def no_aux(scene, arrays, theta_grid=None):
    """The ``aux`` of a method without method data: one unused float."""
    return np.zeros(1)


def no_hint(plan, arrays, state, aux):
    """No method-specific text for a stopped cell."""
    return ""


def no_diagnostics(states, aux, arrays):
    """No statistics and no warnings after a run."""
    return {}, []
