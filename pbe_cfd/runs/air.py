"""The bed's air balance of a run (docs/physics.md section 15, "The bed's air"; the physics in
``physics.air``): the fluidising air's flow, and the bed humidity the granules dry against.

Coupling and lag. The drying rate of every granule is linear in the driving force, which the
packed ``params[DRY_DRIVING]`` carries for every cell at once, so the bed couples its cells
through one number: the bed's conductance K = E / dY_eff [kg/s]. The per-cell integration runs
in pieces of at most ``air_interval``; each piece runs at the driving force dY_eff(K) of the
conductance measured over the piece before (the evaporated liquid it added, exact for that
piece's mean since the rate is linear in dY), and the first piece's K is probed on a copy of
the states over 1% of it. The lag is one piece: first order in the interval (measured in
docs/results/batch.md); a constant K (constant-rate drying of a fixed population) is exact.

With the CFD's gas temperature (``[drying] air_temperature_source = "cfd"``, well-mixed gas)
each cell has its own inlet driving force dY_in,c = Y_s(T_wb,c) - Y_in, and the cells couple
through the bed's humidity rise x (``physics.air.cell_humidity_rise``): each piece writes every
cell row's GAS_DRIVING = D_v,c rho_g,c max(0, dY_in,c - x) from the conductances K_c measured
per cell over the piece before (each cell's own evaporated liquid; a cell that did not dry
keeps its last one), and puts the rows back as they were after the call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..physics import air as air_physics
from ..physics import parameters as P
from ..physics.drying import gas_state
from ..scene.scene import SceneError

#: share of the first piece over which the bed's conductance is probed
PROBE_SHARE = 0.01


@dataclass
class BedAir:
    """The bed's air over a run: ``volumes`` [m3] each batch row stands for, dry-air ``flow``
    G [kg/s], ``inlet_driving`` dY_in = Y_s(T_wb) - Y_in [kg/kg], ``unit_driving`` D_v rho_g
    [kg/(m s)] (params[DRY_DRIVING] = unit_driving x dY), ``mixing`` (``physics.air.MIXING``),
    ``interval`` [s], the state entry of the evaporated liquid and its scale [kg/m3 per scaled
    unit]; the inlet air (temperature [K], humidity [kg/kg], wet bulb [K]) for the outlet's.
    ``pieces`` records (t_end [s], E [kg/s], dY_eff [kg/kg]) of every piece run."""
    volumes: np.ndarray
    flow: float
    inlet_driving: float
    unit_driving: float
    mixing: str
    interval: float
    evaporated_index: int
    scale: float
    inlet_temperature: float
    inlet_humidity: float
    wet_bulb: float
    conductance: float = math.nan
    pieces: list = field(default_factory=list)
    cell_unit: np.ndarray | None = None
    cell_inlet_driving: np.ndarray | None = None
    cell_temperature: np.ndarray | None = None
    cell_conductance: np.ndarray | None = None
    not_drying_noted: bool = False

    @property
    def per_cell(self) -> bool:
        """True if every cell has its own gas temperature (module docstring)."""
        return self.cell_inlet_driving is not None

    def evaporated(self, states) -> float:
        """Liquid evaporated so far in the whole bed [kg]."""
        return float(np.dot(self.volumes, states[:, self.evaporated_index]) * self.scale)

    def cell_evaporated(self, states) -> np.ndarray:
        """Liquid evaporated so far in each cell [kg]."""
        return self.volumes * states[:, self.evaporated_index] * self.scale

    def advance(self, batch, states, t0, t1, run):
        """Run ``run(states, a, b)`` (the batch's per-cell integration) over [t0, t1] [s] in
        pieces of at most ``interval``, each at the bed's driving force (module docstring)."""
        if self.per_cell:
            saved = batch.rows[:, P.GAS_DRIVING].copy()
            try:
                for a, b in self._pieces(t0, t1):
                    self._cell_piece(batch, states, a, b, run)
            finally:
                batch.rows[:, P.GAS_DRIVING] = saved
            return
        for a, b in self._pieces(t0, t1):
            if math.isnan(self.conductance):
                self._probe(batch, states, a, a + PROBE_SHARE * (b - a))
            driving = air_physics.effective_driving(self.conductance, self.flow,
                                                    self.inlet_driving, self.mixing)
            batch.params[P.DRY_DRIVING] = self.unit_driving * driving
            before = self.evaporated(states)
            run(states, a, b)
            rate = (self.evaporated(states) - before) / (b - a)
            self.conductance = rate / driving if driving > 0.0 else 0.0
            self.pieces.append((b, rate, driving))

    def _pieces(self, t0, t1):
        """[(a, b)] [s]: [t0, t1] in equal pieces of at most ``interval``."""
        n = max(1, math.ceil((t1 - t0) / self.interval * (1.0 - 1e-12)))
        return [(t0 + (t1 - t0) * k / n, t1 if k == n - 1 else t0 + (t1 - t0) * (k + 1) / n)
                for k in range(n)]

    def _probe(self, batch, states, a, b):
        """The bed's conductance at time a [s]: a copy of the states run at the inlet's
        driving force from a to b [s]."""
        batch.params[P.DRY_DRIVING] = self.unit_driving * self.inlet_driving
        trial = states.copy()
        before = self.evaporated(trial)
        batch.probe(trial, a, b)
        self.conductance = ((self.evaporated(trial) - before) / (b - a) / self.inlet_driving
                            if self.inlet_driving > 0.0 else 0.0)

    def _cell_piece(self, batch, states, a, b, run):
        """One piece [a, b] [s] with a gas temperature per cell (module docstring)."""
        if self.cell_conductance is None:
            self._probe_cells(batch, states, a, a + PROBE_SHARE * (b - a))
        rise = air_physics.cell_humidity_rise(self.cell_conductance, self.cell_inlet_driving,
                                              self.flow)
        driving = np.maximum(self.cell_inlet_driving - rise, 0.0)
        batch.rows[:, P.GAS_DRIVING] = self.cell_unit * driving
        before = self.cell_evaporated(states)
        run(states, a, b)
        rates = (self.cell_evaporated(states) - before) / (b - a)
        drying = driving > 0.0
        self.cell_conductance = np.where(drying, rates / np.where(drying, driving, 1.0),
                                         self.cell_conductance)
        conductance = float(self.cell_conductance[drying].sum())
        rate = float(rates.sum())
        self.conductance = float(self.cell_conductance.sum())
        self.pieces.append((b, rate, rate / conductance if conductance > 0.0 else 0.0))
        wet = self.cell_conductance > 0.0
        if not self.not_drying_noted and np.any(wet & ~drying):
            self.not_drying_noted = True
            cold = wet & ~drying
            temps = self.cell_temperature[cold]
            batch.notes.append(
                f"the bed's humidity (Y_in + {rise:.4g} kg/kg) reached the saturation at the "
                f"wet bulb of {int(cold.sum())} of {cold.size} cells (gas {temps.min():.5g}.."
                f"{temps.max():.5g} K from the CFD) at t = {a:.6g} s: those cells do not dry "
                "while it stays there (condensation is not modelled; docs/physics.md section "
                "15)")

    def _probe_cells(self, batch, states, a, b):
        """Each cell's conductance at time a [s]: a copy of the states run at each cell's
        inlet driving force from a to b [s]."""
        batch.rows[:, P.GAS_DRIVING] = self.cell_unit * self.cell_inlet_driving
        trial = states.copy()
        before = self.cell_evaporated(trial)
        batch.probe(trial, a, b)
        rates = (self.cell_evaporated(trial) - before) / (b - a)
        positive = self.cell_inlet_driving > 0.0
        self.cell_conductance = np.where(
            positive, rates / np.where(positive, self.cell_inlet_driving, 1.0), 0.0)

    def columns(self, times) -> dict:
        """Per output time [s]: the bed's evaporation rate [kg/s], the driving force its
        granules see [kg/kg], the outlet air's humidity [kg/kg dry air] and temperature [K]
        (of the piece that ended there; time 0: the first piece's). With a gas temperature
        per cell the driving force is the conductance-weighted mean over the cells that dry,
        and the outlet's temperature is not given (the CFD's energy equation has no
        evaporation, the balance no heat)."""
        ends = np.array([p[0] for p in self.pieces])
        names = ("evaporation_rate_kg_s", "air_driving_force", "outlet_humidity") + (
            () if self.per_cell else ("outlet_temperature_K",))
        out = {k: np.zeros(len(times)) for k in names}
        for r, t in enumerate(times):
            if not self.pieces:
                rate, driving = 0.0, self.inlet_driving
            else:
                k = int(np.searchsorted(ends, t - 1e-9 * max(t, 1.0)))
                _, rate, driving = self.pieces[min(k, len(self.pieces) - 1)]
            y, temp = air_physics.outlet_air(rate, self.flow, self.inlet_temperature,
                                             self.inlet_humidity, self.wet_bulb)
            out["evaporation_rate_kg_s"][r] = rate
            out["air_driving_force"][r] = driving
            out["outlet_humidity"][r] = y
            if not self.per_cell:
                out["outlet_temperature_K"][r] = temp
        return out


def air_flow(scene, area=None, inlet_velocity=None) -> float:
    """The dry-air mass flow G [kg/s] of the scene's [drying] table: ``air_mass_flow``, else
    the superficial velocity (the table's, else ``inlet_velocity`` [m/s], the case's gas
    inlet) times the cross section (``bed_area``, else ``area`` [m2], the domain's) times the
    inlet air's dry-air density."""
    dry = scene.drying
    if dry.air_mass_flow is not None:
        return dry.air_mass_flow
    velocity = dry.superficial_velocity if dry.superficial_velocity is not None \
        else inlet_velocity
    section = dry.bed_area if dry.bed_area is not None else area
    if velocity is None:
        raise SceneError(scene.source, "drying.superficial_velocity",
                         "the case's gas inlet velocity could not be read: expected "
                         "superficial_velocity (m/s) or air_mass_flow (kg/s)")
    if section is None:
        raise SceneError(scene.source, "drying.bed_area",
                         "expected the bed's cross section (m2) or air_mass_flow (kg/s)")
    return air_physics.dry_air_flow(velocity, section, dry.air_temperature, dry.air_humidity,
                                    dry.pressure)


@dataclass(frozen=True)
class AirPlan:
    """What the bed's air balance reads of the scene, computed once in the one pass
    (``air_plan``; SI): the ``BedAir`` fields that do not depend on the packed arrays, and
    the scene's ``source`` (messages)."""
    source: str
    volumes: np.ndarray
    flow: float
    inlet_driving: float
    unit_driving: float
    mixing: str
    interval: float
    inlet_temperature: float
    inlet_humidity: float
    wet_bulb: float
    cell_unit: np.ndarray | None = None
    cell_inlet_driving: np.ndarray | None = None
    cell_temperature: np.ndarray | None = None

    def bed_air(self, arrays) -> BedAir:
        """A fresh ``BedAir`` of a run packed into ``arrays`` (its evaporated-liquid entry
        and scale)."""
        return BedAir(volumes=self.volumes, flow=self.flow, inlet_driving=self.inlet_driving,
                      unit_driving=self.unit_driving, mixing=self.mixing,
                      interval=self.interval,
                      evaporated_index=arrays.state_names.index("evaporated_liquid"),
                      scale=arrays.number_scale * arrays.mass_scale,
                      inlet_temperature=self.inlet_temperature,
                      inlet_humidity=self.inlet_humidity, wet_bulb=self.wet_bulb,
                      cell_unit=self.cell_unit, cell_inlet_driving=self.cell_inlet_driving,
                      cell_temperature=self.cell_temperature)


def air_plan(scene, volumes, area=None, inlet_velocity=None) -> AirPlan | None:
    """The ``AirPlan`` of a scene whose [drying] table has an air balance (None without):
    ``volumes`` [m3] of the batch rows; ``area`` [m2] and ``inlet_velocity`` [m/s] of the
    domain where the table gives neither (``air_flow``)."""
    dry = scene.drying
    if dry is None or dry.air_balance == "none":
        return None
    rho, _, diffusivity, t_wb, driving = gas_state(dry.air_temperature, dry.air_humidity,
                                                   dry.pressure)
    return AirPlan(source=scene.source, volumes=np.asarray(volumes, dtype=float),
                   flow=air_flow(scene, area, inlet_velocity), inlet_driving=driving,
                   unit_driving=diffusivity * rho, mixing=dry.air_balance,
                   interval=dry.air_interval, inlet_temperature=dry.air_temperature,
                   inlet_humidity=dry.air_humidity, wet_bulb=t_wb)


def bed_air(scene, arrays, volumes, area=None, inlet_velocity=None) -> BedAir | None:
    """The ``BedAir`` of a scene whose [drying] table has an air balance (None without): see
    ``air_plan``."""
    plan = air_plan(scene, volumes, area, inlet_velocity)
    return None if plan is None else plan.bed_air(arrays)


def domain_section(cells) -> float:
    """Cross section [m2] of an OpenFOAM domain layered in y (the bundled case's gravity
    direction): its volume over its height, the height from the distinct cell-centre levels
    (exact for a mesh uniform in y)."""
    y = np.unique(np.round(np.asarray(cells.cell_centre, dtype=float)[:, 1], 12))
    if y.size < 2:
        raise ValueError("one layer of cells: expected [drying] bed_area")
    height = (y[-1] - y[0]) * y.size / (y.size - 1)
    return float(np.sum(cells.cell_volume)) / height


def coupled_air_plan(scene, cells, idx) -> AirPlan | None:
    """The ``AirPlan`` of a coupled run over the active cells ``idx`` of ``cells`` (None
    without an air balance): the cross section of the domain, the superficial velocity of the
    case's gas inlet (the template's for the bundled snapshot) where the table gives
    neither."""
    dry = scene.drying
    if dry is None or dry.air_balance == "none":
        return None
    velocity = None
    if dry.air_mass_flow is None and dry.superficial_velocity is None:
        velocity = case_inlet_velocity(scene)
    area = None
    if dry.air_mass_flow is None and dry.bed_area is None:
        area = domain_section(cells)
    volumes = np.asarray(cells.cell_volume, dtype=float)[idx]
    plan = air_plan(scene, volumes, area=area, inlet_velocity=velocity)
    if dry.air_temperature_source != "cfd":
        return plan
    from dataclasses import replace

    from ..physics.drying import gas_parts_cells
    from .cell_gas import cell_inputs
    temps = next(item.values for item in cell_inputs(scene, cells)
                 if item.key == "air_temperature_source")[idx]
    unit, driving, _, _ = gas_parts_cells(temps, dry.air_humidity, dry.pressure)
    return replace(plan, cell_unit=unit, cell_inlet_driving=driving, cell_temperature=temps)


def coupled_air(plan: AirPlan | None, arrays, executor=None) -> BedAir | None:
    """The ``BedAir`` of a coupled run of ``plan`` (``coupled_air_plan``; None: no air
    balance). The bed's humidity is one number updated between the per-cell integrations, so
    the cells must run in this process (``executor``: None or a ``SerialExecutor``)."""
    if plan is None:
        return None
    from .executor import SerialExecutor
    if executor is not None and not isinstance(executor, SerialExecutor):
        raise SceneError(plan.source, "drying.air_balance",
                         "the bed's air balance couples every cell between the per-cell "
                         "integrations: expected a run in this process (no --cluster), or "
                         "air_balance = \"none\"")
    return plan.bed_air(arrays)


def case_inlet_velocity(scene):
    """Superficial velocity [m/s] of the gas inlet of the scene's case (the case template's
    for the bundled snapshot), or None where it cannot be read."""
    from ..io import openfoam as of
    from ..io.openfoam import rerun
    from .domain import case_path
    case = case_path(scene)
    if case is None or not case.is_dir():
        case = of.default_case_dir()
    return rerun.fluidisation_inputs(case, scene.domain.phase)["inlet_velocity"]
