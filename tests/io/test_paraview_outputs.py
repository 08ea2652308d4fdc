"""What a ParaView or meshio user finds in a coupled run's outputs: an ``active`` flag to
threshold on (in the VTK series and as ``pbe.active`` in the case), the time of each ``.vtu``
as FieldData, and the series readable with meshio."""
from __future__ import annotations

import meshio
import numpy as np
import pytest
from test_data_safety import _fake_case, tiny_couple_text

from pbe_cfd.io import openfoam as of
from pbe_cfd.io.vtk import read_pvd, read_series, time_values
from pbe_cfd.cli import main

ALPHA_MIN = 0.05        # the fluid-bed scene's [domain] alpha_min


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The bundled fluid-bed scene shortened to 2 s on a case directory (outputs at 0, 1, 2 s),
    with --foam-fields."""
    root = tmp_path_factory.mktemp("paraview")
    case = _fake_case(root)
    scene = root / "s.toml"
    scene.write_text(tiny_couple_text(str(case)))
    assert main(["couple", str(scene), "--out", str(root / "c"), "--foam-fields"]) == 0
    return root / "c", case


def _cell_field(mesh: meshio.Mesh, name: str) -> np.ndarray:
    return np.concatenate([np.asarray(b) for b in mesh.cell_data[name]])


def test_each_vtu_carries_its_process_time_and_the_cfd_time(run):
    out, _ = run
    entries = read_pvd(out / "vtk" / "pbe.pvd")
    assert [t for t, _ in entries] == [0.0, 1.0, 2.0]
    for t, path in entries:
        m = meshio.read(path)
        assert m.field_data["TimeValue"].tolist() == [t]
        assert m.field_data["CFDTime"].tolist() == [1.5]      # the case's time directory
        assert time_values(path) == {"TimeValue": t, "CFDTime": 1.5}


def test_the_series_reads_with_meshio_and_pyvista(run):
    import pyvista as pv

    out, _ = run
    series = read_series(out / "vtk" / "pbe.pvd")
    assert [t for t, _ in series] == [0.0, 1.0, 2.0]
    reader = pv.get_reader(str(out / "vtk" / "pbe.pvd"))
    assert list(reader.time_values) == [0.0, 1.0, 2.0]
    for t, mesh in series:
        reader.set_active_time_value(t)
        grid = reader.read()[0]
        np.testing.assert_array_equal(np.asarray(grid.cell_data["M00"]),
                                      _cell_field(mesh, "M00"))


def test_active_marks_exactly_the_cells_holding_granules(run):
    out, case = run
    cells = of.load_snapshot()
    for _, mesh in read_series(out / "vtk" / "pbe.pvd"):
        active = _cell_field(mesh, "active")
        alpha = _cell_field(mesh, "alpha")
        m00 = _cell_field(mesh, "M00")
        assert set(np.unique(active)) == {0.0, 1.0}
        np.testing.assert_array_equal(active == 1.0, alpha >= ALPHA_MIN)
        # granules in every active cell, none outside: thresholding on active keeps the bed
        assert np.all(m00[active == 1.0] > 0) and np.all(m00[active == 0.0] == 0)
    # the same flag in the case, as an OpenFOAM volScalarField in OpenFOAM's cell order
    from foamlib import FoamFile

    written = np.asarray(FoamFile(case / "1.5" / "pbe.active")["internalField"], dtype=float)
    np.testing.assert_array_equal(written, (cells.alpha >= ALPHA_MIN).astype(float))
