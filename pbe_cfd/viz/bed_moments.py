"""The bed-averaged moments of a coupled run over time (``bed_moments.csv`` to a PNG), in the
units of the VTK cell fields."""
from __future__ import annotations

import csv
import os
import re
from pathlib import Path

import numpy as np

from .figure_parts import (PICTURE_UNITS, _LABELS, _figure, _png_meta, _run_info,
                           distinct_formatter, field_label)

def _read_csv(csv_path: Path) -> tuple[list[str], np.ndarray]:
    with open(csv_path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{csv_path}: empty file")
    header = [h.strip() for h in rows[0]]
    if not header or header[0] != "time_s":
        raise ValueError(f"{csv_path}: first column must be 'time_s', got {header[:1]}")
    try:
        data = np.array([[float(x) for x in r] for r in rows[1:] if r], dtype=float)
    except ValueError as exc:
        raise ValueError(f"{csv_path}: non-numeric value ({exc})") from None
    if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] != len(header):
        raise ValueError(f"{csv_path}: expected rows of {len(header)} numbers under the header")
    return header, data


#: Panels of bed_moments.png: (title, column names, unit) in the units of the VTK fields.
BED_PANELS = (
    # the moments are the whole population's, free droplets included (docs/physics.md 11)
    ("number of particles (free droplets included)", ("M00",), "1/m3"),
    ("particle and binder mass", ("M10", "M01"), "kg/m3"),
    ("second moments", ("M20", "M11", "M02"), "kg2/m3"),
    ("free droplets", ("droplet_number_density",), "1/m3"),
    ("mean diameters", ("d32_m", "d43_m"), "m"),
    ("mass-based percentiles of the size distribution", ("d10_m", "d50_m", "d90_m"), "m"),
    ("binder fraction", ("binder_fraction",), "-"),
    ("particle and binder mass in the whole bed", ("bed_mass_kg", "bed_binder_mass_kg"), "kg"),
    ("liquid in the whole bed", ("liquid_sprayed_kg", "liquid_granules_kg",
                                 "liquid_droplets_kg", "liquid_evaporated_kg"), "kg"),
    ("binder solids in the whole bed", ("solids_sprayed_kg", "solids_held_kg"), "kg"),
    ("moisture content (liquid / dry mass)", ("moisture_content",), "-"),
    ("evaporation rate of the bed", ("evaporation_rate_kg_s",), "kg/s"),
    ("driving force Y_s(T_wb) - Y", ("air_driving_force",), "kg/kg"),
    ("outlet air humidity", ("outlet_humidity",), "kg/kg"),
    ("outlet air temperature", ("outlet_temperature_K",), "K"),
)


def _bed_panels(header) -> list:
    """(title, columns, unit) of every panel for the columns of ``header``: the fixed
    panels, then one per order of any other moment M_ij (i + j >= 3), then one per other
    column (its unit from its name)."""
    have = set(header)
    panels = [(t, [c for c in cols if c in have], u) for t, cols, u in BED_PANELS]
    panels = [p for p in panels if p[1]]
    known = {c for _, cols, _ in panels for c in cols} | {"time_s"}
    orders: dict = {}
    for h in header:
        m = re.fullmatch(r"M(\d)(\d)", h)
        if h not in known and m:
            orders.setdefault(int(m.group(1)) + int(m.group(2)), []).append(h)
            known.add(h)
    for k in sorted(orders):
        panels.append((f"moments of order {k}", orders[k], f"kg{k}/m3"))
    for h in header:
        if h not in known:
            panels.append((h, [h], field_label(h).split("[")[1].rstrip("]")))
    return panels


def _scaled_axis(ax, unit: str):
    """A power of ten of a linear axis goes into its unit ("[1e10 1/m3]"), not above the axis;
    tick labels keep the digits they need to differ."""
    lo, hi = ax.get_ylim()
    big = max(abs(lo), abs(hi))
    exp = int(np.floor(np.log10(big))) if big > 0 else 0
    if -3 < exp < 4:
        ax.set_ylabel(f"[{unit}]", fontsize=9)
        return
    ax.yaxis.set_major_formatter(distinct_formatter(exp))
    ax.set_ylabel(f"[1e{exp} {unit}]" if unit != "-" else f"[1e{exp}]", fontsize=9)


#: line styles of the curves of one panel, in drawing order
_LINE_STYLES = ("-", "--", ":", "-.")
#: a log axis shows at most this many decades below its panel's largest value (ours: a
#: moisture from 5% down to 1e-10, a number over ten orders, stay readable; what falls
#: below leaves the panel at its bottom)
LOG_DECADES = 12

