"""The ``pbe-cfd`` command line: run | plan | scenes | compare | couple | case | render | bench
| compile.

Argument parsing and one ``*_command`` function per verb, nothing else: each command reads its
arguments, calls the runs, studies and writers below, and prints what it wrote. The ``bench``
verb lives in ``cli_bench``, the argument types and checks the verbs share in ``cli_args``.

Exit codes: 0 success, 2 bad input (scene, arguments, files, an output place refused), 1 a
run that failed (or an OS error while writing its output), 130/143 interrupted by SIGINT/SIGTERM.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from .cli_args import add_overwrite as _add_overwrite
from .cli_args import fail as _fail
from .cli_args import positive_int as _positive_int
from .cli_args import threads_refusal as _threads_refusal
from .cli_bench import add_bench_parser

DEFAULT_WELL_MIXED = "seed-wurster"
DEFAULT_COUPLED = "fluid-bed"


def _compile_text(result):
    """The compile time apart from the run time in the printed summary."""
    if result.kernels_compiled:
        return f" (+ {result.compile_time_s:.1f} s compiling kernels, first run only)"
    if result.compile_time_s > 0:
        return f" (+ {result.compile_time_s:.2f} s loading compiled kernels)"
    return ""


def _process_age() -> float:
    """Wall seconds [s] since this process started (Linux /proc), 0 where unknown."""
    import os
    try:
        with open("/proc/self/stat") as fh:
            started = float(fh.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return max(uptime - started / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError, AttributeError):
        return 0.0


def _phases_text(phases) -> str:
    """One line: the wall seconds of each phase of a coupled run."""
    names = ("startup", "read", "setup", "compile", "solve", "assemble", "write", "render")
    return "phases [s]: " + ", ".join(f"{n} {phases[n + '_s']:.2f}" for n in names
                                      if n + "_s" in phases)


def write_size_distribution(directory, psd, labels, title, what) -> list:
    """psd.csv, psd.png and columns.json of a run into ``directory`` (a new output); only
    columns.json where the run has no size distribution (``psd`` None: no granules). Returns
    the names written."""
    from .io import output
    from .viz import psd_figure
    output.write_json(directory / "columns.json", labels)
    if psd is None:
        return ["columns.json"]
    output.write_columns_csv(directory / "psd.csv", psd)
    psd_figure.plot_psd(directory / "psd.png", psd, title=title,
                        metadata=output.figure_metadata("png", what))
    return ["psd.csv", "psd.png", "columns.json"]


def _add_library_warnings(found: list, caught) -> None:
    """Append the Python warnings ``caught`` (``warnings.catch_warnings(record=True)``) of a
    run to its warnings ``found``: each as its first line, once, never as a raw warning."""
    found.extend(m for m in (str(w.message).splitlines()[0] for w in caught) if m not in found)


def run_command(args):
    """``pbe-cfd run [SCENE] --out DIR``: a well-mixed run."""
    from .io import output
    from .viz import plotting
    from .util.progress import Progress
    from .scene.scene import describe, load_scene
    from .runs.simulate import run_well_mixed

    scene = load_scene(args.scene or DEFAULT_WELL_MIXED)
    if scene.domain.type != "well-mixed":
        return _fail(f"{scene.source}: [domain] type is \"openfoam\"; use `pbe-cfd couple`")
    out = output.prepare_directory(args.out, args.overwrite, kind="run",   # before any work
                                   inputs=[("the scene", scene.source)])
    progress = Progress(f"{scene.name} ({scene.method.name})")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = run_well_mixed(scene, progress=progress)
    finally:
        progress.close()
    _add_library_warnings(result.warnings, caught)
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    with output.atomic_directory(out, args.overwrite, kind="run") as tmp:
        output.write_columns_csv(tmp / "moments.csv", result.columns)
        output.write_json(tmp / "summary.json", {
            "scene": describe(scene), "method": scene.method.name,
            "wall_time_s": result.wall_time_s, "compile_time_s": result.compile_time_s,
            "kernels_compiled": result.kernels_compiled, "stats": result.stats,
            "warnings": result.warnings})
        plotting.plot_trajectories(tmp / "moments.png", [(scene.method.name, result.columns)],
                                   title=f"{scene.name}: {scene.method.name}",
                                   metadata=output.figure_metadata("png", "run"))
        sizes = write_size_distribution(tmp, result.psd, result.labels,
                                        f"{scene.name}: {scene.method.name}", "run")
    print(f"{scene.name}: {scene.method.name} to t = {scene.end_time:g} s in "
          f"{result.wall_time_s:.2f} s{_compile_text(result)}; wrote "
          f"{args.out}/moments.csv, summary.json, moments.png, {', '.join(sizes)}")
    return 0


def plan_command(args):
    """``pbe-cfd plan SCENE``: what a scene computes."""
    from .runs.batch import check_physics
    from .runs.plan import describe_plan
    from .scene.scene import load_scene

    scene = load_scene(args.scene)
    check_physics(scene)           # what a run would refuse, plan refuses too
    print(describe_plan(scene))
    return 0


def scenes_command(args):
    """``pbe-cfd scenes``: the bundled scenes."""
    from .scene.scene import EFFECTS, bundled_scenes, load_scene

    for name, path in sorted(bundled_scenes().items()):
        scene = load_scene(path)
        effects = [t for t in EFFECTS if getattr(scene, t) is not None]
        print(f"{name:24s} {scene.domain.type:10s} {scene.method.name:9s} "
              f"end {scene.end_time:g} s  effects: {', '.join(effects) or 'none'}")
    return 0


def compare_command(args):
    """``pbe-cfd compare A B --out F.png``: overlay moment trajectories (a coupled run: its
    bed averages)."""
    from .io.results import compare_runs
    return compare_runs(args.results, args.out, args.overwrite)


def _cluster_wanted(args) -> bool:
    return bool(args.scheduler or args.workers or args.resume or args.decompose)


def _apply_resume(args):
    """``--resume DIR``: ``--out DIR`` and, when not given, SCENE and ``--chunks`` as the
    earlier run recorded them."""
    from .runs.distributed import resume_manifest
    args.out = args.resume
    manifest = resume_manifest(args.resume)
    if not args.scene and manifest.get("scene"):
        args.scene = manifest["scene"]
    if args.chunks is None and manifest.get("partition") in ("blocks", "flux graph"):
        args.chunks = manifest.get("chunks")      # the same blocks as the first run


def _fresh_case(scene, mesh: str, overwrite: bool = False):
    """--run-case: run the bundled OpenFOAM case in ./fluid-bed-case and point the scene at
    it (an earlier case pbe-cfd made there is replaced only with --overwrite)."""
    import dataclasses

    from .runs.batch import SimulationError
    from .io.openfoam import cases
    from .io import openfoam as of
    target = Path("fluid-bed-case")
    try:
        cases.copy_and_run(target, mesh, overwrite, flag="--run-case: fluid-bed-case",
                           log=lambda line: print(line, file=sys.stderr))
    except of.OpenFOAMError as exc:
        raise SimulationError(f"--run-case: {exc}") from None
    return dataclasses.replace(scene, domain=dataclasses.replace(
        scene.domain, case=str(target.resolve()), time="latest"))


def couple_command(args):
    """``pbe-cfd couple [SCENE] --out DIR``: the per-cell run over an OpenFOAM bed."""
    from .io import output
    from .viz import figure_pool

    refusal = _threads_refusal(args.threads)
    if refusal:
        return _fail(refusal)
    from .runs import coupling_command
    if coupling_command.wanted(args, DEFAULT_COUPLED):     # [coupling]: two-way
        return coupling_command.two_way(args, DEFAULT_COUPLED)
    import time
    if args.resume:
        _apply_resume(args)
    t_read = time.perf_counter()
    scene = _coupled_scene(args)
    out = output.prepare_directory(args.out, args.overwrite, kind="couple",   # before any work
                                   inputs=_couple_inputs(scene, args))
    if _cluster_wanted(args) and not args.resume:
        from .runs.distributed import check_store
        check_store(args.out, args.overwrite)
    phases = {"startup_s": _process_age(), "read_s": time.perf_counter() - t_read}
    if not _cluster_wanted(args):
        figure_pool.start_processes()   # they load matplotlib while the run computes
    try:
        return _couple(args, scene, out, phases)
    finally:
        figure_pool.stop_processes()


def _coupled_scene(args):
    """The scene of ``couple`` (SCENE, else the bundled fluid bed); SceneError unless its
    domain is an OpenFOAM bed."""
    from .scene.scene import SceneError, load_scene
    scene = load_scene(args.scene or DEFAULT_COUPLED)
    if scene.domain.type != "openfoam":
        raise SceneError(scene.source, "domain.type",
                         "`pbe-cfd couple` needs type = \"openfoam\"; use `pbe-cfd run` for "
                         "well-mixed scenes")
    return scene


def _couple_inputs(scene, args) -> list:
    """What a coupled run reads (``(what, path)`` pairs), which its --out must not be."""
    from .runs.domain import case_path
    inputs = [("the scene", scene.source)]
    if args.run_case:
        inputs.append(("the case --run-case makes", Path("fluid-bed-case")))
    elif (path := case_path(scene)) is not None:
        if path.suffix == ".vtu":
            inputs += [("the snapshot", path),
                       ("the snapshot's flux", path.with_name(path.stem + "_flux.npz"))]
        else:
            inputs.append(("the OpenFOAM case", path))
    return inputs


def _couple(args, scene, out, phases):
    """The run and its outputs (``couple_command`` after the output directory was checked)."""
    import time

    t_read = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        return _couple_recorded(args, scene, out, phases, t_read, caught)


def _couple_recorded(args, scene, out, phases, t_read, caught):
    """``_couple`` with Python warnings recorded in ``caught`` (written as one-line warnings
    and into summary.json, never as raw warning lines)."""
    import time

    from .io import output
    from .runs.couple import check_foam_fields, run_coupled, write_coupled, write_foam_fields
    from .runs.domain import load_domain
    from .runs.executor import SerialExecutor
    from .util.progress import Progress

    if args.run_case:
        scene = _fresh_case(scene, args.mesh, args.overwrite)
    domain = load_domain(scene, need_flux=scene.transport is not None)
    phases["read_s"] += time.perf_counter() - t_read
    if args.foam_fields:
        check_foam_fields(scene, domain, args.overwrite)
    executor = SerialExecutor()
    if _cluster_wanted(args):
        from .runs.distributed import make_executor
        executor = make_executor(scene, domain, args.out, scene_arg=args.scene,
                                 scheduler=args.scheduler, workers=args.workers,
                                 chunks=args.chunks, decompose=args.decompose,
                                 resume=bool(args.resume))
    progress = Progress(f"{scene.name} ({domain.cells.n_cells} cells)")
    try:
        result = run_coupled(scene, domain, progress=progress, threads=args.threads,
                             executor=executor)
    finally:
        progress.close()
        executor.close()
    _add_library_warnings(result.warnings, caught)
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    with output.atomic_directory(out, args.overwrite, kind="couple") as tmp:
        phases = write_coupled(tmp, domain, result, phases=phases)
        if args.foam_fields:
            written = write_foam_fields(scene, domain, result, args.overwrite)
            written = list(written) + list(executor.mirror_to_processors(written,
                                                                         args.overwrite))
    executor.finish()  # the output is complete: drop what was kept for a resume
    print(f"{scene.name}: {result.stats['active_cells']} of {result.stats['cells']} cells to "
          f"t = {scene.end_time:g} s in {result.wall_time_s:.2f} s "
          f"({result.stats['cell_steps_per_second']:.3g} cell-steps/s)"
          f"{_compile_text(result)}; wrote {args.out}/")
    print(f"{scene.name}: {_phases_text(phases)}")
    if args.foam_fields:
        dirs = sorted({str(Path(p).parent) for p in written})
        print(f"{scene.name}: wrote {len(written)} pbe.* field files into the case: "
              f"{', '.join(dirs)}")
    return 0


def case_command(args):
    """``pbe-cfd case run|make``: see ``io.openfoam.case_command``."""
    from .io.openfoam.case_command import case_command as command
    return command(args)


def render_command(args):
    """``pbe-cfd render DIR``: PNGs of a coupled run's VTK series."""
    from .io.results import render_run
    for p in render_run(args.dir, args.fields, args.times, args.overwrite,
                        section=args.section):
        print(p)
    return 0


