"""The seed scenario (seed 000 tables I-II, the bundled seed-wurster scenes) with a power
breakage added: S = s0 p / p0, s0 = 1e-3 1/s, uniform daughters. Over the 600 s a granule of
the mean size breaks about once (the number falls to 2.58e10 instead of 1.48e10 without
breakage), so breakage shapes the result.
The moment methods (QMOM N = 2, 3; Laguerre m = 3, 4) against the cNMC (10,000 particles x 8
replicas, seed fixed when the test was written): the closure within 10% of the truth where the
issue asks it (docs/physics.md section 8 and docs/results/breakage.md report what the methods
give on every moment and time). The cNMC mean is the truth only to its statistical error, so
the band at each output time is 10% plus t_{0.9995, R-1} standard errors of the reference mean (from its
reported 95% band; a false alarm rate of 1e-3 per comparison), relative to the mean.

These tests are about the closures only: the cNMC and the moment methods evaluate the same
kernel and efficiency functions (pbe_cfd.physics), so an error in a kernel would move both.
The kernels and the breakage selection and daughter rules are checked by their own hand
values, computed in plain Python from the formulas (tests/physics/test_physics_hand_values.py,
tests/physics/test_breakage_hand_values.py).

Why not every moment at every time: QMOM carries the binder only through M_k1, k < N (one
binder value per node), so M02 is an estimate of its quadrature. With breakage the dry granules
spread in size and share the nodes with the few wet aggregates; the binder fraction of a node
is then an average, and the steep accessible-binder sigmoid of that average underrates the
wet-wet aggregation. Measured for N = 2: M11 up to 18% off at 10-30 s, M02 up to 84% at 10 s
(without breakage: 12% and 36%, docs/results/seed-scenario.md), both within 10.5% at 600 s;
with a constant selection instead (breakage sources exact for the carried moments) the same
18% and 84%, so the deviation is the node-wise binder, not the breakage closure. The issue's 10% holds on
M00, M20 and d43 at every time: worst measured 5.6%, 9.8% (N = 3, at 130 s: tight) and 2.8%
against a 10,000 x 32 reference.
"""
import dataclasses
import math

import numpy as np
import pytest

from pbe_cfd.scene.scene import Breakage, load_scene
from pbe_cfd.runs.simulate import run_well_mixed

BREAKAGE = Breakage(selection="power", rate=1e-3, exponent=1.0, daughters="uniform")


def with_breakage(name, **method):
    scene = dataclasses.replace(load_scene(name), breakage=BREAKAGE)
    return scene.with_method(**method) if method else scene


@pytest.fixture(scope="module")
def reference():
    scene = with_breakage("seed-wurster-cnmc", particles=10000, replicas=8, seed=16007)
    res = run_well_mixed(scene)
    # breakage matters: 8,700 breaks per replica of 10,000 particles (measured), about one
    # per particle, while the number falls by a quarter through aggregation
    assert res.stats["events_breakage"] > 0.5 * 10000 * 8
    return res.columns


def deviation(columns, reference, name):
    return columns[name] / reference[name] - 1.0


CLOSURE = 0.10              # the requirement on the closure error


def band(reference, name, replicas=8):
    """CLOSURE plus t_{0.9995, R-1} standard errors of the cNMC mean, relative (per time)."""
    from scipy import stats
    se = (reference[name + "_hi"] - reference[name]) / stats.t.ppf(0.975, replicas - 1)
    return CLOSURE + stats.t.ppf(0.9995, replicas - 1) * se / np.abs(reference[name])


@pytest.mark.slow
@pytest.mark.parametrize("nodes", [2, 3])
def test_qmom_with_breakage_within_ten_percent_of_the_cnmc(reference, nodes):
    c = run_well_mixed(with_breakage("seed-wurster", nodes=nodes)).columns
    assert np.array_equal(c["time_s"], reference["time_s"])
    for name in ("M00", "M20", "d43_m"):
        assert np.all(np.abs(deviation(c, reference, name)) < band(reference, name)), name
    assert abs(deviation(c, reference, "M11")[-1]) < band(reference, "M11")[-1]
    # mass and binder: straight lines of the injected rate Q p_d, to 1e-10 (breakage adds
    # nothing to either)
    t = c["time_s"]
    rate = 1.485e8 * 1000.0 * math.pi / 6.0 * 60e-6 ** 3        # kg/(m3 s)
    for name in ("M10", "M01"):
        assert np.max(np.abs(c[name] / (c[name][0] + rate * t) - 1.0)) < 1e-10, name


@pytest.mark.slow
@pytest.mark.parametrize("order", [3, 4])
def test_laguerre_with_breakage_within_ten_percent_of_the_cnmc(reference, order):
    """The Laguerre ROM (seed-wurster-laguerre: dry class, adaptive weights, 20 x 20 nodes)
    with the same power breakage: every moment the cNMC reports (M00, M20, M11, M02) and d43
    within the issue's 10% at every output time (measured worst 3.6%, m = 4 M00 at 590 s);
    mass and binder exact as without breakage."""
    c = run_well_mixed(with_breakage("seed-wurster-laguerre", order=order)).columns
    assert np.array_equal(c["time_s"], reference["time_s"])
    for name in ("M00", "M20", "M11", "M02", "d43_m"):
        assert np.all(np.abs(deviation(c, reference, name)) < band(reference, name)), name
    t = c["time_s"]
    rate = 1.485e8 * 1000.0 * math.pi / 6.0 * 60e-6 ** 3        # kg/(m3 s)
    for name in ("M10", "M01"):
        assert np.max(np.abs(c[name] / (c[name][0] + rate * t) - 1.0)) < 1e-10, name
