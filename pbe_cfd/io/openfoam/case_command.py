"""``pbe-cfd case run`` (copy and run the bundled OpenFOAM case) and ``pbe-cfd case make --3d``
(write a 3-D bed snapshot of any size)."""
from __future__ import annotations

import sys
from pathlib import Path


def case_command(args):
    """``pbe-cfd case run --mesh small --dir DIR``: copy and run the fluid-bed case."""
    from . import cases
    from .. import openfoam as of
    if args.action == "make":
        return _make_bed(args)
    target = Path(args.dir or "fluid-bed-case")
    try:
        res = cases.copy_and_run(target, args.mesh, args.overwrite, flag="--dir",
                                 log=lambda line: print(line, file=sys.stderr))
    except of.OpenFOAMError as exc:
        print(f"pbe-cfd: error: {exc}", file=sys.stderr)
        return 1
    print(f"case {target} ({args.mesh}) ran to t = {res.latest_time:g} s; "
          + ", ".join(f"{k} {v:.1f} s" for k, v in res.wall_times.items()))
    return 0


def _make_bed(args):
    """``pbe-cfd case make --3d --cells N --dir DIR``: a 3-D bed snapshot (io.openfoam.bed3d)."""
    from . import bed3d
    print(bed3d.make_case(args.dir or "fluid-bed-3d", args.cells, args.depth, args.three_d,
                          args.overwrite))
    return 0
