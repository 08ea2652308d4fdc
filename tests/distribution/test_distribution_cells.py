"""The per-cell size distribution of a coupled run (``[output] cell_psd``, cell_psd.csv).

Physics asserted: a one-cell bed's cell distribution is the bed's; q3 integrates to 1 and Q3
ends at 1 within the psd grid's bounds (GRID_FRACTIONS); the d50 read off Q3 lies in the grid
interval of the cell's d50 field; a single gamma kernel's Q3 equals scipy's closed form; a
selection outside the mesh or in a cell without granules is exit 2 naming the key; a run
without the key writes no cell output and echoes no [output] table; a two-way run (two CFD
segments) writes every output time's cell distributions, each agreeing with its VTK d50.
"""
import dataclasses
import json
import math
import re
import shutil
import tomllib

import numpy as np
import pytest
from scipy import stats

from pbe_cfd.cli import main
from pbe_cfd.distribution import cell_psd, kernel_mixture, tables
from pbe_cfd.io.openfoam import load_snapshot
from pbe_cfd.io.output import read_columns_csv
from pbe_cfd.runs.couple import run_coupled
from pbe_cfd.runs.domain import Domain
from pbe_cfd.runs.problem import output_plan
from pbe_cfd.scene.scene import SceneError, describe, load_scene, resolve_scene_path, scene_from_dict

KEY = "output.cell_psd"


@pytest.fixture(scope="module")
def snapshot():
    return load_snapshot()


def fluid_bed_text(end=10.0, output=None, scene="fluid-bed") -> str:
    """The bundled scene's TOML with end_time = end [s] and an [output] table (TOML text)."""
    text = resolve_scene_path(scene).read_text()
    text = re.sub(r"(?m)^end_time = [0-9.e+]+", f"end_time = {end}", text, count=1)
    return text + (f"\n[output]\n{output}\n" if output else "")


def fluid_bed(end=10.0, output=None, scene="fluid-bed"):
    return scene_from_dict(tomllib.loads(fluid_bed_text(end, output, scene)), "cells.toml")


# ---------------------------------------------------------------------------- the scene key
@pytest.mark.parametrize("value, says", [
    ("[]", "expected a list of mesh cell ids"),
    ('"all"', "expected a list of mesh cell ids"),
    ("[-1]", "entry 0"),
    ("[true]", "entry 0"),
    ("[[0.1, 0.2]]", "three numbers"),
    ("[3, 3]", "each entry once"),
    ("[" + ", ".join(str(k) for k in range(13)) + "]", "at most 12"),
])
def test_bad_cell_psd_values_name_the_key(value, says):
    with pytest.raises(SceneError) as err:
        fluid_bed(output=f"cell_psd = {value}")
    assert err.value.key.startswith(KEY) and says in str(err.value)


def test_cell_psd_needs_a_domain_with_cells():
    text = resolve_scene_path("seed-wurster").read_text() + "\n[output]\ncell_psd = [0]\n"
    with pytest.raises(SceneError, match=r"output.cell_psd.*openfoam"):
        scene_from_dict(tomllib.loads(text), "well-mixed.toml")


def test_without_the_key_the_plan_and_echo_are_main_s():
    scene = load_scene("fluid-bed")
    assert scene.output is None and output_plan(scene).cell_psd == ()
    assert "output" not in describe(scene)        # summary.json's scene echo unchanged
    asked = fluid_bed(output="cell_psd = [457, [0.015, 0.155, 0.0]]")
    assert output_plan(asked).cell_psd == (457, (0.015, 0.155, 0.0))
    assert describe(asked)["output"] == {"cell_psd": (457, (0.015, 0.155, 0.0))}


