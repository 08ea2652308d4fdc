"""Matplotlib figures of granule size distributions (the columns of ``psd.csv``).

``psd.png``: the volume density q3 per unit ln d against d [um] on a log axis, one curve per
output time (coloured by time); a cNMC's replicas' 95% band is filled around its curve.
``psd_overlay``: several runs' distributions at their last output time in one panel.
"""
from __future__ import annotations

import numpy as np

#: opacity of a cNMC's band
BAND_ALPHA = 0.3
#: drawing cost of psd.png relative to one field section (``cfd.figure_pool`` tasks)
PSD_COST = 2.0


def _times(cols):
    return np.unique(np.asarray(cols["time_s"], float))


def _at(cols, t):
    sel = np.asarray(cols["time_s"], float) == t
    return {k: np.asarray(v, float)[sel] for k, v in cols.items()}


def _draw(ax, part, colour, label, lw=1.4):
    d_um = part["d_m"] * 1e6
    if "q3_lo" in part:
        ax.fill_between(d_um, part["q3_lo"], part["q3_hi"], color=colour, alpha=BAND_ALPHA,
                        lw=0)
    ax.plot(d_um, part["q3_per_ln_d"], color=colour, lw=lw, label=label)


#: leading digits of the labelled diameters per decade, coarsest first; the first set that
#: labels at least MIN_LABELS values inside the axis is used (earlier digits win a crowded place)
LABEL_DIGITS = ((1,), (1, 2, 5), (1, 2, 3, 5), (1, 2, 5, 3, 4, 6, 7, 8, 9))
#: labelled ticks a diameter axis shows at least
MIN_LABELS = 4
#: the nearest two labels on the axis, in parts of its span in ln d (the labels stay apart)
MIN_GAP = 0.1


def _spaced(values, lo, hi):
    """``values`` (in order of priority) inside [lo, hi], without those nearer in log d than
    MIN_GAP of the span to one kept before them; sorted."""
    import math
    gap = MIN_GAP * math.log(hi / lo)
    kept = []
    for v in values:
        if lo <= v <= hi and all(abs(math.log(v / k)) >= gap for k in kept):
            kept.append(v)
    return sorted(kept)


def diameter_ticks(lo: float, hi: float) -> list[float]:
    """Labelled tick values (plain numbers, the axis unit, e.g. um) for a log axis from ``lo``
    to ``hi`` (> 0): lead digits x 10^k of the coarsest set in LABEL_DIGITS that puts at least
    MIN_LABELS of them, spaced by MIN_GAP, inside [lo, hi]; for a span narrower than that,
    round values of a linear step (matplotlib's MaxNLocator)."""
    import math

    from matplotlib.ticker import MaxNLocator
    lo, hi = sorted((float(lo), float(hi)))
    decades = range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1)
    for digits in LABEL_DIGITS:
        ticks = _spaced([float(f"{d * 10.0 ** k:.6g}") for d in digits for k in decades],
                        lo, hi)
        if len(ticks) >= MIN_LABELS:
            return ticks
    for bins in range(MIN_LABELS, 3 * MIN_LABELS):
        ticks = MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
        inside = [float(f"{v:.6g}") for v in ticks if lo <= v <= hi and v > 0]
        if len(inside) >= MIN_LABELS:
            break
    return inside


def label_diameter_axis(ax):
    """Put diameter_ticks of the x axis' current limits on a log x axis as plain numbers
    (the minor ticks stay, unlabelled). Call after the data are drawn."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter
    ticks = diameter_ticks(*ax.get_xlim())
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _axes(ax, title):
    ax.set_xscale("log")
    label_diameter_axis(ax)
    ax.set_xlabel("granule diameter d [um]")
    ax.set_ylabel("q3 = dQ3/d(ln d) [-]")
    ax.set_ylim(bottom=0.0)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.25)


def psd_figure(cols, title=""):
    """One curve per output time of one run's psd.csv columns; returns the figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    times = _times(cols)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    cmap = plt.get_cmap("viridis")
    t_max = times.max() if times.size and times.max() > 0 else 1.0
    for t in times:
        _draw(ax, _at(cols, t), cmap(t / t_max), None)
    norm = matplotlib.colors.Normalize(vmin=0.0, vmax=t_max)
    bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax)
    bar.set_label("time [s]")
    _axes(ax, title + ("  (shaded: cNMC 95% band)" if "q3_lo" in cols else ""))
    return fig


def plot_psd(path, cols, title="", metadata=None):
    """Draw ``psd_figure`` of psd.csv columns (a dict, or the path of a psd.csv) to
    ``path``; ``metadata`` goes into the image file. Returns the path."""
    from pathlib import Path

    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not isinstance(cols, dict):
        from ..io.output import read_columns_csv
        cols = read_columns_csv(cols)
    fig = psd_figure(cols, title)
    fig.savefig(path, dpi=110, metadata=metadata, bbox_inches="tight")
    plt.close(fig)
    return path


def psd_overlay_figure(runs, title=""):
    """Several runs' q3 at each run's last output time in one panel: ``runs`` a list of
    (label, psd.csv columns); a run with the replicas' band (a cNMC's q3_lo, q3_hi) gets it
    filled and says so in its legend entry. Returns the figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, cols) in enumerate(runs):
        t = _times(cols)[-1]
        band = ", shaded: 95% band of its replicas" if "q3_lo" in cols else ""
        _draw(ax, _at(cols, t), colours[k % len(colours)], f"{label} (t = {t:g} s{band})")
    _axes(ax, title)
    ax.legend(fontsize=8)
    return fig


def psd_overlay(path, runs, title="", metadata=None):
    """Draw ``psd_overlay_figure`` of ``runs`` (a list of (label, psd.csv columns)) to
    ``path``; ``metadata`` goes into the image file. Returns the path."""
    import matplotlib.pyplot as plt
    fig = psd_overlay_figure(runs, title)
    fig.savefig(path, dpi=110, metadata=metadata, bbox_inches="tight")
    plt.close(fig)
    return path
