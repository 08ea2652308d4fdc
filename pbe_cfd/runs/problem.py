"""A scene becomes a run's arrays in one pass: ``problem_of(scene, domain)``.

One function takes the validated scene and its domain (None: the well-mixed cell) and returns
the packed problem (``Problem``): the method's registry entry, the packed ``params``/``config``
and scales (``model.Arrays``), the method's ``aux``, the rows of the integrated cells, their
initial scaled states, the output times, the tolerances and first step of the step control,
the spray schedule and table, and the small plans of what later code needs of the scene:

- ``OutputPlan`` (``output_plan``): what the written outputs read, with the method's hooks'
  ``methods.entry.MethodPlan`` (``model.moment_outputs``, ``MethodEntry.columns``,
  ``failure_hint``, ``ensemble``) and the size distribution's
  ``distribution.tables.DistributionPlan`` (reconstruction, labels);
- ``transport.operator.TransportSettings`` (the ``[transport]`` table; ``build_transport``);
- ``runs.air.AirPlan`` (the bed's air balance; ``coupled_air``, ``AirPlan.bed_air``).

What reads what: the runs (``simulate``, ``couple``), the cell batch (``CellBatch.for_problem``),
the transport, the air balance, the inventory and the coupled run's outputs read the problem
and its plans, never the scene; the scene's ``source`` rides along for messages. Only this
module and what it calls to pack (``model``, ``domain``, ``batch.check_physics``, the plans'
builders, the methods' ``aux``/``state_names``/``initial_state``) read the scene. The two-way
coupled run (``coupling``) makes this pass once per CFD segment (``coupling.segment_problem``:
the segment's CFD fields, then ``problem_of`` with segment 0's ``scales``, so every segment
integrates in the same scaled units) and otherwise reads its problems and its
``coupling.TwoWayPlan``, never the scene.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from . import model
from .air import AirPlan, air_plan, coupled_air_plan
from .batch import SimulationError, check_physics, output_times
from .domain import (build_cells, coupled_scales, initial_states, theta_grid,
                     with_spray_per_volume)
from ..distribution.tables import DistributionPlan, distribution_plan
from ..methods.entry import MethodEntry, MethodPlan
from ..methods.registry import method_of, method_plan
from ..physics import parameters as P
from ..scene import spray
from ..scene.scene import SceneError

__all__ = ["OutputPlan", "Problem", "output_plan", "problem_of"]

#: the first step of every cell, as a share of the output interval [-]
FIRST_STEP_SHARE = 1e-3


@dataclass(frozen=True)
class OutputPlan:
    """What a run's written outputs read of the scene (SI).

    title           the scene's name (pictures' titles)
    method_name     the scene's ``[method] name`` (summary.json)
    density         granule material density [kg/m3] (mean diameters)
    bivariate       True if the granules carry binder (binder columns)
    separate_droplets  True if free droplets are a population of their own (bed d32/d43)
    alpha_min       solids fraction below which a cell holds no granules [-] (renders)
    sprays          True if the scene has ``[binder_injection]`` (the empty-zone warning)
    spray_zone      its ``zone`` (box_min, box_max [m], alpha_low, alpha_high [-]; None: no
                    zone or no spray), which the empty-zone warning explains
    alpha_max       the packing limit [-] (the capped-cells warning)
    echo            the scene as plain data (summary.json, ``scene.describe``)
    source          the scene's file (messages)
    dries           True if the scene has ``[drying]`` (the liquid columns)
    method_plan     what the method's output hooks read (``methods.entry.MethodPlan``:
                    ``model.moment_outputs``, ``MethodEntry.columns``)
    distribution    the size distribution's plan (``distribution.tables.DistributionPlan``:
                    reconstruction, labels)
    cell_psd        ``[output] cell_psd``: mesh cell ids and points [m] whose own size
                    distribution is written (empty: none; ``distribution.cell_psd``)
    """
    title: str
    method_name: str
    density: float
    bivariate: bool
    separate_droplets: bool
    alpha_min: float
    alpha_max: float
    sprays: bool
    spray_zone: object
    echo: dict
    source: str
    dries: bool
    method_plan: MethodPlan
    distribution: DistributionPlan
    cell_psd: tuple = ()


def output_plan(scene) -> OutputPlan:
    """The output plan of a validated scene (densities in kg/m3)."""
    from ..scene.scene import describe
    return OutputPlan(title=scene.name, method_name=scene.method.name,
                      density=float(scene.material.density), bivariate=bool(scene.bivariate),
                      separate_droplets=bool(scene.separate_droplets),
                      alpha_min=float(scene.domain.alpha_min),
                      alpha_max=float(scene.domain.alpha_max),
                      sprays=scene.binder_injection is not None,
                      spray_zone=(scene.binder_injection.zone
                                  if scene.binder_injection is not None else None),
                      echo=describe(scene), source=scene.source,
                      dries=scene.drying is not None, method_plan=_method_plan(scene),
                      distribution=distribution_plan(scene),
                      cell_psd=scene.output.cell_psd if scene.output is not None else ())


def _method_plan(scene) -> MethodPlan:
    """``methods.registry.method_plan`` with the scene's spray schedule (its segments to the
    end time, ``scene.spray.segments``; empty without a schedule)."""
    plan = method_plan(scene)
    inj = scene.binder_injection
    if inj is None or not inj.schedule:
        return plan
    return dataclasses.replace(plan, spray=tuple(spray.segments(inj, scene.end_time)))


@dataclass(frozen=True)
class Problem:
    """The packed problem of one run (SI, except the scaled states).

    method          the method's registry entry
    arrays          params, config, number and mass scales, droplet mass, state names (for a
                    coupled run packed with the bed's scales, ``domain.coupled_scales``)
    aux             the method's data (None: a method with a run of its own, the cNMC)
    rows            (n, N_CELL) local fields of the integrated cells (SI)
    states          (n, n_state) their initial scaled states (None: not integrated)
    times           output times [s]
    rtol, atol      tolerances of the step control on the scaled state [-]
    first_step      every cell's first step [s]
    schedule        the spray schedule [(t0 [s], t1 [s], factor [-])] (``spray.factors``)
    cell_ids        the mesh cell of each row (None: the well-mixed cell)
    mesh_rows       (n_cells, N_CELL) rows of every mesh cell (coupled; None well-mixed)
    active, spray   (n_cells,) the cells holding granules and the sprayed cells (coupled)
    notes           what building the cell rows reported (``domain.build_cells``)
    scales          the number densities the states are scaled by (granules, free droplets)
                    [1/m3] (coupled; ``domain.coupled_scales``; None well-mixed)
    outputs         the output plan (``OutputPlan``; its ``method_plan`` the method's hooks')
    source          the scene's file (messages)
    end_time        the scene's end time [s] (progress fractions)
    injection       the scene's ``[binder_injection]`` table (None: none; the inventory)
    transport       the ``[transport]`` settings (``transport.operator.TransportSettings``;
                    None: no transport table)
    air             the bed's air balance (``runs.air.AirPlan``; None: no air balance)
    """
    method: MethodEntry
    arrays: model.Arrays
    aux: np.ndarray | None
    rows: np.ndarray
    states: np.ndarray | None
    times: np.ndarray
    rtol: float
    atol: float
    first_step: float
    schedule: list
    outputs: OutputPlan
    source: str
    end_time: float
    injection: object = None
    transport: object = None
    air: AirPlan | None = None
    cell_ids: np.ndarray | None = None
    mesh_rows: np.ndarray | None = None
    active: np.ndarray | None = None
    spray: np.ndarray | None = None
    notes: dict = field(default_factory=dict)
    scales: tuple | None = None

    @property
    def n_cells(self) -> int:
        """Number of integrated cells [-]."""
        return self.rows.shape[0]


def problem_of(scene, domain=None, scales=None) -> Problem:
    """The packed problem of a validated scene on ``domain`` (a ``runs.domain.Domain``; None:
    the well-mixed cell of the scene's ``[domain]``). ``scales``: the (granule, free-droplet)
    number densities [1/m3] the states are scaled by, an earlier problem's ``scales`` (a
    two-way run's later segments keep segment 0's); None: the bed's own (coupled runs). Raises SceneError for a method the
    per-cell integrator does not run on a domain or whose physics cannot run
    (``batch.check_physics``), SimulationError when no mesh cell holds granules (alpha >=
    alpha_min)."""
    check_physics(scene)
    method = method_of(scene)
    if domain is not None and not method.integrated:
        from ..methods import registry
        raise SceneError(scene.source, "method.name", "a coupled run needs a moment method: "
                         f"expected {' or '.join(registry.MOMENT_METHODS)}")
    if domain is not None:             # a nozzle's mass flow over this bed's spray zone
        scene = with_spray_per_volume(scene, domain.cells)
    times = output_times(scene)
    common = dict(method=method, times=times, rtol=scene.method.rtol,
                  atol=scene.method.atol,
                  first_step=scene.output_interval * FIRST_STEP_SHARE,
                  schedule=(spray.factors(scene.binder_injection, scene.end_time)
                            if scene.binder_injection is not None else []),
                  outputs=output_plan(scene), source=scene.source,
                  end_time=scene.end_time, injection=scene.binder_injection,
                  transport=_transport_settings(scene))
    if domain is None:
        arrays = model.pack(scene)
        rows = model.well_mixed_cell(scene)
        if not method.integrated:
            return Problem(arrays=arrays, aux=None, rows=rows, states=None, **common)
        aux = method.aux(scene, arrays, None)
        state = model.initial_moments(scene, arrays, arrays.state_names)
        air = (air_plan(scene, [scene.drying.bed_volume or 1.0])
               if scene.drying is not None else None)
        return Problem(arrays=arrays, aux=aux, rows=rows, states=state[None, :].copy(),
                       air=air, **common)
    cells = domain.cells
    mesh_rows, active, sprayed, notes = build_cells(scene, cells)
    idx = np.flatnonzero(active)
    if idx.size == 0:
        raise SimulationError(f"{scene.source}: no cell has alpha >= alpha_min = "
                              f"{scene.domain.alpha_min:g} (max alpha "
                              f"{float(np.max(cells.alpha)):.3g})")
    scaled_scene = coupled_scales(scene, mesh_rows[idx, P.ALPHA], scales)
    arrays = model.pack(scaled_scene)
    grid = theta_grid(mesh_rows[idx, P.THETA]) if method.tabulates_theta else None
    aux = method.aux(scaled_scene, arrays, grid)
    states = initial_states(scene, arrays, mesh_rows[idx, P.ALPHA])
    return Problem(arrays=arrays, aux=aux, rows=np.ascontiguousarray(mesh_rows[idx]),
                   states=states, cell_ids=idx, mesh_rows=mesh_rows, active=active,
                   spray=sprayed, notes=notes, air=coupled_air_plan(scene, cells, idx),
                   scales=(scaled_scene.initial.number_density,
                           scaled_scene.initial.droplet_number_density), **common)


def _transport_settings(scene):
    """The ``[transport]`` settings of the scene (None without the table)."""
    if scene.transport is None:
        return None
    from ..transport.operator import transport_settings
    return transport_settings(scene)
