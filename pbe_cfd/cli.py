"""The ``pbe-cfd`` command line: run | plan | scenes | compare | couple | case | render | bench.

Exit codes: 0 success, 2 bad input (scene, arguments, files), 1 a run that failed.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_WELL_MIXED = "seed-wurster"
DEFAULT_COUPLED = "fluid-bed"


class _Progress:
    """tqdm progress bar on a terminal; silent otherwise."""

    def __init__(self, label):
        from tqdm import tqdm
        self.bar = tqdm(total=1000, desc=label, unit="‰", disable=None, file=sys.stderr,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining} {postfix}")
        self.last = 0

    def __call__(self, fraction, text=""):
        if self.bar.disable:
            return
        pos = int(round(1000 * min(max(fraction, 0.0), 1.0)))
        if pos > self.last:
            self.bar.update(pos - self.last)
            self.last = pos
        if text:
            self.bar.set_postfix_str(text)

    def close(self):
        self.bar.close()


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _add_overwrite(p, what="the files an earlier pbe-cfd run wrote there"):
    p.add_argument("--overwrite", action="store_true",
                   help=f"replace {what} (files pbe-cfd did not write are never replaced)")


def _fail(message, code=2):
    print(f"pbe-cfd: error: {message}", file=sys.stderr)
    return code


def cmd_run(args):
    from . import output, plotting
    from .scene import describe, load_scene
    from .simulate import run_well_mixed

    scene = load_scene(args.scene or DEFAULT_WELL_MIXED)
    if scene.domain.type != "well-mixed":
        return _fail(f"{scene.source}: [domain] type is \"openfoam\"; use `pbe-cfd couple`")
    out = output.prepare_directory(args.out, args.overwrite)   # refuse before any work
    progress = _Progress(f"{scene.name} ({scene.method.name})")
    try:
        result = run_well_mixed(scene, progress=progress)
    finally:
        progress.close()
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    with output.atomic_directory(out, args.overwrite, kind="run") as tmp:
        output.write_columns_csv(tmp / "moments.csv", result.columns)
        output.write_json(tmp / "summary.json", {
            "scene": describe(scene), "method": scene.method.name,
            "wall_time_s": result.wall_time_s, "stats": result.stats,
            "warnings": result.warnings})
        plotting.plot_trajectories(tmp / "moments.png", [(scene.method.name, result.columns)],
                                   title=f"{scene.name}: {scene.method.name}",
                                   metadata=output.figure_metadata("png", "run"))
    print(f"{scene.name}: {scene.method.name} to t = {scene.end_time:g} s in "
          f"{result.wall_time_s:.2f} s; wrote {out}/moments.csv, summary.json, moments.png")
    return 0


def cmd_plan(args):
    from .plan import describe_plan
    from .scene import load_scene

    scene = load_scene(args.scene)
    print(describe_plan(scene))
    return 0


def cmd_scenes(args):
    from .scene import bundled_scenes, load_scene

    for name, path in sorted(bundled_scenes().items()):
        scene = load_scene(path)
        effects = [t for t in ("aggregation", "binder_injection", "transport")
                   if getattr(scene, t) is not None]
        print(f"{name:24s} {scene.domain.type:10s} {scene.method.name:9s} "
              f"end {scene.end_time:g} s  effects: {', '.join(effects) or 'none'}")
    return 0


def cmd_compare(args):
    from .results import compare_runs
    return compare_runs(args.results, args.out, args.overwrite)


def cmd_couple(args):
    from .couple import couple_command
    return couple_command(args)


def cmd_case(args):
    from .couple import case_command
    return case_command(args)


def cmd_render(args):
    from .couple import render_command
    return render_command(args)


def cmd_bench(args):
    from .bench import bench_command
    return bench_command(args)


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
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("plan", help="print what a scene computes, without running it")
    p.add_argument("scene", help="scene TOML file or bundled scene name")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("scenes", help="list the bundled scenes")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("compare", help="overlay the moment trajectories of results")
    p.add_argument("results", nargs="+", help="run directories (or moments.csv files)")
    p.add_argument("--out", default="compare.png", help="figure path (default: compare.png)")
    _add_overwrite(p, "a figure an earlier pbe-cfd compare wrote")
    p.set_defaults(func=cmd_compare)

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
    _add_overwrite(p, "the files of an earlier pbe-cfd output, case (--run-case) or fields (--foam-fields)")
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
                   help="split the active cells into K blocks (default: 4 per worker, or one "
                        "per processor directory of a decomposed case)")
    g.add_argument("--decompose", metavar="N", type=_positive_int, default=None,
                   help="decomposePar the OpenFOAM case into N subdomains first; one task "
                        "per processor directory, --foam-fields also written per processor")
    g.add_argument("--resume", metavar="DIR", default=None,
                   help="complete the failed or missing chunks of an earlier cluster run "
                        "whose output directory was DIR (implies --out DIR; SCENE defaults "
                        "to that run's)")
    p.set_defaults(func=cmd_couple)

    p = sub.add_parser("case", help="run the bundled OpenFOAM fluid-bed case")
    p.add_argument("action", choices=("run",))
    p.add_argument("--mesh", default="small", choices=("small", "full"))
    p.add_argument("--dir", default="fluid-bed-case", help="where to copy and run the case")
    _add_overwrite(p, "the files of an earlier case pbe-cfd made there")
    p.set_defaults(func=cmd_case)

    p = sub.add_parser("render", help="render PNGs of a coupled run's VTK series")
    p.add_argument("dir", help="output directory of `pbe-cfd couple`")
    p.add_argument("--fields", nargs="+", default=None,
                   help="fields to draw (default: alpha, Theta, M00, d43_m, binder_fraction)")
    p.add_argument("--times", nargs="+", type=float, default=None,
                   help="output times in s (nearest written; default: first and last)")
    _add_overwrite(p, "PNGs an earlier pbe-cfd run or render wrote")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("bench", help="benchmarks: accuracy-vs-cost, throughput, cnmc, coupling")
    p.add_argument("study", choices=("accuracy", "throughput", "cnmc", "laguerre", "couple"))
    p.add_argument("scene", nargs="?", help="scene for the accuracy study")
    p.add_argument("--out", default="bench-out")
    p.add_argument("--quick", action="store_true", help="a tiny configuration (plumbing check)")
    _add_overwrite(p, "the files of this study an earlier pbe-cfd bench wrote")
    p.set_defaults(func=cmd_bench)
    return parser


def main(argv=None):
    from .output import UsageError
    from .scene import SceneError
    from .simulate import SimulationError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (SceneError, UsageError) as exc:
        return _fail(str(exc), 2)
    except SimulationError as exc:
        return _fail(str(exc), 1)
    except FileNotFoundError as exc:
        return _fail(str(exc), 2)
    except KeyboardInterrupt:
        return _fail("interrupted; no output written", 130)


if __name__ == "__main__":
    sys.exit(main())
