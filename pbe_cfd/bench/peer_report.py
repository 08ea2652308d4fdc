"""Outputs of ``pbe-cfd bench peer``: peer.csv, peer.md, peer.png (error against wall time and
against wall time per cell-step) and peer.json."""
from __future__ import annotations

import math
from pathlib import Path

from ..methods.cnmc import ENTRY as CNMC
from ..methods.qmom import ENTRY as QMOM
from .common import _machine_line, _write_csv

_COLUMNS = ("problem", "method", "knob", "groups", "err_M0", "err_M1", "err_M2", "sum_f",
            "wall_s", "cpu_s", "first_call_s", "steps", "cells", "per_cell_step_s")


def _pct(e):
    if e is None or not math.isfinite(e):
        return "-"
    return f"{100 * e:+.2g}%" if abs(e) >= 1e-4 else f"{e:+.1e}"


def _s(v, fmt=".3g"):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def peer_markdown(result) -> str:
    """The peer table and the equal-accuracy ratios as Markdown."""
    lines = [_machine_line(result["machine"]) + f"; commit {result['commit'] or '?'}.", ""]
    titles = result.get("titles", {})
    for problem, text in result["references"].items():
        lines.append(f"- **{problem}** ({titles.get(problem, problem)}): reference {text}.")
    for problem, err in result.get("reference_checks", {}).items():
        lines.append(f"- fixed-pivot reference on the {problem} closed form: M0 {err['M0']:.1e},"
                     f" M2 {err['M2']:.1e} relative error.")
    lines += ["", "| problem | method | knob | M0 err | M1 err | M2 err | sum f | wall [s] | "
              "CPU [s] | steps | wall per cell-step [s] |", "|" + "---|" * 11]
    for r in result["rows"]:
        lines.append(f"| {r['problem']} | {r['method']} | {r['knob']} | {_pct(r['err_M0'])} | "
                     f"{_pct(r['err_M1'])} | {_pct(r['err_M2'])} | {_s(r.get('sum_f'), '.5f')}"
                     f" | {_s(r['wall_s'])} | {_s(r.get('cpu_s'))} | {_s(r['steps'], 'd')} | "
                     f"{_s(r['per_cell_step_s'])} |")
    lines.append("")
    for problem, eq in result["equal_accuracy"].items():
        if not eq:
            continue
        lines.append(f"- {problem}: the class method's M2 error falls as G^-{eq['error_order']:.2f}"
                     f" in the number of groups G; 1% needs G = {eq['groups']:.0f} groups, "
                     f"about {eq['class_wall_s']:.3g} s of wall time and {eq['class_cpu_s']:.3g}"
                     f" s of CPU time (fits over the runs), against {eq['qmom3_wall_s']:.3g} s "
                     f"and {eq['qmom3_cpu_s']:.3g} s for QMOM N = 3 (M2 "
                     f"{_pct(eq['qmom3_err_M2'])}): {eq['ratio_wall_s']:.0f}x in wall time, "
                     f"{eq['ratio_cpu_s']:.0f}x in CPU time.")
    c = result.get("cells_cost")
    if c:
        n = c["cells"]
        lines.append(f"- class method on {n} cells ({c['groups']} groups, {c['steps']} steps): "
                     f"{c[f'wall_{n}_s']:.3g} s against {c['wall_1_s']:.3g} s on one cell, "
                     f"{c['marginal_per_cell_step_s']:.3g} s per added cell-step.")
    return "\n".join(lines) + "\n"


def plot_peer(result, path):
    """Two panels: |M2 error| against wall time [s] and against wall time per cell-step [s],
    one marker per method, one colour per problem."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    colours = {"aggregation": "tab:blue", "breakage": "tab:orange", "mixed": "tab:green"}
    markers = {"class": "s", QMOM.name: "o", CNMC.name: "^"}
    for ax, key, label in ((axes[0], "wall_s", "wall time [s]"),
                           (axes[1], "per_cell_step_s", "wall time per cell-step [s]")):
        for r in result["rows"]:
            err = abs(r["err_M2"])
            if not math.isfinite(err) or not math.isfinite(r[key]) or r[key] <= 0:
                continue
            ax.scatter(r[key], max(err, 1e-16), marker=markers.get(r["method"], "x"),
                       color=colours.get(r["problem"], "k"),
                       facecolors="none" if r.get("dt_check") else None)
            ax.annotate(r["knob"].replace(" groups", "g"), (r[key], max(err, 1e-16)),
                        fontsize=6, xytext=(3, 2), textcoords="offset points")
        c = result.get("cells_cost")
        marginal = [r for r in result["rows"] if c and key == "per_cell_step_s"
                    and r["method"] == "class" and r["problem"] == "aggregation"
                    and r["groups"] == c["groups"] and not r.get("dt_check")]
        for r in marginal:      # the class method's cost per added cell of an N-cell box
            ax.scatter(c["marginal_per_cell_step_s"], abs(r["err_M2"]), marker="*", s=80,
                       color=colours["aggregation"])
            ax.annotate(f"{r['groups']}g, per added cell ({c['cells']} cells)",
                        (c["marginal_per_cell_step_s"], abs(r["err_M2"])), fontsize=6,
                        xytext=(3, -8), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("|relative error of M2| (round-off shown at 1e-16)")
        ax.grid(True, which="major", alpha=0.3)
    handles = [plt.Line2D([], [], color=c, marker="s", ls="", label=p)
               for p, c in colours.items() if any(r["problem"] == p for r in result["rows"])]
    handles += [plt.Line2D([], [], color="k", marker=m, ls="", mfc="none", label=name)
                for name, m in markers.items()]
    axes[1].legend(handles=handles, fontsize=7, loc="best")
    fig.suptitle("OpenFOAM class method (squares; open: at 2 dt; star: per added cell of an "
                 "N-cell box) against pbe-cfd (QMOM circles, cNMC triangles)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_peer(out_dir, result):
    """peer.csv, peer.md, peer.png and peer.json into ``out_dir`` (added to the directory
    safely: files pbe-cfd did not write are never replaced)."""
    from ..io import output
    lines = [list(_COLUMNS)] + [[r.get(k) for k in _COLUMNS] for r in result["rows"]]
    with output.add_to_directory(Path(out_dir), kind="bench") as d:
        _write_csv(d / "peer.csv", lines)
        (d / "peer.md").write_text(peer_markdown(result))
        plot_peer(result, d / "peer.png")
        output.write_json(d / "peer.json", result)
