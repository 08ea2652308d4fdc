"""The bed's liquid and binder-solids inventory of a run with drying (docs/physics.md
section 15, "Inventory"): per output time, in kg over the whole bed,

    liquid:  sprayed = held by granules + held by free droplets + evaporated (+ initial)
    solids:  sprayed = held (the bed's dry mass less its start)

and the moisture content of the granules (their liquid over their dry mass). The sprayed
amounts are the schedule's integral (``scene.spray.injected``) times each spray cell's rate
and volume; the held ones are the states' moments, so the two sides are independent sums
and their difference is the run's conservation error.
"""
from __future__ import annotations

import numpy as np

from ..physics import parameters as P
from ..physics.injection import droplet_liquid
from ..scene import spray

#: inventory columns [kg] (and the moisture content [-]) of bed_moments.csv
COLUMNS = ("liquid_sprayed_kg", "liquid_granules_kg", "liquid_droplets_kg",
           "liquid_evaporated_kg", "solids_sprayed_kg", "solids_held_kg", "moisture_content")


def sprayed_droplets(inj, times, rows, volumes) -> np.ndarray:
    """Droplets sprayed into the bed from 0 to each time [s] [-]: the schedule's integral per
    m3 at the peak rate, times sum over cells of (cell rate / peak rate) x volume [m3];
    ``inj`` the scene's ``[binder_injection]`` table (None: none)."""
    if inj is None or inj.rate <= 0.0:
        return np.zeros(len(times))
    share = float(np.dot(rows[:, P.INJECTION], volumes)) / inj.rate
    return np.array([spray.injected(inj, float(t)) for t in times]) * share


def held_sums(cols, volumes) -> dict | None:
    """What one output time's SI cell columns (``model.moment_outputs``) hold over the bed,
    the inventory's input: {"dry": sum (M10 - M01) V, "liquid_granules", "liquid_droplets",
    "liquid_evaporated": sum of each column [kg/m3] times V [kg], "droplets": sum of the
    droplet number density [1/m3] times V (None without free droplets) [-]}; ``volumes``
    [m3] the cells'. None where the columns of a run with drying are absent. Computed per
    output time so that the columns need not be kept."""
    names = ("liquid_granules", "liquid_droplets", "liquid_evaporated")
    if not all(k in cols for k in ("M10", "M01") + names):
        return None
    v = volumes
    out = {"dry": float(np.dot(cols["M10"] - cols["M01"], v))}
    for name in names:
        out[name] = float(np.dot(cols[name], v))
    nd = cols.get("droplet_number_density")
    out["droplets"] = float(np.dot(nd, v)) if nd is not None else None
    return out


def inventory(injection, arrays, times, held, rows, volumes) -> dict:
    """The inventory columns (``COLUMNS``) per output time of a run with drying:
    ``injection`` the scene's ``[binder_injection]`` table (None: none; the problem's
    ``injection``), ``held`` the ``held_sums`` of each time, ``rows`` the cell rows (their
    injection), ``volumes`` [m3] the cells'."""
    n = len(times)
    out = {k: np.zeros(n) for k in COLUMNS}
    p_d = arrays.droplet_mass
    b_d = float(droplet_liquid(arrays.params))
    droplets = sprayed_droplets(injection, times, rows, volumes)
    out["liquid_sprayed_kg"][:] = droplets * b_d
    out["solids_sprayed_kg"][:] = droplets * (p_d - b_d)
    dry0 = None
    for k, sums in enumerate(held):
        dry = sums["dry"]
        dry0 = dry if dry0 is None else dry0
        out["solids_held_kg"][k] = dry - dry0
        for name in ("liquid_granules", "liquid_droplets", "liquid_evaporated"):
            out[f"{name}_kg"][k] = sums[name]
        droplet_solids = sums["droplets"] * (p_d - b_d) if sums["droplets"] is not None \
            else 0.0
        granule_dry = dry - droplet_solids
        out["moisture_content"][k] = (out["liquid_granules_kg"][k] / granule_dry
                                      if granule_dry > 0.0 else 0.0)
    return out