#: Drawing cost of bed_moments.png in the units of the field pictures' tasks (``render``: 0.4
#: + 0.6 per picture): measured warm on the bundled fluid bed, 1.0 s of CPU for its seven
#: panels against 0.17 s for a field's two pictures (1.6 units)
BED_MOMENTS_COST = 9.0


def plot_bed_moments(csv_path: str | os.PathLike, png_path: str | os.PathLike,
                     title: str | None = None) -> Path:
    """Plot ``bed_moments.csv`` to a PNG (``bed_moments_figure``); returns the path."""
    png_path = Path(png_path)
    fig = bed_moments_figure(csv_path, title)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png_path, dpi=110, metadata=_png_meta("bed moments"))
    return png_path


def _fixed_margins(fig, width, height, nrow, ncol, left=0.8, right=0.2, top=0.75, bottom=0.5,
                   gap=(0.95, 0.8)):
    """Margins and gaps (columns, rows) in inches: one draw, where a constrained layout draws
    the figure several times over."""
    axes_w = (width - left - right - (ncol - 1) * gap[0]) / ncol
    axes_h = (height - top - bottom - (nrow - 1) * gap[1]) / nrow
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=gap[0] / axes_w, hspace=gap[1] / axes_h)


def bed_moments_figure(csv_path: str | os.PathLike, title: str | None = None):
    """The figure of ``bed_moments.csv``: one panel per quantity, in the units of the VTK cell
    fields (moments per m3 of bed: the bed average is the volume-weighted mean of the cells'
    values), diameters in um, time in s, log axes named as such. ``title`` defaults to the
    scene name in the run's summary.json."""
    csv_path = Path(csv_path)
    header, data = _read_csv(csv_path)
    t = data[:, 0]
    col = {h: data[:, i] for i, h in enumerate(header)}
    panels = _bed_panels(header)
    if not panels:
        raise ValueError(f"{csv_path}: no columns to plot besides time_s")
    ncol = min(3, len(panels))
    nrow = -(-len(panels) // ncol)
    width, height = 4.3 * ncol, 3.1 * nrow + 0.6
    fig = _figure(figsize=(width, height))
    axes = fig.subplots(nrow, ncol, squeeze=False)
    _fixed_margins(fig, width, height, nrow, ncol)
    for ax, (name, cols, unit) in zip(axes.ravel(), panels):
        factor, unit = PICTURE_UNITS.get(unit, (1.0, unit))     # diameters in um
        for k, c in enumerate(cols):
            y = col[c] * factor
            # each later curve dashed over the one before: curves that coincide (d10 = d50
            # while the primaries carry most of the mass) stay visible, not hidden
            ax.plot(t, y, lw=1.6, ls=_LINE_STYLES[k % len(_LINE_STYLES)],
                    label=_LABELS.get(c, (c,))[0] if c.endswith("_m") else c)
        ys = np.concatenate([col[c] * factor for c in cols])
        pos = ys[np.isfinite(ys) & (ys > 0)]
        # spans compared in decades: a dried bed's moisture of 1e-316 overflows the ratio
        log = (pos.size > 1 and np.log10(pos.max()) - np.log10(pos.min()) > 2.0
               and np.all(ys[np.isfinite(ys)] >= 0))
        if log:
            ax.set_yscale("log")
            ax.minorticks_off()      # decades and the grid: minor ticks cost a third of the draw
            name += " (log scale)"
            if pos.min() < pos.max() * 10.0 ** -LOG_DECADES:
                # a dried bed's liquid falls to 1e-316: its 300 decades would flatten the rest
                ax.set_ylim(pos.max() * 10.0 ** -LOG_DECADES, pos.max() * 3.0)
                name += f", {LOG_DECADES} decades"
            ax.set_ylabel(f"[{unit}]", fontsize=9)
        else:
            _scaled_axis(ax, unit)
        ax.set_title(name, fontsize=10, y=1.0)
        ax.set_xlabel("time [s]", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
        if len(cols) > 1:
            ax.legend(fontsize=8)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    if title is None:
        info = _run_info(csv_path.parent)
        title = info.get("name")
    head = f"{title}: " if title else ""
    fig.suptitle(f"{head}bed averages (per m3 of bed, the SI units of the VTK cell fields "
                 "but diameters in um; time in s)", fontsize=10)
    return fig
