"""Run a well-mixed (one-cell) scene with any method and collect SI output columns."""
from __future__ import annotations

import dataclasses

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from . import integrate, model
from .methods import qmom
from .physics import parameters as P
from .population import DERIVED, columns_from_particles, mean_diameters, moment_columns
from .scene import Scene


class SimulationError(RuntimeError):
    """The run could not reach its end time; the message says which cell, when and why."""


@dataclass
class RunResult:
    """Time series of SI output columns (``columns['time_s']`` first) and run statistics."""
    scene: Scene
    columns: dict
    stats: dict
    wall_time_s: float
    warnings: list = field(default_factory=list)


def output_times(scene: Scene) -> np.ndarray:
    """Output times [s]: 0, every output_interval, and end_time."""
    n = int(math.floor(scene.end_time / scene.output_interval + 1e-9))
    times = [k * scene.output_interval for k in range(n + 1)]
    if scene.end_time - times[-1] > 1e-9 * scene.end_time:
        times.append(scene.end_time)
    return np.array(times)


def check_physics(scene: Scene):
    """Refuse runs whose answer would be meaningless (product-kernel gelation)."""
    t_gel = model.product_gel_time(scene)
    if t_gel is not None and scene.end_time >= t_gel:
        raise SimulationError(
            f"{scene.source}: the product kernel gels at t = {t_gel:.6g} s "
            f"(1/(k0 M20(0))); moments diverge there. Expected scene.end_time below it, "
            f"got {scene.end_time:g} s")


def method_aux(scene: Scene, arrays: model.Arrays, theta_grid=None) -> tuple[np.ndarray, list]:
    """Auxiliary array of the moment method (empty for QMOM) and any warnings."""
    if scene.method.name == "laguerre":
        from .methods import laguerre_tensor
        return laguerre_tensor.aux_for_scene(scene, arrays, theta_grid=theta_grid), []
    return np.zeros(1), []


def moment_outputs(scene: Scene, arrays: model.Arrays, states: np.ndarray, aux,
                   populations: list | None = None) -> dict:
    """SI output columns (moments, droplets, d32, d43, binder fraction) of scaled states
    (one row per time or per cell). If a list is passed as ``populations``, each row's
    weighted particles (w [1/m3], p [kg], b [kg], from ``population_of``) are appended to it."""
    names = arrays.state_names
    bivariate = scene.bivariate
    cols = moment_columns(names, bivariate)
    separate = scene.separate_droplets
    n_rows = states.shape[0]
    out = {c: np.zeros(n_rows) for c in cols}
    if separate:
        out["droplet_number_density"] = np.zeros(n_rows)
    for c in DERIVED:
        out[c] = np.zeros(n_rows)
    pd = arrays.droplet_mass
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    rho = scene.material.density
    for r in range(n_rows):
        state = states[r]
        w, p, b = population_of(scene, arrays, state, aux)
        if populations is not None:
            populations.append((w, p, b))
        nd = state[-1] * n_ref if separate else 0.0
        estimated = columns_from_particles(w, p, b, cols)
        for c in cols:
            if c in names:
                i, j = int(c[1]), int(c[2])
                value = state[names.index(c)] * n_ref * p_ref ** (i + j)
            else:
                value = estimated[c]
            out[c][r] = value + nd * pd ** (int(c[1]) + int(c[2]))
        if separate:
            out["droplet_number_density"][r] = nd
        ww = np.append(w, nd) if nd > 0 else w
        pp = np.append(p, pd) if nd > 0 else p
        d32, d43 = mean_diameters(ww, pp, rho)
        out["d32_m"][r] = d32
        out["d43_m"][r] = d43
        m10 = out["M10"][r]
        out["binder_fraction"][r] = out["M01"][r] / m10 if bivariate and m10 > 0 else 0.0
    return out


def population_of(scene: Scene, arrays: model.Arrays, state, aux):
    """Weighted particles (w [1/m3], p [kg], b [kg]) describing one cell's granules."""
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    if scene.method.name == "qmom":
        x, w, beta = qmom.quadrature_of(state, arrays.config)
        return w * n_ref, x * p_ref, beta * p_ref
    from .methods import laguerre_tensor
    return laguerre_tensor.population_for_output(state, aux, arrays)


