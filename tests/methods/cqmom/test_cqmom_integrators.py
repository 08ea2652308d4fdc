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


def test_sharp_step_where_no_pair_is_near_it_costs_nothing_and_changes_nothing():
    """The seed scene with N1 = N2 = 3, 600 s: no pair of points comes within a few switch
    widths of St* (any width 0.002-0.01 gives the same run), so the sharp step must give the
    smooth switch's moments within both runs' error bounds (tests/error_bounds.py) and hardly
    ever mark a step as crossing. Each size node's points are held in binder-fraction order
    (methods.cqmom.cqmom._sort_points); listed in the inversion's own order, stages that
    listed them otherwise marked 201,646 steps as crossing and moved M00 by 0.3%."""
    base = load_scene("study-seed").with_method(name="cqmom", nodes=3, binder_nodes=3)
    runs = {}
    for width in (0.0, 0.005):
        material = dataclasses.replace(base.material, stokes_switch_width=width)
        runs[width] = run_well_mixed(dataclasses.replace(base, material=material))
    sharp, smooth = runs[0.0].columns, runs[0.005].columns
    for key in ("M00", "M20", "M11", "M02", "M30", "M03"):
        bound = 2.0 * error_bound(base.method.rtol, smooth[key])
        assert relative(sharp[key], smooth[key]) < bound, key
    # a step is marked crossing only where a stage's own decision differs: 4 here (201,646
    # with the points unordered); 100 is two orders of magnitude from both
    assert runs[0.0].stats["stokes_switch_steps"] < 100
