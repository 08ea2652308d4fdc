"""EQMOM in a coupled run: the bundled fluid bed (OpenFOAM snapshot of the bundled case, ktgf
kernel, geometric + physical efficiency, droplets sprayed in the bed-surface zone) with
``[method] name = "eqmom"``, 10 s. Aggregation and droplet capture add masses and the
inversion's re-projection touches only M(2N)0, so the bed's solids mass grows by exactly the
injected binder (R p_d V_spray t, to 1e-10 like QMOM's run in tests/runs/test_couple.py);
the run reaches its end, and the bed's and the cells' d10/d50/d90 are present, ordered and
finite, with the columns.json labels naming the reconstruction: the bed starts monodisperse
and has no breakage, so the default ``size_distribution = "support"`` refits N gamma kernels
to EQMOM's carried M00 .. M(2N)0 of p - p_min on [p_min, inf) (docs/physics.md section 11.1)
instead of drawing EQMOM's own kernels on [0, inf)."""
import dataclasses
import json

import numpy as np
import pytest

from pbe_cfd.io.openfoam import load_snapshot
from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.runs.couple import run_coupled, write_coupled
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene


@pytest.mark.slow
def test_eqmom_coupled_bed_finishes_conserves_mass_and_writes_d50(tmp_path):
    scene = load_scene("fluid-bed").with_method(name="eqmom", nodes=2)
    scene = dataclasses.replace(scene, end_time=10.0, output_interval=5.0)
    domain = load_domain(scene)
    snapshot = load_snapshot()
    res = run_coupled(scene, domain)
    assert res.times[-1] == pytest.approx(10.0, rel=0, abs=1e-12)
    last = res.cell_fields[-1]
    spray = last["spray_zone"] > 0
    injected = (2.0e10 * np.sum(snapshot.cell_volume[spray]) * res.times
                * droplet_mass(60e-6, 1000.0))
    mass = res.bed_columns["bed_mass_kg"]
    assert np.max(np.abs(mass - mass[0] - injected) / mass) < 1e-10
    bed = res.bed_columns
    for name in ("d10_m", "d50_m", "d90_m"):
        assert np.all(np.isfinite(bed[name])) and np.all(bed[name] > 0), name
    assert np.all(bed["d10_m"] <= bed["d50_m"]) and np.all(bed["d50_m"] <= bed["d90_m"])
    active = last["M00"] > 0
    assert np.all(last["d50_m"][active] > 0) and np.all(last["d50_m"][~active] == 0)
    (tmp_path / "out").mkdir()
    write_coupled(tmp_path / "out", domain, res, render=False)
    labels = json.loads((tmp_path / "out" / "columns.json").read_text())
    for label in (labels["bed_moments.csv"]["d50_m"], labels["vtk cell fields"]["d50_m"]):
        assert "2 gamma kernels of one width refitted to the carried M00 .. M40" in label, label
        assert "on [p_min, inf)" in label and 'size_distribution = "support"' in label, label
