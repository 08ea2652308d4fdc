"""The kernel mixture's special functions in blocks of rows on the run's threads
(``distribution.kernel_mixture.row_blocks``): every number equal to the one-block evaluation,
so the size distribution of a run does not depend on its thread count; a forked child does
not wait on its parent's threads."""
import numba
import numpy as np
import pytest

from pbe_cfd.distribution import kernel_mixture as K


def _mixture(rows=3001, seed=20261205):
    """Random two-kernel rows (seed fixed): floors on half of them, every seventh a discrete
    fit (sigma = 0), every eleventh with its second kernel empty."""
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(1e-11, 1e-10, rows)
    sigma[::7] = 0.0
    x = rng.uniform(1e-10, 1e-8, (rows, 2))
    w = rng.uniform(0.1, 1.0, (rows, 2))
    w[::11, 1] = 0.0
    y = rng.uniform(0.0, 0.2, (rows, 2))
    floor = np.where(rng.random(rows) > 0.5, rng.uniform(1e-11, 1e-10, rows), 0.0)
    return K.KernelMixture.of_arrays(sigma, x, w, y, np.zeros(rows, int), 1000.0, True,
                                     ["ok"], floor=floor)


def _everything(threads, monkeypatch):
    monkeypatch.setattr(K, "BLOCK_ENTRIES", 1)
    numba.set_num_threads(threads)
    try:
        mix = _mixture()
        d = np.geomspace(1e-5, 1e-3, 41)
        return (mix.cdf(d), mix.quantiles([0.1, 0.5, 0.9]), mix.class_binder(d[:-1], d[1:]),
                *mix.kernel_quantiles([0.1, 0.5, 0.9]),
                mix.cdf(d[:3], rows=np.arange(0, 3001, 3)))
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_blocks_on_two_threads_give_the_one_block_numbers(monkeypatch):
    one = _everything(1, monkeypatch)
    two = _everything(2, monkeypatch)
    assert len(K.row_blocks(3001, 10)) == 2       # the blocks were used (monkeypatched size)
    for a, b in zip(one, two):
        assert a.shape == b.shape
        assert np.array_equal(a, b, equal_nan=True)
    # and the numbers are a distribution: Q3 rises from 0 towards 1 in every row
    q3 = two[0]
    assert np.all(np.diff(q3, axis=1) >= -1e-15) and np.all((q3 >= 0) & (q3 <= 1 + 1e-12))


def test_blocks_cover_the_rows_once():
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        for rows in (1, 2, 3, 1000, 100_001):
            blocks = K.row_blocks(rows, 10_000)
            covered = np.concatenate([np.arange(rows)[b] for b in blocks])
            assert np.array_equal(covered, np.arange(rows))
        assert K.row_blocks(10, 1) == [slice(0, 10)]      # below BLOCK_ENTRIES: one block
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


FORKED = """
import os, sys
import numpy as np
from pbe_cfd.distribution import kernel_mixture as K
K.BLOCK_ENTRIES = 1
rng = np.random.default_rng(0)
rows = 100
mix = K.KernelMixture.of_arrays(rng.uniform(1e-11, 1e-10, rows),
                                rng.uniform(1e-10, 1e-8, (rows, 1)), np.ones((rows, 1)),
                                np.zeros((rows, 1)), np.zeros(rows, int), 1000.0, False, ["ok"])
d = np.geomspace(1e-5, 1e-3, 5)
before = mix.cdf(d)
pid = os.fork()
if pid == 0:
    import signal
    signal.alarm(60)               # a child waiting on threads it does not have ends here
    os._exit(0 if np.array_equal(mix.cdf(d), before) else 3)
_, status = os.waitpid(pid, 0)
sys.exit(os.waitstatus_to_exitcode(status))
"""


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_a_forked_child_evaluates_in_blocks_of_its_own():
    """A process forked after the blocks ran (the drawing processes) inherits the thread pool
    without its threads: it makes its own instead of waiting on them for ever."""
    import subprocess
    import sys
    run = subprocess.run([sys.executable, "-c", FORKED], timeout=120, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr[-2000:]
