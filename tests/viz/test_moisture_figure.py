"""moisture.png of a run with drying (``viz.moisture``): drawn from bed_moments.csv's drying
columns, refused with the missing columns named when the run had no [drying] table."""
import csv

import numpy as np
import pytest

from pbe_cfd.viz.moisture import LIQUID, moisture_figure, plot_moisture


def _csv(path, columns):
    t = np.linspace(0.0, 1800.0, 7)
    data = {"time_s": t, **{c: f(t) for c, f in columns.items()}}
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(data))
        for k in range(len(t)):
            w.writerow([repr(float(data[c][k])) for c in data])
    return path


def test_moisture_figure_draws_the_inventory_in_grams(tmp_path):
    cols = {"moisture_content": lambda t: 0.05 * np.sin(np.pi * t / 1800.0),
            "outlet_temperature_K": lambda t: 300.0 + 0.01 * t}
    for c, _ in LIQUID:
        cols[c] = lambda t: 1e-3 * t / 1800.0
    path = _csv(tmp_path / "bed_moments.csv", cols)
    fig = moisture_figure(path, "batch")
    left, twin, right = fig.axes[0], fig.axes[2], fig.axes[1]
    y = left.lines[0].get_ydata()
    assert np.allclose(y, 100.0 * cols["moisture_content"](np.linspace(0, 1800, 7)),
                       rtol=1e-12, atol=1e-12)                    # percent of dry mass
    assert np.allclose(left.lines[0].get_xdata()[-1], 30.0, rtol=0, atol=1e-12)  # minutes
    assert np.allclose(right.lines[0].get_ydata()[-1], 1.0, rtol=0, atol=1e-12)   # grams
    assert np.allclose(twin.lines[0].get_ydata()[0], 300.0 - 273.15, rtol=0, atol=1e-9)
    png = plot_moisture(path, tmp_path / "png" / "moisture.png")
    assert png.stat().st_size > 1000


def test_moisture_figure_refuses_a_run_without_drying(tmp_path):
    path = _csv(tmp_path / "bed_moments.csv", {"M00": lambda t: 1.0 + 0 * t})
    with pytest.raises(ValueError, match="moisture_content"):
        moisture_figure(path)
