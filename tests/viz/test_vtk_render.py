"""VTK series round trip (meshio, pyvista) and off-screen renders."""

from __future__ import annotations

import dataclasses
import re

import meshio
import numpy as np
import pytest

from pbe_cfd.io import openfoam as of
from pbe_cfd.viz.render import image_stats, plot_bed_moments, render_series
from pbe_cfd.io.vtk import VtkSeries, read_pvd

TIMES = [0.0, 300.0, 600.0]  # s


@pytest.fixture(scope="module")
def cells():
    return of.load_snapshot()


ALPHA_MIN = 0.05   # cells leaner than this hold no granules (as a coupled run writes them)


def _fields(cells, t):
    bed = cells.alpha >= ALPHA_MIN
    y = cells.cell_centre[:, 1]
    m00 = np.where(bed, 3.3e10 * cells.alpha / 0.55 * (1 - 0.5 * t / 600), 0.0)   # 1/m3
    return {
        "M00": m00,
        "d43_m": np.where(bed, 100.4e-6 * (1 + t / 600 * y / 0.3), 0.0),
        "binder_fraction": np.where(bed, 0.1 * t / 600 * np.exp(-(y - 0.3) ** 2 / 0.01), 0.0),
        "active": bed.astype(float),
    }


@pytest.fixture(scope="module")
def series_dir(cells, tmp_path_factory):
    out = tmp_path_factory.mktemp("series")
    with VtkSeries(out, cells, name="pbe",
                   static_fields={"alpha": cells.alpha, "Theta": cells.theta}) as s:
        for t in TIMES:
            s.write(t, _fields(cells, t))
    return out


def test_series_round_trip_meshio(series_dir, cells):
    entries = read_pvd(series_dir / "pbe.pvd")
    assert [t for t, _ in entries] == TIMES
    for t, path in entries:
        m = meshio.read(path)
        assert sum(len(b.data) for b in m.cells) == cells.n_cells
        ref = _fields(cells, t)
        for name, arr in ref.items():
            got = np.concatenate(m.cell_data[name])
            np.testing.assert_array_equal(got, arr)
        np.testing.assert_array_equal(np.concatenate(m.cell_data["Theta"]), cells.theta)


def test_series_round_trip_pyvista(series_dir, cells):
    import pyvista as pv

    reader = pv.get_reader(str(series_dir / "pbe.pvd"))
    assert list(reader.time_values) == TIMES
    for t in TIMES:
        reader.set_active_time_value(t)
        block = reader.read()
        grid = block[0]
        assert grid.n_cells == cells.n_cells
        for name in ("alpha", "Theta", "M00", "d43_m", "binder_fraction"):
            vals = np.asarray(grid.cell_data[name])
            assert vals.shape == (cells.n_cells,)
            assert np.all(np.isfinite(vals))
        np.testing.assert_allclose(grid.cell_data["M00"], _fields(cells, t)["M00"], atol=0)
    # cell volumes seen by VTK match ours
    grid = pv.read(series_dir / reader.datasets[0].path)
    vol = grid.compute_cell_sizes(length=False, area=False)["Volume"]
    np.testing.assert_allclose(vol, cells.cell_volume, rtol=1e-9, atol=0)


def test_series_valid_after_each_write(cells, tmp_path):
    s = VtkSeries(tmp_path, cells)
    s.write(0.0, {"M00": np.ones(cells.n_cells)})
    assert len(read_pvd(s.pvd_path)) == 1
    s.write(1.0, {"M00": np.ones(cells.n_cells)})
    # no close(): a crashed run still leaves a complete series
    assert [t for t, _ in read_pvd(s.pvd_path)] == [0.0, 1.0]
    assert not list(tmp_path.glob("*.tmp"))


