"""The throughput study: cell-RHS evaluations and cell-steps per second against cells and
threads, the kernel-only ceiling, and the plain NumPy/SciPy baseline (``pbe-cfd bench
throughput``)."""
from __future__ import annotations

import dataclasses
import math
import statistics
import time
from pathlib import Path

import numba as nb
import numpy as np

from ..runs import model
from ..runs.batch import CellBatch, output_times
from ..methods.registry import METHODS
from ..physics import parameters as P
from ..physics.kernels import collision_velocity
from ..physics.properties import N_PROPS
from ..scene.scene import load_scene
from .breakdown import breakdown_markdown, rhs_breakdown
from .common import _git_describe, _machine_line, _say, _write_csv, machine_info
from .numpy_baseline import NumpyQMOM
from .sweeps import (cqmom_point_properties, laguerre_contraction_sweep, points_kernel_sweep,
                     qmom_kernel_sweep, qmom_node_properties, rhs_sweep)

DEFAULT_THROUGHPUT_SCENE = "study-ktgf"


# ============================================================================ throughput setup
def throughput_scene(method, order, scene_name=DEFAULT_THROUGHPUT_SCENE):
    """The throughput scene (ktgf, geometric + physical efficiency, separate droplets,
    injection) with the method and its order."""
    scene = load_scene(scene_name).with_method(name=method)
    return METHODS[method].bench_scene(scene, order)


def synthetic_cells(n_cells, seed=0, theta_range=(1e-6, 2e-4), alpha_range=(0.05, 0.55),
                    injection=2.0e10, spray_share=0.2):
    """Cell rows like the bundled bed's active cells: alpha uniform, Theta log-uniform over the
    bed's range [m2/s2], u0 = 4 sqrt(Theta / pi), injection in a share of them."""
    rng = np.random.default_rng(seed)
    cells = np.zeros((n_cells, P.N_CELL))
    cells[:, P.ALPHA] = rng.uniform(*alpha_range, n_cells)
    cells[:, P.THETA] = np.exp(rng.uniform(math.log(theta_range[0]), math.log(theta_range[1]),
                                           n_cells))
    cells[:, P.COLLISION_VELOCITY] = collision_velocity(cells[:, P.THETA])
    cells[:, P.INJECTION] = np.where(rng.random(n_cells) < spray_share, injection, 0.0)
    return cells


def trajectory_states(scene, arrays, aux):
    """Scaled states of the well-mixed run of ``scene`` at its output times (t > 0), up to a
    stopped cell."""
    times = output_times(scene)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    batch = CellBatch.for_scene(scene, arrays, aux, model.well_mixed_cell(scene),
                                state[None, :].copy())
    rows = []
    for k in range(1, len(times)):
        batch.advance(times[k - 1], times[k])
        if batch.failed().size:
            break
        rows.append(batch.states[0].copy())
    return np.array(rows)


