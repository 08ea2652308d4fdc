"""The cells shared between threads (``integrate.integrate_cells``): each thread integrates
every n-th cell, so every cell is integrated exactly once and its numbers are those of a
single thread."""
from __future__ import annotations

import dataclasses

import numba
import numpy as np

from pbe_cfd import integrate
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.runs.problem import problem_of
from pbe_cfd.scene.scene import load_scene


def _batch():
    """The bundled bed (fluid-bed: spray zone and dry cells), every active cell."""
    scene = dataclasses.replace(load_scene("fluid-bed"), end_time=2.0, output_interval=1.0)
    return CellBatch.for_problem(problem_of(scene, load_domain(scene)))


def _arrays(batch):
    """Fresh copies of what ``integrate_cells`` writes: states, steps, stats, status,
    reached."""
    return (batch.states.copy(), batch.steps.copy(), np.zeros_like(batch.stats_counts),
            np.zeros_like(batch.status), np.zeros_like(batch.reached))


def _run(batch, arrays, call):
    states, steps, stats, status, reached = arrays
    call(states, batch.rows, batch.aux, batch.params, batch.config, 0.0, 1.0, steps,
         batch.rtol, batch.atol, batch.max_steps, stats, status, reached)
    return arrays


def _equal(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def test_every_cell_once_whatever_the_share_of_the_threads():
    """The kernel's shares (rows k, k + s, k + 2 s, ...) for strides 1, 2 and 3, run one after
    the other: the same states, counters and times to the bit, and every cell reached the end
    of the interval (a cell integrated twice, or skipped, changes its state or its time)."""
    batch = _batch()
    method, scheme = int(batch.config[P.METHOD]), int(batch.config[P.INTEGRATOR])
    results = []
    for stride in (1, 2, 3):
        def shares(*args, stride=stride):
            share = integrate.kernel(method, scheme, args)
            for first in range(stride):
                share(first, stride)
        results.append(_run(batch, _arrays(batch), shares))
    one = results[0]
    assert np.all(one[3] == integrate.OK) and np.all(one[4] == 1.0)
    assert np.all(one[2][:, integrate.ACCEPTED] > 0)
    assert batch.n_cells > 100
    for other in results[1:]:
        assert _equal(one, other)


def test_two_threads_give_the_numbers_of_one():
    """``integrate_cells`` on one thread and on two (where the machine has two)."""
    batch = _batch()
    most = numba.config.NUMBA_NUM_THREADS
    try:
        numba.set_num_threads(1)
        one = _run(batch, _arrays(batch), integrate.integrate_cells)
        numba.set_num_threads(min(2, most))
        two = _run(batch, _arrays(batch), integrate.integrate_cells)
    finally:
        numba.set_num_threads(most)
    assert np.all(one[3] == integrate.OK)
    assert _equal(one, two)


def test_states_of_another_layout_are_integrated_and_written_back():
    """The method's functions take C-contiguous rows; Fortran-ordered states and cells (a
    column-major copy of the same numbers) run on a C-contiguous copy whose result is written
    back into the caller's array: the same numbers to the bit, and every cell moved."""
    batch = _batch()
    c_order = _run(batch, _arrays(batch), integrate.integrate_cells)
    arrays = list(_arrays(batch))
    arrays[0] = np.asfortranarray(arrays[0])
    rows = batch.rows
    batch.rows = np.asfortranarray(rows)
    try:
        f_order = _run(batch, tuple(arrays), integrate.integrate_cells)
    finally:
        batch.rows = rows
    assert not f_order[0].flags.c_contiguous and f_order[0] is arrays[0]
    assert np.all(f_order[3] == integrate.OK)
    assert np.all(np.any(f_order[0] != batch.states, axis=1))
    assert _equal(c_order, f_order)
