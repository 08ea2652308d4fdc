"""The bed's air: the fluidising air carries the evaporated water away (docs/physics.md
section 15, "The bed's air").

The dry-air mass flow G [kg/s] enters at humidity Y_in and leaves at the bed's humidity.
Every granule evaporates e = k f (Y_s(T_wb) - Y) (``physics.drying``): linear in the local
driving force, with the conductance k f [kg/s] of its gas film and drying curve. Summed over
the bed, E = K dY with the bed's conductance K = sum k f [kg/s]. The gas holds up a few
seconds of flow (bed height over superficial velocity), short against the drying, so its
vapour balance is quasi-steady, G (Y_out - Y_in) = E, and it cools along the adiabatic
saturation line, on which the wet-bulb temperature (so Y_s(T_wb)) is unchanged (Lewis
relation, air-water). Two limits of the gas's mixing:

* well-mixed gas (the bubbling bed's emulsion gas stirred by the bubbles): the bed's humidity
  is the outlet's, E = K (dY_in - E / G), so E = dY_in K G / (G + K);
* plug flow through granules that are themselves well mixed: dY/dz falls exponentially, so
  E = G dY_in (1 - exp(-K / G)).

Both give the isolated granule's rate for K << G and the air's capacity G dY_in (the air
leaves saturated at T_wb) for K >> G. Every granule then sees the bed's effective driving
force dY_eff = E / K (``effective_driving``), one number for the bed.
"""
import math

import numpy as np

from .drying import EPSILON, GAS_CONSTANT, MOLAR_MASS_AIR, humid_heat, latent_heat

#: mixing models of the bed's gas (``[drying] air_balance``)
MIXING = ("well-mixed", "plug-flow")


def dry_air_density(temperature, humidity, pressure):
    """Density of the dry air in moist air [kg dry air per m3] at temperature [K], humidity
    [kg water / kg dry air] and pressure [Pa]: the dry air's partial pressure P / (1 + Y /
    0.622) as an ideal gas."""
    partial = pressure / (1.0 + humidity / EPSILON)
    return partial * MOLAR_MASS_AIR / (GAS_CONSTANT * temperature)


def dry_air_flow(superficial_velocity, area, temperature, humidity, pressure):
    """Dry-air mass flow G [kg/s] of air at superficial velocity [m/s] through a bed of cross
    section area [m2], at temperature [K], humidity [kg/kg dry air], pressure [Pa]."""
    return superficial_velocity * area * dry_air_density(temperature, humidity, pressure)


def bed_evaporation(conductance, flow, inlet_driving, mixing):
    """Evaporation rate E [kg/s] of a bed of conductance K [kg/s per unit humidity
    difference] in the dry-air flow G [kg/s] whose inlet driving force is dY_in = Y_s(T_wb) -
    Y_in [kg/kg]; ``mixing`` one of ``MIXING`` (module docstring)."""
    if conductance <= 0.0 or inlet_driving <= 0.0:
        return 0.0
    if flow <= 0.0:
        return 0.0
    if mixing == "well-mixed":
        return inlet_driving * conductance * flow / (flow + conductance)
    if mixing == "plug-flow":
        return flow * inlet_driving * -math.expm1(-conductance / flow)
    raise ValueError(f"mixing: expected one of {MIXING}, got {mixing!r}")


def effective_driving(conductance, flow, inlet_driving, mixing):
    """The driving force dY_eff [kg/kg] every granule of the bed sees, E / K (the inlet's
    dY_in as K -> 0)."""
    if conductance <= 0.0:
        return inlet_driving
    return bed_evaporation(conductance, flow, inlet_driving, mixing) / conductance


def outlet_air(evaporation, flow, inlet_temperature, inlet_humidity, wet_bulb):
    """(humidity [kg/kg dry air], temperature [K]) of the air leaving a bed that evaporates E
    [kg/s] into the dry-air flow G [kg/s] entering at inlet_temperature [K] and
    inlet_humidity [kg/kg]: Y_out = Y_in + E / G, and the adiabatic cooling T_out = T_in -
    lambda(T_wb) (Y_out - Y_in) / c_s(Y_in) (the psychrometric balance of ``physics.drying``,
    which puts T_out = T_wb at the air's capacity)."""
    if flow <= 0.0:
        return inlet_humidity, inlet_temperature
    rise = evaporation / flow
    return (inlet_humidity + rise,
            inlet_temperature - latent_heat(wet_bulb) * rise / humid_heat(inlet_humidity))


def cell_humidity_rise(conductances, inlet_drivings, flow):
    """The well-mixed gas's humidity rise x = Y - Y_in [kg/kg] over cells that each have their
    own conductance K_c [kg/s] and inlet driving force dY_in,c = Y_s(T_wb,c) - Y_in [kg/kg]
    (the gas temperature per cell: each cell's air cools along its own adiabatic saturation
    line, so its wet bulb stays T_wb,c): the root of G x = sum_c K_c max(0, dY_in,c - x) for
    the dry-air flow G [kg/s] > 0. A cell with dY_in,c <= x does not dry (condensation is not
    modelled). Exact: with the cells sorted by dY_in,c falling, sum_c K_c max(0, dY_in,c - x)
    is the largest of its prefix sums sum_{c<=k} K_c (dY_in,c - x), so the root is the largest
    of the prefixes' roots x_k = sum_{c<=k} K_c dY_in,c / (G + sum_{c<=k} K_c), and 0."""
    k = np.asarray(conductances, dtype=float)
    d = np.asarray(inlet_drivings, dtype=float)
    keep = (k > 0.0) & (d > 0.0)
    if not keep.any():
        return 0.0
    k, d = k[keep], d[keep]
    order = np.argsort(-d, kind="stable")
    k, d = k[order], d[order]
    if not flow > 0.0:
        return float(d[0])
    roots = np.cumsum(k * d) / (flow + np.cumsum(k))
    return max(0.0, float(roots.max()))
