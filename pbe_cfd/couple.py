"""``pbe-cfd couple``: the population balance in every cell of an OpenFOAM fluid bed.

Orchestration only: read the CFD fields (bundled snapshot or a case), build one cell row per
mesh cell (alpha, Theta, collision velocity from Theta, spray-zone injection), solve every cell
with alpha >= alpha_min by the same per-cell kernel as well-mixed runs (numba prange), carry
granules between cells when the scene has ``[transport]``, and write the VTK series,
``bed_moments.csv``, ``summary.json`` and PNG renders.
"""
from __future__ import annotations

import dataclasses
import math
import sys
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import integrate, model
from .physics import parameters as P
from .population import mean_diameters
from .scene import Scene, SceneError
from .simulate import (SimulationError, check_physics, failure_hint, method_aux,
                       moment_outputs, output_times)

BUNDLED_PREFIX = "bundled:"
#: alpha is kept this far (relative) below alpha_max so that g0 stays finite; cells moved are
#: counted in the summary.
PACKING_MARGIN = 1.0e-6


@dataclass
class Domain:
    """The mesh cells the population lives in (OpenFOAM cell order)."""
    cells: object                  # pbe_cfd.cfd.openfoam.CellData
    flux: object | None            # pbe_cfd.cfd.openfoam.FaceFlux or None
    description: str


@dataclass
class CoupledResult:
    """Per-output-time cell fields and bed-integrated columns of a coupled run."""
    times: np.ndarray
    cell_fields: list              # one dict name -> (n_cells,) per output time
    bed_columns: dict
    stats: dict
    wall_time_s: float
    warnings: list = field(default_factory=list)


# ---------------------------------------------------------------------------- domain
def load_domain(scene: Scene, need_flux: bool = False) -> Domain:
    """Read the CFD fields named by ``[domain] case`` (a bundled snapshot, a snapshot .vtu, or
    an OpenFOAM case directory whose foamToVTK output exists)."""
    from .cfd import openfoam as of

    case = scene.domain.case
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
            path = Path(case)
            if not path.is_absolute() and scene.source:
                cand = Path(scene.source).parent / path
                path = cand if cand.exists() else path
            if path.suffix == ".vtu":
                loaded = of.load_snapshot(path, with_flux=need_flux)
                desc = f"snapshot {path}"
            elif path.is_dir():
                t = scene.domain.time
                t = "latest" if t == "latest" else float(t)
                cells = of.read_cell_fields(path, t)
                flux = of.read_face_flux(path, cells.time) if need_flux else None
                loaded = (cells, flux) if need_flux else cells
                desc = f"OpenFOAM case {path} at t = {cells.time:g} s"
            else:
                raise SceneError(scene.source, "domain.case",
                                 f"{case!r}: expected an OpenFOAM case directory, a snapshot "
                                 f".vtu or bundled:fluid_bed_small")
    except of.OpenFOAMError as exc:
        raise SceneError(scene.source, "domain.case", str(exc)) from None
    if need_flux:
        cells, flux = loaded
    else:
        cells, flux = loaded, None
    return Domain(cells=cells, flux=flux, description=desc)


def spray_zone(scene: Scene, cells) -> np.ndarray:
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


def build_cells(scene: Scene, cells) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Cell rows (n, N_CELL) for every mesh cell, the active mask (alpha >= alpha_min), the
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
    rows[:, P.COLLISION_VELOCITY] = 4.0 * np.sqrt(theta / math.pi)
    active = np.asarray(cells.alpha) >= scene.domain.alpha_min
    spray = spray_zone(scene, cells) & active
    if scene.binder_injection is not None:
        rows[spray, P.INJECTION] = scene.binder_injection.rate
    notes = {"cells_capped_below_alpha_max": capped}
    return rows, active, spray, notes


