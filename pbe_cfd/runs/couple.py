"""The coupled run: the population balance in every cell of an OpenFOAM fluid bed.

Orchestration only: the domain (``pbe_cfd.runs.domain``: CFD fields, cell rows, initial
states) is solved cell by cell with the same per-cell integrator as well-mixed runs (a
``CellBatch`` of the active cells), by an executor (``pbe_cfd.runs.executor``: serial, or
``pbe_cfd.runs.distributed`` on a Dask cluster) that carries granules between cells with the
transport operator when the scene has ``[transport]``; then the per-cell and bed-integrated
SI outputs are assembled and written (VTK series, ``bed_moments.csv``, ``summary.json``, PNG
renders).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import model
from .air import coupled_air
from .batch import CellBatch, SimulationError  # noqa: F401 (SimulationError: API)
from .domain import PACKING_MARGIN, Domain, spray_zone_cut
from .executor import SerialExecutor
from .inventory import held_sums, inventory
from .problem import OutputPlan, problem_of
from ..util.population import mean_diameters
from ..scene.scene import SceneError

__all__ = ["CoupledResult", "run_coupled", "write_coupled", "check_foam_fields",
           "write_foam_fields"]


@dataclass
class CoupledResult:
    """Per-output-time cell fields and bed-integrated columns of a coupled run."""
    times: np.ndarray
    cell_fields: list              # one dict name -> (n_cells,) per output time (a Spool)
    bed_columns: dict
    stats: dict
    wall_time_s: float
    warnings: list = field(default_factory=list)
    compile_time_s: float = 0.0     # compiling (or loading) the kernels, not in wall_time_s
    kernels_compiled: bool = False  # True: numba compiled them (a first run), else loaded
    phases: dict = field(default_factory=dict)  # wall seconds of setup, compile, solve, assemble
    psd: dict | None = None         # psd.csv columns of the bed (distribution.tables)
    labels: dict = field(default_factory=dict)   # columns.json: file -> column -> meaning
    plan: OutputPlan | None = None  # what the writers read of the scene
    cell_psd: dict | None = None    # cell_psd.csv columns ([output] cell_psd; None: not asked)


def run_coupled(scene, domain: Domain, progress=None, threads: int | None = None,
                executor=None) -> CoupledResult:
    """Solve the population balance in every active cell of ``domain`` to the scene's end
    time. ``progress(fraction, text)`` is called after each output interval. ``executor``
    integrates the per-cell sources (``pbe_cfd.runs.executor``; default serial in this process,
    ``pbe_cfd.runs.distributed.ClusterExecutor`` on a Dask cluster, with the same results).
    The run keeps one OpenBLAS thread (``runs.blas``: its vector work waits for busy cores
    otherwise)."""
    from .blas import blas_threads
    with blas_threads(1):
        return _run_coupled(scene, domain, progress, threads, executor)


def _run_coupled(scene, domain: Domain, progress, threads, executor) -> CoupledResult:
    import numba

    if threads is not None:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    executor = executor if executor is not None else SerialExecutor()
    start = _time.perf_counter()
    cells = domain.cells
    problem = problem_of(scene, domain)        # the one pass: below, the problem only
    method, plan = problem.method, problem.outputs
    arrays, aux, times, idx = problem.arrays, problem.aux, problem.times, problem.cell_ids
    active, spray, notes = problem.active, problem.spray, problem.notes
    warnings = []
    selection = select_psd_cells(plan, cells, active)    # a bad selection fails before the run
    batch = CellBatch.for_problem(problem)
    batch.air = coupled_air(problem.air, arrays, executor)
    transport = None
    if problem.transport is not None:
        from ..transport.operator import build_transport
        transport = build_transport(problem.transport, domain, active, problem.mesh_rows,
                                    arrays=arrays, aux=aux)
        warnings.extend(transport.warnings)
    compile_s = batch.compile_announced(
        progress, None if transport is None else lambda: transport.compile(batch.states.shape[1]))
    solve_start = _time.perf_counter()
    setup_s = solve_start - start - compile_s
    start += compile_s                      # the run time excludes the compile
    history = executor.run(batch, times, transport, progress=progress)
    if not getattr(executor, "checks_outputs", False):
        for k in range(len(times)):
            batch.check_output(times[k], history[k])
    solve_end = _time.perf_counter()
    wall = solve_end - start
    per_time = []
    cell_fields, bed, mixtures = _outputs(plan, arrays, aux, cells, active, spray, idx, times,
                                          history, warnings, per_time)
    if "evaporated_liquid" in arrays.state_names:
        bed.update(inventory(problem.injection, arrays, times, per_time, batch.rows,
                             np.asarray(cells.cell_volume, dtype=float)[idx]))
    if batch.air is not None:
        bed.update(batch.air.columns(times))
    st = batch.stats()
    run_stats = {"cells": int(cells.n_cells), "active_cells": int(idx.size),
                 "spray_cells": int(np.count_nonzero(spray)), **st,
                 "cell_steps_per_second": float(st["accepted_steps"] / wall) if wall > 0 else 0,
                 "threads": int(numba.get_num_threads()), **notes}
    if transport is not None:
        run_stats["transport"] = transport.report()
    report = executor.report()
    if report is not None:
        run_stats["cluster"] = report
    extra, notes_method = method.diagnostics(history[-1], aux, arrays)
    run_stats.update(extra)
    warnings.extend(notes_method)
    if method.closure_check is not None:
        extra, notes_method = method.closure_check(
            history, arrays, lambda k, r: f"cell {int(idx[r])} at t = {times[k]:.6g} s")
        run_stats.update(extra)
        warnings.extend(notes_method)
    warnings.extend(batch.notes)
    run_stats["smooth_stokes_cells"] = int(np.count_nonzero(batch.smoothed))
    warnings.extend(_domain_warnings(plan, spray, notes, cells, active))
    warnings[:0] = list(getattr(domain, "warnings", None) or [])
    phases = {"setup_s": setup_s, "compile_s": compile_s, "solve_s": solve_end - solve_start,
              "assemble_s": _time.perf_counter() - solve_end}
    psd, labels = _bed_distribution(plan, arrays, times, bed, mixtures, cell_fields, warnings)
    cell_psd = _cell_psd(plan, selection, times, mixtures, [idx] * len(times), psd, labels,
                         warnings)
    mixtures.close()
    phases["assemble_s"] = _time.perf_counter() - solve_end
    return CoupledResult(times=times, cell_fields=cell_fields, bed_columns=bed, stats=run_stats,
                         wall_time_s=wall, warnings=warnings, compile_time_s=compile_s,
                         kernels_compiled=batch.compiled_now, phases=phases, psd=psd,
                         labels=labels, plan=plan, cell_psd=cell_psd)


def select_psd_cells(plan, cells, active):
    """The cells of ``[output] cell_psd`` (``distribution.cell_psd.CellSelection``) on the
    mesh ``cells`` with ``active`` the cells holding granules; None when not asked. SceneError
    (exit 2) for a selection outside the mesh or a cell without granules."""
    if not plan.cell_psd:
        return None
    from ..distribution.cell_psd import select_cells
    return select_cells(plan.cell_psd, cells, np.asarray(active, dtype=bool), plan.alpha_min,
                        plan.source)


def _cell_psd(plan, selection, times, mixtures, cell_ids, psd, labels, warnings):
    """cell_psd.csv columns of the selected cells on the bed's psd.csv grid, their labels
    into ``labels``; None without a selection. ``cell_ids``: the mesh cells of each output
    time's rows (the active cells)."""
    if selection is None or psd is None:
        return None
    from ..distribution import cell_psd
    grid = np.unique(np.asarray(psd["d_m"], dtype=float))
    cols, notes = cell_psd.cell_psd_columns(selection, times, (m.parts for m in mixtures),
                                            cell_ids, grid)
    warnings.extend(x for x in notes if x not in warnings)
    labels["cell_psd.csv"] = cell_psd.cell_psd_labels(plan.distribution, cols)
    return cols


