"""The integrator study: explicit vs implicit vs auto, and what transport splitting costs
(``pbe-cfd bench integrators``).

Well-mixed part: each scheme on the seed scene (QMOM N = 3, non-stiff), the ktgf study scene
(non-stiff), and a stiff cell (the ktgf scene next to packing, alpha = alpha_max - 1e-4 without
friction cap, Theta = 1e-4 m2/s2, injection 1e4 times the seed rate, smooth Stokes switch).
Wall time is the median of ``repeats`` runs (compile excluded); the error is the largest
relative difference of M00, M20, M11 and d43 over every output time against a reference run
of the explicit pair at a 100 times tighter tolerance (an independent step sequence and, for
implicit and auto, an independent scheme).

Transport part: the bundled ``fluid-bed-transport`` scene against the same scene without
``[transport]``: the solve phase (``phases['solve_s']``: first step to last, compile and
outputs excluded; median of ``repeats`` runs alternating between the two scenes in one
process, warm cache), the RHS calls, and the whole-process time of
``python -m pbe_cfd.cli couple`` (median of ``repeats``, one process each, alternating), and
their ratios.

Splitting part (``bench.splitting``): the transport scene at other split steps and with Lie
splitting, each against a tight Strang reference: cost and bed-moment differences.
"""
from __future__ import annotations

import dataclasses
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from ..scene.scene import load_scene
from ..runs.simulate import run_well_mixed
from .splitting import splitting_markdown, splitting_rows
from .common import _git_describe, _machine_line, _say, _write_simple, failure_status, \
    machine_info

SCHEMES = ("explicit", "implicit", "auto")
COMPARED = ("M00", "M20", "M11", "d43_m")
SEED_RATE = 1.485e8          # droplets/(m3 s): the seed scene's injection


def stiff_scene(end_time=2.0):
    """The ktgf study cell next to packing (alpha within 1e-4 of alpha_max, no friction cap,
    g0 = 1.9e4), Theta 1e-4 m2/s2, injection 1e4 x the seed rate, Stokes switch width 0.05;
    2 s by default (the explicit pair's reference needs ~1.3e4 steps per second here)."""
    scene = load_scene("study-ktgf")
    dom = dataclasses.replace(scene.domain, solids_fraction=0.62 - 1e-4,
                              granular_temperature=1e-4, alpha_min_friction=None)
    return dataclasses.replace(
        scene, domain=dom, end_time=end_time, output_interval=end_time / 10,
        binder_injection=dataclasses.replace(scene.binder_injection, rate=1e4 * SEED_RATE),
        material=dataclasses.replace(scene.material, stokes_switch_width=0.05))


def _with(scene, **method):
    return scene.with_method(**method)


def _error(columns, ref) -> float:
    worst = 0.0
    for key in COMPARED:
        a, b = np.asarray(columns[key]), np.asarray(ref[key])
        scale = np.abs(b)
        ok = scale > 0
        if np.any(ok):
            worst = max(worst, float(np.max(np.abs(a[ok] - b[ok]) / scale[ok])))
    return worst


def well_mixed_rows(scenes, repeats, quiet) -> list:
    """One row per scene and scheme: median wall [s], RHS calls, steps, error vs reference."""
    rows = []
    for label, scene in scenes:
        tight = _with(scene, integrator="explicit", rtol=scene.method.rtol / 100,
                      atol=scene.method.atol / 100)
        try:
            ref = run_well_mixed(tight).columns
        except Exception as exc:  # noqa: BLE001 - a failed reference is a result
            ref = None
            _say(quiet, f"  {label}: reference failed: {exc}")
        for scheme in SCHEMES:
            run = _with(scene, integrator=scheme)
            try:
                results = [run_well_mixed(run) for _ in range(repeats)]
            except Exception as exc:  # noqa: BLE001
                rows.append({"scene": label, "integrator": scheme, "wall_s": float("nan"),
                             "rhs_calls": 0, "accepted_steps": 0, "implicit_steps": 0,
                             "error": float("nan"), "status": failure_status(exc)})
                _say(quiet, f"  {label} {scheme}: failed: {exc}")
                continue
            res = results[0]
            wall = statistics.median(r.wall_time_s for r in results)
            rows.append({"scene": label, "integrator": scheme, "wall_s": wall,
                         "rhs_calls": res.stats["rhs_calls"],
                         "accepted_steps": res.stats["accepted_steps"],
                         "implicit_steps": res.stats["implicit_steps"],
                         "error": _error(res.columns, ref) if ref is not None
                         else float("nan"), "status": "ok"})
            _say(quiet, f"  {label} {scheme}: {wall:.3g} s, {res.stats['rhs_calls']} RHS, "
                 f"error {rows[-1]['error']:.2e}")
    return rows


