"""Pictures a granulation engineer reads: diameters in um, tick labels that differ, CFD fields
titled with their CFD time, flags with a two-colour bar, a chosen section of a 3-D bed, and
render adding only the pictures not drawn yet."""
from __future__ import annotations

import meshio
import numpy as np
import pytest
from test_data_safety import box, coupled, refused, tree  # noqa: F401 - fixtures

from pbe_cfd.viz import render
from pbe_cfd.viz.section import read_section
from pbe_cfd.io.vtk import VtkSeries
from pbe_cfd.cli import main


def _block(tmp_path, n=4, spacing=(0.1, 0.1, 0.05)):
    """A 3-D block of (n-1)^3 hexahedra as a meshio mesh; z spans 0 to 3 * 0.05 m."""
    idx = np.arange(n ** 3).reshape(n, n, n)          # point index [i, j, k] along x, y, z
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    points = np.stack([i, j, k], axis=-1).reshape(-1, 3) * np.asarray(spacing)
    points = points[np.argsort(idx.ravel())]
    m = n - 1
    a, b, c = (g.ravel() for g in np.meshgrid(np.arange(m), np.arange(m), np.arange(m),
                                                indexing="ij"))
    hexes = np.stack([idx[a, b, c], idx[a + 1, b, c], idx[a + 1, b + 1, c], idx[a, b + 1, c],
                      idx[a, b, c + 1], idx[a + 1, b, c + 1], idx[a + 1, b + 1, c + 1],
                      idx[a, b + 1, c + 1]], axis=1)
    centres = points[hexes].mean(axis=1)
    return meshio.Mesh(points, [("hexahedron", hexes)]), centres


@pytest.fixture
def block_series(tmp_path):
    """A series on a 3-D block: M00 [1/m3] and d43 [m] set from each cell's centre."""
    mesh, c = _block(tmp_path)
    out = tmp_path / "block"
    fields = {"M00": 1e10 * (1 + c[:, 2]), "d43_m": 1e-4 * (1 + c[:, 0]),
              "active": np.ones(len(c))}
    with VtkSeries(out, mesh, name="pbe") as s:
        s.write(0.0, fields)
        s.write(1.0, fields)
    return out, c


def _bar_labels(fig):
    fig.canvas.draw()
    bar = fig.axes[-1]
    lo, hi = bar.get_ylim()
    return [(t.get_position()[1], t.get_text()) for t in bar.get_yticklabels()
            if t.get_text() and lo <= t.get_position()[1] <= hi], bar


@pytest.mark.parametrize("field,lo,hi,unit,scale", [
    ("d43_m", 103.0e-6, 103.9e-6, "d43 [um]", 1e6),          # a narrow size range, in um
    ("d50_m", 100.4e-6, 155.0e-6, "d50 [um]", 1e6),          # the bundled bed's d50 map
    ("M00", 1.030e10, 1.039e10, "M00 [1e10 1/m3]", 1e-10),    # the power of ten in the unit
])
def test_colour_bar_tick_labels_are_distinct_and_true(block_series, field, lo, hi, unit, scale):
    out, c = block_series
    polys, data, _, _ = read_section(out / "pbe_00000.vtu")
    data = dict(data)
    data[field] = np.linspace(lo, hi, len(polys))
    fig = render.field_figure([(polys, data, "")], field)
    labels, bar = _bar_labels(fig)
    texts = [t for _, t in labels]
    assert len(texts) >= 3 and len(set(texts)) == len(texts), texts
    assert bar.get_ylabel() == unit
    for pos, text in labels:
        # each label is its tick's value in the bar's unit, to its last printed digit
        digits = len(text.replace("-", "").replace(".", "").lstrip("0"))
        last = 10.0 ** (np.floor(np.log10(abs(float(text)))) - digits + 1)
        assert float(text) == pytest.approx(pos * scale if field == "M00" else pos,
                                            rel=0, abs=0.5 * last), (text, pos)


