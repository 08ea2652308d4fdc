"""Small parts shared by the pictures of a run: field labels with SI units, the Figure
outside pyplot, PNG metadata and the run's name from its summary.json."""
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
}


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


def _figure(**kw):
    """A matplotlib Figure outside pyplot (no GUI backend, no global figure registry: nothing
    to close, and pyplot is never imported)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(**kw)
    FigureCanvasAgg(fig)
    return fig


def _png_meta(what):
    from ..output import figure_metadata
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
