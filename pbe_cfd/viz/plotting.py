"""Matplotlib figures of moment trajectories (Agg backend: no display needed)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..util.population import is_moment_name, moment_orders  # noqa: E402
from .figure_parts import PICTURE_UNITS  # noqa: E402

UNITS = {"M00": "1/m3", "M10": "kg/m3", "M01": "kg/m3", "M20": "kg2/m3", "M11": "kg2/m3",
         "M02": "kg2/m3", "droplet_number_density": "1/m3", "binder_fraction": "-",
         "span": "-"}


def _unit(name):
    if name in UNITS:
        return UNITS[name]
    if name.endswith("_m"):                          # a diameter column, SI metres
        return "m"
    if is_moment_name(name):
        order = sum(moment_orders(name))
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


#: Opacity of a cNMC band: the lines of other runs stay visible through it.
BAND_ALPHA = 0.35


def _reference(runs):
    """The first run carrying ``_lo``/``_hi`` bands (a cNMC), or None."""
    for label, cols in runs:
        if any(n.endswith("_lo") for n in cols):
            return label, cols
    return None


def _deviation_percent(t_ref, ref_mean, t, values):
    """100 (values / ref_mean - 1) on the reference's times (NaN where the mean is 0 and
    outside the times of ``t``)."""
    v = np.interp(t_ref, t, values, left=np.nan, right=np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * (v / ref_mean - 1.0)
    out[~np.isfinite(out)] = np.nan
    return out


def plot_trajectories(path, runs, title="", common_only=False, metadata=None):
    """Draw ``trajectories_figure`` to ``path``; ``metadata`` goes into the image file
    (``output.figure_metadata``). Returns the path."""
    fig = trajectories_figure(runs, title, common_only)
    # the margins are fixed in inches (``trajectories_figure``): one draw, where a tight
    # bounding box draws the figure twice
    fig.savefig(path, dpi=110, metadata=metadata)
    plt.close(fig)
    return path


def trajectories_figure(runs, title="", common_only=False):
    """One panel per column; ``runs`` is a list of (label, columns dict). A run whose columns
    carry ``_lo``/``_hi`` bands (cNMC) is drawn as a filled band with its mean on top, and
    every panel then gets a second axis below: each run's deviation from that mean in %, with
    the band around zero (a band of a few % is invisible on the absolute axis). With
    ``common_only`` only the columns every run has are drawn (comparisons)."""
    names = []
    for _, cols in runs:
        for n in plotted_columns(cols):
            if n not in names:
                names.append(n)
    if common_only:
        names = [n for n in names if all(n in cols for _, cols in runs)]
    if not names:
        raise ValueError("no column to plot" + (" common to every run" if common_only else ""))
    ref = _reference(runs)
    ncol = 3
    nrow = max(1, math.ceil(len(names) / ncol))
    height = (4.2 if ref else 3.0) * nrow
    width = 4.3 * ncol
    fig = plt.figure(figsize=(width, height))
    # margins in inches: room for the tick labels on the left, none wasted on the right
    outer = fig.add_gridspec(nrow, ncol, hspace=0.5, wspace=0.38, top=1 - 0.55 / height,
                             bottom=0.45 / height, left=0.8 / width, right=1 - 0.25 / width)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for idx, name in enumerate(names):
        cell = outer[divmod(idx, ncol)]
        if ref:
            inner = cell.subgridspec(2, 1, height_ratios=[3, 1.4], hspace=0.08)
            ax = fig.add_subplot(inner[0])
            dev = fig.add_subplot(inner[1], sharex=ax)
        else:
            ax, dev = fig.add_subplot(cell), None
        _draw_quantity(ax, dev, name, runs, ref, colours)
        if idx == 0:
            ax.legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10, y=1 - 0.1 / height, va="top")
    return fig


def _draw_quantity(ax, dev, name, runs, ref, colours):
    log = False
    factor, unit = PICTURE_UNITS.get(_unit(name), (1.0, _unit(name)))   # diameters in um
    for r, (label, cols) in enumerate(runs):
        if name not in cols:
            continue
        t = cols["time_s"]
        colour = colours[r % len(colours)]
        if name + "_lo" in cols:
            ax.fill_between(t, factor * cols[name + "_lo"], factor * cols[name + "_hi"],
                            color=colour,
                            alpha=BAND_ALPHA, lw=0.6, edgecolor=colour,
                            label=f"{label} 95% band", zorder=2)
            ax.plot(t, factor * cols[name], color="k", lw=0.9, label=f"{label} mean",
                    zorder=4)
        else:
            ax.plot(t, factor * cols[name], color=colour, lw=1.6, label=label, zorder=3)
        log = log or spans_decades(cols[name])
    if log:
        ax.set_yscale("log")
    ax.set_title(name, fontsize=10)
    ax.set_ylabel(f"[{unit}]" + (" log scale" if log else ""), fontsize=9)
    ax.grid(alpha=0.3)
    if dev is None:
        ax.set_xlabel("time [s]")
        return
    ax.tick_params(labelbottom=False)
    rlabel, rcols = ref
    t_ref, mean = rcols["time_s"], rcols[name]
    if name + "_lo" in rcols:
        lo = _deviation_percent(t_ref, mean, t_ref, rcols[name + "_lo"])
        hi = _deviation_percent(t_ref, mean, t_ref, rcols[name + "_hi"])
        k = next(i for i, (_, c) in enumerate(runs) if c is rcols)
        dev.fill_between(t_ref, lo, hi, color=colours[k % len(colours)],
                         alpha=BAND_ALPHA, lw=0.6, zorder=2)
    dev.axhline(0.0, color="k", lw=0.9, zorder=4)
    for r, (label, cols) in enumerate(runs):
        if cols is rcols or name not in cols:
            continue
        dev.plot(t_ref, _deviation_percent(t_ref, mean, cols["time_s"], cols[name]),
                 color=colours[r % len(colours)], lw=1.4, zorder=3)
    dev.set_ylabel(f"vs {rlabel}\nmean [%]", fontsize=8)
    dev.set_xlabel("time [s]")
    dev.grid(alpha=0.3)
    dev.tick_params(labelsize=8)