def _cell_distribution(plan, arrays, aux, states, populations, idx, n, t, fields, notes):
    """d10/d50/d90/span cell fields (inactive cells 0) of one output time; returns the
    bed's distribution there (the cells' mixture weighted by their granule mass)."""
    from ..distribution import tables
    label = lambda r: f"cell {int(idx[r])} at t = {t:.6g} s"     # noqa: E731 (a row's name)
    recon = tables.reconstruction_of(plan.distribution, arrays, states, aux, populations,
                                     label)
    size, found = tables.size_columns(recon, label)
    notes.extend(x for x in found if x not in notes)
    for name, values in size.items():
        full = np.zeros(n)
        full[idx] = values
        fields[name] = full
    return recon


def _weighted_particles(populations, volumes):
    """([w V [-] per cell], [p [kg] per cell]) of every cell's particles (w [1/m3], p [kg],
    b [kg]) times its volume [m3]; one array each where every cell has as many particles."""
    from ..distribution.reconstruct import stacked_rows
    w, p = stacked_rows(populations, 0), stacked_rows(populations, 1)
    if w is not None and p is not None and p.shape == w.shape:
        return [(w * volumes[:, None]).ravel()], [p.ravel()]
    return ([np.asarray(w) * volumes[c] for c, (w, _, _) in enumerate(populations)],
            [np.asarray(p) for _, p, _ in populations])