# ---------------------------------------------------------------------------- the selection
def test_points_resolve_to_the_cell_holding_them(snapshot):
    """The bundled mesh is 15 x 60 cells of 1 cm: a point lies within half a cell (5 mm) of
    its cell's centre in x and y; a point on a shared face goes to the nearest centre."""
    active = snapshot.alpha >= 0.05
    points = [(0.075, 0.305, 0.0), (0.0151, 0.1549, 0.001), (0.0999, 0.02, 0.0)]
    sel = cell_psd.select_cells(points + [12], snapshot, active, 0.05)
    for j, p in enumerate(points):
        assert np.all(np.abs(sel.centres[j][:2] - p[:2]) <= 0.005 + 1e-12)
    assert sel.cells[-1] == 12
    centre = np.asarray(snapshot.cell_centre)
    assert np.array_equal(sel.centres, centre[sel.cells])
    # x = 0.1 m is a face between the cells centred at 0.095 and 0.105 m
    on_face = cell_psd.select_cells([(0.1000000001, 0.02, 0.0)], snapshot, active, 0.05)
    assert centre[on_face.cells[0], 0] == pytest.approx(0.105, rel=0, abs=1e-9)


@pytest.mark.parametrize("entry, says", [
    (900, "the mesh has 900 cells"),
    ((0.2, 0.1, 0.0), "lies in no cell of the mesh"),
    ((0.075, 0.5, 0.0), "holds no granules"),            # the freeboard: alpha = 0
])
def test_bad_selections_are_named(snapshot, entry, says):
    active = snapshot.alpha >= 0.05
    with pytest.raises(SceneError) as err:
        cell_psd.select_cells([entry], snapshot, active, 0.05, "cells.toml")
    assert err.value.key == KEY and says in str(err.value)


