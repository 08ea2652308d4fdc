"""The Laguerre ROM's drying drift (docs/physics.md section 15, "Laguerre ROM") on one
sprayed, drying cell of ``fluid-bed-batch`` (scripts/laguerre-drying-cell.toml: a 10% solution
sprayed onto dry granules, droplets as ordinary particles, inlet air).

A linear operator on the signed reconstruction stopped this cell on the step floor (at 0.74 s;
bounded by one evaporation factor, at 1.128 s, its drift lowering wet M20 below W10^2 / W00).
The drift on the state's own points vanishes with the liquid, keeps M10 + E, M01 + E and the
binder solids M10 - M01 exact, and keeps the wet class's second moments realizable; the
sprayed liquid is the schedule's closed form R t p_d (1 - s).
"""
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from pbe_cfd.scene.scene import load_scene

CELL = Path(__file__).resolve().parents[3] / "scripts" / "laguerre-drying-cell.toml"
END = 2.0          # s: the scene's end, past the bounded linear operator's stop at 1.128 s


def _scene(end):
    return dataclasses.replace(load_scene(str(CELL)), end_time=end, output_interval=0.05)


def _drying_rhs(state, problem, batch):
    """The drying part of the ROM's RHS at a state [scaled units per s]: DRYING on minus off."""
    from pbe_cfd.methods.entry import WORK_SIZE
    from pbe_cfd.methods.laguerre.rhs import laguerre_rhs
    from pbe_cfd.physics import parameters as P
    aux, config = problem.aux, problem.arrays.config
    cell = np.ascontiguousarray(problem.rows[0], dtype=float)
    params = np.ascontiguousarray(batch.params, dtype=float)
    off = config.copy()
    off[P.DRYING] = 0
    out_on, out_off = np.zeros(len(state)), np.zeros(len(state))
    laguerre_rhs(state, out_on, cell, aux, params, config, np.empty(WORK_SIZE))
    laguerre_rhs(state, out_off, cell, aux, params, off, np.empty(WORK_SIZE))
    return out_on - out_off


@pytest.mark.slow
def test_drift_vanishes_with_the_liquid_and_keeps_the_invariants():
    """At the state of 0.5 s (wet by the spray): the drift's dM10 = dM01 = -dE (round-off of
    K terms, 1e-12 of dE); with the wet liquid M01 set to 0 it is zero in every entry."""
    from pbe_cfd.runs.batch import CellBatch
    from pbe_cfd.runs.problem import problem_of
    problem = problem_of(_scene(0.5))
    batch = CellBatch.for_problem(problem)
    batch.step(0.0, 0.5)
    state = batch.states[0].copy()
    names = list(problem.arrays.state_names)
    m10, m01, e = (names.index(n) for n in ("wet_M10", "wet_M01", "evaporated_liquid"))
    d = _drying_rhs(state, problem, batch)
    assert d[e] > 0.0
    assert d[m10] == pytest.approx(-d[e], rel=1e-12, abs=0.0)
    assert d[m01] == pytest.approx(-d[e], rel=1e-12, abs=0.0)
    dry = state.copy()
    dry[m01] = 0.0
    assert np.all(_drying_rhs(dry, problem, batch) == 0.0)


@pytest.mark.slow
def test_sprayed_drying_cell_runs_to_its_end_realizable():
    """To 2 s: M01 >= 0 at every output; M01 + E = R t p_d (1 - s) (the integrator keeps it
    to the step control's round-off, 1e-8 relative); M10 - M01 = R t p_d s to 1e-10; the wet
    class's W10^2 <= W00 W20, W01^2 <= W00 W02 and W02 <= W11 <= W20 (b <= p) at every output
    (slack 1e-10 of the larger side: the ROM's own admissibility check's relative slack)."""
    from pbe_cfd.runs.simulate import run_well_mixed
    scene = _scene(END)
    c = run_well_mixed(scene).columns
    t = np.asarray(c["time_s"])
    assert t[-1] == pytest.approx(END, abs=1e-12)
    inj = scene.binder_injection
    rate = inj.schedule[0][1]                                   # 1/(m3 s), until 1200 s
    p_d = scene.material.binder_density * math.pi / 6.0 * inj.droplet_diameter ** 3
    s = inj.solids_fraction
    liquid = rate * t * p_d * (1.0 - s)
    assert np.all(np.asarray(c["M01"]) >= 0.0)
    assert np.allclose(c["M01"] + c["liquid_evaporated"], liquid, rtol=1e-8,
                       atol=1e-8 * liquid[-1])
    m10_0 = c["M10"][0]
    assert np.allclose(c["M10"] - c["M01"] - m10_0, rate * t * p_d * s, rtol=1e-10,
                       atol=1e-10 * m10_0)
    w00, w10, w20 = (np.asarray(c[n]) - np.asarray(c["dry_" + n]) for n in ("M00", "M10", "M20"))
    w01, w11, w02 = (np.asarray(c[n]) for n in ("M01", "M11", "M02"))
    slack = 1e-10
    assert np.all(w10 ** 2 <= w00 * w20 * (1.0 + slack))
    assert np.all(w01 ** 2 <= w00 * w02 * (1.0 + slack))
    assert np.all(w02 <= w11 * (1.0 + slack)) and np.all(w11 <= w20 * (1.0 + slack))


def test_the_points_of_a_last_trace_of_liquid_are_one_point():
    """A wet class that has dried to a trace of liquid (W01 = 1e-159 of W10; the bed batch
    reaches it ~350 s into its drying) and whose carried W02 lies a little below W01^2 / W00:
    the half-width of the liquid pair, 1e-3 of the liquid, squares to 0 in floating point.
    Its points are the class's mass node with the liquid at one point, weights W00, liquid
    W01 (no division by the squared half-width: inside the integrator that raised a
    ZeroDivisionError that numba's function pointers cannot pass on, and the RHS went on with
    what it had)."""
    from pbe_cfd.methods.laguerre.drying import N_POINTS, _point, wet_points
    m = 3
    state = np.zeros(m * m + m)
    state[0], state[m], state[2 * m] = 1.0, 0.6, 0.36          # one mass, 0.6 (scaled)
    state[1], state[2] = 1e-159, 0.5e-318                        # W01, W02 < W01^2 / W00
    state[m + 1], state[m + 2] = 0.6e-159, 0.3e-318
    pts = wet_points(state, m)
    points = [_point(q, pts) for q in range(N_POINTS)]
    assert sum(w for _, _, w in points) == 1.0
    assert sum(w * b for _, b, w in points) == 1e-159
    assert all(x == pytest.approx(0.6, rel=1e-15, abs=0) for x, _, w in points if w != 0.0)
