"""From a scene to the arrays the numba physics and methods run on, and back to SI outputs.

The domain layer: it decides which effects are computed (only those whose table is present),
packs ``params``/``config``/``cell`` (``physics.parameters``) from the scene and the registries
(``physics.kernels``, ``physics.efficiency``, ``methods.registry``), builds the scaled initial
states, and turns scaled states back into the SI output columns of docs/physics.md section 11.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..integrate.codes import SCHEMES
from ..methods.entry import WORK_SIZE
from ..methods.registry import method_of
from ..physics import parameters as P
from ..physics.breakage import DAUGHTERS_BY_NAME, SELECTION_BY_NAME
from ..physics.drying import gas_state
from ..physics.efficiency import switch_on
from ..physics.injection import droplet_liquid, droplet_mass, droplet_moment
from ..physics.kernels import KERNEL_BY_NAME
from ..physics.kernels import collision_velocity as _collision_velocity
from ..util.population import (DERIVED, columns_from_particle_rows, columns_from_particles,
                               mean_diameters, mean_diameters_rows, moment_columns,
                               moment_orders)

__all__ = ["Arrays", "scales", "pack", "well_mixed_cell", "collision_velocity", "size_moment",
           "initial_moments", "product_gel_time", "moment_outputs", "droplet_mass"]


@dataclass
class Arrays:
    """Packed inputs of the numba layer for one scene."""
    params: np.ndarray
    config: np.ndarray
    number_scale: float      # N_ref [1/m3]
    mass_scale: float        # p_ref [kg]
    droplet_mass: float      # p_d [kg] (0 without injection)
    state_names: list = field(default_factory=list)


def scales(scene) -> tuple[float, float]:
    """Number-density and mass scales (N_ref [1/m3], p_ref [kg]) used to non-dimensionalise."""
    n_ref = scene.initial.number_density + scene.initial.droplet_number_density
    p_ref = scene.initial.mean_mass
    if n_ref <= 0.0:
        inj = scene.binder_injection
        n_ref = max(inj.rate * scene.end_time, 1.0) if inj is not None else 1.0
    return float(n_ref), float(p_ref)


def _material_params(scene, params):
    mat = scene.material
    params[P.DENSITY] = mat.density
    params[P.ALPHA_MAX] = scene.domain.alpha_max
    params[P.ALPHA_MIN_FRICTION] = scene.domain.alpha_min_friction or 0.0
    for slot, value in ((P.BINDER_DENSITY, mat.binder_density),
                        (P.BINDER_VISCOSITY, mat.binder_viscosity),
                        (P.GEO_SLOPE, mat.accessible_binder_slope),
                        (P.GEO_CENTRE, mat.accessible_binder_centre),
                        (P.PHI_SLOPE, mat.binder_layer_slope),
                        (P.PHI_CENTRE, mat.binder_layer_centre),
                        (P.ASPERITY, mat.asperity),
                        (P.GYRATION_RADIUS, mat.gyration_radius),
                        (P.POROSITY, mat.porosity),
                        (P.SATURATION_MAX, mat.saturation_max)):
        params[slot] = value if value is not None else 0.0
    params[P.STOKES_WIDTH] = mat.stokes_switch_width


def _breakage_params(scene, params, config):
    """Slots of the [breakage] table (physics.breakage); nothing without the table."""
    brk = scene.breakage
    if brk is None:
        return
    config[P.BREAKAGE] = 1
    config[P.BREAKAGE_SELECTION] = SELECTION_BY_NAME[brk.selection].code
    config[P.BREAKAGE_DAUGHTERS] = DAUGHTERS_BY_NAME[brk.daughters].code
    params[P.BREAKAGE_RATE] = brk.rate
    # the exponent a of S_unit = (p / p_ref)^a; 0 for a selection without one (constant),
    # whose S_unit is then that power too (the Laguerre dry rows weigh the gamma by p^a)
    params[P.BREAKAGE_EXPONENT] = (brk.exponent if "exponent" in
                                   SELECTION_BY_NAME[brk.selection].keys else 0.0)
    params[P.BREAKAGE_REFERENCE_MASS] = (brk.reference_mass if brk.reference_mass is not None
                                         else scene.initial.mean_mass)
    params[P.BREAKAGE_REFERENCE_THETA] = brk.reference_granular_temperature or 0.0
    params[P.YIELD_STRENGTH] = brk.yield_strength or 0.0
    params[P.CRITICAL_DEFORMATION] = brk.critical_deformation_number or 0.0


def _drying_params(scene, params, config):
    """Slots of the [drying] table (physics.drying): the air's state once, the drying curve;
    the switches that make the kernels read the slip velocity or the gas state from the cell
    rows (filled from the CFD: ``runs.cell_gas``)."""
    dry = scene.drying
    if dry is None:
        return
    config[P.DRYING] = 1
    rho, mu, diffusivity, _, driving = gas_state(dry.air_temperature, dry.air_humidity,
                                                 dry.pressure)
    params[P.DRY_DRIVING] = diffusivity * rho * driving
    params[P.DRY_RE] = rho / mu
    params[P.DRY_SCHMIDT] = mu / (rho * diffusivity)
    params[P.DRY_CRITICAL] = dry.critical_moisture
    params[P.DRY_EQUILIBRIUM] = dry.equilibrium_moisture
    params[P.DRY_SLIP] = dry.slip_velocity if dry.slip_velocity is not None else 0.0
    config[P.DRYING_CELL_SLIP] = int(dry.slip_velocity_source == "cfd")
    config[P.DRYING_CELL_AIR] = int(dry.air_temperature_source == "cfd")


def pack(scene) -> Arrays:
    """Pack the scene into the params/config arrays (see ``physics.parameters``)."""
    params = np.zeros(P.N_PARAMS)
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    _material_params(scene, params)
    agg = scene.aggregation
    if agg is not None:
        params[P.RATE] = agg.rate
        config[P.KERNEL] = KERNEL_BY_NAME[agg.kernel].code
        switch_on(config, agg.efficiency)
        ref_d = agg.reference_diameter
        if ref_d is not None:
            params[P.REFERENCE_VOLUME] = math.pi / 6.0 * ref_d ** 3
        else:
            params[P.REFERENCE_VOLUME] = scene.initial.mean_mass / scene.material.density
    else:
        params[P.RATE] = 0.0       # no aggregation table: the kernel is never evaluated
    pd = 0.0
    if scene.binder_injection is not None:
        pd = droplet_mass(scene.binder_injection.droplet_diameter, scene.material.binder_density)
        params[P.DROPLET_SOLIDS] = scene.binder_injection.solids_fraction
    params[P.DROPLET_MASS] = pd
    config[P.SEPARATE_DROPLETS] = int(scene.separate_droplets)
    params[P.DROPLET_FACTOR] = agg.droplet_factor if scene.separate_droplets else 0.0
    config[P.BIVARIATE] = int(scene.bivariate)
    n_ref, p_ref = scales(scene)
    params[P.NUMBER_SCALE] = n_ref
    params[P.MASS_SCALE] = p_ref
    params[P.STEP_FLOOR] = 1.0e-12 * scene.end_time
    _breakage_params(scene, params, config)
    _drying_params(scene, params, config)
    method = method_of(scene)
    config[P.METHOD] = method.code
    config[P.ORDER] = method.order(scene.method)
    for slot, value in method.config_slots(scene).items():
        config[slot] = value
    names = method.state_names(scene)
    config[P.N_STATE] = len(names)
    if "droplet_liquid" in names:       # entry N_STATE - 3 (``injection.droplet_liquid_entry``)
        config[P.DROPLET_LIQUID] = 1
        assert names.index("droplet_liquid") == len(names) - 3, names
    config[P.INTEGRATOR] = SCHEMES[scene.method.integrator]
    need = int(method.work_size(config))
    if need > WORK_SIZE:
        raise ValueError(f"the {method.name} method needs {need} work floats per cell, more "
                         f"than the {WORK_SIZE} of methods.entry.WORK_SIZE")
    return Arrays(params=params, config=config, number_scale=n_ref, mass_scale=p_ref,
                  droplet_mass=pd, state_names=names)


def well_mixed_cell(scene) -> np.ndarray:
    """The single cell row (alpha, theta, u0, injection) of a well-mixed scene (SI)."""
    cell = np.zeros((1, P.N_CELL))
    dom = scene.domain
    cell[0, P.ALPHA] = dom.solids_fraction or 0.0
    cell[0, P.THETA] = dom.granular_temperature or 0.0
    cell[0, P.COLLISION_VELOCITY] = collision_velocity(dom.collision_velocity,
                                                       cell[0, P.THETA])
    if scene.binder_injection is not None:
        cell[0, P.INJECTION] = scene.binder_injection.rate
    return cell


def collision_velocity(given, theta):
    """Collision velocity [m/s]: the scene's value, else 4 sqrt(theta / pi) from theta [m2/s2]."""
    if given is not None:
        return float(given)
    return float(_collision_velocity(float(theta)))