def cell_states(trajectory, n_cells, seed=1):
    """One state per cell: a random row of the trajectory with the number density scaled by a
    random factor in [0.3, 1] (all moments scale alike: still realizable)."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(trajectory), n_cells)
    factor = rng.uniform(0.3, 1.0, n_cells)
    return np.ascontiguousarray(trajectory[pick] * factor[:, None])


@dataclasses.dataclass
class ThroughputCase:
    """Everything one method needs for the throughput measurements."""
    method: str
    order: int
    scene: object
    arrays: object
    aux: np.ndarray
    trajectory: np.ndarray
    aux_build_s: float = 0.0

    @property
    def label(self):
        if isinstance(self.order, tuple):
            return (f"{METHODS[self.method].order_label} x N2 = {self.order[0]} x "
                    f"{self.order[1]}")
        return f"{METHODS[self.method].order_label} = {self.order}"


def throughput_case(method, order, theta_range=(1e-6, 2e-4), slices=24,
                    scene_name=DEFAULT_THROUGHPUT_SCENE):
    """Build the scene, packed arrays, aux (a method whose aux is tabulated in Theta, the
    Laguerre ROM: on a grid of ``slices`` log-spaced values, as ``run_coupled`` does) and a
    trajectory of states."""
    entry = METHODS[method]
    scene = throughput_scene(method, order, scene_name)
    arrays = model.pack(scene)
    build = 0.0
    aux = entry.aux(scene, arrays, None)
    traj = trajectory_states(scene, arrays, aux)
    if entry.tabulates_theta:
        # trajectory with the well-mixed (fixed u0) data, measurements with the Theta grid
        t0 = time.perf_counter()
        aux = entry.aux(dataclasses.replace(
            scene, domain=dataclasses.replace(scene.domain, collision_velocity=None)), arrays,
            np.geomspace(theta_range[0], theta_range[1], slices))
        build = time.perf_counter() - t0
    return ThroughputCase(method, order, scene, arrays, aux, traj, build)


def _time_call(fn, repeats):
    """(best, median) wall seconds of ``repeats`` calls of fn()."""
    walls = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
    return min(walls), statistics.median(walls)


def measure_rhs_rate(case, n_cells, threads, target_evals=200_000, repeats=3, seed=0):
    """Cell-RHS evaluations per second (best and median of ``repeats``) on n_cells cells."""
    nb.set_num_threads(threads)
    cells = synthetic_cells(n_cells, seed=seed)
    states = cell_states(case.trajectory, n_cells, seed=seed + 1)
    out = np.zeros_like(states)
    params, config = case.arrays.params, case.arrays.config
    reps = max(1, int(round(target_evals / n_cells)))
    rhs_sweep(states, cells, case.aux, params, config, 1, out)          # compile / warm
    best, median = _time_call(lambda: rhs_sweep(states, cells, case.aux, params, config, reps,
                                                out), repeats)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError(f"{case.label}: non-finite RHS in the throughput sweep")
    evals = reps * n_cells
    return evals / best, evals / median


def measure_ceiling(case, n_cells, threads, target_evals=400_000, repeats=3, seed=0):
    """Kernel-only rate (cells per second, best and median): see qmom_kernel_sweep and
    laguerre_contraction_sweep."""
    nb.set_num_threads(threads)
    cells = synthetic_cells(n_cells, seed=seed)
    states = cell_states(case.trajectory, n_cells, seed=seed + 1)
    params, config = case.arrays.params, case.arrays.config
    reps = max(1, int(round(target_evals / n_cells)))
    if case.method == "qmom":
        n_max = int(config[P.ORDER])
        props = np.zeros((n_cells, n_max + 1, N_PROPS))
        counts = np.zeros(n_cells, dtype=np.int64)
        factors = np.zeros(n_cells)
        qmom_node_properties(states, cells, params, config, props, counts, factors)
        out = np.zeros(n_cells)
        qmom_kernel_sweep(props, counts, cells, factors, params, config, 1, out)
        best, median = _time_call(lambda: qmom_kernel_sweep(props, counts, cells, factors,
                                                            params, config, reps, out), repeats)
    elif case.method == "laguerre":
        out = np.zeros_like(states)
        laguerre_contraction_sweep(states, case.aux, 1, out)
        best, median = _time_call(lambda: laguerre_contraction_sweep(states, case.aux, reps,
                                                                     out), repeats)
    elif case.method == "cqmom":
        n_points = int(config[P.ORDER] * config[P.BINDER_NODES])
        props = np.zeros((n_cells, n_points + 1, N_PROPS))
        counts = np.zeros(n_cells, dtype=np.int64)
        factors = np.zeros(n_cells)
        cqmom_point_properties(states, cells, params, config, props, counts, factors)
        out = np.zeros(n_cells)
        points_kernel_sweep(props, counts, cells, factors, params, config, 1, out)
        best, median = _time_call(lambda: points_kernel_sweep(props, counts, cells, factors,
                                                              params, config, reps, out),
                                  repeats)
    else:                       # a method without a kernel-only sweep: no ceiling to quote
        return math.nan, math.nan
    evals = reps * n_cells
    return evals / best, evals / median


def measure_steps(case, n_cells, threads, interval=1.0, seed=0, rtol=None, atol=None):
    """Cell-steps per second of ``integrate_cells`` on n_cells cells over one interval [s]
    after a warm-up interval (which also fills each cell's step memory). Returns a dict with
    accepted steps, RHS calls, wall time and the count of cells that did not finish."""
    nb.set_num_threads(threads)
    batch = CellBatch(
        params=case.arrays.params, config=case.arrays.config, aux=case.aux,
        rows=synthetic_cells(n_cells, seed=seed),
        states=cell_states(case.trajectory, n_cells, seed=seed + 1),
        rtol=case.scene.method.rtol if rtol is None else rtol,
        atol=case.scene.method.atol if atol is None else atol,
        steps=np.full(n_cells, interval * 1e-3))
    batch.advance(0.0, interval)                   # warm-up
    batch.stats_counts[...] = 0
    t0 = time.perf_counter()
    batch.advance(interval, 2 * interval)
    wall = time.perf_counter() - t0
    st = batch.stats()
    accepted = st["accepted_steps"]
    return {"cell_steps_per_s": accepted / wall if wall > 0 else float("nan"),
            "accepted": accepted, "rhs_calls": st["rhs_calls"],
            "rejected": st["rejected_error"] + st["rejected_realizability"],
            "wall_s": wall, "failed_cells": int(batch.failed().size),
            "rhs_per_s_in_steps": st["rhs_calls"] / wall if wall > 0 else 0.0}


def measure_baseline(case, n_cells=4, interval=1.0, rhs_samples=200, seed=0, rtol=None,
                     atol=None):
    """Rates of the plain NumPy/SciPy path (one core, Python): RHS evaluations per second on
    ``rhs_samples`` cell states, and solve_ivp (RK23, the same tolerances and interval as
    ``measure_steps``, after the same warm-up interval) on ``n_cells`` cells, extrapolated per
    cell."""
    from scipy.integrate import solve_ivp
    base = NumpyQMOM(case.arrays.params, case.arrays.config)
    cells = synthetic_cells(max(n_cells, rhs_samples), seed=seed)
    states = cell_states(case.trajectory, max(n_cells, rhs_samples), seed=seed + 1)
    t0 = time.perf_counter()
    for i in range(rhs_samples):
        base.rhs(0.0, states[i], cells[i])
    rhs_rate = rhs_samples / (time.perf_counter() - t0)
    rtol = case.scene.method.rtol if rtol is None else rtol
    atol = case.scene.method.atol if atol is None else atol
    nfev = 0
    steps = 0
    wall = 0.0
    for i in range(n_cells):
        y0 = states[i].copy()
        warm = solve_ivp(base.rhs, (0.0, interval), y0, method="RK23", rtol=rtol, atol=atol,
                         args=(cells[i],))
        t0 = time.perf_counter()
        sol = solve_ivp(base.rhs, (interval, 2 * interval), warm.y[:, -1], method="RK23",
                        rtol=rtol, atol=atol, args=(cells[i],))
        wall += time.perf_counter() - t0
        nfev += sol.nfev
        steps += len(sol.t) - 1
    return {"rhs_per_s": rhs_rate, "cell_steps_per_s": steps / wall if wall > 0 else 0.0,
            "rhs_per_s_in_solve_ivp": nfev / wall if wall > 0 else 0.0, "cells": n_cells,
            "steps": steps, "nfev": nfev, "wall_s": wall}


# ============================================================================ throughput study
def throughput_study(out_dir="bench-out", quick=False, cells=None, threads=None, methods=None,
                     interval=None, quiet=False, scene_name=DEFAULT_THROUGHPUT_SCENE) -> dict:
    """Run the throughput study and write throughput.csv, throughput.md, throughput.png and
    machine.json into ``out_dir``. Returns the rows (see module doc)."""
    cells = cells or ((100, 1000) if quick else (100, 1000, 10_000, 100_000))
    max_threads = nb.config.NUMBA_NUM_THREADS
    threads = threads or tuple(t for t in (1, 2) if t <= max_threads)
    methods = methods or ((("qmom", 2), ("qmom", 3), ("eqmom", 3), ("laguerre", 2),
                           ("laguerre", 3), ("cqmom", (2, 2))) if quick
                          else (("qmom", 2), ("qmom", 3), ("qmom", 4), ("eqmom", 2),
                                ("eqmom", 3), ("laguerre", 2), ("laguerre", 3),
                                ("laguerre", 4), ("cqmom", (2, 2)), ("cqmom", (3, 2)),
                                ("cqmom", (3, 3))))
    interval = interval or (0.05 if quick else 0.1)
    repeats = 1 if quick else 3
    target = 20_000 if quick else 300_000
    machine = machine_info()
    _say(quiet, f"throughput study: {len(methods)} methods x {len(cells)} cell counts x "
         f"threads {threads}")
    rows = []
    baseline = None
    cases = {}
    for method, order in methods:
        t0 = time.perf_counter()
        case = throughput_case(method, order, scene_name=scene_name)
        cases[(method, order)] = case
        setup = time.perf_counter() - t0
        _say(quiet, f"  {case.label}: setup {setup:.1f} s")
        for th in threads:
            ceiling = measure_ceiling(case, max(cells), th, target_evals=2 * target,
                                      repeats=repeats)
            for n in cells:
                rhs_best, rhs_median = measure_rhs_rate(case, n, th, target_evals=target,
                                                        repeats=repeats)
                steps = measure_steps(case, n, th, interval=interval)
                rows.append({"method": method, "order": order, "label": case.label,
                             "cells": n, "threads": th, "rhs_per_s": rhs_best,
                             "rhs_per_s_median": rhs_median,
                             "cell_steps_per_s": steps["cell_steps_per_s"],
                             "rhs_per_step": steps["rhs_calls"] / max(steps["accepted"], 1),
                             "rejected_share": steps["rejected"] / max(steps["accepted"]
                                                                      + steps["rejected"], 1),
                             "failed_cells": steps["failed_cells"],
                             "ceiling_per_s": ceiling[0],
                             "share_of_ceiling": rhs_best / ceiling[0],
                             "aux_build_s": case.aux_build_s})
                _say(quiet, f"    {n:>6d} cells, {th} thr: {rhs_best:.3g} RHS/s, "
                     f"{steps['cell_steps_per_s']:.3g} cell-steps/s "
                     f"(ceiling {ceiling[0]:.3g}/s)")
    # plain NumPy/SciPy baseline (QMOM N = 3 if measured, else the first QMOM)
    qm = [k for k in cases if k[0] == "qmom"]
    if qm:
        key = ("qmom", 3) if ("qmom", 3) in cases else qm[0]
        _say(quiet, f"  NumPy/SciPy baseline, QMOM N = {key[1]} ...")
        baseline = measure_baseline(cases[key], n_cells=1 if quick else 4, interval=interval,
                                    rhs_samples=30 if quick else 300)
        baseline["order"] = key[1]
    breakdown = []
    for (method, order), case in cases.items():
        if method in ("qmom", "laguerre"):
            n = min(max(cells), 10_000)
            _say(quiet, f"  {case.label}: RHS breakdown on {n} cells, 1 thread ...")
            breakdown.append(rhs_breakdown(case, synthetic_cells(n, seed=0),
                                           cell_states(case.trajectory, n, seed=1),
                                           reps=2 if quick else 20, repeats=repeats + 2))
    result = {"machine": machine, "commit": _git_describe(), "quick": quick,
              "interval_s": interval, "repeats": repeats, "rows": rows, "baseline": baseline,
              "scene": scene_name, "breakdown": breakdown}
    _write_throughput(Path(out_dir), result)
    return result


def _speedups(result):
    """Speed-ups of the numba path over the NumPy/SciPy baseline (largest cell count)."""
    base = result.get("baseline")
    if not base:
        return []
    order = base["order"]
    rows = [r for r in result["rows"] if r["method"] == "qmom" and r["order"] == order]
    if not rows:
        return []
    n = max(r["cells"] for r in rows)
    out = []
    for r in rows:
        if r["cells"] != n:
            continue
        out.append({"threads": r["threads"], "cells": n,
                    "rhs": r["rhs_per_s"] / base["rhs_per_s"],
                    "steps": r["cell_steps_per_s"] / max(base["cell_steps_per_s"], 1e-300)})
    return out


def thread_scaling(rows, label, n_cells, threads=(1, 2)) -> dict:
    """Ratios (second thread count / first) of one method's rates measured in one run on
    n_cells cells: RHS/s (medians of the repeats), kernel-only ceiling, cell-steps/s."""
    pick = {r["threads"]: r for r in rows if r["label"] == label and r["cells"] == n_cells}
    lo, hi = threads
    if lo not in pick or hi not in pick:
        return {}
    a, b = pick[lo], pick[hi]
    return {key: b[key] / a[key] for key in ("rhs_per_s_median", "ceiling_per_s",
                                             "cell_steps_per_s")
            if a.get(key) and b.get(key) is not None}


def thread_scaling_markdown(rows, labels, n_cells, threads) -> list:
    """The 2-thread / 1-thread table (empty without both thread counts)."""
    if len(threads) < 2:
        return []
    pair = (threads[0], threads[-1])
    out = ["", f"**Thread scaling** ({pair[1]} thr / {pair[0]} thr, {n_cells:g} cells, "
           "same run; on a shared machine the load average below bounds what a second "
           "thread can give):", "",
           "| method | RHS/s (median) | kernel-only ceiling | cell-steps/s |", "|---|---|---|---|"]
    for label in labels:
        sc = thread_scaling(rows, label, n_cells, pair)
        out.append(f"| {label} | " + " | ".join(
            f"{sc[k]:.2f}x" if k in sc else "-"
            for k in ("rhs_per_s_median", "ceiling_per_s", "cell_steps_per_s")) + " |")
    return out


def throughput_markdown(result) -> str:
    """Throughput tables (RHS/s, cell-steps/s per method, cells, threads) as Markdown."""
    rows = result["rows"]
    cells = sorted({r["cells"] for r in rows})
    threads = sorted({r["threads"] for r in rows})
    labels = []
    for r in rows:
        if r["label"] not in labels:
            labels.append(r["label"])

    def cell(label, n, th, key):
        for r in rows:
            if r["label"] == label and r["cells"] == n and r["threads"] == th:
                return r[key]
        return float("nan")

    out = [f"Scene `{result['scene']}` (ktgf kernel, geometric and physical efficiency, "
           "droplets as their own population, injection in 20% of the cells); cells with "
           "alpha 0.05-0.55 and Theta 1e-6-2e-4 m2/s2 (log-uniform, the bundled bed's range); "
           "states from the well-mixed run, number density scaled per cell.", ""]
    for key, title in (("rhs_per_s", "Cell-RHS evaluations per second"),
                       ("cell_steps_per_s", "Cell-steps per second (accepted RK3(2) steps, "
                                            "realizability checks and re-projection included)")):
        out += [f"**{title}**", ""]
        head = "| method | " + " | ".join(f"{n:g} cells, {th} thr" for n in cells
                                          for th in threads) + " |"
        out += [head, "|" + "---|" * (head.count("|") - 1)]
        for label in labels:
            out.append(f"| {label} | " + " | ".join(f"{cell(label, n, th, key):.3g}"
                                                    for n in cells for th in threads) + " |")
        out.append("")
    n = max(cells)
    reference = next((r["label"] for r in rows if r["method"] == "qmom" and r["order"] == 3),
                     None)
    conditional = [label for label in labels if label.startswith(METHODS["cqmom"].order_label)]
    if reference and conditional:
        out += [f"**CQMOM against {reference}** (RHS/s ratio, {n:g} cells): " + "; ".join(
            f"{label}: " + ", ".join(
                f"{cell(label, n, th, 'rhs_per_s') / cell(reference, n, th, 'rhs_per_s'):.2f}"
                f" ({th} thr)" for th in threads) for label in conditional), ""]
    out += [f"**Kernel-only ceiling and share** ({n:g} cells): QMOM -- the registry pair rates "
            "its RHS needs (N(N+1)/2 granule pairs + N droplet captures) on precomputed "
            "property rows; CQMOM -- the same over its N1 N2 points (its RHS evaluates the "
            "collision frequency once per pair of size nodes only, so it can beat this); "
            "Laguerre -- the bare quadratic form of one tensor slice.", ""]
    head = "| method | " + " | ".join(f"ceiling {th} thr [1/s] | share {th} thr"
                                      for th in threads) + " | RHS calls per step |"
    out += [head, "|" + "---|" * (head.count("|") - 1)]
    for label in labels:
        parts = []
        for th in threads:
            parts.append(f"{cell(label, n, th, 'ceiling_per_s'):.3g}")
            parts.append(f"{100 * cell(label, n, th, 'share_of_ceiling'):.0f}%")
        out.append(f"| {label} | " + " | ".join(parts)
                   + f" | {cell(label, n, threads[0], 'rhs_per_step'):.2f} |")
    out += thread_scaling_markdown(rows, labels, n, threads)
    base = result.get("baseline")
    if base:
        out += ["", f"**Plain NumPy/SciPy QMOM N = {base['order']}** (bench.NumpyQMOM: "
                "numpy Wheeler + eigh per call, Python loops; one core): "
                f"{base['rhs_per_s']:.3g} RHS/s; solve_ivp RK23 per cell: "
                f"{base['cell_steps_per_s']:.3g} cell-steps/s "
                f"({base['rhs_per_s_in_solve_ivp']:.3g} RHS/s inside solve_ivp, measured on "
                f"{base['cells']} cells and extrapolated per cell).", ""]
        sp = _speedups(result)
        if sp:
            out += ["| speed-up over NumPy/SciPy | " + " | ".join(
                f"{s['threads']} thr" for s in sp) + " |",
                "|---|" + "---|" * len(sp),
                "| RHS evaluations | " + " | ".join(f"{s['rhs']:.0f}x" for s in sp) + " |",
                "| cell-steps | " + " | ".join(f"{s['steps']:.0f}x" for s in sp) + " |"]
    if result.get("breakdown"):
        out += [""] + breakdown_markdown(result["breakdown"])
    out += ["", f"RHS rates: best of {result['repeats']} sweeps; cell-steps: one interval of "
            f"{result['interval_s']:g} s after a warm-up interval. Machine: "
            f"{_machine_line(result['machine'])}."]
    return "\n".join(out) + "\n"


def plot_throughput(path, result):
    from ..viz import plotting  # noqa: F401 - selects the Agg backend
    import matplotlib.pyplot as plt

    rows = result["rows"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    labels = []
    for r in rows:
        if r["label"] not in labels:
            labels.append(r["label"])
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, title in ((axes[0], "rhs_per_s", "cell-RHS evaluations / s"),
                           (axes[1], "cell_steps_per_s", "cell-steps / s")):
        for i, label in enumerate(labels):
            for th, ls in ((1, "--"), (2, "-")):
                sel = sorted((r["cells"], r[key]) for r in rows
                             if r["label"] == label and r["threads"] == th)
                if not sel:
                    continue
                ax.plot([s[0] for s in sel], [s[1] for s in sel], ls, marker="o",
                        color=colours[i % len(colours)], label=f"{label}, {th} thr")
        base = result.get("baseline")
        if base:
            v = base["rhs_per_s"] if key == "rhs_per_s" else base["cell_steps_per_s"]
            ax.axhline(v, color="k", lw=1, ls=":",
                       label=f"NumPy/SciPy QMOM N = {base['order']} (1 core)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cells")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2, loc="center left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _write_throughput(out_dir, result):
    from ..io import output
    lines = [["method", "order", "cells", "threads", "rhs_per_s", "rhs_per_s_median",
              "cell_steps_per_s", "rhs_per_step", "rejected_share", "failed_cells",
              "ceiling_per_s", "share_of_ceiling", "aux_build_s"]]
    for r in result["rows"]:
        lines.append([r[k] for k in lines[0]])
    base = result.get("baseline")
    if base:
        lines.append(["numpy-scipy-qmom", base["order"], base["cells"], 1, base["rhs_per_s"],
                      base["rhs_per_s"], base["cell_steps_per_s"],
                      base["nfev"] / max(base["steps"], 1), "", "", "", "", ""])
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / "throughput.csv", lines)
        (d / "throughput.md").write_text(throughput_markdown(result))
        plot_throughput(d / "throughput.png", result)
        output.write_json(d / "throughput.json", result)
        output.write_json(d / "machine.json", result["machine"])
