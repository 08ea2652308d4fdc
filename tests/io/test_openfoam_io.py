"""OpenFOAM I/O: bundled snapshot, cell order, times, field write-back, and the real case."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import meshio
import numpy as np
import pytest

from pbe_cfd.io import openfoam as of

BED_WIDTH, BED_HEIGHT, BED_DEPTH = 0.15, 0.6, 0.02  # m
ALPHA_MAX = 0.62  # packing limit of the case (constant/phaseProperties)
CASE = (Path(__file__).resolve().parents[2] / "openfoam_case").resolve()   # the template

needs_openfoam = pytest.mark.skipif(shutil.which("blockMesh") is None,
                                    reason="OpenFOAM (blockMesh) not installed")


# --------------------------------------------------------------------------- snapshot

@pytest.fixture(scope="module")
def snap():
    return of.load_snapshot(with_flux=True)


def test_snapshot_is_small_and_bundled():
    vtu, npz = of.default_snapshot_path(), of.default_flux_path()
    assert vtu.is_file() and npz.is_file()
    assert vtu.stat().st_size + npz.stat().st_size < 500_000
    # plain meshio can read it
    m = meshio.read(vtu)
    assert {"alpha", "Theta", "cell_volume", "cell_centre"} <= set(m.cell_data)


def test_snapshot_fields(snap):
    cells, _ = snap
    assert 800 <= cells.n_cells <= 1000
    assert cells.averaged
    assert cells.time == pytest.approx(1.5, rel=1e-12, abs=0)
    assert np.all(np.isfinite(cells.alpha)) and np.all(np.isfinite(cells.theta))
    assert np.all(cells.alpha >= 0) and np.all(cells.alpha < ALPHA_MAX)
    assert cells.alpha.max() > 0.4            # a dense bed is there
    assert np.mean(cells.alpha > 0.3) > 0.3   # and fills a good part of the column
    assert np.all(cells.theta >= 0)
    bed = cells.alpha > 0.3
    assert 1e-7 < np.median(cells.theta[bed]) < 1e-2   # m2/s2, bubbling-bed range


def test_snapshot_volumes_sum_to_bed(snap):
    cells, _ = snap
    assert np.all(cells.cell_volume > 0)
    np.testing.assert_allclose(cells.cell_volume.sum(), BED_WIDTH * BED_HEIGHT * BED_DEPTH,
                               rtol=1e-9, atol=0)
    lo, hi = cells.cell_centre.min(0), cells.cell_centre.max(0)
    assert lo[0] > 0 and hi[0] < BED_WIDTH and lo[1] > 0 and hi[1] < BED_HEIGHT


def test_snapshot_keeps_openfoam_cell_order(snap):
    # blockMesh numbers the 15 x 60 cells x fastest: cell i sits at column i % 15, row i // 15
    cells, _ = snap
    i = np.arange(cells.n_cells)
    nx = 15
    dx = BED_WIDTH / nx
    np.testing.assert_allclose(cells.cell_centre[:, 0], (i % nx + 0.5) * dx, atol=1e-7)
    np.testing.assert_allclose(cells.cell_centre[:, 1], (i // nx + 0.5) * dx, atol=1e-7)


def test_snapshot_flux(snap):
    cells, flux = snap
    assert flux.n_cells == cells.n_cells
    assert flux.owner.shape == flux.neighbour.shape == flux.flux.shape
    assert np.all(flux.owner < flux.neighbour)          # OpenFOAM's upper-triangular order
    assert np.all(np.isfinite(flux.flux)) and np.abs(flux.flux).max() > 0
    assert set(flux.patch_names) == {"inlet", "outlet", "walls"}
    # closed for solids: nothing leaves through the boundaries, and internal fluxes cancel
    total_abs = np.abs(flux.flux).sum()
    assert all(abs(v) <= 1e-12 * total_abs for v in flux.patch_flux.values())
    assert abs(flux.net_outflow().sum()) <= 1e-12 * total_abs
    # faces connect neighbouring cells only
    d = np.linalg.norm(cells.cell_centre[flux.owner] - cells.cell_centre[flux.neighbour], axis=1)
    np.testing.assert_allclose(d, BED_WIDTH / 15, rtol=1e-5, atol=0)


def test_snapshot_flux_balances_alpha_change(snap):
    # the window-averaged solids flux carries exactly the solids that moved over the window:
    # net outflow = -(alpha_end - alpha_start) V / T, up to the time discretisation
    cells, flux = snap
    assert flux.window_start == pytest.approx(0.5, rel=1e-12, abs=0) and flux.time == pytest.approx(1.5, rel=1e-12, abs=0)
    out = flux.net_outflow()
    moved = -(flux.alpha_end - flux.alpha_start) * cells.cell_volume / (flux.time -
                                                                       flux.window_start)
    assert np.abs(out - moved).max() < 0.01 * np.abs(out).max()
    # the solids inventory is constant, so the mean field holds the same solids volume
    np.testing.assert_allclose((cells.alpha * cells.cell_volume).sum(),
                               (flux.alpha_end * cells.cell_volume).sum(), rtol=1e-4, atol=0)


# --------------------------------------------------------------------------- fake cases

def _fake_case(tmp_path: Path, mesh: meshio.Mesh, cell_data: dict, time: float = 1.5) -> Path:
    """A case directory holding only a time dir and foamToVTK-style output."""
    case = tmp_path / "case"
    (case / f"{time:g}").mkdir(parents=True)
    (case / "0").mkdir()
    sub = case / "VTK" / "case_100"
    sub.mkdir(parents=True)
    out = meshio.Mesh(mesh.points, mesh.cells, cell_data=cell_data)
    meshio.write(sub / "internal.vtu", out, file_format="vtu")
    (case / "VTK" / "case.vtm.series").write_text(json.dumps(
        {"file-series-version": "1.0", "files": [{"name": "case_100.vtm", "time": time}]}))
    return case


def test_cellid_permutation_is_undone(tmp_path, snap):
    cells, _ = snap
    hexes = cells.mesh.cells[0].data
    rng = np.random.default_rng(1)
    perm = rng.permutation(cells.n_cells)        # VTK cell k is OpenFOAM cell perm[k]
    mesh = meshio.Mesh(cells.mesh.points, [("hexahedron", hexes[perm])])
    case = _fake_case(tmp_path, mesh, {
        "alpha.particlesMean": [cells.alpha[perm]],
        "Theta.particlesMean": [cells.theta[perm]],
        "cellID": [perm.astype(np.int32)],
    })
    got = of.read_cell_fields(case, "latest")
    np.testing.assert_array_equal(got.alpha, cells.alpha)
    np.testing.assert_array_equal(got.theta, cells.theta)
    np.testing.assert_allclose(got.cell_volume, cells.cell_volume, rtol=1e-12, atol=0)
    np.testing.assert_allclose(got.cell_centre, cells.cell_centre, atol=1e-12)
    # spreading back onto VTK cells follows the same map
    np.testing.assert_array_equal(got.to_vtk_cells(got.alpha), cells.alpha[perm])


def test_split_cells_map_through_cellid(tmp_path, snap):
    # split OpenFOAM cell 0 into two wedges, as foamToVTK -poly-decomp would split a polyhedron
    cells, _ = snap
    hexes = cells.mesh.cells[0].data
    h = hexes[0]
    w1 = [h[0], h[1], h[2], h[4], h[5], h[6]]
    w2 = [h[0], h[2], h[3], h[4], h[6], h[7]]
    mesh = meshio.Mesh(cells.mesh.points, [("wedge", np.array([w1, w2])),
                                           ("hexahedron", hexes[1:])])
    ids = np.concatenate([[0, 0], np.arange(1, cells.n_cells)])
    a = np.concatenate([[cells.alpha[0]] * 2, cells.alpha[1:]])
    th = np.concatenate([[cells.theta[0]] * 2, cells.theta[1:]])
    case = _fake_case(tmp_path, mesh, {"alpha.particlesMean": [a[:2], a[2:]],
                                       "Theta.particlesMean": [th[:2], th[2:]],
                                       "cellID": [ids[:2], ids[2:]]})
    got = of.read_cell_fields(case)
    assert got.n_cells == cells.n_cells
    assert len(got.vtk_cell_id) == cells.n_cells + 1
    np.testing.assert_allclose(got.cell_volume, cells.cell_volume, rtol=1e-9, atol=0)
    np.testing.assert_allclose(got.cell_centre, cells.cell_centre, atol=1e-9)
    np.testing.assert_array_equal(got.alpha, cells.alpha)


def test_instantaneous_fallback_warns(tmp_path, snap):
    cells, _ = snap
    case = _fake_case(tmp_path, cells.mesh, {"alpha.particles": [cells.alpha],
                                             "Theta.particles": [cells.theta]})
    got = of.read_cell_fields(case, 1.5)
    # one warning per field that falls back: alpha and Theta, and no other, each one line
    # naming the time directory and the key that changes it (recorded in summary.json)
    texts = got.source["warnings"]
    assert len(texts) == 2, texts
    assert all("\n" not in t and str(case / "1.5") in t and "[domain] time" in t
               for t in texts)
    for field in ("alpha", "Theta"):
        assert sum(f"no time-averaged '{field}.particlesMean'" in t for t in texts) == 1
    assert not got.averaged
    assert got.source["alpha_field"] == "alpha.particles"


def test_missing_field_is_a_clear_error(tmp_path, snap):
    cells, _ = snap
    case = _fake_case(tmp_path, cells.mesh, {"alpha.particlesMean": [cells.alpha]})
    with pytest.raises(of.OpenFOAMError, match="granular temperature.*Theta.particlesMean"
                       ) as err:
        of.read_cell_fields(case)
    # the time directory, not an internal VTK file, and the key to choose another time
    assert str(err.value).startswith(str(case / "1.5")) and "[domain] time" in str(err.value)


def test_times(tmp_path):
    case = tmp_path / "c"
    with pytest.raises(of.OpenFOAMError, match="does not exist"):
        of.written_times(case)
    case.mkdir()
    with pytest.raises(of.OpenFOAMError, match="no time directories"):
        of.pick_time(case)
    for name in ("0", "0.5", "1", "1.5", "constant", "0.orig"):
        (case / name).mkdir()
    assert of.written_times(case) == [0.0, 0.5, 1.0, 1.5]
    assert of.pick_time(case) == 1.5
    assert of.pick_time(case, "latest") == 1.5
    (case / "0.5" / "alpha.particlesMean").touch()   # only 0.5 holds CFD fields
    assert of.pick_time(case, "latest") == 0.5
    (case / "0.5" / "alpha.particlesMean").unlink()
    assert of.pick_time(case, 0.5) == 0.5
    assert of.pick_time(case, "1") == 1.0
    assert of.time_name(case, 1.0) == "1"
    with pytest.raises(of.OpenFOAMError, match=r"t = 0.7 s is not a written time.*0.5"):
        of.pick_time(case, 0.7)
    with pytest.raises(of.OpenFOAMError, match="'latest' or a number"):
        of.pick_time(case, "last")


def _fake_polymesh(case: Path, n_cells: int) -> None:
    pm = case / "constant" / "polyMesh"
    pm.mkdir(parents=True)
    head = ('FoamFile\n{\n    version 2.0;\n    format ascii;\n    class labelList;\n'
            f'    note "nPoints:0 nCells:{n_cells} nFaces:0 nInternalFaces:0";\n'
            '    object owner;\n}\n')
    (pm / "owner").write_text(head + f"{n_cells}\n(\n" + "\n".join(
        str(i) for i in range(n_cells)) + "\n)\n")
    (pm / "boundary").write_text(
        "FoamFile\n{\n    version 2.0;\n    format ascii;\n    class polyBoundaryMesh;\n"
        "    object boundary;\n}\n2\n(\n    walls\n    {\n        type wall;\n"
        "        nFaces 0;\n        startFace 0;\n    }\n    frontAndBack\n    {\n"
        "        type empty;\n        nFaces 0;\n        startFace 0;\n    }\n)\n")


def test_write_foam_fields_round_trip(tmp_path):
    from foamlib import FoamFieldFile

    case = tmp_path / "case"
    _fake_polymesh(case, 5)
    vals = np.array([0.0, 1.5e10, 3e-7, 2.0, 1e-300])
    paths = of.write_foam_fields(case, "600", {"M00": vals, "d43_m": vals * 0 + 1e-4},
                                 dimensions={"M00": "[0 -3 0 0 0 0 0]"})
    assert [p.name for p in paths] == ["M00", "d43_m"]
    f = FoamFieldFile(case / "600" / "M00")
    np.testing.assert_allclose(np.asarray(f.internal_field), vals, rtol=1e-9, atol=0)
    assert f.boundary_field["walls"]["type"] == "zeroGradient"
    assert f.boundary_field["frontAndBack"]["type"] == "empty"
    assert "[0 -3 0 0 0 0 0]" in (case / "600" / "M00").read_text()
    with pytest.raises(ValueError, match="has 3 values.*5 cells"):
        of.write_foam_fields(case, "600", {"x": np.zeros(3)})
    with pytest.raises(ValueError, match="non-finite"):
        of.write_foam_fields(case, "600", {"x": np.full(5, np.nan)})


def test_missing_openfoam_is_one_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(of.OpenFOAMError, match="'blockMesh' not found.*apt-get install"):
        of.find_openfoam()
    assert not of.have_openfoam()
    case = of.copy_case(CASE, tmp_path / "case")
    with pytest.raises(of.OpenFOAMError, match="blockMesh"):
        of.run_case(case)


def test_default_case_dir(monkeypatch, tmp_path):
    assert (of.default_case_dir() / "Allrun").is_file()
    monkeypatch.setenv("PBE_CFD_CASE", str(CASE))
    assert of.default_case_dir() == CASE
    monkeypatch.setenv("PBE_CFD_CASE", str(tmp_path))
    with pytest.raises(of.OpenFOAMError, match="PBE_CFD_CASE.*no Allrun"):
        of.default_case_dir()


def test_copy_case_copies_template_only(tmp_path):
    case = of.copy_case(CASE, tmp_path / "case")
    for p in ("Allrun", "Allclean", "0.orig/alpha.particles", "system/controlDict",
              "system/blockMeshDict.small", "system/blockMeshDict.full",
              "constant/phaseProperties"):
        assert (case / p).is_file(), p
    assert not (case / "constant" / "polyMesh").exists()
    assert os.access(case / "Allrun", os.X_OK)
    with pytest.raises(of.OpenFOAMError, match="not empty"):
        of.copy_case(CASE, case)


# --------------------------------------------------------------------------- real OpenFOAM

@pytest.mark.openfoam
@needs_openfoam
def test_failing_tool_names_tool_and_log_tail(tmp_path):
    case = of.copy_case(CASE, tmp_path / "case")
    bmd = case / "system" / "blockMeshDict.small"
    bmd.write_text(bmd.read_text().replace("blocks", "blockz"))
    with pytest.raises(of.OpenFOAMError) as err:
        of.run_case(case, "small", end_time=0.01)
    assert err.value.tool == "blockMesh"
    assert err.value.log_path == case / "log.blockMesh"
    assert "FOAM FATAL" in err.value.log_tail
    assert "blockMesh failed" in str(err.value)


@pytest.fixture(scope="module")
def real_case(tmp_path_factory):
    if shutil.which("blockMesh") is None:
        pytest.skip("OpenFOAM (blockMesh) not installed")
    case = of.copy_case(CASE, tmp_path_factory.mktemp("of") / "case")
    lines = []
    res = of.run_case(case, "small", log=lines.append, end_time=0.3, avg_start=0.1)
    return case, res, lines


@pytest.mark.openfoam
def test_real_case_end_to_end(real_case):
    from foamlib import FoamFieldFile

    case, res, lines = real_case
    assert res.latest_time == pytest.approx(0.3, rel=1e-12, abs=0)
    assert set(res.wall_times) == {"blockMesh", "setFields", "twoPhaseEulerFoam", "foamToVTK"}
    assert any("twoPhaseEulerFoam: t =" in s for s in lines)
    for tool in res.wall_times:
        assert (case / f"log.{tool}").is_file()
    cells = of.read_cell_fields(case, "latest")
    assert cells.n_cells == 900 and cells.averaged
    assert np.all(cells.alpha >= 0) and np.all(cells.alpha < ALPHA_MAX)
    assert cells.alpha.max() > 0.4
    assert np.all(np.isfinite(cells.theta)) and np.all(cells.theta >= 0)
    assert cells.theta.max() > 0
    # the VTK values are OpenFOAM's, in OpenFOAM's order (VTK stores float32)
    tdir = case / of.time_name(case, cells.time)
    for name, got in (("alpha.particlesMean", cells.alpha), ("Theta.particlesMean", cells.theta)):
        ref = np.asarray(FoamFieldFile(tdir / name).internal_field, dtype=float)
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-30)
    # volumes from the VTK hexes agree with OpenFOAM's own cell volumes
    env = of.find_openfoam().env()
    subprocess.run(["postProcess", "-func", "writeCellVolumes", "-time", tdir.name],
                   cwd=case, env=env, check=True, capture_output=True)
    V = np.asarray(FoamFieldFile(tdir / "V").internal_field, dtype=float)
    np.testing.assert_allclose(cells.cell_volume, V, rtol=1e-6, atol=0)
    np.testing.assert_allclose(V.sum(), BED_WIDTH * BED_HEIGHT * BED_DEPTH, rtol=1e-12, atol=0)
    # face flux
    flux = of.read_face_flux(case)
    assert flux.field == "alphaPhi.particlesMean"
    assert flux.n_cells == 900 and len(flux.flux) == 14 * 60 + 15 * 59
    assert np.all(np.isfinite(flux.flux))
    assert flux.window_start == pytest.approx(0.1, rel=1e-12, abs=0)
    out = flux.net_outflow()
    moved = -(flux.alpha_end - flux.alpha_start) * V / (flux.time - flux.window_start)
    assert np.abs(out - moved).max() < 0.02 * np.abs(out).max()


@pytest.mark.openfoam
def test_real_case_write_back_and_snapshot(real_case, tmp_path):
    import pyvista as pv
    from foamlib import FoamFieldFile

    case, _, _ = real_case
    cells = of.read_cell_fields(case)
    m00 = cells.alpha * 1e12
    of.write_foam_fields(case, "600", {"M00": m00}, dimensions={"M00": "[0 -3 0 0 0 0 0]"})
    f = FoamFieldFile(case / "600" / "M00")
    np.testing.assert_allclose(np.asarray(f.internal_field), m00, rtol=1e-9, atol=0)
    # ParaView's reader (VTK's vtkOpenFOAMReader) sees the new time and field
    (case / "case.foam").touch()
    reader = pv.OpenFOAMReader(str(case / "case.foam"))
    assert 600.0 in list(reader.time_values)
    reader.set_active_time_value(600.0)
    grid = reader.read()["internalMesh"]
    assert grid.n_cells == cells.n_cells
    np.testing.assert_allclose(grid.cell_data["M00"], m00, rtol=1e-6, atol=0)  # VTK reads float32
    with pytest.warns(UserWarning, match="not a number"):
        of.write_foam_fields(case, "pbe_final", {"M00": m00})
    # "latest" still means the CFD time, not the written-back 600
    assert of.pick_time(case, "latest") == pytest.approx(0.3, rel=1e-12, abs=0)
    vtu, npz = of.write_snapshot(case, "latest", tmp_path / "snap.vtu")
    assert npz == tmp_path / "snap_flux.npz"
    back, flux = of.load_snapshot(vtu, with_flux=True)
    np.testing.assert_array_equal(back.alpha, cells.alpha)
    np.testing.assert_array_equal(back.theta, cells.theta)
    np.testing.assert_allclose(back.cell_volume, cells.cell_volume, atol=0)
    assert back.source["control"]["endTime"] == pytest.approx(0.3, rel=1e-12, abs=0)
    assert flux.flux.shape == of.read_face_flux(case).flux.shape


@pytest.mark.openfoam
def test_real_case_coupled_end_to_end(real_case, tmp_path):
    """OpenFOAM case -> meshio read -> per-cell PBE -> VTK series -> a non-blank render ->
    moment fields back in the case, all through the command line."""
    import pyvista as pv

    from pbe_cfd.viz.render import image_stats
    from pbe_cfd.cli import main
    from pbe_cfd.scene.scene import resolve_scene_path

    case, _, _ = real_case
    text = resolve_scene_path("fluid-bed").read_text()
    text = text.replace('case = "bundled:fluid_bed_small"', f'case = "{case}"')
    text = text.replace("end_time = 60.0", "end_time = 10.0")
    # 0.3 s of flow has not expanded the bed yet: spray onto every bed cell
    text = text.replace("alpha_high = 0.45", "alpha_high = 0.62").replace(
        "box_min = [0.0, 0.28, -1.0]", "box_min = [0.0, 0.0, -1.0]")
    scene = tmp_path / "real.toml"
    scene.write_text(text)
    out = tmp_path / "out"
    assert main(["couple", str(scene), "--out", str(out), "--foam-fields"]) == 0
    reader = pv.get_reader(str(out / "vtk" / "pbe.pvd"))
    assert reader.time_values[-1] == pytest.approx(10.0, rel=1e-12, abs=0)
    reader.set_active_time_value(10.0)
    mesh = reader.read()[0]
    assert mesh.n_cells == 900
    for name in ("alpha", "Theta", "M00", "d43_m", "binder_fraction"):
        assert np.all(np.isfinite(mesh.cell_data[name]))
    assert np.asarray(mesh.cell_data["M01"]).max() > 0
    png = out / "png" / "d43_m_t10s.png"
    variance, colours = image_stats(png)
    assert variance > 0 and colours > 10
    tdir = case / of.time_name(case, of.pick_time(case, "latest"))
    assert (tdir / "pbe.M00").is_file() and (tdir / "pbe.d43_m").is_file()
