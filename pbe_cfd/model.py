"""From a scene to the arrays the numba physics and methods run on, and back to SI outputs.

This is orchestration: it decides which effects are computed (only those whose table is
present), packs ``params``/``config``/``cell`` (``physics.parameters``), builds each method's
initial state and auxiliary data, and turns states into the SI output columns of DESIGN
section 4.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .physics import parameters as P
from .physics.injection import droplet_mass
from .physics.kernels import KERNELS
from .scene import Scene

MOMENT_METHODS = ("qmom", "laguerre")


@dataclass
class Arrays:
    """Packed inputs of the numba layer for one scene."""
    params: np.ndarray
    config: np.ndarray
    number_scale: float      # N_ref [1/m3]
    mass_scale: float        # p_ref [kg]
    droplet_mass: float      # p_d [kg] (0 without injection)
    state_names: list = field(default_factory=list)


def scales(scene: Scene) -> tuple[float, float]:
    """Number-density and mass scales (N_ref [1/m3], p_ref [kg]) used to non-dimensionalise."""
    n_ref = scene.initial.number_density + scene.initial.droplet_number_density
    p_ref = scene.initial.mean_mass
    if n_ref <= 0.0:
        inj = scene.binder_injection
        n_ref = max(inj.rate * scene.end_time, 1.0) if inj is not None else 1.0
    return float(n_ref), float(p_ref)


def pack(scene: Scene) -> Arrays:
    """Pack the scene into the params/config arrays (see ``physics.parameters``)."""
    params = np.zeros(P.N_PARAMS)
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
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
    agg = scene.aggregation
    if agg is not None:
        params[P.RATE] = agg.rate
        config[P.KERNEL] = KERNELS[agg.kernel][0]
        config[P.USE_GEOMETRIC] = int("geometric" in agg.efficiency)
        config[P.USE_PHYSICAL] = int("physical" in agg.efficiency)
        config[P.USE_SATURATION] = int("saturation" in agg.efficiency)
        ref_d = agg.reference_diameter
        if ref_d is not None:
            params[P.REFERENCE_VOLUME] = math.pi / 6.0 * ref_d ** 3
        else:
            params[P.REFERENCE_VOLUME] = scene.initial.mean_mass / mat.density
    else:
        params[P.RATE] = 0.0       # no aggregation table: the kernel is never evaluated
    pd = 0.0
    if scene.binder_injection is not None:
        pd = droplet_mass(scene.binder_injection.droplet_diameter, mat.binder_density)
    params[P.DROPLET_MASS] = pd
    config[P.SEPARATE_DROPLETS] = int(scene.separate_droplets)
    params[P.DROPLET_FACTOR] = agg.droplet_factor if scene.separate_droplets else 0.0
    config[P.BIVARIATE] = int(scene.bivariate)
    n_ref, p_ref = scales(scene)
    params[P.NUMBER_SCALE] = n_ref
    params[P.MASS_SCALE] = p_ref
    params[P.STEP_FLOOR] = 1.0e-12 * scene.end_time
    method = scene.method
    if method.name == "qmom":
        from .methods import qmom
        config[P.METHOD] = 0
        config[P.ORDER] = method.nodes
        names = qmom.state_names(method.nodes, scene.bivariate, scene.separate_droplets)
    elif method.name == "laguerre":
        config[P.METHOD] = 1
        config[P.ORDER] = method.order
        names = laguerre_state_names(method.order, scene.separate_droplets)
    else:
        config[P.METHOD] = -1
        names = []
    config[P.N_STATE] = len(names)
    from .integrate import SCHEMES
    config[P.INTEGRATOR] = SCHEMES[method.integrator]
    return Arrays(params=params, config=config, number_scale=n_ref, mass_scale=p_ref,
                  droplet_mass=pd, state_names=names)


def laguerre_state_names(order, separate_droplets):
    """State entry names of the Laguerre ROM: M_ij, i-major over i, j < order."""
    names = [f"M{i}{j}" for i in range(order) for j in range(order)]
    if separate_droplets:
        names.append("droplet_number_density")
    return names


def well_mixed_cell(scene: Scene) -> np.ndarray:
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
    return 4.0 * math.sqrt(max(float(theta), 0.0) / math.pi)


def size_moment(scene: Scene, k: int, j: int = 0) -> float:
    """Initial granule moment M_kj [kg^(k+j)/m3] (free droplets excluded)."""
    init = scene.initial
    n0, p0, y0 = init.number_density, init.mean_mass, init.binder_fraction
    if init.distribution == "monodisperse":
        return n0 * p0 ** k * (y0 * p0) ** j
    # exponential in p, every granule with the same binder fraction y0: b = y0 p
    return n0 * p0 ** (k + j) * math.factorial(k + j) * y0 ** j


def initial_moments(scene: Scene, arrays: Arrays, names) -> np.ndarray:
    """Scaled initial state for moment methods whose state entries are named ``names``."""
    state = np.zeros(len(names))
    nd0 = scene.initial.droplet_number_density
    pd = arrays.droplet_mass
    for idx, name in enumerate(names):
        if name == "droplet_number_density":
            state[idx] = nd0 / arrays.number_scale
            continue
        i, j = int(name[1]), int(name[2])
        value = size_moment(scene, i, j)
        if not scene.separate_droplets and nd0 > 0.0:
            value += nd0 * pd ** (i + j)
        state[idx] = value / (arrays.number_scale * arrays.mass_scale ** (i + j))
    return state


def product_gel_time(scene: Scene) -> float | None:
    """Gel time [s] of the product kernel from the initial M20 (1/(k0 M20(0))), else None."""
    agg = scene.aggregation
    if agg is None or agg.kernel != "product":
        return None
    m20 = size_moment(scene, 2)
    if m20 <= 0.0:
        return None
    return 1.0 / (agg.rate * m20)
