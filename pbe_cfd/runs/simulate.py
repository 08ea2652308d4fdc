"""Run a well-mixed (one-cell) scene with any method and collect SI output columns."""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from . import model
from ..methods.entry import RunStopped
from ..physics.injection import droplet_liquid
from ..scene import spray
from .batch import CellBatch, SimulationError, check_physics, output_times
from .problem import problem_of

__all__ = ["RunResult", "SimulationError", "run_well_mixed", "output_times", "check_physics"]


@dataclass
class RunResult:
    """Time series of SI output columns (``columns['time_s']`` first) and run statistics."""
    scene: object
    columns: dict
    stats: dict
    wall_time_s: float
    warnings: list = field(default_factory=list)
    compile_time_s: float = 0.0     # compiling (or loading) the kernels, not in wall_time_s
    kernels_compiled: bool = False  # True: numba compiled them (a first run), else loaded
    psd: dict | None = None         # psd.csv columns (distribution.tables), None if none
    labels: dict = field(default_factory=dict)   # columns.json: file -> column -> meaning


def run_well_mixed(scene, progress=None) -> RunResult:
    """Run a well-mixed scene to its end time. ``progress(fraction, text)`` is called after each
    output interval (and told when the kernels compile). ``wall_time_s`` is the run,
    ``compile_time_s`` compiling or loading the integration kernel [s]. Raises SimulationError
    on a stall or an unrealizable start."""
    start = _time.perf_counter()
    problem = problem_of(scene)                 # the one pass: below, the problem only
    method = problem.method
    if not method.integrated:
        return _run_ensemble(scene, problem, start, progress)
    arrays, aux, times = problem.arrays, problem.aux, problem.times
    outputs = problem.outputs
    warnings = []
    states = np.zeros((len(times), problem.states.shape[1]))
    states[0] = problem.states[0]
    batch = CellBatch.for_problem(problem)
    if problem.air is not None:
        batch.air = problem.air.bed_air(arrays)
    compile_s = batch.compile_announced(progress)
    start += compile_s                      # the run time excludes the compile
    for k in range(1, len(times)):
        batch.step(times[k - 1], times[k])
        batch.check_output(times[k])
        states[k] = batch.states[0]
        if progress is not None:
            progress(times[k] / problem.end_time, f"t = {times[k]:.4g} s")
    wall = _time.perf_counter() - start
    columns = {"time_s": times}
    populations = []
    columns.update(model.moment_outputs(outputs.method_plan, arrays, states, aux,
                                        populations=populations))
    if outputs.dries:
        inj = problem.injection
        columns["liquid_sprayed"] = (np.array([spray.injected(inj, t) for t in times])
                                     * float(droplet_liquid(arrays.params))
                                     if inj is not None else np.zeros(len(times)))
        if batch.air is not None:
            columns.update(batch.air.columns(times))
    run_stats = batch.stats()
    extra, notes = method.diagnostics(states, aux, arrays)
    run_stats.update(extra)
    warnings.extend(notes)
    if method.closure_check is not None:
        extra, notes = method.closure_check([states], arrays,
                                             lambda k, r: f"t = {times[r]:.6g} s")
        run_stats.update(extra)
        warnings.extend(notes)
    warnings.extend(batch.notes)
    run_stats["smooth_stokes_cells"] = int(np.count_nonzero(batch.smoothed))
    psd, labels = _size_distribution(outputs.distribution, arrays, states, aux, populations,
                                     columns, warnings)
    return RunResult(scene=scene, columns=columns, stats=run_stats, wall_time_s=wall,
                     warnings=warnings, compile_time_s=compile_s,
                     kernels_compiled=batch.compiled_now, psd=psd, labels=labels)


def warm_outputs(problem, scene=None) -> None:
    """Assemble the output columns of ``problem``'s start states (moments of every row, the
    size distribution of the row with the most granules: d10/d50/d90, the PSD) and discard
    them: this compiles, or loads from numba's cache, the functions a run's output assembly
    calls (the method's populations, the size distribution's reconstruction, the method's
    output-time watch), so that ``pbe-cfd compile`` leaves a run nothing to compile. With
    ``scene``, also the size distribution of a broad population (``_broad_start``): a start
    that is monodisperse or empty does not reach the reconstruction's general fit, which a
    run reaches once its population spreads. States that the assembly refuses are left to
    the run, which names what it refuses."""
    if not problem.method.integrated:
        return
    try:
        states = np.array(problem.states, dtype=np.float64)
        _warm_distribution(problem, states, most_granules=True)
        watch = problem.outputs.method_plan.method.output_watch
        if watch is not None:                    # the method's output-time watch
            watch().update(0.0, states, problem.rows, problem.aux, problem.arrays,
                           problem.cell_ids)
        if scene is not None:
            _warm_distribution(problem, _broad_start(scene, problem), most_granules=False)
    except (ValueError, ArithmeticError):        # the run names what it refuses
        return