def _add_case_parser(sub):
    p = sub.add_parser("case", help="run the bundled OpenFOAM fluid-bed case, or make a 3-D "
                                    "bed of any size (make --3d --cells N)")
    p.add_argument("action", choices=("run", "make"))
    p.add_argument("--mesh", default="small", choices=("small", "full"))
    p.add_argument("--dir", default=None, help="where to copy and run the case (default "
                   "fluid-bed-case), or to write the 3-D bed (default fluid-bed-3d)")
    p.add_argument("--cells", type=_positive_int, default=None,
                   help="make: cells of the 3-D bed (near-cubic cells)")
    p.add_argument("--3d", dest="three_d", action="store_true",
                   help="make: the bundled bed extruded in depth (the one kind made)")
    p.add_argument("--depth", type=float, default=None, help="make: depth of the bed in m "
                   "(default 0.15)")
    _add_overwrite(p, "the files of an earlier case pbe-cfd made there")
    p.set_defaults(func=case_command)


def build_parser():
    parser = argparse.ArgumentParser(
        prog="pbe-cfd",
        description="Population balance of fluid-bed granulation: moment methods (QMOM, "
                    "Laguerre ROM), a constant-number Monte Carlo reference, and per-cell "
                    "coupling to OpenFOAM Euler-Euler fields.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a well-mixed scene (default: the bundled seed-wurster)")
    p.add_argument("scene", nargs="?", help="scene TOML file or bundled scene name")
    p.add_argument("--out", default="out", help="output directory (default: out)")
    _add_overwrite(p)
    p.set_defaults(func=run_command)

    p = sub.add_parser("plan", help="print what a scene computes, without running it")
    p.add_argument("scene", help="scene TOML file or bundled scene name")
    p.set_defaults(func=plan_command)

    p = sub.add_parser("scenes", help="list the bundled scenes")
    p.set_defaults(func=scenes_command)

    p = sub.add_parser("compare", help="overlay the moment trajectories of results")
    p.add_argument("results", nargs="+", help="run directories (or moments.csv files)")
    p.add_argument("--out", default="compare.png", help="figure path (default: compare.png)")
    _add_overwrite(p, "a figure an earlier pbe-cfd compare wrote")
    p.set_defaults(func=compare_command)

    p = sub.add_parser("couple", help="solve the population balance in every cell of an "
                                      "OpenFOAM fluid bed (default: bundled fluid-bed scene)")
    p.add_argument("scene", nargs="?", help="scene TOML file or bundled scene name")
    p.add_argument("--out", default="out-couple", help="output directory")
    p.add_argument("--run-case", action="store_true",
                   help="run the OpenFOAM case first to make a fresh snapshot")
    p.add_argument("--mesh", default="small", choices=("small", "full"))
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    p.add_argument("--foam-fields", action="store_true",
                   help="also write the fields as OpenFOAM volScalarFields into the case")
    _add_overwrite(p, "the files of an earlier pbe-cfd output, case (--run-case) or fields "
                   "(--foam-fields)")
    g = p.add_argument_group(
        "cluster (dask.distributed; pip install \"pbe_cfd[dask]\")",
        "Solve the cells on a Dask cluster. Finished chunks are kept in DIR.chunks/ next to "
        "the output DIR until the output is written; a run with failed chunks names them "
        "and --resume DIR computes only those.")
    w = g.add_mutually_exclusive_group()
    w.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="address of a running Dask scheduler (e.g. tcp://host:8786)")
    w.add_argument("--workers", metavar="N", type=_positive_int, default=None,
                   help="start a local cluster of N worker processes (numba threads per "
                        "worker: cores // N)")
    g.add_argument("--chunks", metavar="K", type=_positive_int, default=None,
                   help="split the active cells into K blocks (default: 4 per worker, with "
                        "[transport] one per worker; one per processor directory of a "
                        "decomposed case)")
    g.add_argument("--decompose", metavar="N", type=_positive_int, default=None,
                   help="decomposePar the OpenFOAM case into N subdomains first; one task "
                        "per processor directory, --foam-fields also written per processor")
    g.add_argument("--resume", metavar="DIR", default=None,
                   help="complete the failed or missing chunks of an earlier cluster run "
                        "whose output directory was DIR (implies --out DIR; SCENE defaults "
                        "to that run's)")
    p.set_defaults(func=couple_command)

    _add_case_parser(sub)
    from .runs.precompile import add_compile_parser      # the parser only: nothing heavy
    add_compile_parser(sub, (DEFAULT_WELL_MIXED, DEFAULT_COUPLED))

    p = sub.add_parser("render", help="render PNGs of a coupled run's VTK series")
    p.add_argument("dir", help="output directory of `pbe-cfd couple`")
    p.add_argument("--fields", nargs="+", default=None,
                   help="fields to draw (default: alpha, Theta, M00, d43_m, binder_fraction)")
    p.add_argument("--times", nargs="+", type=float, default=None,
                   help="output times in s (nearest written; default: first and last)")
    p.add_argument("--section", default=None, metavar="AXIS=POSITION",
                   help="the plane drawn, e.g. z=0.01 (m; default: the mid-plane normal to "
                        "the thinnest extent)")
    _add_overwrite(p, "PNGs an earlier pbe-cfd run or render wrote (others are skipped)")
    p.set_defaults(func=render_command)

    add_bench_parser(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every command cleans up on the way out."""


def _on_signal(signum, frame):
    """First SIGINT/SIGTERM: raise (KeyboardInterrupt or Terminated); later ones are ignored
    while the command removes what it had half-written."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def main(argv=None):
    from .runs.batch import SimulationError
    from .integrate.faults import MethodRaised
    from .io.output import OutputFailed, UsageError, interrupted_text, release_claims
    from .scene.scene import SceneError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (SceneError, UsageError) as exc:
        return _fail(str(exc), 2)
    except (SimulationError, OutputFailed, MethodRaised) as exc:
        return _fail(str(exc), 1)
    except FileNotFoundError as exc:
        return _fail(str(exc), 2)
    except OSError as exc:
        where = f": {exc.filename}" if exc.filename else ""
        return _fail(f"{exc.strerror or exc}{where}", 1)
    except KeyboardInterrupt as exc:
        what = "SIGTERM" if isinstance(exc, Terminated) else "Ctrl-C"
        return _fail(f"interrupted ({what}); {interrupted_text()}",
                     143 if isinstance(exc, Terminated) else 130)
    finally:
        release_claims()


def run():
    """Console entry point: ``main``, then exit without a last garbage collection over every
    object of the run (numba, matplotlib and VTK leave about 0.4 s of it at exit; the
    objects' memory goes back to the system with the process either way)."""
    import gc
    import signal
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()