def _bed_distribution(plan, arrays, times, bed, mixtures, cell_fields, warnings):
    """Bed d10/d50/d90/span columns (added after the others), the bed's psd.csv columns
    and the columns.json labels."""
    from ..distribution import reconstruct, tables
    stack = reconstruct.Stack(mixtures)
    size, notes = tables.size_columns(stack, lambda r: f"the bed at t = {times[r]:.6g} s")
    bed.update(size)
    psd, grid_notes = tables.psd_if_granules(times, stack)
    warnings.extend(x for x in notes + grid_notes if x not in warnings)
    names = arrays.state_names
    hooks = plan.distribution           # the method's and the distribution's labels
    return psd, {"bed_moments.csv": tables.column_labels(hooks, names, bed, bed=True),
                 "vtk cell fields": tables.column_labels(hooks, names, cell_fields[0]),
                 **tables.psd_file_labels(hooks, psd)}


def _domain_warnings(plan, spray, notes, cells, active) -> list:
    out = []
    if plan.sprays and not np.any(spray):
        out.append(f"the spray zone of [binder_injection] holds no cell: "
                   f"{spray_zone_cut(plan.spray_zone, plan.alpha_min, cells, active)}; "
                   "no binder is injected (change [binder_injection] zone)")
    if notes["cells_capped_below_alpha_max"]:
        out.append(f"{notes['cells_capped_below_alpha_max']} cells had alpha at or above "
                   f"alpha_max = {plan.alpha_max:g}; kept {PACKING_MARGIN:g} "
                   "below it so that g0 stays finite")
    return out


def _outputs(plan, arrays, aux, cells, active, spray, idx, times, history, warnings,
             per_time=None):
    """Per output time: the cell fields (every mesh cell; inactive cells 0) and the bed
    columns (volume averages of the moments [per m3 of bed], d32, d43 [m] of the whole bed's
    population, binder fraction, bed mass [kg]), the cells' d10/d50/d90/span, and per output
    time the bed's size distribution (``distribution.reconstruct.Mixture``); plan: the
    problem's ``OutputPlan``. ``per_time`` (a list) receives each output time's
    ``inventory.held_sums`` (None without drying). The cell fields and the bed mixtures are
    spooled to disk (``io.spool``), one output time in memory at a time."""
    from ..distribution.reconstruct import Mixture
    from ..io.spool import Spool
    mixtures = Spool()                 # one output time in memory at a time
    n = cells.n_cells
    volumes = np.asarray(cells.cell_volume, dtype=float)
    v_active = volumes[idx]
    bed_volume = float(volumes.sum())
    cell_fields = Spool()              # one output time in memory at a time
    bed = {"time_s": times}
    rho = plan.density
    pd = arrays.droplet_mass
    for k, states in enumerate(history):
        populations = []
        cols = model.moment_outputs(plan.method_plan, arrays, states, aux,
                                    populations=populations)
        if per_time is not None:
            per_time.append(held_sums(cols, v_active))
        fields = {"alpha": np.asarray(cells.alpha, dtype=float),
                  "Theta": np.asarray(cells.theta, dtype=float),
                  "active": active.astype(float), "spray_zone": spray.astype(float)}
        for name, values in cols.items():
            full = np.zeros(n)
            full[idx] = values
            fields[name] = full
        recon = _cell_distribution(plan, arrays, aux, states, populations, idx, n, times[k],
                                   fields, warnings)
        mixtures.append(Mixture(recon, recon.mass * v_active))
        cell_fields.append(fields)
        for name, values in cols.items():
            if name.startswith("M") or name == "droplet_number_density":
                bed.setdefault(name, np.zeros(len(times)))[k] = float(
                    np.sum(values * v_active) / bed_volume)
        # bed d32/d43 from every cell's population, weighted by cell volume
        ws, ps = _weighted_particles(populations, v_active)
        if plan.separate_droplets and "droplet_number_density" in cols:
            ws.append(np.array([np.sum(cols["droplet_number_density"] * v_active)]))
            ps.append(np.array([pd]))
        d32, d43 = mean_diameters(np.concatenate(ws), np.concatenate(ps), rho)
        bed.setdefault("d32_m", np.zeros(len(times)))[k] = d32
        bed.setdefault("d43_m", np.zeros(len(times)))[k] = d43
        m10 = bed["M10"][k]
        bed.setdefault("binder_fraction", np.zeros(len(times)))[k] = (
            bed["M01"][k] / m10 if plan.bivariate and m10 > 0 else 0.0)
        bed.setdefault("bed_mass_kg", np.zeros(len(times)))[k] = m10 * bed_volume
        if plan.bivariate:
            bed.setdefault("bed_binder_mass_kg", np.zeros(len(times)))[k] = (
                bed["M01"][k] * bed_volume)
    return cell_fields, bed, mixtures