def size_moment(scene, k: int, j: int = 0) -> float:
    """Initial granule moment M_kj [kg^(k+j)/m3] (free droplets excluded)."""
    init = scene.initial
    n0, p0, y0 = init.number_density, init.mean_mass, init.binder_fraction
    if init.distribution == "monodisperse":
        return n0 * p0 ** k * (y0 * p0) ** j
    # exponential in p, every granule with the same binder fraction y0: b = y0 p
    return n0 * p0 ** (k + j) * math.factorial(k + j) * y0 ** j


def initial_moments(scene, arrays: Arrays, names) -> np.ndarray:
    """Scaled initial state for moment methods whose state entries are named ``names`` (a
    method's own ``initial_state`` in the registry takes precedence)."""
    own = method_of(scene).initial_state
    if own is not None:
        return own(scene, arrays, lambda i, j: size_moment(scene, i, j))
    state = np.zeros(len(names))
    nd0 = scene.initial.droplet_number_density
    pd = arrays.droplet_mass
    for idx, name in enumerate(names):
        if name == "droplet_number_density":
            state[idx] = nd0 / arrays.number_scale
            continue
        if name == "evaporated_liquid":          # nothing has evaporated at the start
            continue
        if name == "droplet_liquid":             # the initial droplets hold b_d each
            state[idx] = nd0 * droplet_liquid(arrays.params) / (arrays.number_scale
                                                                 * arrays.mass_scale)
            continue
        i, j = moment_orders(name)
        value = size_moment(scene, i, j)
        if not scene.separate_droplets and nd0 > 0.0:
            value += nd0 * droplet_moment(pd, droplet_liquid(arrays.params), i, j)
        state[idx] = value / (arrays.number_scale * arrays.mass_scale ** (i + j))
    return state


