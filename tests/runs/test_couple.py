"""Per-cell coupling over the OpenFOAM fluid bed (bundled snapshot of the small case)."""
import dataclasses
import math

import numpy as np
import pytest

from pbe_cfd.io.openfoam import load_snapshot
from pbe_cfd.runs.couple import run_coupled, write_coupled
from pbe_cfd.runs.domain import Domain, load_domain
from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import AVICEL, make_scene


@pytest.fixture(scope="module")
def snapshot():
    return load_snapshot()


def short_fluid_bed(end=10.0, interval=5.0, **method):
    scene = load_scene("fluid-bed")
    scene = dataclasses.replace(scene, end_time=end, output_interval=interval)
    if method:
        scene = scene.with_method(**method)
    return scene


def one_cell(snapshot, index):
    cells = snapshot
    sl = slice(index, index + 1)
    return dataclasses.replace(cells, alpha=cells.alpha[sl].copy(), theta=cells.theta[sl].copy(),
                               cell_volume=cells.cell_volume[sl].copy(),
                               cell_centre=cells.cell_centre[sl].copy(),
                               vtk_cell_id=np.zeros(1, dtype=np.int64))


def test_one_coupled_cell_equals_the_well_mixed_run(snapshot):
    """The coupled path and the well-mixed path are one kernel: same cell, same numbers."""
    scene = short_fluid_bed(end=20.0, interval=5.0)
    c = int(np.argmax(snapshot.alpha))
    cell = one_cell(snapshot, c)
    alpha, theta = float(cell.alpha[0]), float(cell.theta[0])
    # the spray zone does not hold the densest cell: inject everywhere for this comparison
    scene = dataclasses.replace(scene, binder_injection=dataclasses.replace(
        scene.binder_injection, zone=None))
    coupled = run_coupled(scene, Domain(cells=cell, flux=None, description="one cell"))
    p0 = scene.initial.mean_mass
    mixed_scene = make_scene(
        scene={"end_time": 20.0, "output_interval": 5.0},
        domain={"type": "well-mixed", "solids_fraction": alpha, "granular_temperature": theta,
                "alpha_max": 0.62, "alpha_min_friction": 0.5},
        material=dict(AVICEL),
        initial={"distribution": "monodisperse", "number_density": alpha * 1021.0 / p0,
                 "mean_mass": p0, "binder_fraction": 0.0},
        aggregation={"kernel": "ktgf", "rate": 1.0e-5, "efficiency": ["geometric", "physical"],
                     "droplet_factor": 100.0},
        binder_injection={"rate": 2.0e10, "droplet_diameter": 60e-6},
        method={"name": "qmom", "nodes": 2})
    mixed = run_well_mixed(mixed_scene)
    for name in ("M00", "M10", "M01", "M20", "M11", "droplet_number_density", "d43_m"):
        a = np.array([f[name][0] for f in coupled.cell_fields])
        b = mixed.columns[name]
        assert np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)) < 1e-12, name
    # the kernel really saw this cell's Theta and alpha: aggregation happened
    assert mixed.columns["M00"][-1] < mixed.columns["M00"][0]


def test_bed_run_conserves_binder_and_leaves_lean_cells_empty(snapshot):
    scene = short_fluid_bed()
    domain = load_domain(scene)
    res = run_coupled(scene, domain)
    active = snapshot.alpha >= scene.domain.alpha_min
    assert 0 < active.sum() < snapshot.n_cells
    last = res.cell_fields[-1]
    for name in ("M00", "M10", "M01", "M20", "d43_m"):
        assert np.all(last[name][~active] == 0.0), name
        assert np.all(np.isfinite(last[name]))
    assert np.all(last["M00"][active] > 0)
    # injected binder mass: rate x volume of spray cells x time x droplet mass
    spray = last["spray_zone"] > 0
    assert spray.sum() > 0
    pd = droplet_mass(60e-6, 1000.0)
    injected = 2.0e10 * np.sum(snapshot.cell_volume[spray]) * res.times * pd
    bed_binder = res.bed_columns["bed_binder_mass_kg"]
    assert bed_binder[0] == 0.0
    assert np.max(np.abs(bed_binder[1:] - injected[1:]) / injected[1:]) < 1e-10
    # binder only where it was sprayed (no transport in this scene)
    assert np.all(last["M01"][active & ~spray] == 0.0)
    assert np.all(last["M01"][spray] > 0.0)
    # total solids mass grows by exactly the injected binder
    mass = res.bed_columns["bed_mass_kg"]
    assert np.max(np.abs(mass - mass[0] - injected) / mass) < 1e-12


def test_vtk_series_opens_in_pyvista_with_finite_fields(tmp_path, snapshot):
    pv = pytest.importorskip("pyvista")
    scene = short_fluid_bed(end=5.0, interval=5.0)
    domain = load_domain(scene)
    res = run_coupled(scene, domain)
    write_coupled(tmp_path, domain, res, render=False)
    reader = pv.get_reader(str(tmp_path / "vtk" / "pbe.pvd"))
    assert len(reader.time_values) == 2
    reader.set_active_time_value(reader.time_values[-1])
    mesh = reader.read()[0]
    assert mesh.n_cells == snapshot.n_cells
    for name in ("alpha", "Theta", "M00", "M10", "M01", "d32_m", "d43_m", "binder_fraction"):
        values = np.asarray(mesh.cell_data[name])
        assert values.shape == (snapshot.n_cells,)
        assert np.all(np.isfinite(values)), name
    bed = np.genfromtxt(tmp_path / "bed_moments.csv", delimiter=",", names=True)
    assert bed["time_s"][-1] == pytest.approx(5.0, rel=1e-12, abs=0)