def failure_hint(scene: Scene, arrays: model.Arrays, state, aux) -> str:
    """Extra context for a stopped cell: for the Laguerre ROM, the share of the mass that has
    left the integration support (the usual reason the ROM's moments stop being realizable)."""
    if scene.method.name != "laguerre":
        return ""
    from .methods import laguerre_tensor
    m10 = state[int(arrays.config[P.ORDER])]
    if state[1] <= 1e-6 * max(m10, 0.0):
        return ("; the Laguerre ROM cannot take a binder-free population that starts receiving "
                "binder (its reconstruction spreads the first binder over the b-weight, and the "
                "binder moments turn negative): start with initial.binder_fraction > 0 or "
                "initial droplets, or use qmom")
    share, _ = laguerre_tensor.escaped_share_report(np.atleast_2d(state), aux, arrays)
    return (f"; {share:.1%} of the granule mass had left the Laguerre support (p_max = "
            f"{scene.method.support_mass:g} kg, b_max = {scene.method.support_binder:g} kg): "
            "widen the support or use qmom")


def run_well_mixed(scene: Scene, progress=None) -> RunResult:
    """Run a well-mixed scene to its end time. ``progress(fraction, text)`` is called after each
    output interval. Raises SimulationError on a stall or an unrealizable start."""
    check_physics(scene)
    if scene.method.name == "cnmc":
        return _run_cnmc(scene, progress)
    start = _time.perf_counter()
    arrays = model.pack(scene)
    aux, warnings = method_aux(scene, arrays)
    times = output_times(scene)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    states = np.zeros((len(times), len(state)))
    states[0] = state
    cells = model.well_mixed_cell(scene)
    work = state[None, :].copy()
    steps = np.array([scene.output_interval * 1e-3])
    stats = np.zeros((1, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(1, dtype=np.int64)
    reached = np.zeros(1)
    m = scene.method
    for k in range(1, len(times)):
        integrate.integrate_cells(work, cells, aux, arrays.params, arrays.config,
                                  times[k - 1], times[k], steps, m.rtol, m.atol, integrate.MAX_STEPS_PER_INTERVAL,
                                  stats, status, reached)
        if status[0] != integrate.OK:
            raise SimulationError(
                f"{scene.source}: cell 0 stopped at t = {reached[0]:.6g} s: "
                f"{integrate.failure_reason(status[0], stats[0], arrays.params, arrays.config)} "
                f"(floor {arrays.params[P.STEP_FLOOR]:.3g} s)" + failure_hint(scene, arrays,
                                                                               work[0], aux))
        states[k] = work[0]
        if progress is not None:
            progress(times[k] / scene.end_time, f"t = {times[k]:.4g} s")
    wall = _time.perf_counter() - start
    columns = {"time_s": times}
    columns.update(moment_outputs(scene, arrays, states, aux))
    st = stats[0]
    run_stats = integrate.stats_summary(st)
    if scene.method.name == "laguerre":
        from .methods import laguerre_tensor
        share, text = laguerre_tensor.escaped_share_report(states, aux, arrays)
        run_stats["escaped_mass_share"] = share
        if text:
            warnings.append(text)
    return RunResult(scene=scene, columns=columns, stats=run_stats, wall_time_s=wall,
                     warnings=warnings)


def _run_cnmc(scene: Scene, progress) -> RunResult:
    from .methods import cnmc
    start = _time.perf_counter()
    arrays = model.pack(scene)
    times = output_times(scene)
    cells = model.well_mixed_cell(scene)
    initial = dataclasses.asdict(scene.initial)     # the keys simulate_ensemble reads
    m = scene.method
    cb = (lambda f: progress(f, "")) if progress is not None else None
    res = cnmc.simulate_ensemble(arrays.params, arrays.config, cells[0], initial, times,
                                 m.particles, m.replicas, m.seed, progress=cb)
    wall = _time.perf_counter() - start
    columns = {"time_s": times}
    stats = {}
    for key, value in res.items():
        if key == "time_s":
            continue
        if np.ndim(value) == 0:
            stats[key] = value.item() if hasattr(value, "item") else value
        else:
            columns[key] = np.asarray(value, dtype=float)
    if not scene.bivariate:
        for key in list(columns):
            base = key.split("_")[0]
            if base in ("M01", "M11", "M02") or key.startswith("binder_fraction"):
                columns.pop(key)
    if not scene.separate_droplets:
        for key in list(columns):
            if key.startswith("droplet_number_density"):
                columns.pop(key)
    return RunResult(scene=scene, columns=columns, stats=stats, wall_time_s=wall)