def _scene_text_without_transport(text: str) -> str:
    """The scene file's text with its [transport] table removed."""
    out, skip = [], False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("["):
            skip = stripped == "[transport]"
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def _process_seconds(scene_path, out_dir) -> tuple[float, float]:
    """(wall [s], CPU [s] user + system) of one ``pbe_cfd.cli couple`` process."""
    from .transport_cost import _one_process
    res = _one_process(None, scene_path, out_dir)
    return res["wall_s"], res["cpu_s"]


def transport_rows(repeats, quiet, quick=False, baseline=None) -> list:
    """Solve phase and whole-process time of fluid-bed-transport with and without [transport].

    Both scenes are loaded and run once first (kernels compiled or loaded from the cache),
    then ``repeats`` times alternately in this process, so that load changes hit both alike;
    the solve phase is ``phases['solve_s']`` of the run (first step to last, no compile, no
    output); the first run's counters give the RHS calls and steps per cell and split step of
    the spray cells and the others (``transport_cost.per_cell_split_step``). The whole
    process (``python -m pbe_cfd.cli couple``, outputs and renders written) alternates the
    same way."""
    from ..runs.couple import run_coupled
    from ..runs.domain import load_domain
    from .transport_cost import CountingExecutor, per_cell_split_step
    with_transport = load_scene("fluid-bed-transport")
    text = Path(with_transport.source).read_text()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        plain_path = Path(tmp) / "fluid-bed-no-transport.toml"
        plain_path.write_text(_scene_text_without_transport(text))
        paths = {"with [transport]": Path(with_transport.source),
                 "without [transport]": plain_path}
        scenes, domains, per_cell = {}, {}, {}
        split = with_transport.transport.split_step   # both runs counted per this length
        for label, path in paths.items():
            scene = load_scene(str(path))
            if quick:
                scene = dataclasses.replace(scene, end_time=2.0, output_interval=1.0)
            scenes[label] = scene
            domains[label] = load_domain(scene, need_flux=scene.transport is not None)
            counting = CountingExecutor()                    # compile or load the kernels
            run_coupled(scene, domains[label], executor=counting)
            per_cell[label] = {"split_step_s": split, **per_cell_split_step(
                counting.counts, counting.spray, scene.end_time, split)}
        solve = {k: [] for k in paths}
        cpu = {k: [] for k in paths}
        source = {k: [] for k in paths}
        stats = {}
        for _ in range(repeats):
            for label in paths:
                cpu0 = time.process_time()
                res = run_coupled(scenes[label], domains[label])
                cpu[label].append(time.process_time() - cpu0)
                solve[label].append(res.phases["solve_s"])
                stats[label] = res.stats
                if "transport" in res.stats:
                    source[label].append(res.stats["transport"]["source_wall_s"])
        if baseline is not None:
            from .transport_cost import before_after_rows
            rows_ba = before_after_rows(baseline, paths, repeats, quiet)
        process = {k: [] for k in paths}
        if not quick:
            for _ in range(repeats):
                for label, path in paths.items():
                    process[label].append(_process_seconds(path, Path(tmp) / "out"))
        nan = float("nan")
        for label in paths:
            st = stats[label]
            rows.append({"scene": label, "solver_s": statistics.median(solve[label]),
                         "solver_all_s": [round(x, 4) for x in solve[label]],
                         "solver_cpu_s": statistics.median(cpu[label]),
                         "source_s": statistics.median(source[label]) if source[label]
                         else nan,
                         "process_s": statistics.median(p[0] for p in process[label])
                         if process[label] else nan,
                         "process_cpu_s": statistics.median(p[1] for p in process[label])
                         if process[label] else nan,
                         "accepted_steps": st["accepted_steps"],
                         "rejected_error": st["rejected_error"],
                         "rhs_calls": st["rhs_calls"],
                         "implicit_steps": st["implicit_steps"],
                         "exponential_steps": st.get("exponential_steps", 0),
                         "per_cell": per_cell[label]})
            _say(quiet, f"  {label}: solve {rows[-1]['solver_s']:.3g} s, process "
                 f"{rows[-1]['process_s']:.3g} s")
    if baseline is not None:
        rows.extend(rows_ba)
    return rows


