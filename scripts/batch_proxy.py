"""The bundled bed batch as one well-mixed cell, by every method against the cNMC.

    python scripts/batch_proxy.py OUT [--end 900] [--particles 20000] [--replicas 8]
        [--seed 2026]

Writes, in the new directory OUT, the batch proxy's scenes: `fluid-bed-laguerre-batch` with
its domain replaced by one well-mixed cell at the active cells' mean solids fraction
(0.38139) and granular temperature (7.5256e-5 m2/s2), its spray rate by the spray zone's
share of the bed's (3.5926e9 droplets/(m3 s)), no transport (``proxy_source`` of
tests/methods/laguerre/test_laguerre_number_rate.py; the following support's default
closure kept), and the same scene with `[method]` replaced by QMOM N = 3 and 4,
CQMOM 3 x 3 and the cNMC. Runs each with `pbe-cfd run` and prints, per output minute up to
the end, the cNMC's M00, d43, d50 and binder fraction (mean and 95% half-width of its
replicas) and each method's relative difference from it [%].
"""
import argparse
import csv
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "methods" / "laguerre"))

import test_laguerre_number_rate as P            # noqa: E402  the proxy, fixed there

METHODS = {
    "laguerre": None,                  # the bundled scene's [method]
    "qmom3": 'name = "qmom"\nnodes = 3\nrtol = 1e-6\n',
    "qmom4": 'name = "qmom"\nnodes = 4\nrtol = 1e-6\n',
    "cqmom3x3": 'name = "cqmom"\nnodes = 3\nbinder_nodes = 3\nrtol = 1e-6\n',
}
QUANTITIES = ("M00", "d43_m", "d50_m", "binder_fraction")


def proxy_source(end):
    """The proxy scene's TOML text (the test module's ``proxy_source``), run to ``end`` [s]."""
    src, count = re.subn(r"^end_time = [0-9.e+]+", f"end_time = {end!r}", P.proxy_source(),
                         flags=re.M)
    if count != 1:
        raise SystemExit("batch_proxy: the bundled scene's end_time line was not found")
    return src


def _rows(path):
    with open(path) as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    return {round(float(r["time_s"]), 6): r for r in rows}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--end", type=float, default=900.0)
    ap.add_argument("--particles", type=int, default=20000)
    ap.add_argument("--replicas", type=int, default=8)
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args(argv)
    out = Path(args.out)
    if out.exists():
        raise SystemExit(f"batch_proxy: {out} exists; give a new directory (nothing in an "
                         "existing one is overwritten)")
    out.mkdir(parents=True)
    src = proxy_source(args.end)
    head = src.split("[method]")[0]
    methods = dict(METHODS, cnmc=f'name = "cnmc"\nparticles = {args.particles}\n'
                                 f'replicas = {args.replicas}\nseed = {args.seed}\n')
    for name, method in methods.items():
        scene = out / f"{name}.toml"
        scene.write_text(src if method is None else head + "[method]\n" + method)
        subprocess.run(["pbe-cfd", "run", str(scene), "--out", str(out / name)], check=True,
                       stdout=subprocess.DEVNULL)
    ref = _rows(out / "cnmc" / "moments.csv")
    runs = {name: _rows(out / name / "moments.csv") for name in METHODS}
    print("| t [min] | quantity | cNMC (95% half-width) | "
          + " | ".join(f"{name} [%]" for name in METHODS) + " |")
    print("|---" * (3 + len(METHODS)) + "|")
    for t in sorted(ref):
        if t <= 0.0 or t % 60.0:
            continue
        for q in QUANTITIES:
            mean = float(ref[t][q])
            half = 50.0 * (float(ref[t][q + "_hi"]) - float(ref[t][q + "_lo"])) / mean
            cells = [f"{100.0 * (float(runs[m][t][q]) / mean - 1.0):+.1f}" for m in METHODS]
            print(f"| {t / 60.0:g} | {q} | {mean:.4g} ({half:.1f}%) | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
