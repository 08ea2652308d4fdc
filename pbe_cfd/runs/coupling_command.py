"""``pbe-cfd couple SCENE --out DIR`` for a scene with ``[coupling]``: the two-way run
(``runs.coupling``), its outputs (``runs.coupling_output``) and ``--resume DIR``.

Two-way runs are serial (no cluster options) and read the case they re-run: OpenFOAM must be
installed (exit 2 naming what is missing otherwise). The output directory follows the rules of
every output (``pbe_cfd.output``); the segments are kept in ``DIR.coupling/`` until it is
written, and ``--resume DIR`` continues from the last finished step.
"""
from __future__ import annotations

import json
import sys
import time as _time
from pathlib import Path

from ..io import output
from .coupling_store import PROGRESS, SegmentStore, store_path

#: couple options a two-way run does not take (serial, its own segment cases)
REFUSED = (("scheduler", "--scheduler"), ("workers", "--workers"), ("chunks", "--chunks"),
           ("decompose", "--decompose"), ("foam_fields", "--foam-fields"),
           ("run_case", "--run-case"))


def wanted(args, default_scene: str) -> bool:
    """True when ``couple`` runs two-way: SCENE has ``[coupling]``, or --resume DIR names the
    output of a two-way run."""
    from ..scene.scene import load_scene
    if args.resume:
        return (store_path(args.resume) / PROGRESS).is_file()
    return load_scene(args.scene or default_scene).coupling is not None


def _scene(args, default_scene):
    from ..scene.scene import load_scene
    source = args.scene
    if args.resume and not source:
        source = json.loads((store_path(args.resume) / PROGRESS).read_text())["scene"]
    return load_scene(source or default_scene)


def _check(args, scene):
    from ..io import openfoam as of
    for attr, flag in REFUSED:
        if getattr(args, attr, None):
            raise output.UsageError(f"{scene.source}: [coupling] runs serially in its own "
                                    f"segment cases: drop {flag}")
    try:
        of.find_openfoam()
    except of.OpenFOAMError as exc:
        raise output.UsageError(f"{scene.source}: [coupling] re-runs the CFD, which needs "
                                f"OpenFOAM: {str(exc).splitlines()[0]}") from None


def two_way(args, default_scene: str) -> int:
    """Run a two-way coupled scene and write its outputs; returns the exit code."""
    from .domain import case_path
    from ..util.progress import Progress
    from .coupling import run_two_way
    from .coupling_output import combined_result

    scene = _scene(args, default_scene)
    _check(args, scene)
    out_arg = args.resume or args.out
    inputs = [("the scene", scene.source)]
    if (path := case_path(scene)) is not None:
        inputs.append(("the OpenFOAM case", path))
    out = output.prepare_directory(out_arg, args.overwrite, kind="couple", inputs=inputs)
    store = SegmentStore(store_path(out))
    output.check_not_input(store.path, inputs, flag="--out")
    store.open(scene, resume=bool(args.resume))
    progress = Progress(f"{scene.name} (two-way)")
    started = _time.perf_counter()
    said = []                       # warnings already printed during the run
    try:
        run = run_two_way(scene, store, progress=progress, log=progress.notice,
                          warn=lambda text: (said.append(text),
                                             print(f"warning: {text}", file=sys.stderr)))
    except KeyboardInterrupt:
        output.note_interrupted(out, f"{out} not written; the finished segments are kept in "
                                f"{store.path} (`pbe-cfd couple --resume {out_arg}` continues)")
        raise
    finally:
        progress.close()
    result = combined_result(run, _time.perf_counter() - started)
    for w in result.warnings:
        if w not in said:
            print(f"warning: {w}", file=sys.stderr)
    with output.atomic_directory(out, args.overwrite, kind="couple") as tmp:
        write_two_way(tmp, store, run, result)
    store.remove()
    st = result.stats
    print(f"{run.plan.name}: two-way, {st['segments']} segments to t = {run.plan.end_time:g} s; "
          f"CFD {st['cfd_wall_s']:.1f} s, population balance {st['pbe_wall_s']:.1f} s of wall "
          f"time; wrote {out_arg}/ (segments.csv, segments.png, segments/NNN/ logs)")
    return 0


def write_two_way(tmp: Path, store, run, result):
    """The coupled outputs across segments, segments.csv and .png, each segment's logs and
    dictionaries (segments/NNN/), and summary.json's ``coupling`` section (of the run's
    ``coupling.TwoWayPlan``)."""
    from .couple import write_coupled
    from ..io.openfoam import rerun
    from .coupling_output import plot_segments, segment_rows
    plan = run.plan
    cols = segment_rows(run)
    phases = write_coupled(tmp, run.segments[0].domain, result)
    output.write_columns_csv(tmp / "segments.csv", cols)
    plot_segments(tmp / "png" / "segments.png", cols, f"{plan.name}: two-way segments",
                  metadata=output.figure_metadata("png", "couple"))
    for seg in run.segments:
        case = Path(seg.case)
        if case.parent == store.path:             # a case this run made (not the user's)
            rerun.copy_logs(case, tmp / "segments" / f"{seg.index:03d}")
    summary = json.loads((tmp / "summary.json").read_text())
    summary["coupling"] = {
        "table": {k: getattr(plan.coupling, k) for k in plan.coupling.__dataclass_fields__},
        "segments": {k: v.tolist() for k, v in cols.items()},
        "fluidisation": run.fluidisation,
        "cfd_wall_s": result.stats["cfd_wall_s"], "pbe_wall_s": result.stats["pbe_wall_s"]}
    summary["phases"] = phases
    output.write_json(tmp / "summary.json", summary)