@pytest.mark.parametrize("field", ["active", "spray_zone"])
def test_a_flag_gets_two_colours_and_two_labels(block_series, field):
    out, c = block_series
    polys, data, _, _ = read_section(out / "pbe_00000.vtu")
    data = dict(data)
    data[field] = (np.arange(len(polys)) % 2).astype(float)
    fig = render.field_figure([(polys, data, "")], field)
    labels, bar = _bar_labels(fig)
    assert [t for _, t in labels] == ["0 no", "1 yes"]
    assert [p for p, _ in labels] == [0.0, 1.0]
    assert "[SI]" not in bar.get_ylabel() and "[" not in bar.get_ylabel()
    coll = fig.axes[0].collections[0]
    colours = {tuple(np.round(rgba, 6)) for rgba in coll.get_facecolors()}
    assert len(colours) == 2          # 0 and 1, and no cell in the empty-cell grey


def test_cfd_fields_are_titled_with_their_cfd_time(monkeypatch, tmp_path):
    from pbe_cfd.io import openfoam as of

    assert render.panel_title("alpha", 60.0, 0.5) == "alpha (CFD, t = 0.5 s)"
    assert render.panel_title("Theta", 60.0, None) == "Theta (CFD input)"
    assert render.panel_title("d43_m", 60.0, 0.5) == "d43 at t = 60 s"
    cells = of.load_snapshot()
    cells.time = 0.5                       # the CFD time of the fields (s)
    with VtkSeries(tmp_path / "s", cells, name="pbe",
                   static_fields={"alpha": cells.alpha, "Theta": cells.theta}) as s:
        for t in (0.0, 60.0):
            s.write(t, {"M00": np.ones(cells.n_cells), "active": np.ones(cells.n_cells)})
    titles = {}

    def record(items, field, **kw):
        titles[field] = [panels[0][2] for panels, _ in items]
        return [p for _, p in items]
    monkeypatch.setattr(render, "_render_times", record)
    monkeypatch.setenv("PBE_CFD_DRAW_PROCESSES", "1")
    render.render_series(tmp_path / "s", fields=["alpha", "Theta", "M00"], times=[0, 60],
                         png_dir=tmp_path / "png")
    assert titles == {"alpha": ["alpha (CFD, t = 0.5 s)"] * 2,
                      "Theta": ["Theta (CFD, t = 0.5 s)"] * 2,
                      "M00": ["M00 at t = 0 s", "M00 at t = 60 s"]}


def test_a_chosen_section_of_a_3d_bed(block_series, capsys):
    out, c = block_series
    polys, data, axes, note = read_section(out / "pbe_00000.vtu", ("z", 0.02))
    # z = 0.02 m cuts the first layer (0 to 0.05 m): its 9 cells and their values
    assert axes == ("x", "y") and note == "section z = 0.02 m" and len(polys) == 9
    np.testing.assert_allclose(np.sort(data["M00"]), np.full(9, 1e10 * (1 + 0.025)),
                               rtol=1e-6, atol=0)          # float32 VTK values
    polys, data, axes, note = read_section(out / "pbe_00000.vtu", ("x", 0.25))
    assert axes == ("y", "z") and len(polys) == 9
    np.testing.assert_allclose(data["d43_m"], np.full(9, 1e-4 * 1.25), rtol=1e-6, atol=0)
    assert main(["render", str(out), "--section", "x=0.25", "--fields", "d43_m"]) == 0
    assert (out / "png" / "d43_m_t1s.png").is_file()
    refused(["render", str(out), "--section", "z=0.5", "--overwrite"], capsys,
            "z=0.5", "outside the mesh", "z = 0 to 0.15 m")
    refused(["render", str(out), "--section", "q0.5", "--overwrite"], capsys, "AXIS=POSITION")


def test_render_draws_the_times_not_drawn_yet_and_names_the_rest(coupled, capsys):
    png = coupled / "png"
    before = tree(png)
    assert {"d43_m_t0s.png", "d43_m_t2s.png"} <= set(before)     # couple drew 0 and 2 s
    capsys.readouterr()
    assert main(["render", "c", "--fields", "d43_m", "--times", "0", "1", "2"]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if "skipped" in ln]
    assert len(err) == 1 and "d43_m_t0s.png" in err[0] and "d43_m_t2s.png" in err[0]
    assert "--overwrite" in err[0]
    after = tree(png)
    assert "d43_m_t1s.png" in after and "d43_m_sequence.png" in after
    for name in ("d43_m_t0s.png", "d43_m_t2s.png"):
        assert after[name] == before[name]                         # not redrawn
    # nothing new to draw: refused, naming --overwrite; with it, redrawn
    refused(["render", "c", "--fields", "d43_m", "--times", "0", "2"], capsys, "--overwrite")
    assert main(["render", "c", "--fields", "d43_m", "--times", "0", "2", "--overwrite"]) == 0
    assert tree(png)["d43_m_t0s.png"][1] != before["d43_m_t0s.png"][1]     # mtime: redrawn