def test_series_rejects_bad_input(cells, tmp_path):
    s = VtkSeries(tmp_path, cells)
    with pytest.raises(ValueError, match="'M00' has shape"):
        s.write(0.0, {"M00": np.ones(3)})
    bad = np.ones(cells.n_cells)
    bad[7] = np.nan
    with pytest.raises(ValueError, match="'M00' has 1 non-finite"):
        s.write(0.0, {"M00": bad})
    s.write(1.0, {"M00": np.ones(cells.n_cells)})
    with pytest.raises(ValueError, match="times must increase"):
        s.write(1.0, {"M00": np.ones(cells.n_cells)})


def test_series_spreads_over_split_cells(cells, tmp_path):
    # OpenFOAM cell 0 drawn as two VTK wedges: its value appears on both
    h = cells.mesh.cells[0].data[0]
    w = np.array([[h[0], h[1], h[2], h[4], h[5], h[6]], [h[0], h[2], h[3], h[4], h[6], h[7]]])
    mesh = meshio.Mesh(cells.mesh.points, [("wedge", w),
                                           ("hexahedron", cells.mesh.cells[0].data[1:])])
    split = dataclasses.replace(
        cells, mesh=mesh,
        vtk_cell_id=np.concatenate([[0, 0], np.arange(1, cells.n_cells)]))
    s = VtkSeries(tmp_path, split)
    vals = np.arange(cells.n_cells, dtype=float)
    path = s.write(0.0, {"x": vals})
    m = meshio.read(path)
    got = np.concatenate(m.cell_data["x"])
    np.testing.assert_array_equal(got, np.concatenate([[0.0, 0.0], vals[1:]]))


@pytest.mark.slow
def test_render_series_non_blank(series_dir):
    pngs = render_series(series_dir, times=[0.0, 600.0])
    names = {p.name for p in pngs}
    for field in ("alpha", "Theta", "M00", "d43_m", "binder_fraction"):
        assert f"{field}_t600s.png" in names
    assert len(pngs) == 10
    for p in pngs:
        var, colours = image_stats(p)
        assert var > 0 and colours > 1, p
    # at t = 0 the binder fraction is zero everywhere: still a valid (flat) image
    var, colours = image_stats(series_dir / "png" / "binder_fraction_t0s.png")
    assert colours > 1


def test_render_series_errors(series_dir):
    notes = []
    pngs = render_series(series_dir, fields=["M00"], times=[123.0], notes=notes)
    assert [p.name for p in pngs] == ["M00_t0s.png"]          # nearest written time
    assert "t = 123 s is not an output time" in notes[0] and "t = 0 s" in notes[0]
    with pytest.raises(ValueError, match="no field nope in"):
        render_series(series_dir, fields=["nope"])
    with pytest.raises(FileNotFoundError, match=r"no VTK series \(.pvd\)"):
        render_series(series_dir / "png")


def _count(png, rgb):
    import matplotlib.image as mpimg
    img = np.round(mpimg.imread(str(png))[..., :3] * 255)
    return int(np.count_nonzero(np.all(np.abs(img - rgb) <= 1, axis=2)))


def test_empty_cells_look_the_same_in_every_field(series_dir, cells, tmp_path):
    """Cells holding no granules (the freeboard) are drawn in one grey in every field, never
    in the colour of zero (which would make an empty freeboard look like a dry bed)."""
    from matplotlib.colors import to_rgb

    from pbe_cfd.viz.render import EMPTY_COLOUR
    grey = np.array(to_rgb(EMPTY_COLOUR)) * 255
    pngs = render_series(series_dir, times=[0.0], png_dir=tmp_path)
    counts = {p.stem: _count(p, grey) for p in pngs}
    empty_share = np.mean(cells.alpha < ALPHA_MIN)
    assert empty_share > 0.2                   # the freeboard is a good part of the bed
    ref = counts["M00_t0s"]
    import matplotlib.image as mpimg
    pixels = mpimg.imread(str(pngs[0])).shape[0] * mpimg.imread(str(pngs[0])).shape[1]
    assert ref > 0.1 * empty_share * pixels      # the freeboard is grey (axes ~1/4 of image)
    for name, n in counts.items():
        assert abs(n - ref) <= 0.01 * ref, (name, counts)      # the same cells, every field


