"""The method registry: what each method (QMOM, Laguerre ROM, cNMC) declares, in one place.

Every part of the program that depends on the method asks its entry here, never the method's
name: the scene parses ``[method]`` with the entry's ``scene_keys``, ``model.pack`` writes its
``code`` and ``order`` into ``config`` and names the state entries with ``state_names``, the runs
build its auxiliary data with ``aux``, turn a state into SI columns through ``population``,
explain a stopped cell with ``failure_hint``, report ``diagnostics`` after a run, and
``pbe-cfd plan`` prints its ``plan_line``.

Adding a method (for example a conditional QMOM): its numba ``rhs``/``realizable``/``project``
functions in a module of this package, one branch for its code in ``methods.dispatch`` (numba
needs a static call graph), and one ``MethodEntry`` in ``METHOD_REGISTRY`` below.

Entries take the scene and the packed arrays (``model.Arrays``: params, config, number and mass
scales, droplet mass, state names) as arguments; the units are those of ``model``: SI outside,
scaled moments in the state.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..physics import parameters as P
from .cqmom import cqmom
from .laguerre import tensor as laguerre_tensor
from .qmom import qmom
from .dispatch import CQMOM, EQMOM, LAGUERRE, QMOM
from .eqmom import entry as eqmom_entry

#: config[P.METHOD] of a method that the per-cell integrator does not run (the cNMC)
NOT_INTEGRATED = -1


class MethodEntry(NamedTuple):
    """One method of the registry (see the module docstring for who calls what).

    name            the scene's ``[method] name``
    code            config[P.METHOD]: its branch in ``methods.dispatch``; NOT_INTEGRATED for
                    a method with a run of its own (cNMC)
    scene_keys      f(table, defaults) -> dict of its ``scene.Method`` fields, read from the
                    ``[method]`` table by the scene's table reader (``t.number``,
                    ``t.boolean``, ...); defaults: the ``Method`` class (its field defaults)
    order_key       the ``Method`` field of its accuracy order (config[P.ORDER]): "nodes",
                    "order", or None (0)
    order_label     how studies name that order ("QMOM N")
    state_names     f(scene) -> names of the state entries ("M{i}{j}", then
                    "droplet_number_density")
    aux             f(scene, arrays, theta_grid) -> float array of method data (theta_grid
                    [m2/s2]: the cells' granular temperatures to tabulate over, or None)
    tabulates_theta True if a coupled run hands ``aux`` a grid of the cells' Theta
    population      f(state, aux, arrays) -> (w [1/m3], p [kg], b [kg]): the granules of one
                    scaled state as weighted particles (for SI columns and mean diameters)
    failure_hint    f(scene, arrays, state, aux) -> text appended to a stopped cell's message
    diagnostics     f(states, aux, arrays) -> (stats dict, warnings list) after a run
    plan_line       f(scene) -> the method's line of ``pbe-cfd plan``
    repairs_mixture f(scene) -> True if a mixture of realizable states (transport) may need
                    the method's projection before the next source step
    initial_state   f(scene, arrays, granule_moment) -> the scaled initial state, or None for
                    the generic one (state entries "M{i}{j}" and "droplet_number_density";
                    granule_moment(i, j) [kg^(i+j)/m3] of the initial granules)
    columns         f(scene, arrays, states, aux, populations) -> SI output columns, or None
                    for the generic ones (``model.moment_outputs``)
    ensemble        a method that is not integrated per cell: f(scene, arrays, cell, times
                    [s], progress) -> dict of result columns and statistics (cNMC:
                    ``cnmc.simulate_ensemble``)
    config_slots    f(scene) -> {config slot: value} of further knobs (CQMOM: BINDER_NODES)
    table_bytes     f(method) -> peak memory [bytes] its tables take to build (``aux``), from
                    the scene's ``Method``; table_keys the ``[method]`` keys that set it
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

    repairs_mixture: Callable = lambda scene: False
    ensemble: Callable | None = None
    config_slots: Callable = lambda scene: {}
    initial_state: Callable | None = None
    columns: Callable | None = None
    table_bytes: Callable = lambda method: 0
    table_keys: tuple = ()

    def order(self, method) -> int:
        """config[P.ORDER] of the scene's ``Method`` (nodes, order; 0)."""
        return int(getattr(method, self.order_key)) if self.order_key else 0

    @property
    def integrated(self) -> bool:
        """True if the per-cell integrator runs it (a moment method)."""
        return self.code != NOT_INTEGRATED


def _no_aux(scene, arrays, theta_grid=None):
    return np.zeros(1)


def _no_hint(scene, arrays, state, aux):
    return ""


def _no_diagnostics(states, aux, arrays):
    return {}, []


# ---------------------------------------------------------------------------- QMOM
def _qmom_keys(t, defaults):
    return {"nodes": t.number("nodes", 3, integer=True, low=1, high=5)}


def _qmom_state_names(scene):
    return qmom.state_names(scene.method.nodes, scene.bivariate, scene.separate_droplets)


def _qmom_population(state, aux, arrays):
    x, w, beta = qmom.quadrature_of(state, arrays.config)
    return w * arrays.number_scale, x * arrays.mass_scale, beta * arrays.mass_scale


def _qmom_plan(scene):
    m = scene.method
    return (f"QMOM with {m.nodes} nodes; state {', '.join(_qmom_state_names(scene))}"
            f"; rtol {m.rtol:g}")


# ---------------------------------------------------------------------------- Laguerre ROM
def laguerre_state_names(order, separate_droplets):
    """State entry names of the Laguerre ROM (wet moments, dry moments, free droplets)."""
    return laguerre_tensor.state_names(order, separate_droplets)


def _laguerre_keys(t, defaults):
    kw = {"order": t.number("order", 3, integer=True, low=2, high=5),
          "consistent": t.boolean("consistent", True)}
    for key, unit in (("weight_mean_mass", "kg"), ("weight_mean_binder", "kg"),
                      ("weight_shape_mass", ""), ("weight_shape_binder", ""),
                      ("support_mass", "kg"), ("support_binder", "kg")):
        kw[key] = t.number(key, getattr(defaults, key), positive=True, unit=unit)
    for key in ("grid_mass", "grid_binder"):
        kw[key] = t.number(key, getattr(defaults, key), integer=True, low=4, high=400)
    kw["grid_spacing"] = t.choice("grid_spacing", ("fraction", "uniform"), "fraction")
    kw.update(laguerre_tensor.scene_keys(t, defaults))
    return kw


def _laguerre_aux(scene, arrays, theta_grid=None):
    return laguerre_tensor.aux_for_scene(scene, arrays, theta_grid=theta_grid)


def _laguerre_hint(scene, arrays, state, aux):
    return laguerre_tensor.failure_hint(state, aux, arrays)


def _laguerre_diagnostics(states, aux, arrays):
    share, text = laguerre_tensor.escaped_share_report(states, aux, arrays)
    return {"escaped_mass_share": share}, ([text] if text else [])


def _laguerre_plan(scene):
    m = scene.method
    n_state = len(laguerre_state_names(m.order, scene.separate_droplets))
    return (f"Laguerre ROM of order {m.order} "
            f"({'moment-consistent' if m.consistent else 'plain projection'}"
            f"{', dry class' if m.dry_class else ''}"
            f"{', adaptive weights' if m.adaptive_weights else ''}), "
            f"support p <= {m.support_mass:g} kg, b <= {m.support_binder:g} kg, grid "
            f"{m.grid_mass} x {m.grid_binder}; {n_state} states")


# ---------------------------------------------------------------------------- cNMC
def _cnmc_keys(t, defaults):
    return {"particles": t.number("particles", 10000, integer=True, low=2, high=10_000_000),
            "replicas": t.number("replicas", 8, integer=True, low=1, high=100_000),
            "seed": t.number("seed", 1, integer=True, low=0)}


def _cnmc_plan(scene):
    m = scene.method
    return (f"constant-number Monte Carlo, {m.particles} particles x {m.replicas} replicas, "
            f"seed {m.seed}")


def _cnmc_ensemble(scene, arrays, cell, times, progress=None):
    import dataclasses

    from .cnmc import ensemble as cnmc
    m = scene.method
    initial = dataclasses.asdict(scene.initial)     # the keys simulate_ensemble reads
    return cnmc.simulate_ensemble(arrays.params, arrays.config, cell, initial, times,
                                  m.particles, m.replicas, m.seed, progress=progress)


def _cnmc_population(state, aux, arrays):
    raise TypeError("the cNMC carries particles, not a moment state")


# ---------------------------------------------------------------------------- CQMOM
def _cqmom_keys(t, defaults):
    return {"nodes": t.number("nodes", 2, integer=True, low=1, high=cqmom.MAX_SIZE_NODES),
            "binder_nodes": t.number("binder_nodes", 2, integer=True, low=1,
                                     high=cqmom.MAX_BINDER_NODES)}


def _cqmom_state_names(scene):
    m = scene.method
    return cqmom.state_names(m.nodes, m.binder_nodes, scene.bivariate, scene.separate_droplets)


def _cqmom_population(state, aux, arrays):
    x, w, b = cqmom.quadrature_of(state, arrays.config)
    return w * arrays.number_scale, x * arrays.mass_scale, b * arrays.mass_scale


def _cqmom_plan(scene):
    m = scene.method
    return (f"CQMOM with {m.nodes} size nodes x {m.binder_nodes} binder-fraction nodes; "
            f"state {', '.join(_cqmom_state_names(scene))}; rtol {m.rtol:g}")


# ---------------------------------------------------------------------------- the registry
METHOD_REGISTRY = (
    MethodEntry(name="qmom", code=QMOM, scene_keys=_qmom_keys,
                order_key="nodes", order_label="QMOM N", state_names=_qmom_state_names, aux=_no_aux,
                tabulates_theta=False, population=_qmom_population, failure_hint=_no_hint,
                diagnostics=_no_diagnostics, plan_line=_qmom_plan,
                repairs_mixture=lambda scene: scene.bivariate),
    MethodEntry(name="laguerre", code=LAGUERRE, scene_keys=_laguerre_keys,
                order_key="order", order_label="Laguerre m",
                state_names=lambda s: laguerre_state_names(s.method.order, s.separate_droplets),
                aux=_laguerre_aux, tabulates_theta=True,
                population=laguerre_tensor.population_for_output,
                failure_hint=_laguerre_hint, diagnostics=_laguerre_diagnostics,
                plan_line=_laguerre_plan, initial_state=laguerre_tensor.scene_initial_state,
                columns=laguerre_tensor.scene_columns,
                table_bytes=laguerre_tensor.table_bytes,
                table_keys=("grid_mass", "grid_binder", "dry_grid_mass")),
    MethodEntry(name="cnmc", code=NOT_INTEGRATED, scene_keys=_cnmc_keys,
                order_key=None, order_label="cNMC particles", state_names=lambda s: [], aux=_no_aux,
                tabulates_theta=False, population=_cnmc_population, failure_hint=_no_hint,
                diagnostics=_no_diagnostics, plan_line=_cnmc_plan, ensemble=_cnmc_ensemble),
    MethodEntry(name="cqmom", code=CQMOM, scene_keys=_cqmom_keys,
                order_key="nodes", order_label="CQMOM N1", state_names=_cqmom_state_names,
                aux=_no_aux, tabulates_theta=False, population=_cqmom_population,
                failure_hint=_no_hint, diagnostics=_no_diagnostics, plan_line=_cqmom_plan,
                repairs_mixture=lambda scene: scene.bivariate,
                config_slots=lambda scene: {P.BINDER_NODES: scene.method.binder_nodes}),
    MethodEntry(name="eqmom", code=EQMOM, scene_keys=eqmom_entry.scene_keys,
                order_key="nodes", order_label="EQMOM N", state_names=eqmom_entry.state_names,
                aux=eqmom_entry.aux, tabulates_theta=False, population=eqmom_entry.population,
                failure_hint=eqmom_entry.failure_hint, diagnostics=eqmom_entry.diagnostics,
                plan_line=eqmom_entry.plan_line, repairs_mixture=lambda scene: True),
)

#: name -> entry
METHODS = {m.name: m for m in METHOD_REGISTRY}
#: the names a scene accepts, in registry order
METHOD_NAMES = tuple(METHODS)
#: the methods the per-cell integrator runs (a coupled run needs one)
MOMENT_METHODS = tuple(m.name for m in METHOD_REGISTRY if m.integrated)


def method_of(scene) -> MethodEntry:
    """The registry entry of the scene's method."""
    return METHODS[scene.method.name]
