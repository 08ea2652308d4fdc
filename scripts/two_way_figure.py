"""One-way against two-way coupling, side by side: the figure and the numbers of
docs/results/two-way.md from the outputs of

    pbe-cfd couple docs/results/two-way/one-way.toml --out ONE
    pbe-cfd couple docs/results/two-way/two-way.toml --out TWO
    python scripts/two_way_figure.py ONE TWO --out docs/results/two-way.png

Prints (markdown) d50 and d43 at the end, the bed-averaged alpha and Theta and the spray
zone per segment (one-way: its one CFD field over the same segments), and the wall seconds
of CFD and population balance.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def main(argv=None):
    from pbe_cfd.runs.domain import build_cells, load_domain
    from pbe_cfd.io.output import read_columns_csv
    from pbe_cfd.runs.coupling_output import bed_state
    from pbe_cfd.scene.scene import load_scene

    ap = argparse.ArgumentParser()
    ap.add_argument("one")
    ap.add_argument("two")
    ap.add_argument("--out", default="two-way.png")
    a = ap.parse_args(argv)
    one, two = Path(a.one), Path(a.two)
    b1 = read_columns_csv(one / "bed_moments.csv")
    b2 = read_columns_csv(two / "bed_moments.csv")
    seg = _columns(two / "segments.csv")
    s1 = json.loads((one / "summary.json").read_text())
    s2 = json.loads((two / "summary.json").read_text())
    scene = load_scene(s1["scene"]["source"])
    dom = load_domain(scene)
    _, active, spray, _ = build_cells(scene, dom.cells)
    flat = bed_state(dom, active, spray)

    print("| | one-way | two-way |\n|---|---|---|")
    for name in ("d50_m", "d43_m", "d32_m"):
        print(f"| {name[:-2]} at {b1['time_s'][-1]:g} s [um] | {b1[name][-1] * 1e6:.4g} | "
              f"{b2[name][-1] * 1e6:.4g} |")
    pbe1 = s1["phases"]["solve_s"]
    print(f"| wall [s]: CFD | 0 (the bundled snapshot) | {s2['coupling']['cfd_wall_s']:.1f} |")
    print(f"| wall [s]: population balance | {pbe1:.1f} | {s2['coupling']['pbe_wall_s']:.1f} |")
    print()
    print("| segment | process time [s] | CFD d [um] | mean alpha (two / one) | bed height [m] "
          "(two / one) | Theta p50 [m2/s2] (two / one) | spray cells (two / one) | U_mf [m/s] |")
    print("|---|---|---|---|---|---|---|---|")
    for k in range(len(seg["segment"])):
        print(f"| {int(seg['segment'][k])} | {seg['process_start_s'][k]:g}-"
              f"{seg['process_end_s'][k]:g} | {seg['diameter_m'][k] * 1e6:.4g} | "
              f"{seg['mean_alpha'][k]:.4f} / {flat['mean_alpha']:.4f} | "
              f"{seg['bed_height_m'][k]:.3f} / {flat['bed_height_m']:.3f} | "
              f"{seg['theta_p50_m2_s2'][k]:.3g} / {flat['theta_p50_m2_s2']:.3g} | "
              f"{int(seg['spray_cells'][k])} / {flat['spray_cells']} | "
              f"{seg['u_mf_m_s'][k]:.3g} |")
    _figure(a.out, b1, b2, seg, flat)


def _columns(path):
    import csv
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def _figure(path, b1, b2, seg, flat):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    edges = np.append(seg["process_start_s"], seg["process_end_s"][-1])
    n = len(seg["segment"])
    fig, ax = plt.subplots(2, 3, figsize=(14, 7.5), constrained_layout=True)
    for name, style in (("d50_m", "-"), ("d43_m", "--"), ("d32_m", ":")):
        ax[0, 0].plot(b1["time_s"], b1[name] * 1e6, "C0" + style, label=f"one-way {name[:-2]}")
        ax[0, 0].plot(b2["time_s"], b2[name] * 1e6, "C3" + style, label=f"two-way {name[:-2]}")
    ax[0, 0].stairs(seg["diameter_m"] * 1e6, edges, color="k", lw=0.8,
                    label="two-way CFD diameter")
    ax[0, 0].set_ylabel("diameter [um]")
    ax[0, 0].legend(fontsize=7)
    panels = ((ax[0, 1], "mean_alpha", "bed-averaged alpha (active cells) [-]"),
              (ax[0, 2], "bed_height_m", "bed height (99% of solids) [m]"),
              (ax[1, 0], "theta_p50_m2_s2", "Theta, solids-weighted median [m2/s2]"),
              (ax[1, 1], "spray_cells", "spray-zone cells"))
    for a, key, label in panels:
        a.stairs(np.full(n, flat[key]), edges, color="C0", label="one-way")
        a.stairs(seg[key], edges, color="C3", label="two-way")
        a.set_ylabel(label)
        a.legend(fontsize=8)
    ax[1, 0].stairs(seg["theta_p10_m2_s2"], edges, color="C3", ls=":", label="two-way p10")
    ax[1, 0].stairs(seg["theta_p90_m2_s2"], edges, color="C3", ls="--", label="two-way p90")
    ax[1, 0].set_yscale("log")
    ax[1, 0].legend(fontsize=8)
    ax[1, 2].bar(["CFD", "population balance"],
                 [float(np.sum(seg["cfd_wall_s"])), float(np.sum(seg["pbe_wall_s"]))],
                 color=["C1", "C2"])
    ax[1, 2].set_ylabel("two-way wall time [s]")
    for a in ax.flat[:5]:
        a.set_xlabel("process time [s]")
    fig.suptitle("fluid-bed-transport over 600 s: one-way (CFD once, d = 100.4 um) and "
                 "two-way (CFD re-run with the bed's d32)")
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