def test_the_bed_percentiles_share_one_panel_in_um():
    """d10, d50 and d90 of the bed are drawn together (one axis in um, so a percentile that
    stays at the primary size reads as a value, not as an offset of 1e-5 um)."""
    from pbe_cfd.viz.bed_moments import _bed_panels
    panels = _bed_panels(["time_s", "M00", "d32_m", "d43_m", "d10_m", "d50_m", "d90_m", "span"])
    holding = [(cols, unit) for _, cols, unit in panels if "d50_m" in cols]
    assert holding == [(["d10_m", "d50_m", "d90_m"], "m")]


@pytest.mark.parametrize("lo_um, hi_um", [(80.3, 401.6), (78.0, 205.0), (20.0, 3000.0),
                                          (95.0, 110.0), (100.39, 100.41)])
def test_the_log_diameter_axis_labels_at_least_four_values_apart(lo_um, hi_um):
    """A psd.png of any span labels at least MIN_LABELS distinct diameters inside the axis,
    no two nearer than MIN_GAP of its span in ln d (the seed run's 80-400 um axis labelled only
    100 and 200 before)."""
    import math

    from pbe_cfd.viz import psd_figure
    d = np.geomspace(lo_um, hi_um, 40) * 1e-6
    q3 = np.exp(-0.5 * ((np.log(d) - np.log(d).mean()) / 0.1) ** 2)
    cols = {"time_s": np.zeros(40), "d_m": d, "Q3": np.cumsum(q3) / q3.sum(), "q3_per_ln_d": q3}
    fig = psd_figure.psd_figure(cols, "ticks")
    fig.canvas.draw()
    ax = fig.axes[0]
    lo, hi = ax.get_xlim()
    shown = [(t.get_position()[0], t.get_text()) for t in ax.get_xticklabels()
             if t.get_text() and lo <= t.get_position()[0] <= hi]
    assert len(shown) >= psd_figure.MIN_LABELS, shown
    assert len({text for _, text in shown}) == len(shown), shown
    assert all(float(text) == pytest.approx(v, rel=1e-9, abs=0) for v, text in shown), shown
    where = sorted(v for v, _ in shown)
    gaps = np.diff(np.log(where)) / math.log(hi / lo)
    assert gaps.min() >= psd_figure.MIN_GAP * (1 - 1e-12), (shown, gaps)
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_the_psd_overlay_fills_the_cnmc_band_between_its_bounds():
    """`compare`'s PSD overlay: a run with the replicas' band (q3_lo, q3_hi) gets the band
    filled between exactly those bounds at its last output time, and its legend entry says so;
    a run without one gets a line only."""
    from matplotlib.collections import PolyCollection

    from pbe_cfd.viz import psd_figure
    d = np.geomspace(80e-6, 400e-6, 30)
    q3 = np.exp(-0.5 * ((np.log(d) - np.log(170e-6)) / 0.2) ** 2)
    one = {"time_s": np.repeat([0.0, 600.0], 30), "d_m": np.tile(d, 2),
           "Q3": np.tile(np.cumsum(q3) / q3.sum(), 2), "q3_per_ln_d": np.tile(q3, 2)}
    cnmc = dict(one, q3_lo=np.tile(0.9 * q3, 2) - np.repeat([1.0, 0.0], 30),
                q3_hi=np.tile(1.2 * q3, 2) + np.repeat([1.0, 0.0], 30))
    fig = psd_figure.psd_overlay_figure([("qmom", one), ("cnmc", cnmc)])
    ax = fig.axes[0]
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(bands) == 1
    y = bands[0].get_paths()[0].vertices[:, 1]
    assert y.min() == pytest.approx(0.9 * q3.min(), rel=1e-12, abs=0)      # the last time's
    assert y.max() == pytest.approx(1.2 * q3.max(), rel=1e-12, abs=0)      # band, not t = 0
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["qmom (t = 600 s)", "cnmc (t = 600 s, shaded: 95% band of its replicas)"]
    import matplotlib.pyplot as plt
    plt.close(fig)