@pytest.mark.parametrize("entry, says", [
    ("900", "the mesh has 900 cells"),
    ("[0.2, 0.1, 0.0]", "lies in no cell of the mesh"),
    ("[0.075, 0.5, 0.0]", "holds no granules"),
])
def test_couple_refuses_a_bad_selection_with_exit_2(tmp_path, capsys, entry, says):
    path = tmp_path / "cells.toml"
    path.write_text(fluid_bed_text(output=f"cell_psd = [{entry}]"))
    out = tmp_path / "out"
    assert main(["couple", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "[output.cell_psd]" in err and says in err
    assert not out.exists()                           # nothing written
    assert main(["plan", str(path)]) == 2              # plan refuses what the run refuses
    assert "[output.cell_psd]" in capsys.readouterr().err


def test_plan_lists_the_resolved_cells(tmp_path, capsys):
    path = tmp_path / "cells.toml"
    path.write_text(fluid_bed_text(output="cell_psd = [[0.075, 0.305, 0.0], 226]"))
    assert main(["plan", str(path)]) == 0
    line = [x for x in capsys.readouterr().out.splitlines() if "per-cell size" in x]
    assert len(line) == 1
    assert "cell 457 at (75, 305, 0) mm, alpha 0.363" in line[0] and "cell 226 at" in line[0]


# ---------------------------------------------------------------------------- the columns
def test_a_gamma_kernel_cell_against_the_closed_form():
    """One gamma kernel of shape l, scale sigma in mass: Q3(d) = P(l + 1, p(d) / sigma)
    (docs/physics.md 11.1); scipy's gamma cdf is the independent reference. A cell missing
    from a time's active rows is the stated empty row (active = 0, Q3 = q3 = 0)."""
    rho, sigma, l = 1000.0, 2.0e-10, 5.0
    x = l * sigma
    mix = kernel_mixture.KernelMixture.of_arrays(
        np.array([sigma, sigma]), np.array([[x], [2 * x]]), np.array([[1e10], [1e10]]),
        np.zeros((2, 1)), np.zeros(2, int), rho, False, ("ok",))
    sel = cell_psd.CellSelection(cells=np.array([7, 3]), centres=np.array([[0, 0.1, 0],
                                                                           [0, 0.2, 0.]]))
    grid = np.geomspace(30e-6, 300e-6, 41)
    cols, notes = cell_psd.cell_psd_columns(sel, [0.0, 5.0], [mix, mix],
                                            [np.array([3, 7]), np.array([3, 9])], grid)
    assert list(cols)[:6] == list(cell_psd.CELL_COLUMNS)
    n = grid.size
    p = rho * math.pi / 6 * grid ** 3
    first = slice(0, n)                               # t = 0, cell 7: row 1 (centre 2x)
    ref = stats.gamma.cdf(p / sigma, 2 * x / sigma + 1)
    assert np.allclose(cols["Q3"][first], ref, rtol=0, atol=1e-12)
    assert np.all(cols["cell"][first] == 7) and np.all(cols["active"][first] == 1)
    second = slice(n, 2 * n)                          # t = 0, cell 3: row 0
    ref = stats.gamma.cdf(p / sigma, l + 1)
    assert np.allclose(cols["Q3"][second], ref, rtol=0, atol=1e-12)
    gone = slice(2 * n, 3 * n)                        # t = 5, cell 7 not among the rows
    assert np.all(cols["active"][gone] == 0) and not np.any(cols["Q3"][gone])
    assert not np.any(cols["q3_per_ln_d"][gone]) and np.all(cols["time_s"][gone] == 5.0)
    assert any("cell 7" in t and "t = 5 s" in t for t in notes)


@pytest.fixture(scope="module")
def one_cell_run(snapshot):
    """The densest cell of the bundled bed alone (sprayed everywhere: the spray zone does not
    hold it), 10 s, outputs every 5 s, with that cell selected."""
    c = int(np.argmax(snapshot.alpha))
    sl = slice(c, c + 1)
    cell = dataclasses.replace(snapshot, alpha=snapshot.alpha[sl].copy(),
                               theta=snapshot.theta[sl].copy(),
                               cell_volume=snapshot.cell_volume[sl].copy(),
                               cell_centre=snapshot.cell_centre[sl].copy(),
                               vtk_cell_id=np.zeros(1, dtype=np.int64))
    scene = fluid_bed(output="cell_psd = [0]")
    scene = dataclasses.replace(scene, binder_injection=dataclasses.replace(
        scene.binder_injection, zone=None))
    return run_coupled(scene, Domain(cells=cell, flux=None, description="one cell"))


def test_a_one_cell_bed_s_cell_psd_is_the_bed_s(one_cell_run):
    res = one_cell_run
    bed, cell = res.psd, res.cell_psd
    assert np.array_equal(cell["d_m"], bed["d_m"]) and np.array_equal(cell["time_s"],
                                                                        bed["time_s"])
    # the bed is the cell's mixture weighted by its own mass: W Q3 / W, one rounding of each
    # of the product and the quotient (2 ulp of a Q3 <= 1)
    assert np.allclose(cell["Q3"], bed["Q3"], rtol=0, atol=4.5e-16)
    assert np.allclose(cell["q3_per_ln_d"], bed["q3_per_ln_d"], rtol=0,
                       atol=4.5e-16 * 2 / math.log(bed["d_m"][1] / bed["d_m"][0]))
    # the binder fraction of the classes holding mass (an empty class: the bed's mixture says
    # 0, the cell's reconstruction its nearest node's value, as a well-mixed run's psd.csv)
    held = bed["q3_per_ln_d"] > 0
    assert np.count_nonzero(held) > 10 and np.any(cell["binder_fraction"][held] > 0)
    # one row's mixture: (W dm y) / (W dm), three roundings of a fraction <= 1 (3 ulp)
    assert np.allclose(cell["binder_fraction"][held], bed["binder_fraction"][held], rtol=0,
                       atol=6.7e-16)
    assert json.dumps(res.labels["cell_psd.csv"])          # labelled for columns.json
    assert set(res.labels["cell_psd.csv"]) == set(cell)


def test_cell_psd_conserves_mass_and_gives_the_cell_s_d50(one_cell_run):
    """Per output time: sum q3 h = Q3(top edge) - Q3(bottom edge) telescopes, and the grid
    runs from below the cells' Q3 = 1e-4 to above their Q3 = 1 - 1e-4 (tables.GRID_FRACTIONS,
    with GRID_MARGIN), so the integral of q3 over ln d is 1 within 2e-4 and Q3 ends above
    1 - 1e-4. The d50 read off Q3 on the grid lies in the grid interval [d_j, d_j+1] of the
    cell's d50 field (the reconstruction's own percentile): within the spacing h in ln d."""
    res = one_cell_run
    cols = res.cell_psd
    lo_f, hi_f = tables.GRID_FRACTIONS
    grid = np.unique(cols["d_m"])
    h = math.log(grid[1] / grid[0])
    for k, t in enumerate(res.times):
        at = cols["time_s"] == t
        q3, big_q, d = cols["q3_per_ln_d"][at], cols["Q3"][at], cols["d_m"][at]
        assert np.sum(q3) * h == pytest.approx(1.0, rel=0, abs=lo_f + (1 - hi_f))
        assert big_q[-1] >= hi_f and big_q[0] <= lo_f
        assert np.all(np.diff(big_q) >= 0)
        d50 = res.cell_fields[k]["d50_m"][0]
        j = int(np.searchsorted(big_q, 0.5))           # first grid point with Q3 >= 0.5
        assert d[j - 1] <= d50 * (1 + 1e-12) and d50 <= d[j] * (1 + 1e-12)
        read = math.exp(np.interp(0.5, big_q[j - 1:j + 1], np.log(d[j - 1:j + 1])))
        assert abs(math.log(read / d50)) <= h


# ---------------------------------------------------------------------------- the outputs
@pytest.mark.slow
@pytest.mark.parametrize("scene", ["fluid-bed", "fluid-bed-transport"])
def test_couple_writes_cell_psd_through_the_output_machinery(tmp_path, capsys, scene):
    path = tmp_path / "cells.toml"
    sel = "cell_psd = [[0.075, 0.305, 0.0], [0.015, 0.155, 0.0], [0.075, 0.355, 0.0]]"
    path.write_text(fluid_bed_text(end=10.0, output=sel, scene=scene))
    out = tmp_path / "out"
    assert main(["couple", str(path), "--out", str(out)]) == 0
    cols = read_columns_csv(out / "cell_psd.csv")
    bed = read_columns_csv(out / "psd.csv")
    assert list(cols) == [*cell_psd.CELL_COLUMNS, "d_m", "Q3", "q3_per_ln_d", "binder_fraction"]
    n_grid = np.unique(bed["d_m"]).size
    assert cols["d_m"].size == 3 * 3 * n_grid        # 3 times (0, 5, 10 s) x 3 cells x grid
    assert set(np.unique(cols["cell"])) == {457, 226, 532}
    assert np.all(cols["active"] == 1)
    labels = json.loads((out / "columns.json").read_text())
    assert set(labels["cell_psd.csv"]) == set(cols)
    assert (out / "png" / "cell_psd.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    manifest = json.loads((out / "pbe-cfd-manifest.json").read_text())
    assert {"cell_psd.csv", "png/cell_psd.png"} <= set(manifest["files"])
    # the run refuses to write into its own output without --overwrite, rewrites it with it
    assert main(["couple", str(path), "--out", str(out)]) == 2
    assert main(["couple", str(path), "--out", str(out), "--overwrite"]) == 0
    assert np.array_equal(read_columns_csv(out / "cell_psd.csv")["Q3"], cols["Q3"])


def test_couple_without_the_key_writes_no_cell_output(tmp_path):
    out = tmp_path / "out"
    path = tmp_path / "plain.toml"
    path.write_text(fluid_bed_text(end=5.0))
    assert main(["couple", str(path), "--out", str(out)]) == 0
    assert not (out / "cell_psd.csv").exists() and not (out / "png" / "cell_psd.png").exists()
    assert "cell_psd.csv" not in json.loads((out / "columns.json").read_text())
    assert "output" not in json.loads((out / "summary.json").read_text())["scene"]


# ---------------------------------------------------------------------------- two-way
def two_way_text() -> str:
    """The bundled transport scene over 4 s in two segments of 0.05 s of flow each (the
    smallest two-way setup, tests/runs/test_coupling_two_way.py: its spray zone moved into the
    packed bed), three cells selected by point: sprayed (y 0.2 m, and y 0.25 m at the wall) and
    below the spray zone (y 0.05 m)."""
    text = fluid_bed_text(end=4.0, scene="fluid-bed-transport")
    text = re.sub(r"(?m)^output_interval = .*", "output_interval = 1.0", text, count=1)
    text = re.sub(r"(?m)^zone = .*", "zone = { alpha_low = 0.05, alpha_high = 0.6, box_min = "
                  "[0.0, 0.1, -1.0], box_max = [0.15, 0.3, 1.0] }", text, count=1)
    return text + ("\n[coupling]\ninterval = 2.0\nflow_time = 0.05\naverage_from = 0.02\n"
                   "\n[output]\ncell_psd = [[0.075, 0.2, 0.0], [0.075, 0.05, 0.0], "
                   "[0.015, 0.25, 0.0]]\n")


@pytest.mark.openfoam
@pytest.mark.skipif(shutil.which("twoPhaseEulerFoam") is None, reason="needs OpenFOAM")
def test_a_two_way_run_writes_each_cell_s_distribution_at_every_time(tmp_path):
    """`pbe-cfd couple` of a two-way scene (each segment its own CFD) writes cell_psd.csv at
    every output time of both segments: per cell and time q3 integrates to 1 and Q3 ends at 1
    within GRID_FRACTIONS, and the d50 the run wrote into that segment's VTK field for that cell
    lies in the grid interval where the cell's Q3 crosses 1/2 (the same reconstruction)."""
    import meshio
    path = tmp_path / "two-way.toml"
    path.write_text(two_way_text())
    out = tmp_path / "out"
    assert main(["couple", str(path), "--out", str(out)]) == 0
    cols = read_columns_csv(out / "cell_psd.csv")
    manifest = json.loads((out / "pbe-cfd-manifest.json").read_text())
    assert {"cell_psd.csv", "png/cell_psd.png"} <= set(manifest["files"])
    times = np.unique(cols["time_s"])
    assert np.array_equal(times, [0.0, 1.0, 2.0, 3.0, 4.0])
    cells = [int(c) for c in dict.fromkeys(cols["cell"])]
    assert len(cells) == 3
    for c, want in zip(cells, [(0.075, 0.2), (0.075, 0.05), (0.015, 0.25)]):
        at = cols["cell"] == c
        assert abs(cols["x_m"][at][0] - want[0]) <= 0.005 + 1e-12      # half a cell: 5 mm
        assert abs(cols["y_m"][at][0] - want[1]) <= 0.005 + 1e-12
    lo_f, hi_f = tables.GRID_FRACTIONS
    grid = np.unique(cols["d_m"])
    h = math.log(grid[1] / grid[0])
    series = sorted((out / "vtk").glob("*.vtu"))
    assert len(series) == len(times)
    for k, t in enumerate(times):
        d50_field = meshio.read(series[k]).cell_data["d50_m"][0]
        for c in cells:
            at = (cols["time_s"] == t) & (cols["cell"] == c)
            assert np.all(cols["active"][at] == 1)
            q3, big_q, d = cols["q3_per_ln_d"][at], cols["Q3"][at], cols["d_m"][at]
            assert np.sum(q3) * h == pytest.approx(1.0, rel=0, abs=lo_f + (1 - hi_f))
            assert big_q[-1] >= hi_f and np.all(np.diff(big_q) >= 0)
            j = int(np.searchsorted(big_q, 0.5))
            d50 = d50_field[c]
            assert d[j - 1] <= d50 * (1 + 1e-12) and d50 <= d[j] * (1 + 1e-12), (t, c, d50)
    # the sprayed cells hold binder once the spray has run, the bed's lowest cell at the start not
    first = cols["time_s"] == 1.0
    assert np.max(cols["binder_fraction"][first & (cols["cell"] == cells[0])]) > 0
