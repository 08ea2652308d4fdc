"""Render a pbe_cfd VTK series and plot bed_moments.csv (the same as `pbe-cfd render`).

    python postprocess/render.py OUT_DIR [--fields alpha Theta M00 d43_m binder_fraction]
                                         [--times 0 600] [--overwrite]

OUT_DIR is a `pbe-cfd couple` output directory (its vtk/ subdirectory holds the .pvd) or a
directory holding a .pvd directly; the PNGs go to OUT_DIR/png/ under the same rules as the
command (a picture pbe-cfd drew earlier is replaced only with --overwrite, any other file
never). The code lives in pbe_cfd.io.results and pbe_cfd.viz.render.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pbe_cfd.io.output import UsageError
from pbe_cfd.io.results import render_run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--fields", nargs="+", default=None, help="cell fields to draw")
    ap.add_argument("--times", nargs="+", type=float, default=None,
                    help="output times in s (nearest written; default: first and last)")
    ap.add_argument("--overwrite", action="store_true",
                    help="replace pictures pbe-cfd drew earlier")
    args = ap.parse_args(argv)
    try:
        paths = render_run(args.out_dir, args.fields, args.times, args.overwrite)
    except UsageError as exc:
        print(f"render: error: {exc}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
