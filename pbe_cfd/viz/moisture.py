"""The moisture of a batch (``bed_moments.csv`` of a run with drying, to ``moisture.png``):
the granules' moisture content over time, and the bed's liquid inventory (sprayed, held by
granules and by free droplets, evaporated) with the air's capacity line."""
from __future__ import annotations

import os
from pathlib import Path

from .bed_moments import _read_csv
from .figure_parts import _figure, _png_meta

#: inventory curves of the right panel: column, label
LIQUID = (("liquid_sprayed_kg", "sprayed"), ("liquid_granules_kg", "held by granules"),
          ("liquid_droplets_kg", "held by free droplets"),
          ("liquid_evaporated_kg", "evaporated"))
#: drawing cost in units of one field section (figure_pool tasks)
MOISTURE_COST = 1.5


def moisture_figure(csv_path: str | os.PathLike, title: str | None = None):
    """The figure of a run's ``bed_moments.csv`` with drying columns: moisture content [%,
    kg liquid per 100 kg dry solids] and outlet air temperature [deg C] (left), liquid
    inventory [g] (right); time in min. ValueError without the columns."""
    header, data = _read_csv(Path(csv_path))
    col = {h: data[:, i] for i, h in enumerate(header)}
    need = ["moisture_content"] + [c for c, _ in LIQUID]
    missing = [c for c in need if c not in col]
    if missing:
        raise ValueError(f"{csv_path}: no drying columns ({', '.join(missing)}): expected a "
                         "run with a [drying] table")
    t = col["time_s"] / 60.0
    fig = _figure(figsize=(11.0, 4.0))
    left, right = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.14, top=0.86, wspace=0.35)
    left.plot(t, 100.0 * col["moisture_content"], lw=1.8, color="C0")
    left.set_ylabel("moisture content [% of dry mass]", fontsize=9, color="C0")
    left.set_ylim(bottom=0.0)
    if "outlet_temperature_K" in col:
        twin = left.twinx()
        twin.plot(t, col["outlet_temperature_K"] - 273.15, lw=1.2, color="C3", ls="--")
        twin.set_ylabel("outlet air temperature [deg C]", fontsize=9, color="C3")
        twin.tick_params(labelsize=8)
    left.set_title("granules' moisture", fontsize=10)
    for c, label in LIQUID:
        right.plot(t, 1e3 * col[c], lw=1.6, label=label)
    right.set_ylabel("liquid in the bed [g]", fontsize=9)
    right.set_title("liquid inventory", fontsize=10)
    right.legend(fontsize=8, loc="upper left")
    for ax in (left, right):
        ax.set_xlabel("time [min]", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=8)
    if title:
        fig.suptitle(title, fontsize=11)
    return fig


def plot_moisture(csv_path: str | os.PathLike, png_path: str | os.PathLike,
                  title: str | None = None) -> Path:
    """Plot ``moisture_figure`` of ``csv_path`` to ``png_path``; returns the path."""
    png_path = Path(png_path)
    fig = moisture_figure(csv_path, title)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png_path, dpi=110, metadata=_png_meta("moisture"))
    return png_path