def test_field_figure_axes_in_metres_log_bar_named_and_no_empty_canvas(series_dir, tmp_path):
    import pyvista as pv

    from pbe_cfd.viz.render import field_figure, section
    from pbe_cfd.io.vtk import read_pvd
    polys, data, axes, note = section(pv.read(read_pvd(series_dir / "pbe.pvd")[-1][1]))
    assert note == ""                              # one cell thick: the section is the mesh
    spread = dict(data)                            # M20 over four decades in the bed
    spread["M20"] = np.where(data["active"] > 0, np.logspace(-16, -12, len(polys)), 0.0)
    fig = field_figure([(polys, spread, "M20")], "M20")
    bed, bar = fig.axes[0], fig.axes[1]
    assert bed.get_xlabel() == "x [m]" and bed.get_ylabel() == "y [m]"
    assert bed.get_aspect() == 1.0                 # drawn to scale
    assert bar.get_ylabel() == "M20 [kg2/m3], log scale"
    lin = field_figure([(polys, data, "d43")], "d43_m")
    assert lin.axes[1].get_ylabel() == "d43 [um]"          # diameters in um in pictures
    lin.canvas.draw()
    lo, hi = lin.axes[1].get_ylim()
    ticks = [float(t.get_text()) for t in lin.axes[1].get_yticklabels()
             if t.get_text() and lo <= t.get_position()[1] <= hi]
    # the bar in um spans the bed's d43 (round-off of the float32 VTK values: 1e-6)
    bed_d43 = np.asarray(data["d43_m"])[np.asarray(data["active"]) > 0] * 1e6
    assert (lo, hi) == pytest.approx((bed_d43.min(), bed_d43.max()), rel=1e-6, abs=0)
    assert len(ticks) >= 3 and all(lo <= v <= hi for v in ticks), (ticks, lo, hi)
    # no half-empty canvas: no white band wider than 10 % of the picture
    import matplotlib.image as mpimg
    for png in render_series(series_dir, times=[0.0, 600.0], png_dir=tmp_path):
        nonwhite = np.any(mpimg.imread(str(png))[..., :3] < 0.97, axis=2)
        for axis in (0, 1):
            used = nonwhite.any(axis=axis)
            gaps = np.diff(np.flatnonzero(np.r_[True, used, True])) - 1
            assert gaps.max() < 0.1 * used.size, (png.name, axis, gaps.max() / used.size)


@pytest.mark.slow
def test_plot_bed_moments(tmp_path):
    t = np.linspace(0, 600, 31)
    cols = {
        "time_s": t, "M00": 3.3e10 * 2 / (2 + t / 100), "M10": np.full_like(t, 1e-3),
        "M20": 1e-14 * (1 + t / 50), "M01": 1e-5 * t, "d43_m": 1e-4 * (1 + t / 600),
        "binder_fraction": 0.01 * t / 600,
    }
    csv = tmp_path / "bed_moments.csv"
    csv.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(repr(float(cols[k][i])) for k in cols) for i in range(len(t))) + "\n")
    png = plot_bed_moments(csv, tmp_path / "png" / "bed.png", title="my-bed")
    var, colours = image_stats(png)
    assert var > 0 and colours > 10
    # a real title; each panel in the units of the VTK cell field of the same name
    from pbe_cfd.viz.render import bed_moments_figure, picture_scale
    fig = bed_moments_figure(csv, title="my-bed")
    assert fig._suptitle.get_text().startswith("my-bed: bed averages")
    assert "per m3 of bed" in fig._suptitle.get_text()
    seen = set()
    for ax in fig.axes:
        for line in ax.get_lines():
            name = {"d43": "d43_m"}.get(line.get_label(), line.get_label())
            if name in cols:
                unit = picture_scale(name)[1]
                # the unit of the VTK field (diameters in um), a power of ten in front where
                # the axis needs one
                assert re.fullmatch(r"\[(1e-?\d+ )?" + re.escape(unit) + r"\]",
                                    ax.get_ylabel()), (name, ax.get_ylabel())
                seen.add(name)
    assert seen == set(cols) - {"time_s"}
    d43_axis = [ax for ax in fig.axes if "d43" in [ln.get_label() for ln in ax.get_lines()]][0]
    assert d43_axis.get_ylabel() == "[um]"
    bad = tmp_path / "bad.csv"
    bad.write_text("t,M00\n0,1\n")
    with pytest.raises(ValueError, match="first column must be 'time_s'"):
        plot_bed_moments(bad, tmp_path / "x.png")


