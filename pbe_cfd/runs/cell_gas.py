"""The drying's gas per cell from the CFD (docs/physics.md section 15, "Per-cell inputs from
the CFD"): with ``[drying] slip_velocity_source = "cfd"`` each cell row's SLIP_VELOCITY is the
case's |U.<gas> - U.<solids>| [m/s] at the coupled time, with ``air_temperature_source = "cfd"``
its GAS_DRIVING, GAS_REYNOLDS, GAS_SCHMIDT are the gas state of the case's T.<gas> [K] at the
scene's humidity and pressure (``physics.drying.gas_state_cells``, once, vectorised over the
cells). The time-averaged ``...Mean`` fields are taken where the case wrote them (as alpha and
Theta), else the instantaneous ones. A field the case lacks is a SceneError naming it, the
case and the time (exit 2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics import parameters as P
from ..physics.drying import gas_state_cells
from ..scene.scene import SceneError

#: the gas temperatures [K] the per-cell gas state holds for (the [drying] air_temperature
#: key's range; the vapour diffusivity's correlation is fitted over 280..450 K)
TEMPERATURE_RANGE = (250.0, 450.0)


@dataclass(frozen=True)
class CellInput:
    """One per-cell drying input read from the case: the [drying] ``key`` that asks for it,
    ``what`` it is, the ``fields`` read, and its ``values`` per mesh cell (SI: m/s or K)."""
    key: str
    what: str
    fields: tuple
    values: np.ndarray


def from_cfd(scene) -> bool:
    """True if the scene's [drying] table takes an input per cell from the CFD."""
    dry = scene.drying
    return dry is not None and "cfd" in (dry.slip_velocity_source, dry.air_temperature_source)


def _where(cells) -> str:
    """The case (or snapshot) and time of ``cells``, for messages."""
    src = cells.source
    case = src.get("case") if src.get("time_dir") else src.get("file")
    return f"{case or src.get('file', '?')} at t = {cells.time:g} s"


def gas_phase(scene, cells) -> str | None:
    """The gas phase of the case: the case's phaseProperties' other phase (as
    ``rerun.fluidisation_inputs`` resolves it), else, for a snapshot, the one phase other than
    the solids (``[domain] phase``) whose velocity the snapshot holds."""
    solids = scene.domain.phase
    if cells.source.get("time_dir"):
        from ..io.openfoam import rerun
        gas = rerun.fluidisation_inputs(cells.source["case"], solids)["gas"]
        if gas is not None:
            return gas
    names = {k.split(".", 1)[1].removesuffix("Mean") for k in cells.flow if k.startswith("U.")}
    others = sorted(names - {solids})
    return others[0] if len(others) == 1 else None


def _field(scene, cells, base, phase, key, need) -> tuple[str, np.ndarray]:
    """(name, values) of ``<base>.<phase>Mean``, else ``<base>.<phase>``, of ``cells``; a
    SceneError on ``key`` naming the field, the case and the time where neither is there."""
    for name in (f"{base}.{phase}Mean", f"{base}.{phase}"):
        if name in cells.flow:
            values = np.asarray(cells.flow[name], dtype=float)
            if not np.all(np.isfinite(values)):
                raise SceneError(scene.source, key, f"field {name} of {_where(cells)} has "
                                                    "non-finite values")
            return name, values
    found = sorted(cells.flow) or "none"
    raise SceneError(scene.source, key,
                     f"{need}, but {_where(cells)} has no field {base}.{phase} (nor "
                     f"{base}.{phase}Mean; velocity/temperature fields found: {found}): "
                     f"expected a case time that holds it, or {key.split('.')[1]} = \"scene\"")


def cell_inputs(scene, cells) -> list[CellInput]:
    """The per-cell drying inputs the scene takes from ``cells`` (``CellData``): the slip
    velocity [m/s] and the gas temperature [K], those asked for; SceneError where the case
    lacks a field or (temperature) holds values outside ``TEMPERATURE_RANGE``."""
    if not from_cfd(scene):
        return []
    dry = scene.drying
    gas = gas_phase(scene, cells)
    solids = scene.domain.phase

    def gas_phase_for(key, need):
        if gas is None:
            raise SceneError(scene.source, key, f"{need}, but the gas phase of {_where(cells)} "
                                                "could not be resolved (no phaseProperties, "
                                                "and not one U.<phase> besides the solids')")
        return gas

    out = []
    if dry.slip_velocity_source == "cfd":
        key = "drying.slip_velocity_source"
        need = "slip_velocity_source = \"cfd\" reads the gas and solids velocities"
        g_name, u_gas = _field(scene, cells, "U", gas_phase_for(key, need), key, need)
        s_name, u_solids = _field(scene, cells, "U", solids, key, need)
        out.append(CellInput("slip_velocity_source", "slip velocity [m/s]", (g_name, s_name),
                             np.linalg.norm(u_gas - u_solids, axis=1)))
    if dry.air_temperature_source == "cfd":
        key = "drying.air_temperature_source"
        need = "air_temperature_source = \"cfd\" reads the gas temperature"
        name, temp = _field(scene, cells, "T", gas_phase_for(key, need), key, need)
        lo, hi = TEMPERATURE_RANGE
        if not (temp.min() >= lo and temp.max() <= hi):
            raise SceneError(scene.source, key,
                             f"field {name} of {_where(cells)} spans {temp.min():.4g}.."
                             f"{temp.max():.4g} K: expected {lo:g}..{hi:g} K")
        out.append(CellInput("air_temperature_source", "gas temperature [K]", (name,), temp))
    return out


def fill_gas_rows(scene, cells, rows: np.ndarray) -> list[CellInput]:
    """Write the per-cell drying inputs of ``cell_inputs`` into the cell rows (n, N_CELL)
    of every mesh cell, in place: SLIP_VELOCITY [m/s]; GAS_DRIVING [kg/(m s)], GAS_REYNOLDS
    [s/m2], GAS_SCHMIDT [-] of the gas temperature. Returns the inputs read."""
    inputs = cell_inputs(scene, cells)
    dry = scene.drying
    for item in inputs:
        if item.key == "slip_velocity_source":
            rows[:, P.SLIP_VELOCITY] = item.values
        else:
            driving, reynolds, schmidt = gas_state_cells(item.values, dry.air_humidity,
                                                         dry.pressure)
            rows[:, P.GAS_DRIVING] = driving
            rows[:, P.GAS_REYNOLDS] = reynolds
            rows[:, P.GAS_SCHMIDT] = schmidt
    return inputs


def source_lines(scene, cells, active) -> list[str]:
    """The plan's lines on where each per-cell drying input comes from: the scene's value, or
    the CFD's fields with their range over the ``active`` cells (mask)."""
    dry = scene.drying
    inputs = {item.key: item for item in cell_inputs(scene, cells)} if cells is not None \
        else {}
    out = []
    for what, scene_value, key in (
            ("slip velocity [m/s]", dry.slip_velocity, "slip_velocity_source"),
            ("gas temperature [K]", dry.air_temperature, "air_temperature_source")):
        item = inputs.get(key)
        if item is None:
            out.append(f"    {what}: the scene's {scene_value:g}, in every cell (per cell from "
                       f"the case with [drying] {key} = \"cfd\")")
            continue
        v = item.values[np.asarray(active, dtype=bool)]
        out.append(f"    {what}: per cell from the CFD ({' - '.join(item.fields)}, "
                   f"{_where(cells)}): {v.min():.4g}..{v.max():.4g} over the "
                   f"{v.size} active cells")
    return out
