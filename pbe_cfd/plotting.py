"""Matplotlib figures of moment trajectories (Agg backend: no display needed)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

UNITS = {"M00": "1/m3", "M10": "kg/m3", "M01": "kg/m3", "M20": "kg2/m3", "M11": "kg2/m3",
         "M02": "kg2/m3", "droplet_number_density": "1/m3", "d32_m": "m", "d43_m": "m",
         "binder_fraction": "-"}


def _unit(name):
    if name in UNITS:
        return UNITS[name]
    if name.startswith("M") and len(name) == 3:
        order = int(name[1]) + int(name[2])
        return f"kg{order}/m3" if order > 1 else ("kg/m3" if order == 1 else "1/m3")
    return ""


def plotted_columns(columns):
    """Columns worth a panel: the moments, droplets and derived sizes (bands excluded)."""
    names = []
    for name in columns:
        if name == "time_s" or name.endswith("_lo") or name.endswith("_hi"):
            continue
        if name in ("trials", "accepted"):
            continue
        names.append(name)
    return names


def spans_decades(values):
    """True if positive values span more than two decades (log axis is then clearer)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    return v.size > 1 and v.max() / v.min() > 100.0


def plot_trajectories(path, runs, title="", common_only=False):
    """One panel per column; ``runs`` is a list of (label, columns dict). A run whose columns
    carry ``_lo``/``_hi`` bands (cNMC) is drawn as a band with its mean; others as lines.
    With ``common_only`` only the columns every run has are drawn (comparisons)."""
    names = []
    for _, cols in runs:
        for n in plotted_columns(cols):
            if n not in names:
                names.append(n)
    if common_only:
        names = [n for n in names if all(n in cols for _, cols in runs)]
    ncol = 3
    nrow = max(1, math.ceil(len(names) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for idx, name in enumerate(names):
        ax = axes[idx // ncol][idx % ncol]
        log = False
        for r, (label, cols) in enumerate(runs):
            if name not in cols:
                continue
            t = cols["time_s"]
            colour = colours[r % len(colours)]
            if name + "_lo" in cols:
                ax.fill_between(t, cols[name + "_lo"], cols[name + "_hi"], color=colour,
                                alpha=0.3, lw=0, label=f"{label} 95% band")
                ax.plot(t, cols[name], color=colour, lw=0.8, ls="--", label=f"{label} mean")
            else:
                ax.plot(t, cols[name], color=colour, lw=1.6, label=label)
            log = log or spans_decades(cols[name])
        if log:
            ax.set_yscale("log")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"[{_unit(name)}]")
        ax.grid(alpha=0.3)
        if idx == 0:
            ax.legend(fontsize=7)
    for idx in range(len(names), nrow * ncol):
        axes[idx // ncol][idx % ncol].axis("off")
    if title:
        fig.suptitle(title, fontsize=10)
        fig.tight_layout(rect=(0, 0, 1, 0.97))
    else:
        fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