def cell_number_densities(scene: Scene, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Initial granule and free-droplet number densities per m3 of bed [1/m3] per cell.

    Granules fill the solids fraction: n = alpha rho_s / p0. Free droplets follow alpha too:
    ``initial.droplet_number_density`` is read per m3 of solids, n_d = alpha * value.
    """
    p0 = scene.initial.mean_mass
    granules = alpha * scene.material.density / p0
    droplets = alpha * scene.initial.droplet_number_density
    return granules, droplets


def initial_states(scene: Scene, arrays: model.Arrays, alpha: np.ndarray) -> np.ndarray:
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


def coupled_scales(scene: Scene, alpha_active: np.ndarray) -> Scene:
    """The scene with the number density set to the bed's largest cell value, so that the
    non-dimensional states of all cells are O(1) or below."""
    granules, droplets = cell_number_densities(scene, alpha_active)
    n_max = float(granules.max()) if granules.size else 1.0
    nd_max = float(droplets.max()) if droplets.size else 0.0
    return dataclasses.replace(scene, initial=dataclasses.replace(
        scene.initial, number_density=max(n_max, 1.0), droplet_number_density=nd_max))


# ---------------------------------------------------------------------------- run
def run_coupled(scene: Scene, domain: Domain, progress=None, threads: int | None = None,
                executor=None) -> CoupledResult:
    """Solve the population balance in every active cell of ``domain`` to the scene's end
    time. ``progress(fraction, text)`` is called after each output interval. ``executor``
    (``pbe_cfd.distributed.ClusterExecutor``) integrates the per-cell sources on a Dask
    cluster instead of in this process, with the same results."""
    import numba

    if scene.method.name not in model.MOMENT_METHODS:
        raise SceneError(scene.source, "method.name",
                         "a coupled run needs a moment method: expected qmom or laguerre")
    check_physics(scene)
    if threads is not None:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    start = _time.perf_counter()
    cells = domain.cells
    rows, active, spray, notes = build_cells(scene, cells)
    idx = np.flatnonzero(active)
    if idx.size == 0:
        raise SimulationError(f"{scene.source}: no cell has alpha >= alpha_min = "
                              f"{scene.domain.alpha_min:g} (max alpha "
                              f"{float(np.max(cells.alpha)):.3g})")
    scaled_scene = coupled_scales(scene, rows[idx, P.ALPHA])
    arrays = model.pack(scaled_scene)
    theta_grid = None
    if scene.method.name == "laguerre":
        th = rows[idx, P.THETA]
        lo = max(float(th.min()), 1e-12)
        theta_grid = np.geomspace(lo, max(float(th.max()), lo * 1.0001), 24)
    aux, warnings = method_aux(scaled_scene, arrays, theta_grid=theta_grid)
    states = initial_states(scene, arrays, rows[idx, P.ALPHA])
    work_rows = np.ascontiguousarray(rows[idx])
    times = output_times(scene)
    transport = None
    if scene.transport is not None:
        from .transport import build_transport
        transport = build_transport(scene, domain, active, rows)
        warnings.extend(transport.warnings)
    steps = np.full(idx.size, scene.output_interval * 1e-3)
    stats = np.zeros((idx.size, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(idx.size, dtype=np.int64)
    reached = np.zeros(idx.size)
    history = [states.copy()]
    m = scene.method
    if executor is not None:  # the per-cell sources on a Dask cluster (pbe_cfd.distributed)
        history = executor.run(states, times, transport, rows=work_rows, aux=aux,
                               arrays=arrays, method=m, steps=steps, stats=stats,
                               status=status, reached=reached, idx=idx, scene=scene,
                               progress=progress)
    for k in range(len(history), len(times)):
        if transport is None:
            _advance(states, work_rows, aux, arrays, m, times[k - 1], times[k], steps, stats,
                     status, reached, idx, scene)
        else:
            transport.advance(states, times[k - 1], times[k],
                              lambda s, t0, t1: _advance(s, work_rows, aux, arrays, m, t0, t1,
                                                         steps, stats, status, reached, idx,
                                                         scene))
        history.append(states.copy())
        if progress is not None:
            progress(times[k] / scene.end_time, f"t = {times[k]:.4g} s")
    wall = _time.perf_counter() - start
    cell_fields, bed = _outputs(scene, arrays, aux, cells, rows, active, spray, idx, times,
                                history)
    st = stats.sum(axis=0)
    run_stats = {"cells": int(cells.n_cells), "active_cells": int(idx.size),
                 "spray_cells": int(np.count_nonzero(spray)),
                 **integrate.stats_summary(st),
                 "cell_steps_per_second": float(st[integrate.ACCEPTED] / wall) if wall > 0 else 0,
                 "threads": int(numba.get_num_threads()), **notes}
    if transport is not None:
        run_stats["transport"] = transport.report()
    if executor is not None:
        run_stats["cluster"] = executor.report()
    if scene.method.name == "laguerre":
        from .methods import laguerre_tensor
        share, text = laguerre_tensor.escaped_share_report(history[-1], aux, arrays)
        run_stats["escaped_mass_share"] = share
        if text:
            warnings.append(text)
    if scene.binder_injection is not None and not np.any(spray):
        warnings.append("the spray zone of [binder_injection] holds no cell with alpha >= "
                        "alpha_min: no binder is injected (check zone's box and alpha window "
                        "against the bed)")
    if notes["cells_capped_below_alpha_max"]:
        warnings.append(f"{notes['cells_capped_below_alpha_max']} cells had alpha at or above "
                        f"alpha_max = {scene.domain.alpha_max:g}; kept {PACKING_MARGIN:g} "
                        "below it so that g0 stays finite")
    return CoupledResult(times=times, cell_fields=cell_fields, bed_columns=bed, stats=run_stats,
                         wall_time_s=wall, warnings=warnings)


def _advance(states, rows, aux, arrays, method, t0, t1, steps, stats, status, reached, idx,
             scene):
    integrate.integrate_cells(states, rows, aux, arrays.params, arrays.config, t0, t1, steps,
                              method.rtol, method.atol, integrate.MAX_STEPS_PER_INTERVAL, stats, status, reached)
    bad = np.flatnonzero(status != integrate.OK)
    if bad.size:
        c = int(bad[0])
        raise SimulationError(
            f"{scene.source}: cell {int(idx[c])} (alpha {rows[c, P.ALPHA]:.4g}, Theta "
            f"{rows[c, P.THETA]:.3g} m2/s2) stopped at t = {reached[c]:.6g} s: "
            f"{integrate.failure_reason(status[c], stats[c], arrays.params, arrays.config)}; "
            f"{bad.size} cell(s) affected"
            + failure_hint(scene, arrays, states[c], aux))


def _outputs(scene, arrays, aux, cells, rows, active, spray, idx, times, history):
    n = cells.n_cells
    volumes = np.asarray(cells.cell_volume, dtype=float)
    v_active = volumes[idx]
    bed_volume = float(volumes.sum())
    cell_fields = []
    bed = {"time_s": times}
    rho = scene.material.density
    pd = arrays.droplet_mass
    for k, states in enumerate(history):
        populations = []
        cols = moment_outputs(scene, arrays, states, aux, populations=populations)
        fields = {"alpha": np.asarray(cells.alpha, dtype=float),
                  "Theta": np.asarray(cells.theta, dtype=float),
                  "active": active.astype(float), "spray_zone": spray.astype(float)}
        for name, values in cols.items():
            full = np.zeros(n)
            full[idx] = values
            fields[name] = full
        cell_fields.append(fields)
        for name, values in cols.items():
            if name.startswith("M") or name == "droplet_number_density":
                bed.setdefault(name, np.zeros(len(times)))[k] = float(
                    np.sum(values * v_active) / bed_volume)
        # bed d32/d43 from every cell's population, weighted by cell volume
        ws = [np.asarray(w) * v_active[c] for c, (w, _, _) in enumerate(populations)]
        ps = [np.asarray(p) for _, p, _ in populations]
        if scene.separate_droplets and "droplet_number_density" in cols:
            ws.append(np.array([np.sum(cols["droplet_number_density"] * v_active)]))
            ps.append(np.array([pd]))
        d32, d43 = mean_diameters(np.concatenate(ws), np.concatenate(ps), rho)
        bed.setdefault("d32_m", np.zeros(len(times)))[k] = d32
        bed.setdefault("d43_m", np.zeros(len(times)))[k] = d43
        m10 = bed["M10"][k]
        bed.setdefault("binder_fraction", np.zeros(len(times)))[k] = (
            bed["M01"][k] / m10 if scene.bivariate and m10 > 0 else 0.0)
        bed.setdefault("bed_mass_kg", np.zeros(len(times)))[k] = m10 * bed_volume
        if scene.bivariate:
            bed.setdefault("bed_binder_mass_kg", np.zeros(len(times)))[k] = (
                bed["M01"][k] * bed_volume)
    return cell_fields, bed


# ---------------------------------------------------------------------------- CLI verbs
def couple_command(args) -> int:
    """``pbe-cfd couple [SCENE] --out DIR``."""
    from . import output
    from .cli import DEFAULT_COUPLED, _Progress
    from .distributed import executor_from_args, prepare_args
    from .scene import describe, load_scene

    prepare_args(args)  # --resume DIR: the output directory and the scene of the first run
    scene = load_scene(args.scene or DEFAULT_COUPLED)
    if scene.domain.type != "openfoam":
        raise SceneError(scene.source, "domain.type",
                         "`pbe-cfd couple` needs type = \"openfoam\"; use `pbe-cfd run` for "
                         "well-mixed scenes")
    if args.run_case:
        scene = _fresh_case(scene, args.mesh)
    domain = load_domain(scene, need_flux=scene.transport is not None)
    executor = executor_from_args(args, scene, domain)  # --workers/--scheduler, or None
    progress = _Progress(f"{scene.name} ({domain.cells.n_cells} cells)")
    try:
        result = run_coupled(scene, domain, progress=progress, threads=args.threads,
                             executor=executor)
    finally:
        progress.close()
        if executor is not None:
            executor.close()
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = Path(args.out)
    with output.atomic_directory(out) as tmp:
        write_coupled(tmp, scene, domain, result)
        if args.foam_fields and not scene.domain.case.startswith(BUNDLED_PREFIX):
            written = _write_foam(scene, domain, result)
            if executor is not None:  # a decomposed case: the same fields per processor
                executor.mirror_to_processors(written)
    if executor is not None:
        executor.finish()  # the output is complete: drop the chunk store DIR.chunks/
    print(f"{scene.name}: {result.stats['active_cells']} of {result.stats['cells']} cells to "
          f"t = {scene.end_time:g} s in {result.wall_time_s:.2f} s "
          f"({result.stats['cell_steps_per_second']:.3g} cell-steps/s); wrote {out}/")
    return 0


def write_coupled(out_dir: Path, scene: Scene, domain: Domain, result: CoupledResult,
                  render: bool = True):
    """Write fields.pvd + .vtu, bed_moments.csv, summary.json and PNG renders into out_dir."""
    from . import output
    from .cfd.vtk import VtkSeries
    from .scene import describe

    with VtkSeries(out_dir / "vtk", domain.cells, name="pbe") as series:
        for t, fields in zip(result.times, result.cell_fields):
            series.write(t, fields)
    output.write_columns_csv(out_dir / "bed_moments.csv", result.bed_columns)
    output.write_json(out_dir / "summary.json", {
        "scene": describe(scene), "method": scene.method.name, "domain": domain.description,
        "wall_time_s": result.wall_time_s, "stats": result.stats, "warnings": result.warnings})
    if render:
        from .cfd.render import plot_bed_moments, render_series
        png = out_dir / "png"
        render_series(out_dir / "vtk", times=[result.times[0], result.times[-1]], png_dir=png)
        plot_bed_moments(out_dir / "bed_moments.csv", png / "bed_moments.png")


def _write_foam(scene, domain, result):
    """Write the final moment fields as volScalarFields into the case's time directory of the
    CFD fields they were computed from (ParaView's OpenFOAM reader lists numeric times only)."""
    from .cfd import openfoam as of
    case = Path(scene.domain.case)
    if not case.is_dir():
        return []
    units = {"M00": "[0 -3 0 0 0 0 0]", "M10": "[1 -3 0 0 0 0 0]", "M01": "[1 -3 0 0 0 0 0]",
             "M20": "[2 -3 0 0 0 0 0]", "M11": "[2 -3 0 0 0 0 0]", "M02": "[2 -3 0 0 0 0 0]",
             "d32_m": "[0 1 0 0 0 0 0]", "d43_m": "[0 1 0 0 0 0 0]",
             "droplet_number_density": "[0 -3 0 0 0 0 0]"}
    fields = {f"pbe.{k}": v for k, v in result.cell_fields[-1].items()
              if k in units or k == "binder_fraction"}
    dims = {f"pbe.{k}": u for k, u in units.items()}
    return of.write_foam_fields(case, of.time_name(case, domain.cells.time), fields,
                                dimensions=dims)


def _fresh_case(scene: Scene, mesh: str) -> Scene:
    from .cfd import openfoam as of
    target = Path("fluid-bed-case")
    if target.exists() and any(target.iterdir()):
        raise SceneError(scene.source, "domain.case",
                         f"--run-case: {target.resolve()} exists; remove it or run "
                         "`pbe-cfd case run --dir NEW` and point [domain] case at it")
    of.copy_case(of.default_case_dir(), target)
    of.run_case(target, mesh=mesh, log=lambda line: print(line, file=sys.stderr))
    return dataclasses.replace(scene, domain=dataclasses.replace(
        scene.domain, case=str(target.resolve()), time="latest"))


def case_command(args) -> int:
    """``pbe-cfd case run --mesh small --dir DIR``: copy and run the fluid-bed case."""
    from .cfd import openfoam as of
    target = Path(args.dir)
    try:
        of.copy_case(of.default_case_dir(), target)
        res = of.run_case(target, mesh=args.mesh, log=lambda line: print(line, file=sys.stderr))
    except of.OpenFOAMError as exc:
        print(f"pbe-cfd: error: {exc}", file=sys.stderr)
        return 1
    print(f"case {target} ({args.mesh}) ran to t = {res.latest_time:g} s; "
          + ", ".join(f"{k} {v:.1f} s" for k, v in res.wall_times.items()))
    return 0


def render_command(args) -> int:
    """``pbe-cfd render DIR``: PNGs of a coupled run's VTK series."""
    from .cfd.render import plot_bed_moments, render_series
    out = Path(args.dir)
    vtk_dir = out / "vtk" if (out / "vtk").is_dir() else out
    paths = render_series(vtk_dir, fields=args.fields, times=args.times, png_dir=out / "png")
    if (out / "bed_moments.csv").is_file():
        paths.append(plot_bed_moments(out / "bed_moments.csv", out / "png" / "bed_moments.png"))
    for p in paths:
        print(p)
    return 0
from .transport import transport_plan_lines  # noqa: E402
