"""Outputs of the accuracy study: accuracy.csv, accuracy.md, pareto.png, accuracy.json."""
from __future__ import annotations

import math

from .common import _machine_line, _write_csv

#: quantities compared by the accuracy study (columns of RunResult)
QUANTITIES = ("M00", "M20", "M11", "M02", "d43_m", "binder_fraction", "d50_m")


def _fmt_err(e):
    if e is None or not math.isfinite(e):
        return "n/a"
    return f"{100 * e:.2g}%" if abs(e) >= 1e-4 else f"{e:.1e}"


def _accuracy_csv_rows(result):
    lines = []
    header = ["method", "knob", "status", "time_s"] + [f"err_{q}" for q in QUANTITIES] + [
        "max_abs_error", "wall_s_median", "first_call_s", "tensor_build_s", "steps",
        "rhs_calls", "cnmc_trials"]
    lines.append(header)
    for row in result["rows"]:
        times = result["times_s"] if row["status"] == "ok" else [float("nan")]
        for k, t in enumerate(times):
            rec = [row["method"], row["knob"], row["status"], t]
            for q in QUANTITIES:
                vals = row.get("errors", {}).get(q)
                rec.append(vals[k] if vals is not None else float("nan"))
            rec += [row.get("max_abs_error"), row.get("wall_s"), row.get("first_call_s"),
                    row.get("tensor_build_s", float("nan")), row.get("steps"),
                    row.get("rhs_calls"), row.get("trials")]
            lines.append(rec)
    return lines


