"""Physical checks of CFD input at read time: every failure names the field, the time, the
number of bad cells and the first one (OpenFOAM cell index), as one line."""
from __future__ import annotations

import numpy as np

from .install import OpenFOAMError

#: relative overshoot of alpha above alpha_max accepted as the solver's packing round-off
PACKING_OVERSHOOT = 0.01


def _bad(where: str, field: str, mask: np.ndarray, values: np.ndarray, expected: str,
         item: str = "cell"):
    bad = np.flatnonzero(mask)
    if bad.size:
        first = int(bad[0])
        raise OpenFOAMError(f"{where}: {field} has {bad.size} {item}s {expected} (first: "
                            f"{item} {first}, value {values[first]:.6g})")


def check_cells(cells, where: str, alpha_max: float, alpha_field: str = "alpha",
                theta_field: str = "Theta"):
    """Refuse non-finite or out-of-range alpha [-] (outside [0, 1], or above alpha_max by more
    than PACKING_OVERSHOOT), non-finite or negative Theta [m2/s2] and non-finite or
    non-positive cell volumes [m3] of a CellData read at ``where`` (a time directory or
    snapshot, with its time)."""
    alpha = np.asarray(cells.alpha, dtype=float)
    theta = np.asarray(cells.theta, dtype=float)
    vol = np.asarray(cells.cell_volume, dtype=float)
    _bad(where, alpha_field, ~np.isfinite(alpha), alpha, "not finite")
    _bad(where, alpha_field, (alpha < 0) | (alpha > 1), alpha, "outside [0, 1]")
    # the solver holds alpha at packing only through g0's divergence, so a cell may overshoot
    # alpha_max slightly; those within PACKING_OVERSHOOT are kept just below it (and counted
    # in the summary), beyond it the field is not a packed bed's
    _bad(where, alpha_field, alpha > alpha_max * (1.0 + PACKING_OVERSHOOT), alpha,
         f"above alpha_max = {alpha_max:g} by more than {100 * PACKING_OVERSHOOT:g}% "
         "([domain] alpha_max)")
    _bad(where, theta_field, ~np.isfinite(theta), theta, "not finite")
    _bad(where, theta_field, theta < 0, theta, "negative")
    _bad(where, "the cell volume", ~np.isfinite(vol) | (vol <= 0), vol, "not positive")


def check_flux(flux, n_cells: int, where: str):
    """Refuse a face flux [m3/s] that does not fit the mesh of ``n_cells`` cells: another
    cell count, face lists of unequal length, a face naming a cell outside 0..n_cells-1, or
    non-finite values."""
    if flux.n_cells != n_cells:
        raise OpenFOAMError(f"{where}: the face flux's mesh has {flux.n_cells} cells, the "
                            f"cell fields' {n_cells}; they come from different meshes")
    for kind, arrays in (("internal", {"owner": flux.owner, "neighbour": flux.neighbour,
                                       "face flux": flux.flux}),
                         ("boundary", {"boundary face cell": flux.boundary_face_cell,
                                       "boundary face flux": flux.boundary_face_flux})):
        sizes = {name: int(np.size(arr)) for name, arr in arrays.items()}
        if len(set(sizes.values())) > 1:
            shown = ", ".join(f"{name} {n}" for name, n in sizes.items())
            raise OpenFOAMError(f"{where}: the {kind} faces' lists differ in length ({shown}); "
                                "expected one entry per face")
    for name, arr in (("face flux", flux.flux), ("boundary face flux", flux.boundary_face_flux)):
        arr = np.asarray(arr, dtype=float)
        _bad(where, name, ~np.isfinite(arr), arr, "not finite", item="face")
    for name, arr in (("owner", flux.owner), ("neighbour", flux.neighbour),
                      ("boundary face cell", flux.boundary_face_cell)):
        arr = np.asarray(arr, dtype=np.int64)
        _bad(where, f"the face flux's {name}", (arr < 0) | (arr >= n_cells), arr,
             f"naming a cell outside 0..{n_cells - 1} (the mesh has {n_cells} cells)",
             item="face")