# ---------------------------------------------------------------------------- writing
def write_coupled(out_dir: Path, domain: Domain, result: CoupledResult,
                  render: bool = True, phases: dict | None = None) -> dict:
    """Write fields.pvd + .vtu, bed_moments.csv, PNG renders and summary.json into out_dir;
    what they need of the scene is the result's output plan (``result.plan``).

    ``phases``: wall seconds [s] of the phases before the run (start-up, read), merged with
    the run's (``result.phases``) and this function's (write, render) into summary.json's
    ``phases``; returns that dict."""
    from ..io import output
    from ..viz import figure_pool

    plan = result.plan
    t0 = _time.perf_counter()
    phases = {**(phases or {}), **result.phases}
    output.write_columns_csv(out_dir / "bed_moments.csv", result.bed_columns)
    if result.psd is not None:
        output.write_columns_csv(out_dir / "psd.csv", result.psd)
        if result.cell_psd is not None:
            output.write_columns_csv(out_dir / "cell_psd.csv", result.cell_psd)
        output.write_json(out_dir / "columns.json", result.labels)
    extra, started = [], None
    if render:
        extra = _bed_figures(out_dir, plan, result)
        if figure_pool.drawing_elsewhere():     # drawn while the VTK series is written
            started, extra = figure_pool.start_tasks(extra), []
    try:
        _write_and_render(out_dir, plan, domain, result, render, extra, started, phases, t0)
    except BaseException:
        if started is not None:      # nothing may still be drawing into a directory removed
            _quietly(figure_pool.finish_tasks, started)
        raise
    t2 = _time.perf_counter()
    summary = {"scene": plan.echo, "method": plan.method_name,
               "domain": domain.description, "wall_time_s": result.wall_time_s,
               "compile_time_s": result.compile_time_s,
               "kernels_compiled": result.kernels_compiled, "stats": result.stats,
               "phases": phases, "warnings": result.warnings}
    output.write_json(out_dir / "summary.json", summary)
    phases["write_s"] += _time.perf_counter() - t2
    return phases


def _write_and_render(out_dir, plan, domain, result, render, extra, started, phases, t0):
    """The VTK series, then the field pictures (with ``extra`` drawing tasks) and the
    collection of the ``started`` ones; the write and render seconds go into ``phases``."""
    from ..io.vtk import VtkSeries
    from ..viz import figure_pool
    with VtkSeries(out_dir / "vtk", domain.cells, name="pbe") as series:
        for t, fields in zip(result.times, result.cell_fields):
            series.write(t, fields)
    phases["write_s"] = _time.perf_counter() - t0
    if render:
        from ..viz.render import render_series
        t1 = _time.perf_counter()
        render_series(out_dir / "vtk", times=[result.times[0], result.times[-1]],
                      png_dir=out_dir / "png",
                      info={"name": plan.title, "alpha_min": plan.alpha_min},
                      extra_tasks=extra)
        if started is not None:
            figure_pool.finish_tasks(started)
        phases["render_s"] = _time.perf_counter() - t1


def _quietly(fn, *args):
    """fn(*args), its own failure ignored (while another failure is being raised)."""
    try:
        fn(*args)
    except Exception:  # noqa: BLE001 - the first failure is the one reported
        pass


