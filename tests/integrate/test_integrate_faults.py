"""An exception raised by the method's functions inside the integration kernel stops the cell
it came from, with the exception named, instead of leaving the cell with a partial
right-hand side (``integrate.faults``).

The method here is a decay dy/dt = -y of every scaled moment whose right-hand side raises a
ZeroDivisionError, before it writes anything, once y0 falls below 1/2 in the cells flagged by
their granular temperature: those cells would otherwise go on with stale rates and report
success."""
from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest

from pbe_cfd import integrate
from pbe_cfd.integrate import kernel_types
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.runs.problem import problem_of

from conftest import make_scene

FAKE_METHOD = 10_001          # method codes no registered method has
FAKE_TEST_RAISES = 10_002
RAISING_THETA = 5.0           # m2/s2: cells at or above it raise once y0 < 1/2


@nb.njit
def _decay_rhs(state, out, cell, aux, params, config, work):
    zero = 0.0
    if cell[P.THETA] >= RAISING_THETA and state[0] < 0.5:
        zero = 1.0 / zero     # ZeroDivisionError: nothing below is written
    for i in range(state.shape[0]):
        out[i] = -state[i] + zero


@nb.njit
def _realizable(state, aux, params, config, work):
    return True


@nb.njit
def _raising_realizable(state, aux, params, config, work):
    zero = 0.0
    if state[0] < 0.5:
        zero = 1.0 / zero
    return zero == 0.0


@nb.njit
def _project(state, aux, params, config, work):
    return None


@nb.njit
def _conserved(config, params, pivots, coefs):
    return 0


@pytest.fixture
def decay_method(monkeypatch):
    """The decay method under code FAKE_METHOD, on a packed constant-kernel scene."""
    real = kernel_types.functions_of

    def functions_of(method):
        if method == FAKE_METHOD:
            return kernel_types.MethodFunctions(_decay_rhs, _realizable, _project, _conserved)
        if method == FAKE_TEST_RAISES:
            return kernel_types.MethodFunctions(_decay_rhs, _raising_realizable, _project,
                                                _conserved)
        return real(method)
    monkeypatch.setattr(kernel_types, "functions_of", functions_of)
    scene = make_scene(scene={"end_time": 1.0, "output_interval": 1.0},
                       aggregation={"kernel": "constant", "rate": 1e-20},
                       method={"integrator": "explicit", "rtol": 1e-8})
    batch = CellBatch.for_problem(problem_of(scene))
    config = batch.config.copy()
    config[P.METHOD] = FAKE_METHOD
    return batch, config


@pytest.mark.parametrize("threads", [1, 2])
def test_a_cell_whose_rates_raise_stops_and_the_others_finish(decay_method, threads, capfd):
    """Four cells, the third flagged: it stops with METHOD_RAISED, at the start of the
    interval with its start state, and the message names the ZeroDivisionError; the other
    three end at exp(-1) to the tolerance's bound (10 rtol, for a global error of a few local
    ones), as they do when no cell raises; nothing is printed."""
    batch, config = decay_method
    n = 4
    states = np.ones((n, batch.states.shape[1]))
    rows = np.repeat(batch.rows[:1], n, axis=0)
    rows[:, P.THETA] = 0.1
    rows[2, P.THETA] = RAISING_THETA
    steps, reached = np.full(n, 1e-3), np.zeros(n)
    stats = np.zeros((n, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(n, dtype=np.int64)
    nb.set_num_threads(threads)
    try:
        integrate.integrate_cells(states, rows, batch.aux, batch.params, config, 0.0, 1.0,
                                  steps, 1e-8, 1e-14, 100_000, stats, status, reached)
    finally:
        nb.set_num_threads(nb.config.NUMBA_NUM_THREADS)
    assert status[2] == integrate.METHOD_RAISED
    assert reached[2] == 0.0 and np.all(states[2] == 1.0)
    assert np.all(stats[2] == 0) and steps[2] == 1e-3
    others = [0, 1, 3]
    assert np.all(status[others] == integrate.OK) and np.all(reached[others] == 1.0)
    assert np.max(np.abs(states[others] / math.exp(-1.0) - 1.0)) < 10 * 1e-8
    text = integrate.failure_reason(status[2], stats[2], batch.params, config)
    assert "raised ZeroDivisionError" in text
    captured = capfd.readouterr()
    assert "ZeroDivisionError" not in captured.err + captured.out


def test_a_realizability_test_that_raises_in_the_transport_repair_is_an_error(decay_method,
                                                                            capfd):
    """The transport's repair kernel calls the method's realizability test through the same
    entry points: one that raises is a MethodRaised naming the exception (exit 1 from the
    CLI), not a count of unrealizable cells made of whatever the test returned."""
    from pbe_cfd.integrate.faults import MethodRaised
    from pbe_cfd.transport.operator import cells_off_closure
    batch, config = decay_method
    config[P.METHOD] = FAKE_TEST_RAISES
    states = np.ones((3, batch.states.shape[1]))
    assert cells_off_closure(states, batch.aux, batch.params, config) == (0, 0.0)
    states[1, 0] = 0.25
    with pytest.raises(MethodRaised, match="ZeroDivisionError"):
        cells_off_closure(states, batch.aux, batch.params, config)
    captured = capfd.readouterr()
    assert "ZeroDivisionError" not in captured.err + captured.out
