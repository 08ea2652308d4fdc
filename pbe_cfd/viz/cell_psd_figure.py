"""``png/cell_psd.png``: the size distributions of the cells of ``[output] cell_psd`` at the
last output time, against the bed's (the columns of ``cell_psd.csv`` and ``psd.csv``).

Left: the volume density q3 per unit ln d; right: the cumulative Q3 (d50 where it crosses
0.5); both against d [um] on a log axis, one curve per cell (named by its mesh id and centre
[mm]), the bed's dashed black. A cell without granules at that time is left out of the panels
and named in the legend's title.
"""
from __future__ import annotations

import numpy as np

from .psd_figure import _axes

#: drawing cost of cell_psd.png relative to one field section (``figure_pool`` tasks)
CELL_PSD_COST = 2.0


def _read(cols):
    if isinstance(cols, dict):
        return {k: np.asarray(v, float) for k, v in cols.items()}
    from ..io.output import read_columns_csv
    return read_columns_csv(cols)


def cell_psd_figure(cells, bed=None, title=""):
    """The figure of cell_psd.csv columns ``cells`` (and psd.csv columns ``bed`` or None) at
    the last output time; returns it."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t = float(np.max(cells["time_s"]))
    at = cells["time_s"] == t
    fig, (ax_q, ax_c) = plt.subplots(1, 2, figsize=(10.5, 4.2), constrained_layout=True)
    empty = []
    for k, cell in enumerate(dict.fromkeys(cells["cell"][at])):
        sel = at & (cells["cell"] == cell)
        x, y, z = (round(cells[a][sel][0] * 1e3, 6) + 0.0 for a in ("x_m", "y_m", "z_m"))
        label = f"cell {int(cell)} at ({x:.3g}, {y:.3g}, {z:.3g}) mm"
        if not np.all(cells["active"][sel] > 0):
            empty.append(f"{int(cell)}")
            continue
        d_um = cells["d_m"][sel] * 1e6
        ax_q.plot(d_um, cells["q3_per_ln_d"][sel], color=f"C{k % 10}", lw=1.4, label=label)
        ax_c.plot(d_um, cells["Q3"][sel], color=f"C{k % 10}", lw=1.4, label=label)
    if bed is not None:
        sel = bed["time_s"] == np.max(bed["time_s"])
        for ax, name in ((ax_q, "q3_per_ln_d"), (ax_c, "Q3")):
            ax.plot(bed["d_m"][sel] * 1e6, bed[name][sel], "k--", lw=1.2, label="the bed")
    _axes(ax_q, f"{title}, t = {t:g} s")
    _axes(ax_c, "cumulative")
    ax_c.set_ylabel("Q3 = mass fraction below d [-]")
    ax_c.set_ylim(0.0, 1.0)
    ax_c.axhline(0.5, color="0.6", lw=0.8)
    legend = ax_q.legend(fontsize=7, title=(f"no granules: cell {', '.join(empty)}"
                                            if empty else None), title_fontsize=7)
    legend.set_zorder(5)
    return fig


def plot_cell_psd(path, cells, bed=None, title="", metadata=None):
    """Draw ``cell_psd_figure`` of cell_psd.csv (columns or its path) and psd.csv (columns,
    path or None) to ``path``; ``metadata`` goes into the image file. Returns the path."""
    from pathlib import Path

    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig = cell_psd_figure(_read(cells), None if bed is None else _read(bed), title)
    fig.savefig(path, dpi=110, metadata=metadata)
    plt.close(fig)
    return path