def _bed_figures(out_dir: Path, plan, result: CoupledResult) -> list:
    """The drawing tasks (``viz.figure_pool``) of the bed's pictures: bed_moments.png,
    moisture.png where the run dries, and psd.png where the run has a size distribution; they
    read the CSV files already written."""
    from ..viz.render import BED_MOMENTS_COST, plot_bed_moments
    png = out_dir / "png"
    tasks = [(plot_bed_moments, (out_dir / "bed_moments.csv", png / "bed_moments.png"),
              {"title": plan.title}, BED_MOMENTS_COST)]
    if "moisture_content" in result.bed_columns:
        from ..viz.moisture import MOISTURE_COST, plot_moisture
        tasks.append((plot_moisture, (out_dir / "bed_moments.csv", png / "moisture.png"),
                      {"title": f"{plan.title}: moisture"}, MOISTURE_COST))
    if result.psd is not None:
        from ..viz.psd_figure import PSD_COST, plot_psd
        tasks.append((plot_psd, (png / "psd.png", out_dir / "psd.csv"),
                      {"title": f"{plan.title}: the bed's granules"}, PSD_COST))
    if result.cell_psd is not None:
        from ..viz.cell_psd_figure import CELL_PSD_COST, plot_cell_psd
        tasks.append((plot_cell_psd, (png / "cell_psd.png", out_dir / "cell_psd.csv",
                                      out_dir / "psd.csv"),
                      {"title": f"{plan.title}: granules of single cells"}, CELL_PSD_COST))
    return tasks


#: OpenFOAM dimensions of the fields written back into a case
FOAM_UNITS = {"M00": "[0 -3 0 0 0 0 0]", "M10": "[1 -3 0 0 0 0 0]", "M01": "[1 -3 0 0 0 0 0]",
              "M20": "[2 -3 0 0 0 0 0]", "M11": "[2 -3 0 0 0 0 0]", "M02": "[2 -3 0 0 0 0 0]",
              "d32_m": "[0 1 0 0 0 0 0]", "d43_m": "[0 1 0 0 0 0 0]",
              "droplet_number_density": "[0 -3 0 0 0 0 0]",
              "active": "[0 0 0 0 0 0 0]"}     # 1 in a cell holding granules, 0 elsewhere


def check_foam_fields(scene, domain: Domain, overwrite: bool = False):
    """Before a run with --foam-fields: refuse (SceneError or output.OutputRefused, exit 2)
    when the domain has no case time directory to write into (a snapshot), or when that
    directory holds ``pbe.*`` fields pbe-cfd may not replace."""
    from ..io import openfoam as of
    from .domain import case_path, is_case_directory
    if not is_case_directory(scene):
        raise SceneError(scene.source, "domain.case",
                         f"--foam-fields: {scene.domain.case!r} is a snapshot, which has no "
                         "OpenFOAM case time directory to write fields into; point [domain] "
                         "case at a case directory (`pbe-cfd case run --dir DIR`) or drop "
                         "--foam-fields")
    case = case_path(scene)
    names = [f"pbe.{k}" for k in (*FOAM_UNITS, "binder_fraction")]
    of.check_foam_fields(case, of.time_name(case, domain.cells.time), names, overwrite)


def write_foam_fields(scene, domain: Domain, result: CoupledResult,
                      overwrite: bool = False) -> list:
    """Write the final moment fields as volScalarFields ``pbe.<name>`` (SI) into the case's
    time directory of the CFD fields they were computed from (ParaView's OpenFOAM reader lists
    numeric times only). Returns the files written ([] for a snapshot domain)."""
    from ..io import openfoam as of
    from .domain import case_path, is_case_directory
    if not is_case_directory(scene):
        return []
    case = case_path(scene)
    fields = {f"pbe.{k}": v for k, v in result.cell_fields[-1].items()
              if k in FOAM_UNITS or k == "binder_fraction"}
    dims = {f"pbe.{k}": u for k, u in FOAM_UNITS.items()}
    name = of.time_name(case, domain.cells.time)
    if domain.cells.source.get("decomposed"):        # the time only the processors hold
        from .distributed.decompose import read_decomposition, write_processor_fields
        return write_processor_fields(case, read_decomposition(case, domain.cells.n_cells),
                                      name, fields, dimensions=dims, overwrite=overwrite)
    return of.write_foam_fields(case, name, fields, dimensions=dims, overwrite=overwrite)
