"""The [drying] table of a scene (docs/physics.md section 15): the fluidising air and the
drying curve of the granules. Absent: nothing evaporates.

The bed's air balance (``air_balance``, ``physics.air``): "none" (every granule sees the inlet
air, as an isolated granule would), "well-mixed" or "plug-flow" (the dry-air flow carries the
evaporated water away and the granules see the bed's humidity). The flow is ``air_mass_flow``
[kg dry air / s], or ``superficial_velocity`` [m/s] times the bed's cross section (``bed_area``
[m2], by default an OpenFOAM domain's volume over its height) times the inlet air's dry-air
density; without either an OpenFOAM domain takes the superficial velocity of its case's gas
inlet. A well-mixed domain stands for ``bed_volume`` [m3] of bed.

Per cell from the CFD (an OpenFOAM domain): ``slip_velocity_source = "cfd"`` takes each cell's
slip velocity |U.<gas> - U.<solids>| [m/s] from the case's velocity fields at the coupled time
instead of the one ``slip_velocity``; ``air_temperature_source = "cfd"`` takes each cell's gas
temperature T.<gas> [K] for its gas state and driving force (the humidity and pressure stay
the scene's, ``air_temperature`` the inlet air's). Default "scene": the scene's values in
every cell.
"""
from dataclasses import dataclass

#: gas mixing of the bed's air balance; "none": the inlet air everywhere
AIR_BALANCES = ("none", "well-mixed", "plug-flow")
#: where a per-cell drying input comes from: the scene's one value, or the CFD's cell fields
INPUT_SOURCES = ("scene", "cfd")


@dataclass(frozen=True)
class Drying:
    """Drying of the liquid binder: air_temperature [K], air_humidity [kg water / kg dry air],
    pressure [Pa], slip_velocity [m/s] (gas-particle, for the Ranz-Marshall Sherwood number;
    None where slip_velocity_source is "cfd"), critical_moisture X_cr and equilibrium_moisture
    X_eq [kg liquid / kg dry solids]; slip_velocity_source and air_temperature_source, "scene"
    or "cfd" (per cell from the case's fields, module docstring); the
    bed's air balance (module docstring): air_balance, air_mass_flow [kg/s],
    superficial_velocity [m/s], bed_area [m2], bed_volume [m3] (None: not given), and
    air_interval [s], the longest time over which the bed's humidity is held (it is updated
    from the evaporation of the interval before)."""
    air_temperature: float
    air_humidity: float
    critical_moisture: float
    # required with slip_velocity_source = "scene"; none with "cfd" (each cell its own)
    slip_velocity: float | None = None
    # "cfd": each cell's |U.<gas> - U.<solids>| of the case at the coupled time
    slip_velocity_source: str = "scene"
    # "cfd": each cell's T.<gas> of the case for its gas state (air_temperature: the inlet's)
    air_temperature_source: str = "scene"
    pressure: float = 101325.0
    equilibrium_moisture: float = 0.0
    air_balance: str = "none"
    air_mass_flow: float | None = None
    superficial_velocity: float | None = None
    bed_area: float | None = None
    bed_volume: float | None = None
    air_interval: float = 0.25


def parse_drying(path, data, table, error):
    """The [drying] table ``data`` as a ``Drying``; ``table``, ``error``: the scene reader's
    ``_Table`` and ``SceneError``."""
    t = table(path, "drying", data)
    values = dict(
        air_temperature=t.number("air_temperature", positive=True, low=250.0, high=450.0,
                                 unit="K"),
        air_humidity=t.number("air_humidity", non_negative=True, high=0.5,
                              unit="kg water per kg dry air"),
        slip_velocity_source=t.choice("slip_velocity_source", INPUT_SOURCES, "scene"),
        air_temperature_source=t.choice("air_temperature_source", INPUT_SOURCES, "scene"),
        critical_moisture=t.number("critical_moisture", positive=True,
                                   unit="kg liquid per kg dry solids"),
        pressure=t.number("pressure", 101325.0, positive=True, unit="Pa"),
        equilibrium_moisture=t.number("equilibrium_moisture", 0.0, non_negative=True,
                                      unit="kg liquid per kg dry solids"),
        air_balance=t.choice("air_balance", AIR_BALANCES, "none"),
        air_mass_flow=t.number("air_mass_flow", None, positive=True, unit="kg dry air/s"),
        superficial_velocity=t.number("superficial_velocity", None, positive=True,
                                      unit="m/s"),
        bed_area=t.number("bed_area", None, positive=True, unit="m2"),
        bed_volume=t.number("bed_volume", None, positive=True, unit="m3"),
        air_interval=t.number("air_interval", 0.25, positive=True, unit="s"))
    from_cfd = values["slip_velocity_source"] == "cfd"
    if from_cfd and t.has("slip_velocity"):
        raise error(path, "drying.slip_velocity",
                    "slip_velocity_source = \"cfd\" takes each cell's slip velocity from the "
                    "case: expected no slip_velocity")
    values["slip_velocity"] = t.number("slip_velocity", None if from_cfd else ...,
                                       non_negative=True, unit="m/s")
    t.finish()
    if values["air_mass_flow"] is not None and values["superficial_velocity"] is not None:
        raise error(path, "drying.superficial_velocity",
                    "give either air_mass_flow or superficial_velocity (with bed_area), not "
                    "both")
    if not values["equilibrium_moisture"] < values["critical_moisture"]:
        raise error(path, "drying.equilibrium_moisture",
                    f"expected below critical_moisture ({values['critical_moisture']:g}), got "
                    f"{values['equilibrium_moisture']:g}")
    return Drying(**values)


