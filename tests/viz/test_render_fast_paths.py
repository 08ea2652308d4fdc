"""The fast paths of the pictures give what the general paths give: the meshio section of a
one-cell-thick mesh equals VTK's cut cell by cell, and drawing on two processes writes every
picture once, in order, and loses none when the child fails."""
import os

import numpy as np
import pytest

from pbe_cfd.viz import figure_pool
from pbe_cfd.io import openfoam as of
from pbe_cfd.viz.section import read_section, section, thin_section
from pbe_cfd.io.vtk import VtkSeries, read_pvd


@pytest.fixture(scope="module")
def vtu(tmp_path_factory):
    cells = of.load_snapshot()
    out = tmp_path_factory.mktemp("thin")
    with VtkSeries(out, cells, name="pbe", static_fields={"alpha": cells.alpha}) as s:
        s.write(0.0, {"M00": np.arange(cells.alpha.size, dtype=float) + 1.0})
    return read_pvd(out / "pbe.pvd")[0][1]


def _area(p):
    return 0.5 * abs(np.dot(p[:, 0], np.roll(p[:, 1], 1)) - np.dot(p[:, 1], np.roll(p[:, 0], 1)))


def _by_centre(polys):
    centres = np.round(np.array([p.mean(axis=0) for p in polys]) * 1e6)
    return np.lexsort(centres.T[::-1]), centres


def test_thin_section_equals_the_vtk_cut_cell_by_cell(vtu):
    import pyvista as pv
    fast = thin_section(vtu)
    cut = section(pv.read(str(vtu)))
    assert fast is not None and len(fast[0]) == len(cut[0])
    assert fast[2] == cut[2] and fast[3] == cut[3] == ""
    order_fast, c_fast = _by_centre(fast[0])
    order_cut, c_cut = _by_centre(cut[0])
    np.testing.assert_array_equal(c_fast[order_fast], c_cut[order_cut])    # same places, um
    # same outlines: VTK stores the cut's points in float32, so areas agree to its epsilon
    area_fast = np.array([_area(fast[0][i]) for i in order_fast])
    area_cut = np.array([_area(cut[0][i]) for i in order_cut])
    np.testing.assert_allclose(area_fast, area_cut, rtol=8 * np.finfo(np.float32).eps, atol=0)
    assert np.all(area_fast > 0)                   # outlines in order, not bow ties
    for name in ("M00", "alpha"):
        np.testing.assert_array_equal(np.asarray(fast[1][name])[order_fast],
                                      np.asarray(cut[1][name])[order_cut])


def test_a_mesh_of_several_layers_is_cut_by_vtk_with_a_note(tmp_path):
    import pyvista as pv
    grid = pv.ImageData(dimensions=(4, 4, 4), spacing=(0.1, 0.1, 0.05)).cast_to_unstructured_grid()
    grid.cell_data["M00"] = np.arange(grid.n_cells, dtype=float)
    path = tmp_path / "block.vtu"
    grid.save(str(path))
    assert thin_section(path) is None              # three layers: not its own section
    polys, data, axes, note = read_section(path)
    assert axes == ("x", "y") and note == "section z = 0.075 m" and len(polys) == 9


def test_read_section_names_a_file_it_cannot_read(tmp_path):
    bad = tmp_path / "broken.vtu"
    bad.write_text("<VTKFile>not a mesh")
    with pytest.raises(ValueError, match="cannot read .*broken.vtu"):
        read_section(bad)


# ---------------------------------------------------------------------------- figure pool
def _write(path, text, die_in_child_of=None):
    if die_in_child_of is not None and os.getpid() != die_in_child_of:
        os._exit(3)                                # the child dies without a word
    path.write_text(text)
    return (str(path), os.getpid())


def _fail(message):
    raise ValueError(message)


def test_every_task_runs_once_and_results_keep_their_order(tmp_path):
    tasks = [(_write, (tmp_path / f"{k}.txt", str(k)), {}, 1.0 + (k == 0) * 3)
             for k in range(7)]
    results = figure_pool.run_tasks(tasks)
    assert [r[0] for r in results] == [str(tmp_path / f"{k}.txt") for k in range(7)]
    assert [(tmp_path / f"{k}.txt").read_text() for k in range(7)] == [str(k) for k in range(7)]
    pids = {r[1] for r in results}
    if figure_pool._use_child(tasks):
        assert len(pids) == 2 and os.getpid() in pids   # both processes drew
    else:
        assert pids == {os.getpid()}


