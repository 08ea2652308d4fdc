"""Render a pbe_cfd VTK series (off-screen pyvista PNGs) and plot bed_moments.csv.

    python postprocess/render.py OUT_DIR [--fields alpha Theta M00 d43_m binder_fraction]
                                         [--times 0 600] [--png-dir DIR]

OUT_DIR is a `pbe-cfd couple` output directory (its vtk/ subdirectory holds the .pvd) or a
directory holding a .pvd directly. The code lives in pbe_cfd.cfd.render (also behind
`pbe-cfd render`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pbe_cfd.cfd.render import plot_bed_moments, render_series


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--fields", nargs="+", default=None, help="cell fields to draw")
    ap.add_argument("--times", nargs="+", type=float, default=None,
                    help="output times in s (default: first and last)")
    ap.add_argument("--png-dir", type=Path, default=None)
    args = ap.parse_args(argv)
    out = args.out_dir
    vtk_dir = out / "vtk" if (out / "vtk").is_dir() else out
    png_dir = args.png_dir or out / "png"
    try:
        paths = render_series(vtk_dir, fields=args.fields, times=args.times, png_dir=png_dir)
        if (out / "bed_moments.csv").is_file():
            paths.append(plot_bed_moments(out / "bed_moments.csv", png_dir / "bed_moments.png"))
    except (FileNotFoundError, ValueError) as exc:
        print(f"render: error: {exc}", file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