def pareto_front(points):
    """Indices of the points (time, error) not dominated by another (lower time and error)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front = []
    best = float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def accuracy_markdown(result) -> str:
    """The accuracy table (max |relative error| over the chosen times) as Markdown."""
    ref = result["reference"]
    times = ", ".join(f"{t:g}" for t in result["times_s"])
    lines = [f"Scene `{result['scene']}`; errors are max |relative error| over t = {times} s "
             f"against the reference: {ref['text']}.", ""]
    names = {"M00": "M00", "M20": "M20", "M11": "M11", "M02": "M02", "d43_m": "d43",
             "binder_fraction": "binder fr.", "d50_m": "d50"}
    head = "| method | knob | " + " | ".join(names[q] for q in QUANTITIES) + \
        " | max | wall [s] | first call [s] |"
    lines += [head, "|" + "---|" * (head.count("|") - 1)]
    pts = [(r["wall_s"], r["max_abs_error"]) for r in result["rows"] if r["status"] == "ok"
           and math.isfinite(r["max_abs_error"])]
    ok_rows = [r for r in result["rows"] if r["status"] == "ok"
               and math.isfinite(r["max_abs_error"])]
    front = {id(ok_rows[i]) for i in pareto_front(pts)}
    for r in result["rows"]:
        if r["status"] != "ok":
            lines.append(f"| {r['method']} | {r['knob']} | " + " | ".join("-" for _ in QUANTITIES)
                         + f" | {r['status'][:60]} | - | - |")
            continue
        cells = []
        for q in QUANTITIES:
            vals = r["errors"].get(q)
            cells.append(_fmt_err(max((abs(v) for v in vals if math.isfinite(v)), default=None))
                         if vals else "n/a")
        star = " *" if id(r) in front else ""
        extra = ""
        if "tensor_build_s" in r and math.isfinite(r["tensor_build_s"]):
            extra = f" (+{r['tensor_build_s']:.2g} tensor)"
        lines.append(f"| {r['method']} | {r['knob']}{star} | " + " | ".join(cells)
                     + f" | {_fmt_err(r['max_abs_error'])} | {r['wall_s']:.3g} | "
                     f"{r['first_call_s']:.3g}{extra} |")
    own = [(r["knob"], max((b for b in r.get("own_band", {}).values() if math.isfinite(b)),
                           default=float("nan")))
           for r in result["rows"] if r["status"] == "ok" and "own_band" in r]
    if own:
        lines += ["", "Particle-ensemble variants' own 95% band half-width (max over quantities and times): "
                  + ", ".join(f"{k} {_fmt_err(b)}" for k, b in own) + "; their wall time is "
                  "the whole ensemble."]
    band = {q: b for q, b in (ref.get("band") or {}).items() if b and math.isfinite(b)}
    if band:
        lines += ["", "Reference's own resolution (an ensemble: its 95% band half-width; a lattice "
                  "percentile: one lattice step; max over the chosen times): "
                  + ", ".join(f"{names[q]} {_fmt_err(b)}" for q, b in band.items()) + "."]
    lines += ["", "`*` on the Pareto front (no other variant is both faster and more accurate). "
              f"Wall time: median of {result['repeats']} runs; first call: the first run in the "
              "process (numba compilation or cache load; Laguerre: tensor build or disk-cache "
              "load), reported apart, with the uncached tensor build time in brackets. cNMC "
              "errors are those of one ensemble mean (one seed) and scatter by about its own "
              "band.", "", f"Machine: {_machine_line(result['machine'])}."]
    return "\n".join(lines) + "\n"


SIZE_QUANTITIES = ("M00", "M20", "d43_m")


def _row_error(row, quantities):
    """max |relative error| of a row over the given quantities and the chosen times."""
    vals = [abs(v) for q in quantities for v in row.get("errors", {}).get(q, [])
            if math.isfinite(v)]
    return max(vals) if vals else float("nan")


def plot_pareto(path, result):
    """Error against wall time, log-log, one marker per method and knob, the Pareto front
    drawn; left: all six quantities, right: the size distribution only (M00, M20, d43)."""
    from ..viz import plotting  # noqa: F401 - selects the Agg backend
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    methods = list(dict.fromkeys(r["method"] for r in result["rows"]))
    style = {m: ("osD^vP*X"[k % 8], f"C{k % 10}") for k, m in enumerate(methods)}
    for ax, quantities, what in ((axes[0], QUANTITIES,
                                  "M00, M20, M11, M02, d43, binder fraction"),
                                 (axes[1], SIZE_QUANTITIES, "M00, M20, d43")):
        rows = [(r, _row_error(r, quantities)) for r in result["rows"] if r["status"] == "ok"]
        rows = [(r, e) for r, e in rows if math.isfinite(e) and e > 0]
        seen = set()
        for r, e in rows:
            marker, colour = style.get(r["method"], ("x", "k"))
            filled = "plain" not in r["knob"]
            ax.plot(r["wall_s"], e, marker=marker, color=colour, ls="none", ms=8,
                    mfc=colour if filled else "none",
                    label=r["method"] if r["method"] not in seen else None)
            seen.add(r["method"])
            ax.annotate(r["knob"], (r["wall_s"], e), fontsize=7, xytext=(4, 3),
                        textcoords="offset points")
        pts = [(r["wall_s"], e) for r, e in rows]
        front = sorted(pareto_front(pts), key=lambda i: pts[i][0])
        if front:
            xs = [pts[i][0] for i in front]
            ys = [pts[i][1] for i in front]
            ax.step(xs + [max(p[0] for p in pts) * 1.5], ys + [ys[-1]], where="post",
                    color="k", lw=1, ls="--", label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per run [s] (median, compile excluded)")
        ax.set_ylabel(f"max |relative error| of {what}")
        ax.grid(True, which="both", alpha=0.3)
        if rows:
            ax.legend(fontsize=8)
    fig.suptitle(f"{result['scene']}: error vs cost (reference: "
                 f"{result['reference']['kind']}; unfilled: plain Laguerre projection)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_accuracy(out_dir, result):
    """Write accuracy.csv, accuracy.md, pareto.png and accuracy.json into out_dir."""
    from ..io import output
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / "accuracy.csv", _accuracy_csv_rows(result))
        (d / "accuracy.md").write_text(accuracy_markdown(result))
        plot_pareto(d / "pareto.png", result)
        output.write_json(d / "accuracy.json", result)