def test_curves_that_coincide_stay_visible(tmp_path):
    """d10 = d50 for a whole run (the primaries carry over half the mass, as in the bundled
    bed's first minute): every curve of a panel gets its own line style, so the later one is
    drawn dashed over the earlier and neither hides the other."""
    from pbe_cfd.viz.render import bed_moments_figure
    t = np.linspace(0, 60, 13)
    d = np.full_like(t, 100.4e-6)
    cols = {"time_s": t, "d10_m": d, "d50_m": d, "d90_m": d * (1 + t / 200)}
    csv = tmp_path / "bed_moments.csv"
    csv.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(repr(float(cols[k][i])) for k in cols) for i in range(len(t))) + "\n")
    fig = bed_moments_figure(csv, title="my-bed")
    lines = [ln for ax in fig.axes for ln in ax.get_lines()]
    assert [ln.get_label() for ln in lines] == ["d10", "d50", "d90"]
    styles = [ln.get_linestyle() for ln in lines]
    assert len(set(styles)) == 3, styles


def test_a_truncated_vtu_is_one_error_and_nothing_printed(tmp_path, capfd):
    """A VTU cut short (a killed writer): reading its section raises one ValueError naming the
    file, and neither meshio (which prints, then calls sys.exit) nor VTK's reader (a page of
    XML parser errors on the C++ side, file descriptor 2) prints anything."""
    from pbe_cfd.viz.section import read_section
    data = of.default_snapshot_path().read_bytes()
    path = tmp_path / "cut.vtu"
    path.write_bytes(data[: len(data) // 3])
    capfd.readouterr()
    with pytest.raises(ValueError, match="cannot read .*cut.vtu") as err:
        read_section(path)
    assert "\n" not in str(err.value)
    out, errs = capfd.readouterr()
    assert out == "" and errs == "", (out, errs)


def test_a_dried_bed_draws_on_a_log_axis_without_an_overflow(tmp_path):
    """A batch's binder fraction falls to 4e-316 as its granules dry: the panel spans 300
    decades, drawn on a log axis of LOG_DECADES below its largest value, and the span is
    judged without the ratio max / min, which overflows to inf (a RuntimeWarning in every
    batch's run)."""
    import warnings
    from pbe_cfd.viz.render import bed_moments_figure
    t = np.linspace(0, 1800, 7)
    cols = {"time_s": t, "M00": np.full_like(t, 1e11), "d43_m": np.full_like(t, 2e-4),
            "binder_fraction": np.array([0.01, 0.05, 0.03, 1e-3, 1e-186, 4e-316, 4e-316])}
    csv = tmp_path / "bed_moments.csv"
    csv.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(repr(float(cols[k][i])) for k in cols) for i in range(len(t))) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = bed_moments_figure(csv, title="dried")
    axis = [ax for ax in fig.axes
            if "binder_fraction" in [ln.get_label() for ln in ax.get_lines()]][0]
    assert axis.get_yscale() == "log"
    # the 300 decades do not flatten the spray's: the axis ends 12 decades below 0.05
    from pbe_cfd.viz.bed_moments import LOG_DECADES
    assert axis.get_ylim()[0] == pytest.approx(0.05 * 10.0 ** -LOG_DECADES, rel=1e-12, abs=0)
