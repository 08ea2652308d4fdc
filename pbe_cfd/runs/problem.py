"""A scene becomes a run's arrays in one pass: ``problem_of(scene, domain)``.

One function takes the validated scene and its domain (None: the well-mixed cell) and returns
the packed problem -- the method's registry entry, the packed ``params``/``config`` and scales
(``model.Arrays``), the method's ``aux``, the rows of the integrated cells, their initial
scaled states, the output times and the tolerances and first step of the step control. The
runs (``simulate``, ``couple``) and the cell batch read the problem, not the scene; the scene
rides along for the SI outputs and the messages (its ``source``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import model
from .batch import SimulationError, output_times
from .domain import build_cells, coupled_scales, initial_states, theta_grid
from ..methods.entry import MethodEntry
from ..methods.registry import method_of
from ..physics import parameters as P
from ..scene import spray

__all__ = ["Problem", "problem_of"]

#: the first step of every cell, as a share of the output interval [-]
FIRST_STEP_SHARE = 1e-3


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
    scene           the validated scene: SI outputs and messages only
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
    scene: object
    cell_ids: np.ndarray | None = None
    mesh_rows: np.ndarray | None = None
    active: np.ndarray | None = None
    spray: np.ndarray | None = None
    notes: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        """Number of integrated cells [-]."""
        return self.rows.shape[0]


def problem_of(scene, domain=None) -> Problem:
    """The packed problem of a validated scene on ``domain`` (a ``runs.domain.Domain``; None:
    the well-mixed cell of the scene's ``[domain]``). Raises SimulationError when no mesh
    cell holds granules (alpha >= alpha_min)."""
    method = method_of(scene)
    times = output_times(scene)
    common = dict(method=method, times=times, rtol=scene.method.rtol,
                  atol=scene.method.atol,
                  first_step=scene.output_interval * FIRST_STEP_SHARE,
                  schedule=(spray.factors(scene.binder_injection, scene.end_time)
                            if scene.binder_injection is not None else []), scene=scene)
    if domain is None:
        arrays = model.pack(scene)
        rows = model.well_mixed_cell(scene)
        if not method.integrated:
            return Problem(arrays=arrays, aux=None, rows=rows, states=None, **common)
        aux = method.aux(scene, arrays, None)
        state = model.initial_moments(scene, arrays, arrays.state_names)
        return Problem(arrays=arrays, aux=aux, rows=rows, states=state[None, :].copy(),
                       **common)
    cells = domain.cells
    mesh_rows, active, sprayed, notes = build_cells(scene, cells)
    idx = np.flatnonzero(active)
    if idx.size == 0:
        raise SimulationError(f"{scene.source}: no cell has alpha >= alpha_min = "
                              f"{scene.domain.alpha_min:g} (max alpha "
                              f"{float(np.max(cells.alpha)):.3g})")
    scaled_scene = coupled_scales(scene, mesh_rows[idx, P.ALPHA])
    arrays = model.pack(scaled_scene)
    grid = theta_grid(mesh_rows[idx, P.THETA]) if method.tabulates_theta else None
    aux = method.aux(scaled_scene, arrays, grid)
    states = initial_states(scene, arrays, mesh_rows[idx, P.ALPHA])
    return Problem(arrays=arrays, aux=aux, rows=np.ascontiguousarray(mesh_rows[idx]),
                   states=states, cell_ids=idx, mesh_rows=mesh_rows, active=active,
                   spray=sprayed, notes=notes, **common)
