"""Small parts shared by the pictures of a run: field labels with their units (SI, but
diameters in um: PICTURE_UNITS), tick labels that stay distinct, the Figure outside pyplot,
PNG metadata and the run's name from its summary.json."""
from __future__ import annotations

import json
import re
from pathlib import Path

_LABELS = {
    "alpha": ("alpha", "-"),
    "alpha.particles": ("alpha", "-"),
    "alpha.particlesMean": ("mean alpha", "-"),
    "Theta": ("Theta", "m2/s2"),
    "Theta.particles": ("Theta", "m2/s2"),
    "Theta.particlesMean": ("mean Theta", "m2/s2"),
    "d32_m": ("d32", "m"),
    "d43_m": ("d43", "m"),
    "d10_m": ("d10", "m"),
    "d50_m": ("d50", "m"),
    "d90_m": ("d90", "m"),
    "span": ("span", "-"),
    "binder_fraction": ("binder fraction", "-"),
    "droplet_number_density": ("free droplets", "1/m3"),
    "cell_volume": ("cell volume", "m3"),
    "active": ("cell holds granules", "flag"),
    "spray_zone": ("spray zone", "flag"),
}

#: Units a picture shows instead of the SI unit of the data: (factor from SI, unit). The VTK
#: and CSV files stay SI.
PICTURE_UNITS = {"m": (1.0e6, "um")}
#: Fields that are 0/1 flags: drawn with two colours and a colour bar of two labels.
FLAG_FIELDS = frozenset({"active", "spray_zone"})


def field_label(name: str) -> str:
    """Short colour-bar title with SI unit, e.g. 'Theta' -> 'Theta [m2/s2]'."""
    if name in _LABELS:
        text, unit = _LABELS[name]
        return f"{text} [{unit}]"
    m = re.fullmatch(r"M(\d)(\d)", name)
    if m:
        k = int(m.group(1)) + int(m.group(2))
        unit = "1/m3" if k == 0 else ("kg/m3" if k == 1 else f"kg{k}/m3")
        return f"{name} [{unit}]"
    unit = "m" if name.endswith("_m") else "SI"
    return f"{name} [{unit}]"


def picture_scale(name: str) -> tuple[float, str]:
    """(factor from the SI value, unit) in which pictures show field or column ``name``:
    diameters (SI unit m) in um, everything else as it is."""
    unit = field_label(name).rsplit(" [", 1)[1].rstrip("]")
    return PICTURE_UNITS.get(unit, (1.0, unit))


def picture_label(name: str) -> str:
    """Colour-bar title in the picture's unit, e.g. 'd43_m' -> 'd43 [um]'."""
    text = field_label(name).rsplit(" [", 1)[0]
    return f"{text} [{picture_scale(name)[1]}]"


def distinct_formatter(exp: int = 0):
    """A matplotlib tick Formatter showing v / 10**exp with the fewest significant digits (at
    least 3) that keep the labels of all ticks on the axis distinct."""
    from matplotlib.ticker import Formatter

    class DistinctFormatter(Formatter):
        digits = 3

        def set_locs(self, locs):
            super().set_locs(locs)
            vals = [v / 10.0 ** exp for v in locs]
            for d in range(3, 17):
                self.digits = d
                if len({f"{v:.{d}g}" for v in vals}) == len(set(vals)):
                    break

        def __call__(self, x, pos=None):
            return f"{x / 10.0 ** exp:.{self.digits}g}"

    return DistinctFormatter()


def _figure(**kw):
    """A matplotlib Figure outside pyplot (no GUI backend, no global figure registry: nothing
    to close, and pyplot is never imported)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(**kw)
    FigureCanvasAgg(fig)
    return fig


def _png_meta(what):
    from ..io.output import figure_metadata
    return figure_metadata("png", what)


def _run_info(*dirs: Path) -> dict:
    """Scene name and alpha_min from the run's summary.json in the first of ``dirs`` that
    has one."""
    for d in dirs:
        f = d / "summary.json"
        if f.is_file():
            try:
                s = json.loads(f.read_text())
                return {"name": s["scene"]["name"],
                        "alpha_min": float(s["scene"]["domain"]["alpha_min"])}
            except (OSError, ValueError, KeyError, TypeError):
                return {}
    return {}