def integrator_markdown(result) -> str:
    """The study's tables (Markdown)."""
    end_load = result.get("load_average_at_end")
    lines = [f"Machine: {_machine_line(result['machine'])}"
             + (f"; at the end {' / '.join(str(x) for x in end_load)}" if end_load else "")
             + f"; commit {result['commit']}; wall times are medians of {result['repeats']} runs.",
             "",
             "| scene | integrator | wall [s] | RHS calls | steps (implicit) | max rel. error |",
             "|---|---|---|---|---|---|"]
    for r in result["well_mixed"]:
        if r["status"] != "ok":
            lines.append(f"| {r['scene']} | {r['integrator']} | - | - | - | {r['status']} |")
            continue
        lines.append(f"| {r['scene']} | {r['integrator']} | {r['wall_s']:.3g} | "
                     f"{r['rhs_calls']} | {r['accepted_steps']} ({r['implicit_steps']}) | "
                     f"{r['error']:.1e} |")
    rows = [r for r in result["transport"] if "tree" not in r]
    before_after = [r for r in result["transport"] if "tree" in r]
    if rows:
        lines += ["", "| fluid-bed-transport | solve phase [s] | run CPU [s] | sources [s] "
                  "| process wall [s] | process CPU [s] | steps (implicit, exponential) "
                  "| error rejections | RHS calls |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['scene']} | {r['solver_s']:.3g} | {r['solver_cpu_s']:.3g} | "
                         f"{r['source_s']:.3g} | {r['process_s']:.3g} | "
                         f"{r['process_cpu_s']:.3g} | {r['accepted_steps']} "
                         f"({r['implicit_steps']}, {r.get('exponential_steps', 0)}) | "
                         f"{r.get('rejected_error', 0)} | {r['rhs_calls']} |")
        if len(rows) == 2:
            a, b = rows
            lines += ["", f"Ratios with / without transport: solve phase "
                      f"{a['solver_s'] / b['solver_s']:.2f}, RHS calls "
                      f"{a['rhs_calls'] / b['rhs_calls']:.2f}, run CPU "
                      f"{a['solver_cpu_s'] / b['solver_cpu_s']:.2f}, whole process wall "
                      f"{a['process_s'] / b['process_s']:.2f} (CPU "
                      f"{a['process_cpu_s'] / b['process_cpu_s']:.2f})."]
    from .transport_cost import per_cell_markdown
    lines += per_cell_markdown(rows)
    if before_after:
        from .transport_cost import before_after_markdown
        lines += before_after_markdown(before_after, result.get("baseline", "baseline"))
    if result.get("splitting"):
        plain = [r for r in rows if r["scene"] == "without [transport]"]
        lines += splitting_markdown(result["splitting"],
                                    plain[0]["rhs_calls"] if plain and not result.get("quick")
                                    else None)
    return "\n".join(lines) + "\n"


def integrator_study(out_dir="bench-out", quick=False, quiet=False, repeats=None,
                     baseline=None, parts=("well_mixed", "transport", "splitting")) -> dict:
    """Run the ``parts`` (quick: short scenes, one repeat, no subprocess timing) and write
    integrators.csv, integrators.md and integrators.json into out_dir. ``baseline``: a source
    tree (directory holding pbe_cfd/) whose transport ratios are measured in the same run
    (``bench.transport_cost``)."""
    repeats = repeats or (1 if quick else 3)
    machine = machine_info()                 # its load average: when the study started
    end = 20.0 if quick else None
    seed = load_scene("seed-wurster")
    ktgf = load_scene("study-ktgf")
    if end is not None:
        seed = dataclasses.replace(seed, end_time=end, output_interval=end / 4)
        ktgf = dataclasses.replace(ktgf, end_time=end, output_interval=end / 4)
    scenes = [("seed-wurster (QMOM)", seed), ("study-ktgf (QMOM)", ktgf),
              ("stiff: ktgf cell at packing, 1e4 x injection, 2 s", stiff_scene(2.0))]
    well_mixed = well_mixed_rows(scenes, repeats, quiet) if "well_mixed" in parts else []
    transport = transport_rows(repeats, quiet, quick=quick, baseline=baseline) \
        if "transport" in parts else []
    splitting = splitting_rows(quiet, quick=quick) if "splitting" in parts else []
    result = {"machine": machine, "commit": _git_describe(), "repeats": repeats,
              "quick": bool(quick), "well_mixed": well_mixed, "transport": transport,
              "splitting": splitting, "baseline": str(baseline) if baseline else None,
              "load_average_at_end": [round(x, 2) for x in os.getloadavg()]}
    rows = [{"part": "well-mixed", **r} for r in well_mixed] + \
        [{"part": "transport", **r} for r in transport] + \
        [{"part": "splitting", **r} for r in splitting]
    keys = list(dict.fromkeys(k for r in rows for k in r))
    _write_simple(out_dir, "integrators", [{k: r.get(k) for k in keys} for r in rows],
                  integrator_markdown(result), result)
    return result