def _warm_distribution(problem, states, most_granules) -> None:
    """The moments of ``states`` (scaled, one per row) and the size distribution of its row
    with the most granules (largest M00; ``most_granules`` False: its first row)."""
    populations = []
    moments = model.moment_outputs(problem.outputs.method_plan, problem.arrays, states,
                                   problem.aux, populations=populations)
    row = int(np.argmax(moments["M00"])) if most_granules and "M00" in moments else 0
    columns = {"time_s": np.asarray(problem.times[:1], dtype=np.float64)}
    columns.update({k: np.asarray(v)[row:row + 1] for k, v in moments.items()
                    if np.ndim(v) == 1 and len(v) == len(states)})
    _size_distribution(problem.outputs.distribution, problem.arrays, states[row:row + 1],
                       problem.aux, populations[row:row + 1], columns, [])


def _broad_start(scene, problem) -> np.ndarray:
    """One state (1, n_state) of a broad population packed like ``problem``'s start states:
    ``scene``'s initial population made exponential in mass (its mean mass [kg]) at the
    problem's number scale [1/m3], granules present whatever the scene starts with."""
    import dataclasses
    initial = dataclasses.replace(scene.initial, distribution="exponential",
                                  number_density=problem.arrays.number_scale)
    broad = dataclasses.replace(scene, initial=initial)
    return model.initial_moments(broad, problem.arrays, problem.arrays.state_names)[None, :]


def _size_distribution(plan, arrays, states, aux, populations, columns, warnings):
    """Add d10/d50/d90/span to ``columns`` and return (psd.csv columns, columns.json);
    ``plan`` the run's ``distribution.tables.DistributionPlan``."""
    from ..distribution import tables
    if plan.method.distribution is None:            # a method without a reconstruction
        return None, {"moments.csv": tables.column_labels(plan, arrays.state_names, columns)}
    times = columns["time_s"]
    label = lambda r: f"t = {times[r]:.6g} s"         # noqa: E731 (a row's name)
    recon = tables.reconstruction_of(plan, arrays, states, aux, populations, label)
    size, notes = tables.size_columns(recon, label)
    columns.update(size)
    psd, grid_notes = tables.psd_if_granules(times, recon)
    warnings.extend(notes + grid_notes)
    return psd, {"moments.csv": tables.column_labels(plan, arrays.state_names, columns),
                 **tables.psd_file_labels(plan, psd)}


def _run_ensemble(scene, problem, start, progress) -> RunResult:
    """A method with a run of its own (the cNMC ensemble of a well-mixed scene, packed into
    ``problem`` from ``start``, a ``perf_counter`` time [s]): mean and 95% band columns per
    output time; ``scene`` only rides along into the result."""
    times = problem.times
    outputs = problem.outputs
    cb = (lambda f: progress(f, "")) if progress is not None else None
    try:
        res = problem.method.ensemble(outputs.method_plan, problem.arrays, problem.rows[0],
                                      times, cb)
    except RunStopped as exc:
        raise SimulationError(f"{scene.source}: {exc}") from None
    wall = _time.perf_counter() - start
    columns = {"time_s": times}
    stats = {}
    psd, psd_notes = _cnmc_distribution(outputs.bivariate, times, res)
    for key, value in res.items():
        if key == "time_s" or key.startswith("psd_"):
            continue
        if np.ndim(value) == 0:
            stats[key] = value.item() if hasattr(value, "item") else value
        else:
            columns[key] = np.asarray(value, dtype=float)
    if not outputs.bivariate:
        for key in list(columns):
            base = key.split("_")[0]
            if base in ("M01", "M11", "M02") or key.startswith("binder_fraction"):
                columns.pop(key)
    if not outputs.separate_droplets:
        for key in list(columns):
            if key.startswith("droplet_number_density"):
                columns.pop(key)
    from ..distribution import tables
    labels = {"moments.csv": tables.column_labels(outputs.distribution, [], columns),
              **tables.psd_file_labels(outputs.distribution, psd)}
    return RunResult(scene=scene, columns=columns, stats=stats, wall_time_s=wall,
                     warnings=psd_notes, psd=psd, labels=labels)


def _cnmc_distribution(bivariate, times, res):
    """(psd.csv columns, notes) of a cNMC ensemble's histograms (``bivariate``: True if the
    granules carry binder)."""
    from ..distribution import tables
    return tables.cnmc_psd_columns(times, res, bivariate)