def drying_refusals(scene, methods):
    """[(key, refusal)] of a scene's [drying] table: a liquid to dry, its density, a method
    that carries the drift (``methods``: the registered ``MethodEntry`` list, those with
    ``dries``), no pure-liquid droplets among the particles."""
    if scene.drying is None:
        return []
    dries = [m.name for m in methods if m.dries]
    if scene.method.name not in dries:
        return [("drying", f"drying runs in {', '.join(dries)}: expected method.name "
                           f"= {' or '.join(repr(n) for n in dries)}, got "
                           f"{scene.method.name!r}")]
    if not scene.bivariate or scene.material.binder_density is None:
        return [("drying", "nothing to dry: expected a liquid binder ([binder_injection] or "
                           "initial.binder_fraction > 0) and material.binder_density (kg/m3)")]
    air = _cfd_refusals(scene) or _air_refusals(scene)
    if air:
        return air
    entry = next(m for m in methods if m.name == scene.method.name)
    if scene.separate_droplets and not entry.evaporates_droplets:
        evaporate = [m.name for m in methods if m.evaporates_droplets]
        return [("aggregation.droplet_factor",
                 f"the {entry.name} method's free droplets do not evaporate: expected no "
                 f"droplet_factor with [drying], or method.name = "
                 f"{' or '.join(repr(n) for n in evaporate)}")]
    inj = scene.binder_injection
    if inj is not None and not scene.separate_droplets and inj.solids_fraction == 0.0:
        return [("binder_injection.solids_fraction",
                 "pure-liquid droplets among the particles would dry to particles of no mass: "
                 "expected solids_fraction > 0, or [aggregation] droplet_factor (droplets a "
                 "population of their own)")]
    return []


def _cfd_refusals(scene):
    """[(key, refusal)] of the per-cell inputs from the CFD: an OpenFOAM domain to read them
    from, and with the CFD's gas temperature a well-mixed bed air (the plug flow's gas rises
    through granules that see the height's average, not a cell's own temperature)."""
    dry = scene.drying
    keys = [k for k in ("slip_velocity_source", "air_temperature_source")
            if getattr(dry, k) == "cfd"]
    if not keys:
        return []
    if scene.domain.type == "well-mixed":
        return [(f"drying.{keys[0]}", "a well-mixed domain has no CFD fields: expected "
                                      "\"scene\", or an OpenFOAM domain")]
    if dry.air_temperature_source == "cfd" and dry.air_balance == "plug-flow":
        return [("drying.air_temperature_source",
                 "the plug-flow air balance's granules see the average over the bed's height, "
                 "not their cell's gas temperature: expected air_balance = \"well-mixed\" or "
                 "\"none\" with air_temperature_source = \"cfd\", or air_temperature_source "
                 "= \"scene\"")]
    return []


def _air_refusals(scene):
    """[(key, refusal)] of the bed's air balance: what fixes the air flow and the bed."""
    dry = scene.drying
    if dry.air_balance == "none":
        return []
    if scene.coupling is not None:
        return [("drying.air_balance", "the two-way coupling's segments run each at the inlet "
                                       "air: expected air_balance = \"none\" with [coupling]")]
    well_mixed = scene.domain.type == "well-mixed"
    if well_mixed and dry.bed_volume is None:
        return [("drying.bed_volume", f"air_balance = {dry.air_balance!r} in a well-mixed "
                                      "domain: expected the bed volume (m3) the cell stands for")]
    if not well_mixed and dry.bed_volume is not None:
        return [("drying.bed_volume", "an OpenFOAM domain's bed is its cells: expected no "
                                      "bed_volume")]
    if dry.air_mass_flow is None and well_mixed and (dry.superficial_velocity is None
                                                     or dry.bed_area is None):
        return [("drying.air_mass_flow", "a well-mixed domain has no gas inlet: expected "
                                         "air_mass_flow (kg/s), or superficial_velocity (m/s) "
                                         "with bed_area (m2)")]
    return []