def product_gel_time(scene) -> float | None:
    """Gel time [s] of the product kernel from the initial M20 (1/(k0 M20(0))), else None."""
    agg = scene.aggregation
    if agg is None or agg.kernel != "product":
        return None
    m20 = size_moment(scene, 2)
    if m20 <= 0.0:
        return None
    return 1.0 / (agg.rate * m20)


def _population_rows(method, states, aux, arrays):
    """Every row's weighted particles (w [1/m3], p [kg], b [kg]) as a list of tuples, and as
    (w, p, b) arrays (rows, particles) where all rows have one count of particles (else
    None); from the method's ``populations`` in one pass where it has one."""
    n_rows = states.shape[0]
    if n_rows == 0:
        return [], None
    if method.populations is None:
        rows = [method.population(states[r], aux, arrays) for r in range(n_rows)]
        if len({len(w) for w, _, _ in rows}) > 1:
            return rows, None
        return rows, tuple(np.array([r[k] for r in rows], dtype=float) for k in range(3))
    w, p, b, counts = method.populations(states, aux, arrays)
    rows = [(w[r, :c], p[r, :c], b[r, :c]) for r, c in enumerate(counts.tolist())]
    if np.all(counts == w.shape[1]):
        return rows, (w, p, b)
    if np.all(counts == counts[0]):
        c = int(counts[0])
        return rows, (w[:, :c].copy(), p[:, :c].copy(), b[:, :c].copy())
    return rows, None


def _outputs_by_row(out, rows, states, names, cols, nd, pd, bd, n_ref, p_ref, rho):
    """``moment_outputs``'s moments, d32 and d43 row by row (populations of different
    sizes): see there; pd, bd [kg] one droplet's mass and liquid, per row."""
    for r, (w, p, b) in enumerate(rows):
        state = states[r]
        estimated = columns_from_particles(w, p, b, cols)
        for c in cols:
            i, j = moment_orders(c)
            value = (state[names.index(c)] * n_ref * p_ref ** (i + j) if c in names
                     else estimated[c])
            out[c][r] = value + nd[r] * droplet_moment(pd[r], bd[r], i, j)
        ww = np.append(w, nd[r]) if nd[r] > 0 else w
        pp = np.append(p, pd[r]) if nd[r] > 0 else p
        out["d32_m"][r], out["d43_m"][r] = mean_diameters(ww, pp, rho)


