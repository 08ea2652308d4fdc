"""The CFD domain of a coupled run: the mesh cells, their fields and their initial states.

Reads the time-averaged fields of an OpenFOAM fluid bed (a bundled snapshot, a snapshot .vtu or
a case directory), builds one cell row per mesh cell (alpha [-], Theta [m2/s2], collision
velocity [m/s] from Theta, spray-zone injection [droplets/(m3 s)], and the drying's slip
velocity [m/s] and gas state where the scene takes them from the CFD), marks the cells that hold
granules (alpha >= alpha_min), sets the scales of the non-dimensional states and builds each
cell's initial state. All SI.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import model
from .cell_gas import fill_gas_rows
from ..physics import parameters as P
from ..physics.kernels import collision_velocity
from ..scene.scene import SceneError

BUNDLED_PREFIX = "bundled:"
#: alpha is kept this far (relative) below alpha_max so that g0 stays finite; cells moved are
#: counted in the summary.
PACKING_MARGIN = 1.0e-6


@dataclass
class Domain:
    """The mesh cells the population lives in (OpenFOAM cell order)."""
    cells: object                  # pbe_cfd.io.openfoam.CellData
    flux: object | None            # pbe_cfd.io.openfoam.FaceFlux or None
    description: str
    warnings: list = dataclasses.field(default_factory=list)   # one line each


def case_path(scene) -> Path | None:
    """The case or snapshot path of ``[domain] case`` (the scene loader made it absolute,
    relative to the scene file), or None for a bundled snapshot. Reading and writing (fields
    written back, --decompose) use this one path."""
    case = scene.domain.case
    if case.startswith(BUNDLED_PREFIX):
        return None
    path = Path(case)
    if not path.is_absolute() and scene.source:      # a Scene built in code
        path = Path(scene.source).resolve().parent / path
    return path


def is_case_directory(scene) -> bool:
    """True when ``[domain] case`` names an OpenFOAM case directory (not a snapshot)."""
    path = case_path(scene)
    return path is not None and path.is_dir()


def load_domain(scene, need_flux: bool = False) -> Domain:
    """Read the CFD fields named by ``[domain] case`` (a bundled snapshot, a snapshot .vtu, or
    an OpenFOAM case directory: plain, binary, compressed or decomposed, read through
    pbe-cfd's own readable copy); with ``need_flux`` also the solids face flux [m3/s]."""
    from ..io import openfoam as of

    case = scene.domain.case
    phase = scene.domain.phase
    flux, case_dir = None, None
    try:
        if case.startswith(BUNDLED_PREFIX):
            name = case[len(BUNDLED_PREFIX):]
            path = of.default_snapshot_path().with_name(name + ".vtu")
            if not path.is_file():
                raise SceneError(scene.source, "domain.case",
                                 f"no bundled snapshot {name!r} (expected bundled:fluid_bed_small)")
            loaded = of.load_snapshot(path, with_flux=need_flux)
            desc = f"bundled snapshot {path.name}"
        else:
            path = case_path(scene)
            if path.suffix == ".vtu" and path.is_file():
                loaded = of.load_snapshot(path, with_flux=need_flux)
                desc = f"snapshot {path}"
            elif path.is_dir():
                t = scene.domain.time
                cells = of.read_cell_fields(path, t, phase=phase)
                flux = (of.read_face_flux(path, cells.time, phase=phase) if need_flux
                        else None)
                loaded = (cells, flux) if need_flux else cells
                case_dir = path
                desc = f"OpenFOAM case {path / cells.source['time_dir']} (t = {cells.time:g} s)"
            else:
                raise SceneError(scene.source, "domain.case",
                                 f"{case!r}: no such OpenFOAM case directory or snapshot .vtu "
                                 "(relative paths are read from the scene file's directory; "
                                 "or bundled:fluid_bed_small)")
        if need_flux:
            cells, flux = loaded
        else:
            cells = loaded
        _check_input(scene, cells, flux, desc)
        warnings = list(cells.source.get("warnings", []))
        warnings += list(getattr(flux, "notes", None) or [])
        if case_dir is not None:
            warnings += _check_material(scene, case_dir)
    except of.OpenFOAMError as exc:
        raise SceneError(scene.source, "domain.case", str(exc)) from None
    return Domain(cells=cells, flux=flux, description=desc, warnings=warnings)


def _check_input(scene, cells, flux, desc: str):
    """Physical checks of the CFD input (``openfoam.validate``) and, for a snapshot, that
    ``[domain] time`` is the snapshot's own time."""
    from ..io.openfoam import validate
    src = cells.source
    where = desc if src.get("time_dir") else f"{desc} (t = {cells.time:g} s)"
    validate.check_cells(cells, where, scene.domain.alpha_max,
                         src.get("alpha_field", "alpha"), src.get("theta_field", "Theta"))
    if flux is not None:
        validate.check_flux(flux, cells.n_cells, where)
    t = scene.domain.time
    if t != "latest" and not src.get("time_dir"):       # a snapshot holds one time
        if not abs(float(t) - cells.time) <= 1e-6 * max(1.0, abs(cells.time)):
            raise SceneError(scene.source, "domain.time",
                             f"{t} s is not the time of {desc} (t = {cells.time:g} s); "
                             "drop it or set time = \"latest\"")
    if not np.any(np.asarray(cells.alpha) >= scene.domain.alpha_min):
        raise SceneError(scene.source, "domain.alpha_min",
                         f"no cell of {desc} has alpha >= alpha_min = "
                         f"{scene.domain.alpha_min:g} (max alpha "
                         f"{float(np.max(cells.alpha)):.3g}); lower alpha_min")


#: relative difference between the scene's and the case's particle density or diameter
#: beyond which the two describe different materials
MATERIAL_TOLERANCE = 0.01


def _check_material(scene, case: Path) -> list:
    """Compare the scene's particle density [kg/m3] and initial diameter [m] (of a granule of
    the initial mean mass) with the case's own (``openfoam.material``): beyond 1% an error
    naming both values and files, or with ``[domain] accept_material_mismatch`` a warning."""
    from ..io.openfoam.material import case_material
    rho_s = scene.material.density
    d_s = (6.0 * scene.initial.mean_mass / (np.pi * rho_s)) ** (1.0 / 3.0)
    own = case_material(case, scene.domain.phase)
    out = []
    for what, mine, key, unit in (("density", rho_s, "[material] density", "kg/m3"),
                                  ("diameter", d_s, "[initial] diameter", "m")):
        theirs, where = own[what]
        if theirs is None or abs(mine - theirs) <= MATERIAL_TOLERANCE * abs(theirs):
            continue
        text = (f"the scene's particle {what} {mine:.4g} {unit} ({key} of {scene.source}) "
                f"differs from the case's {theirs:.4g} {unit} ({where}) by more than "
                f"{100 * MATERIAL_TOLERANCE:g}%")
        if not scene.domain.accept_material_mismatch:
            raise SceneError(scene.source, "domain.case",
                             f"{text}; make them agree, or set [domain] "
                             "accept_material_mismatch = true to run with both")
        out.append(f"{text}; accepted ([domain] accept_material_mismatch = true)")
    return out


def spray_zone(scene, cells) -> np.ndarray:
    """Boolean mask of the spray-zone cells: alpha window and box of ``[binder_injection]
    zone`` (all cells when no zone is given)."""
    inj = scene.binder_injection
    n = cells.n_cells
    if inj is None:
        return np.zeros(n, dtype=bool)
    zone = inj.zone
    if zone is None:
        return np.ones(n, dtype=bool)
    centre = cells.cell_centre
    inside = np.all((centre >= np.array(zone.box_min)) & (centre <= np.array(zone.box_max)),
                    axis=1)
    window = (cells.alpha >= zone.alpha_low) & (cells.alpha <= zone.alpha_high)
    return inside & window


def spray_zone_volume(scene, cells) -> float:
    """Volume [m3] of the spray zone's cells that hold granules (alpha >= alpha_min)."""
    sprayed = spray_zone(scene, cells) & (np.asarray(cells.alpha) >= scene.domain.alpha_min)
    return float(np.sum(np.asarray(cells.cell_volume, dtype=float)[sprayed]))


def with_spray_per_volume(scene, cells):
    """The scene with its ``[binder_injection]`` rates in droplets/(m3 s) of spray-zone cell:
    a nozzle's mass flow [kg/s] (``rate_unit = "kg/s"``) spread evenly over the zone's cells
    of ``cells`` (``scene.spray.per_volume``); a scene without one unchanged. Raises
    SceneError when the zone holds no cell with granules."""
    from ..physics.injection import droplet_mass
    from ..scene import spray
    inj = scene.binder_injection
    if inj is None or inj.rate_unit != spray.MASS_FLOW:
        return scene
    try:
        converted = spray.per_volume(inj, spray_zone_volume(scene, cells),
                                     droplet_mass(inj.droplet_diameter,
                                                  scene.material.binder_density))
    except ValueError as exc:
        raise SceneError(scene.source, "binder_injection.rate", str(exc)) from None
    return dataclasses.replace(scene, binder_injection=converted)


def spray_zone_cut(zone, alpha_min: float, cells, active) -> str:
    """Which criterion of the spray zone ``zone`` (``[binder_injection] zone``: box_min,
    box_max [m], alpha_low, alpha_high [-]; None: no zone) removed the cells of its box: counts
    of the box's cells with alpha below alpha_low, above alpha_high, below alpha_min [-]."""
    if zone is None:
        return "no cell has alpha >= alpha_min"
    centre = cells.cell_centre
    box = np.all((centre >= np.array(zone.box_min)) & (centre <= np.array(zone.box_max)),
                 axis=1)
    if not box.any():
        return "no cell centre lies inside box_min..box_max"
    a = np.asarray(cells.alpha)[box]
    parts = [f"{int(np.count_nonzero(c))} with alpha {w}" for c, w in (
        (a < zone.alpha_low, f"< alpha_low = {zone.alpha_low:g}"),
        (a > zone.alpha_high, f"> alpha_high = {zone.alpha_high:g}"),
        (~np.asarray(active)[box], f"< alpha_min = {alpha_min:g}")) if c.any()]
    return (f"its box holds {int(box.sum())} cells (alpha {a.min():.3g}..{a.max():.3g}), "
            f"removed by the alpha window: {', '.join(parts)}")


def build_cells(scene, cells) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Cell rows (n, N_CELL) for every mesh cell (with the drying's gas from the CFD where the
    scene asks for it: ``cell_gas.fill_gas_rows``), the active mask (alpha >= alpha_min), the
    spray mask, and notes (cells whose alpha was kept below alpha_max)."""
    n = cells.n_cells
    rows = np.zeros((n, P.N_CELL))
    alpha = np.asarray(cells.alpha, dtype=float).copy()
    alpha_max = scene.domain.alpha_max
    cap = alpha_max * (1.0 - PACKING_MARGIN)
    capped = int(np.count_nonzero(alpha > cap))
    alpha = np.minimum(alpha, cap)
    theta = np.maximum(np.asarray(cells.theta, dtype=float), 0.0)
    rows[:, P.ALPHA] = alpha
    rows[:, P.THETA] = theta
    # the same formula in NumPy: no numba call (and its start-up) before the kernels load
    rows[:, P.COLLISION_VELOCITY] = collision_velocity.py_func(theta)
    active = np.asarray(cells.alpha) >= scene.domain.alpha_min
    spray = spray_zone(scene, cells) & active
    if scene.binder_injection is not None:     # droplets/(m3 s), a nozzle's flow converted
        rows[spray, P.INJECTION] = with_spray_per_volume(scene, cells).binder_injection.rate
    fill_gas_rows(scene, cells, rows)
    notes = {"cells_capped_below_alpha_max": capped}
    return rows, active, spray, notes


def cell_number_densities(scene, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Initial granule and free-droplet number densities per m3 of bed [1/m3] per cell.

    Granules fill the solids fraction: n = alpha rho_s / p0. Free droplets follow alpha too:
    ``initial.droplet_number_density`` is read per m3 of solids, n_d = alpha * value.
    """
    p0 = scene.initial.mean_mass
    granules = alpha * scene.material.density / p0
    droplets = alpha * scene.initial.droplet_number_density
    return granules, droplets


def initial_states(scene, arrays: model.Arrays, alpha: np.ndarray) -> np.ndarray:
    """Scaled initial states (n_cells, n_state): the scene's initial distribution with the
    number density of each cell (``cell_number_densities``). The state is linear in the
    granule and droplet densities, so it is built from two unit states."""
    granules, droplets = cell_number_densities(scene, alpha)

    def unit(n_granules, n_droplets):
        local = dataclasses.replace(
            scene, initial=dataclasses.replace(scene.initial, number_density=n_granules,
                                               droplet_number_density=n_droplets))
        return model.initial_moments(local, arrays, arrays.state_names)

    return granules[:, None] * unit(1.0, 0.0) + droplets[:, None] * unit(0.0, 1.0)


def coupled_scales(scene, alpha_active: np.ndarray, scales=None):
    """The scene with the number density set to the bed's largest cell value, so that the
    non-dimensional states of all cells are O(1) or below; ``scales``: given (granule,
    free-droplet) number densities [1/m3] instead (an earlier segment's)."""
    if scales is not None:
        n_max, nd_max = scales
        return dataclasses.replace(scene, initial=dataclasses.replace(
            scene.initial, number_density=n_max, droplet_number_density=nd_max))
    granules, droplets = cell_number_densities(scene, alpha_active)
    n_max = float(granules.max()) if granules.size else 1.0
    nd_max = float(droplets.max()) if droplets.size else 0.0
    return dataclasses.replace(scene, initial=dataclasses.replace(
        scene.initial, number_density=max(n_max, 1.0), droplet_number_density=nd_max))


def theta_grid(theta_active: np.ndarray, points: int = 24) -> np.ndarray:
    """Log-spaced granular temperatures [m2/s2] spanning the active cells' Theta, for methods
    whose auxiliary data is tabulated in Theta (``MethodEntry.tabulates_theta``)."""
    lo = max(float(theta_active.min()), 1e-12)
    return np.geomspace(lo, max(float(theta_active.max()), lo * 1.0001), points)