def test_split_by_cost_balances_the_two_sides():
    tasks = [(None, (), {}, c) for c in (4.0, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1)]
    here, child = figure_pool.split_by_cost(tasks)
    assert sorted(here + child) == list(range(len(tasks)))
    load = [sum(tasks[i][3] for i in side) for side in (here, child)]
    assert abs((load[0] + 1.0) - load[1]) <= 1.0   # the parent starts one unit behind


def test_a_child_that_dies_loses_no_picture(tmp_path):
    parent = os.getpid()
    tasks = [(_write, (tmp_path / f"{k}.txt", str(k)), {"die_in_child_of": parent}, 1.0)
             for k in range(6)]
    results = figure_pool.run_tasks(tasks)
    assert all((tmp_path / f"{k}.txt").read_text() == str(k) for k in range(6))
    assert {r[1] for r in results} == {parent}     # the child's share was drawn here


def test_an_error_in_a_task_reaches_the_caller():
    tasks = [(_fail, (f"bad {k}",), {}, 1.0) for k in range(4)]
    with pytest.raises(ValueError, match="bad"):
        figure_pool.run_tasks(tasks)


def test_one_process_when_asked(monkeypatch, tmp_path):
    monkeypatch.setenv("PBE_CFD_DRAW_PROCESSES", "1")
    tasks = [(_write, (tmp_path / f"{k}.txt", str(k)), {}, 1.0) for k in range(5)]
    assert {r[1] for r in figure_pool.run_tasks(tasks)} == {os.getpid()}


def test_started_drawing_processes_draw_every_task_and_lose_none(tmp_path):
    if not figure_pool._two_processes_allowed():
        pytest.skip("one core or no fork: drawing stays in this process")
    parent = os.getpid()
    try:
        assert figure_pool.start_processes() and figure_pool.drawing_elsewhere()
        tasks = [(_write, (tmp_path / f"{k}.txt", str(k)), {}, 1.0 + k) for k in range(6)]
        results = figure_pool.run_tasks(tasks)
        assert [r[0] for r in results] == [str(tmp_path / f"{k}.txt") for k in range(6)]
        assert parent not in {r[1] for r in results}          # drawn by the started ones
        with pytest.raises(ValueError, match="bad"):
            figure_pool.run_tasks([(_fail, ("bad",), {}, 1.0)])
        dying = [(_write, (tmp_path / f"d{k}.txt", str(k)), {"die_in_child_of": parent}, 1.0)
                 for k in range(4)]
        figure_pool.run_tasks(dying)                           # the pool breaks ...
        assert all((tmp_path / f"d{k}.txt").read_text() == str(k) for k in range(4))
    finally:
        figure_pool.stop_processes()
    assert not figure_pool.drawing_elsewhere()


def test_tasks_started_early_finish_with_their_results_and_lose_none(tmp_path):
    """``start_tasks`` hands tasks out while the caller goes on; ``finish_tasks`` returns their
    results in order, draws here what a dying process could not, and without started
    processes runs them as ``run_tasks`` does."""
    parent = os.getpid()
    tasks = [(_write, (tmp_path / f"e{k}.txt", str(k)), {}, 1.0 + k) for k in range(3)]
    here = figure_pool.finish_tasks(figure_pool.start_tasks(tasks))   # no processes started
    assert [r[0] for r in here] == [str(tmp_path / f"e{k}.txt") for k in range(3)]
    if not figure_pool._two_processes_allowed():
        pytest.skip("one core or no fork: drawing stays in this process")
    try:
        assert figure_pool.start_processes()
        started = figure_pool.start_tasks(
            [(_write, (tmp_path / f"s{k}.txt", str(k)), {}, 1.0 + k) for k in range(4)])
        (tmp_path / "meanwhile.txt").write_text("the caller went on")
        results = figure_pool.finish_tasks(started)
        assert [r[0] for r in results] == [str(tmp_path / f"s{k}.txt") for k in range(4)]
        assert parent not in {r[1] for r in results}
        dying = figure_pool.start_tasks(
            [(_write, (tmp_path / f"x{k}.txt", str(k)), {"die_in_child_of": parent}, 1.0)
             for k in range(3)])
        figure_pool.finish_tasks(dying)
        assert all((tmp_path / f"x{k}.txt").read_text() == str(k) for k in range(3))
    finally:
        figure_pool.stop_processes()
