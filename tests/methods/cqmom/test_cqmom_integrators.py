"""CQMOM under the stiff-capable integrators (pbe_cfd.integrate): the linear invariants.

``cqmom_conserved`` hands the implicit (Rosenbrock) and auto schemes the rows of granule mass
M10 and binder mass M01 (each plus the free droplets' mass): the schemes keep c . state
exactly on those rows, so M10 and M01 must grow at exactly the injected droplet mass rate,
to 1e-10 relative (round-off of the scaled sums over ~1e3 steps; no truncation error enters
a linear invariant). The other moments must agree with the explicit pair within twice the
error bound of tests/error_bounds.py over the explicit run's curve.
"""
import dataclasses

import numpy as np
import pytest

from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.runs.simulate import run_well_mixed

from error_bounds import error_bound


def relative(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b)))


def with_integrator(scene, name):
    return dataclasses.replace(scene, method=dataclasses.replace(scene.method, integrator=name))


@pytest.mark.parametrize("integrator", ["implicit", "auto"])
def test_cqmom_keeps_mass_and_binder_exact(integrator):
    """Seed physics (EKE kernel, both success factors, droplets captured 100 times faster than
    granules meet, injection), N1 = N2 = 2, 60 s."""
    scene = load_scene("seed-wurster-cqmom")
    scene = dataclasses.replace(scene, end_time=60.0, output_interval=10.0)
    runs = {name: run_well_mixed(with_integrator(scene, name))
            for name in ("explicit", integrator)}
    c, t = runs[integrator].columns, runs[integrator].columns["time_s"]
    rate = scene.binder_injection.rate * droplet_mass(scene.binder_injection.droplet_diameter,
                                                      scene.material.binder_density)
    for key in ("M10", "M01"):
        assert relative(c[key], c[key][0] + rate * t) < 1e-10, key
    for key in ("M00", "M20", "M11", "M02"):
        # each scheme within error_bound of the truth (tests/error_bounds.py): they differ by
        # at most twice the bound of the explicit run's curve
        bound = 2.0 * error_bound(scene.method.rtol, runs["explicit"].columns[key])
        assert relative(c[key], runs["explicit"].columns[key]) < bound, key
