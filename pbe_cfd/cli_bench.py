"""``pbe-cfd bench STUDY``: the studies' subcommand (its parser and its command).

The study names come from the bench package (``bench.STUDY_FILES``; the studies of one method
are named by its registry entry), asked only when an argument is checked.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .cli_args import add_overwrite, fail, threads_refusal


def bench_command(args):
    """``pbe-cfd bench STUDY [SCENE] --out DIR [--quick]``."""
    import time

    from . import bench
    from .io import output
    out, quick, study = Path(args.out), bool(args.quick), args.study
    refusal = threads_refusal(args.threads) or (study == "integrators" and args.scene and
                                                bench.transport_cost.refusal(args.scene))
    if refusal:
        return fail(refusal)
    if args.results_doc:
        from .bench import results_doc
        try:
            results_doc.check(args.results_doc, study)
        except results_doc.ResultsDocError as exc:
            return fail(str(exc))
    output.prepare_directory(out, args.overwrite, names=bench.STUDY_FILES[study],
                             kind="bench")
    start = time.perf_counter()
    if study == "accuracy":
        res = bench.accuracy_study(args.scene, out, quick=quick)
        print(bench.accuracy_markdown(res))
    elif study == "throughput":
        res = bench.throughput_study(out, quick=quick, cells=args.cells, threads=args.threads,
                                     methods=args.methods,
                                     scene_name=args.scene or bench.DEFAULT_THROUGHPUT_SCENE)
        print(bench.throughput_markdown(res))
    elif study == "peer":
        try:
            bench.peer_study(out, quick=quick)
        except (bench.PeerUnavailable, bench.PeerRunError) as exc:
            print(f"pbe-cfd: error: {exc}", file=sys.stderr)
            return 2 if isinstance(exc, bench.PeerUnavailable) else 1
        print((out / "peer.md").read_text())
    else:
        kw = {"baseline": Path(args.scene)} if study == "integrators" and args.scene else {}
        bench.SIMPLE_STUDY_RUNS[study](out, quick=quick, **kw)
        print((out / f"{study}.md").read_text())
    files = ", ".join(bench.STUDY_FILES[study])
    print(f"bench {study}: {time.perf_counter() - start:.1f} s; wrote {out}/{{{files}}}")
    if args.results_doc:
        done = results_doc.refresh(args.results_doc, study, (out / f"{study}.md").read_text(),
                                   results_doc.command_line(args))
        print(f"bench {study}: {done} its block in {args.results_doc}")
    return 0


class _Studies:
    """The study names of ``pbe-cfd bench``, asked of the bench package when checked."""

    def __iter__(self):
        from .bench.common import STUDY_FILES      # a method's study: named by its entry
        return iter(tuple(STUDY_FILES))

    def __contains__(self, name):
        return name in tuple(self)


def int_list(text):
    """argparse type: '1000,100000' -> (1000, 100000), positive whole numbers."""
    try:
        values = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected whole numbers separated by commas, got "
                                         f"{text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected positive whole numbers, got {text!r}")
    return values


def method_list(text):
    """'qmom:3,laguerre:3,cqmom:2x2' -> (("qmom", 3), ("laguerre", 3), ("cqmom", (2, 2))): each
    method's order as its registry entry's ``bench_orders`` reads it."""
    from .methods.registry import METHOD_REGISTRY
    readers = {m.name: m.bench_orders for m in METHOD_REGISTRY if m.bench_orders is not None}
    out = []
    for item in (x.strip() for x in text.split(",") if x.strip()):
        name, _, order = item.partition(":")
        try:
            out.append((name, readers[name](order)))
        except (KeyError, ValueError):
            raise argparse.ArgumentTypeError(
                f"{item!r}: expected one of {', '.join(n + ':ORDER' for n in readers)} "
                "(qmom:N, laguerre:M, cqmom:N1xN2)") from None
    if not out:
        raise argparse.ArgumentTypeError("name at least one method")
    return tuple(out)


def add_bench_parser(sub):
    """The ``bench`` subcommand of the ``pbe-cfd`` parser's subparsers ``sub``."""
    p = sub.add_parser("bench", help="benchmarks: accuracy-vs-cost, throughput, cnmc, coupling")
    # a metavar: argparse then lists the studies (importing the bench) only for help/errors
    p.add_argument("study", choices=_Studies(), metavar="STUDY", help="one of: %(choices)s")
    p.add_argument("scene", nargs="?", help="scene for the accuracy study; integrators: a "
                   "pbe_cfd source tree whose transport ratios are timed in the same run")
    p.add_argument("--out", default="bench-out")
    p.add_argument("--quick", action="store_true", help="a tiny configuration (plumbing check)")
    p.add_argument("--methods", type=method_list, default=None, metavar="LIST",
                   help="throughput: methods and orders, e.g. qmom:3,laguerre:3,cqmom:2x2 "
                        "(default: all)")
    p.add_argument("--cells", type=int_list, default=None, metavar="LIST",
                   help="throughput: cell counts, e.g. 1000,100000")
    p.add_argument("--threads", type=int_list, default=None, metavar="LIST",
                   help="throughput: thread counts, e.g. 1,2")
    p.add_argument("--results-doc", default=None, metavar="FILE",
                   help="write the study's report into FILE (docs/results/STUDY.md) between "
                        "its marker lines, keeping the rest of FILE as it is")
    add_overwrite(p, "the files of this study an earlier pbe-cfd bench wrote")
    p.set_defaults(func=bench_command)
    return p
