"""Regenerate the bundled CFD snapshot (pbe_cfd/data/fluid_bed_small.vtu + _flux.npz).

Copies openfoam_case/ to a temporary directory, runs it (small mesh, default end time and
averaging window), and writes the snapshot. Needs OpenFOAM v1912.

    python postprocess/make_snapshot.py [--mesh small|full] [--out PATH] [--keep DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from pbe_cfd.io import openfoam as of


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="small", choices=["small", "full"])
    ap.add_argument("--out", type=Path, default=of.default_snapshot_path())
    ap.add_argument("--keep", type=Path, default=None,
                    help="run the case in this directory (kept) instead of a temporary one")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp) / "openfoam_case"
        of.copy_case(of.default_case_dir(), work)
        t0 = time.perf_counter()
        res = of.run_case(work, args.mesh, log=print)
        print(f"case ran in {time.perf_counter() - t0:.1f} s: {res.wall_times}")
        vtu, npz = of.write_snapshot(work, "latest", args.out)
    cells = of.load_snapshot(vtu)
    print(f"wrote {vtu} ({vtu.stat().st_size} B) and {npz} ({npz.stat().st_size} B): "
          f"{cells.n_cells} cells, alpha {cells.alpha.min():.3g}..{cells.alpha.max():.3g}, "
          f"Theta {cells.theta.min():.3g}..{cells.theta.max():.3g} m2/s2")
    return 0


if __name__ == "__main__":
    sys.exit(main())
