"""The [drying] table of a scene (docs/physics.md section 15): the fluidising air and the
drying curve of the granules. Absent: nothing evaporates."""
from dataclasses import dataclass


@dataclass(frozen=True)
class Drying:
    """Drying of the liquid binder: air_temperature [K], air_humidity [kg water / kg dry air],
    pressure [Pa], slip_velocity [m/s] (gas-particle, for the Ranz-Marshall Sherwood number),
    critical_moisture X_cr and equilibrium_moisture X_eq [kg liquid / kg dry solids]."""
    air_temperature: float
    air_humidity: float
    slip_velocity: float
    critical_moisture: float
    pressure: float = 101325.0
    equilibrium_moisture: float = 0.0


def parse_drying(path, data, table, error):
    """The [drying] table ``data`` as a ``Drying``; ``table``, ``error``: the scene reader's
    ``_Table`` and ``SceneError``."""
    t = table(path, "drying", data)
    values = dict(
        air_temperature=t.number("air_temperature", positive=True, low=250.0, high=450.0,
                                 unit="K"),
        air_humidity=t.number("air_humidity", non_negative=True, high=0.5,
                              unit="kg water per kg dry air"),
        slip_velocity=t.number("slip_velocity", non_negative=True, unit="m/s"),
        critical_moisture=t.number("critical_moisture", positive=True,
                                   unit="kg liquid per kg dry solids"),
        pressure=t.number("pressure", 101325.0, positive=True, unit="Pa"),
        equilibrium_moisture=t.number("equilibrium_moisture", 0.0, non_negative=True,
                                      unit="kg liquid per kg dry solids"))
    t.finish()
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
    inj = scene.binder_injection
    if inj is not None and not scene.separate_droplets and inj.solids_fraction == 0.0:
        return [("binder_injection.solids_fraction",
                 "pure-liquid droplets among the particles would dry to particles of no mass: "
                 "expected solids_fraction > 0, or [aggregation] droplet_factor (droplets a "
                 "population of their own)")]
    return []