def droplet_points(arrays: Arrays, states: np.ndarray, nd: np.ndarray):
    """(mass [kg], liquid [kg]) of one free droplet in each row of scaled ``states`` (nd
    [1/m3] the rows' droplets): (p_d, b_d), or with a "droplet_liquid" entry (drying) the
    class's mean liquid l = L_d / n_d and the mass s p_d + l (b_d where there are none)."""
    pd = arrays.droplet_mass
    bd = float(droplet_liquid(arrays.params))
    n_rows = states.shape[0]
    if "droplet_liquid" not in arrays.state_names:
        return np.full(n_rows, pd), np.full(n_rows, bd)
    held = states[:, arrays.state_names.index("droplet_liquid")] * (arrays.number_scale
                                                                    * arrays.mass_scale)
    liquid = np.where(nd > 0, np.maximum(held, 0.0) / np.where(nd > 0, nd, 1.0), bd)
    return (pd - bd) + liquid, liquid


def _liquid_columns(out, evaporated, in_droplets):
    """The liquid inventory [kg/m3] and the moisture content [-] of a run with drying:
    evaporated, held by free droplets, held by granules (M01 less the droplets'), and
    liquid over dry mass M01 / (M10 - M01) (docs/physics.md section 15)."""
    out["liquid_evaporated"] = evaporated
    out["liquid_droplets"] = in_droplets
    out["liquid_granules"] = out["M01"] - in_droplets
    dry = out["M10"] - out["M01"]
    out["moisture_content"] = np.where(dry > 0, out["M01"] / np.where(dry > 0, dry, 1.0), 0.0)


def moment_outputs(plan, arrays: Arrays, states: np.ndarray, aux,
                   populations: list | None = None) -> dict:
    """SI output columns (moments, droplets, d32, d43, binder fraction) of scaled states
    (one row per time or per cell); ``plan`` the run's ``methods.entry.MethodPlan``
    (``methods.registry.method_plan``). If a list is passed as ``populations``, each row's
    weighted particles (w [1/m3], p [kg], b [kg], from the method's ``population``) are
    appended to it. A method's own ``columns`` in the registry takes precedence."""
    own = plan.method.columns
    if own is not None:
        return own(plan, arrays, states, aux, populations)
    names = arrays.state_names
    bivariate = plan.bivariate
    cols = moment_columns(names, bivariate)
    separate = plan.separate_droplets
    n_rows = states.shape[0]
    out = {c: np.zeros(n_rows) for c in cols}
    if separate:
        out["droplet_number_density"] = np.zeros(n_rows)
    for c in DERIVED:
        out[c] = np.zeros(n_rows)
    pd = arrays.droplet_mass
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    rho = plan.density
    rows, padded = _population_rows(plan.method, states, aux, arrays)
    if populations is not None:
        populations.extend(rows)
    if n_rows == 0:
        return out
    nd = states[:, -1] * n_ref if separate else np.zeros(n_rows)
    pd_rows, bd_rows = droplet_points(arrays, states, nd)
    if padded is None:                               # populations of different sizes
        _outputs_by_row(out, rows, states, names, cols, nd, pd_rows, bd_rows, n_ref, p_ref, rho)
    else:                                            # one (rows, particles) array each
        w_all, p_all, b_all = padded
        estimated = columns_from_particle_rows(w_all, p_all, b_all,
                                               [c for c in cols if c not in names])
        for c in cols:
            i, j = moment_orders(c)
            value = (states[:, names.index(c)] * n_ref * p_ref ** (i + j) if c in names
                     else estimated[c])
            out[c][:] = value + nd * (droplet_moment(pd, droplet_liquid(arrays.params), i, j)
                                      if "droplet_liquid" not in names
                                      else pd_rows ** i * bd_rows ** j)
        with_droplets = nd > 0
        for sel in (with_droplets, ~with_droplets):
            if not np.any(sel):
                continue
            ww, pp = w_all[sel], p_all[sel]
            if sel is with_droplets:
                ww = np.hstack([ww, nd[sel, None]])
                pp = np.hstack([pp, pd_rows[sel, None]])
            out["d32_m"][sel], out["d43_m"][sel] = mean_diameters_rows(ww, pp, rho)
    if separate:
        out["droplet_number_density"][:] = nd
    if "evaporated_liquid" in names:
        _liquid_columns(out, states[:, names.index("evaporated_liquid")] * n_ref * p_ref,
                        nd * bd_rows)
    m10 = out["M10"]
    out["binder_fraction"][:] = (np.where(m10 > 0, out["M01"] / np.where(m10 > 0, m10, 1.0),
                                          0.0) if bivariate else 0.0)
    return out
