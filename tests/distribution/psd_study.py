"""docs/results/psd.md: QMOM N = 3 (its N - 1 kernel gamma fit), EQMOM N = 3 and the Laguerre
ROM against the independent particle list (psd_reference_run.py's JSON) on the cases of
psd_cases.py: percentiles, L1 distance of Q3, and the overlaid q3 curves.

python tests/distribution/psd_study.py REFERENCE.json OUT.png OUT.json
"""
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import psd_cases  # noqa: E402
import psd_methods_run as M  # noqa: E402

AIMS = (0.05, 0.03, 0.05)


def l1_q3(d, q3, grid, ref_q3):
    """int |Q3_method - Q3_ref| d(ln d) [-] over the method's psd grid d [m] (the reference's
    Q3 interpolated linearly in ln d from its grid)."""
    ref = np.interp(np.log(d), np.log(grid), ref_q3)
    y = np.abs(q3 - ref)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(np.log(d))))


def measure(ref):
    grid = np.asarray(ref["grid_m"])
    rows = []
    for case in psd_cases.CASES:
        r = ref[case]
        want, half = np.array(r["percentiles"]), np.array(r["percentiles_half"])
        for label, method in M.METHODS.items():
            t0 = time.time()
            row = {"case": case, "method": label, "reference": want.tolist(),
                   "reference_half": half.tolist()}
            try:
                res = M.run(case, method)
                q, d, q3 = M.final(res)
                t = np.asarray(res.psd["time_s"])
                last = t == t.max()
                row.update(percentiles=q.tolist(), deviation=(q / want - 1.0).tolist(),
                           l1_q3=l1_q3(d, q3, grid, np.array(r["q3"])), d_m=d.tolist(),
                           q3_per_ln_d=np.asarray(res.psd["q3_per_ln_d"])[last].tolist(),
                           t_end=float(res.columns["time_s"][-1]),
                           M00=float(res.columns["M00"][-1]),
                           one_gamma=(M.one_gamma(res, res.scene.material.density)
                                      / want - 1.0).tolist(),
                           warnings=list(getattr(res, "warnings", [])))
            except Exception as exc:              # a stop is a result
                row["stops"] = str(exc).splitlines()[0][:200]
            row["seconds"] = time.time() - t0
            print(json.dumps({k: v for k, v in row.items() if k not in ("d_m", "q3_per_ln_d")}),
                  flush=True)
            rows.append(row)
    return rows


def markdown(rows):
    lines = ["| case | method | d10 % | d50 % | d90 % | L1 of Q3 over ln d | within aims | "
             "one gamma on M00..M20: d10 d50 d90 % |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "stops" in r:
            lines.append(f"| {r['case']} | {r['method']} | stops: {r['stops'][:80]} | | | | no | |")
            continue
        dev, half = np.array(r["deviation"]), np.array(r["reference_half"]) / np.array(
            r["reference"])
        ok = bool(np.all(np.abs(dev) + half <= AIMS))
        lines.append(f"| {r['case']} | {r['method']} | " + " | ".join(
            f"{100 * v:+.2f}" for v in dev) + f" | {r['l1_q3']:.4f} | {'yes' if ok else 'no'} | "
            + (" ".join(f"{100 * v:+.2f}" for v in r["one_gamma"]) if r["method"].startswith(
                "QMOM") else "") + " |")
    return "\n".join(lines)


def figure(ref, rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from pbe_cfd.viz.psd_figure import label_diameter_axis
    grid = np.asarray(ref["grid_m"])
    fig, axes = plt.subplots(1, len(psd_cases.CASES), figsize=(15, 4.4))
    for ax, case in zip(axes, psd_cases.CASES):
        r = ref[case]
        q, h = np.array(r["q3"]), np.array(r["q3_half"])
        # the reference's q3 per ln d: differences of Q3 over 4 grid steps (smoothing the
        # particle list's steps), band from the Q3 band at both ends
        k = 4
        mid = np.sqrt(grid[k:] * grid[:-k])
        dl = np.log(grid[k:] / grid[:-k])
        dens = (q[k:] - q[:-k]) / dl
        band = (h[k:] + h[:-k]) / dl
        used = (q[k:] > 1e-4) & (q[:-k] < 1 - 1e-4)
        ax.fill_between(mid[used] * 1e6, (dens - band)[used], (dens + band)[used],
                        color="0.8", label="particle list, 95% band")
        ax.plot(mid[used] * 1e6, dens[used], "k-", lw=1.5, label="particle list (reference)")
        for style, row in zip(("C0--", "C1-.", "C2:", "C3:"), [x for x in rows if x["case"] == case]):
            if "stops" in row:
                continue
            ax.plot(np.array(row["d_m"]) * 1e6, row["q3_per_ln_d"], style, lw=2,
                    label=f"{row['method']}, L1(Q3) = {row['l1_q3']:.3f}")
        ax.set_xscale("log")
        label_diameter_axis(ax)                           # plain um, at least 4 labels
        ax.set_xlabel("d [um]")
        ax.set_ylabel("q3 = dQ3/d ln d [-]")
        ax.set_title(f"{case}, t = {psd_cases.END[case]:g} s")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    with open(sys.argv[1]) as fh:
        ref = json.load(fh)
    if len(sys.argv) > 4 and sys.argv[4] == "--redraw":      # the figure of the stored rows
        with open(sys.argv[3]) as fh:
            figure(ref, json.load(fh), sys.argv[2])
        sys.exit(0)
    rows = measure(ref)
    with open(sys.argv[3], "w") as fh:
        json.dump(rows, fh)
    print(markdown(rows))
    figure(ref, rows, sys.argv[2])
