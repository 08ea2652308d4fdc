"""The README's breakage figure: d43 over the bundled bed after 60 s, without and with breakage,
side by side on one colour scale.

    python scripts/breakage_figure.py RUN_WITHOUT RUN_WITH --out docs/img/fluid-bed-breakage-d43.png

RUN_WITHOUT and RUN_WITH are output directories of ``pbe-cfd couple fluid-bed`` and
``pbe-cfd couple fluid-bed-breakage``. Prints the bed's d43 and d32 at the last output time of
each (from bed_moments.csv) and the range of the cells' d43.
"""
from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path

import numpy as np


def last_row(run: Path) -> dict:
    with open(run / "bed_moments.csv") as fh:
        rows = list(csv.DictReader(fh))
    return {k: float(v) for k, v in rows[-1].items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("without", type=Path)
    parser.add_argument("with_breakage", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pyvista as pv

    from pbe_cfd.viz.render import render_mesh_field
    from pbe_cfd.io.vtk import read_pvd

    meshes, labels = [], ("without breakage", "with breakage")
    for run in (args.without, args.with_breakage):
        t, path = read_pvd(next(run.glob("vtk/*.pvd")))[-1]
        meshes.append((t, pv.read(path)))
    d43 = [np.asarray(m.cell_data["d43_m"], float) for _, m in meshes]
    positive = np.concatenate([v[v > 0] for v in d43])
    clim = (float(positive.min()), float(positive.max()))
    with tempfile.TemporaryDirectory() as tmp:
        panels = []
        for (t, mesh), label in zip(meshes, labels):
            png = Path(tmp) / f"{label.replace(' ', '_')}.png"
            render_mesh_field(mesh, "d43_m", png, clim=clim, log_scale=False,
                              title=f"d43, {label}, t = {t:g} s")
            panels.append(plt.imread(png))
        image = np.concatenate(panels, axis=1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(args.out, image)
    for run, v, label in zip((args.without, args.with_breakage), d43, labels):
        row = last_row(run)
        cells = v[v > 0]
        print(f"{label}: bed d43 {row['d43_m'] * 1e6:.2f} um, d32 {row['d32_m'] * 1e6:.2f} um, "
              f"M00 {row['M00']:.4g} 1/m3; cells d43 {cells.min() * 1e6:.1f} .. "
              f"{cells.max() * 1e6:.1f} um")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
