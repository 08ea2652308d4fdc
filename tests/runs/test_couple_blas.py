"""One OpenBLAS thread while a coupled run does its vector work (runs/blas): inside the block
every loaded OpenBLAS runs one thread, the previous counts come back after it (also on an
error), and a dot product computed either way agrees to round-off."""
import numpy as np
import pytest

from pbe_cfd.runs.blas import blas_thread_counts, blas_threads


def test_one_thread_inside_and_the_counts_restored():
    x = np.random.default_rng(3).random(100_000)
    before = blas_thread_counts()
    if not before:
        pytest.skip("no OpenBLAS loaded in this process")
    ref = float(x @ x)
    with blas_threads(1):
        assert blas_thread_counts() == [1] * len(before)
        one = float(x @ x)
    assert blas_thread_counts() == before
    # a different summation order at most: n * eps of the sum
    assert one == pytest.approx(ref, abs=x.size * np.finfo(float).eps * ref)
    with pytest.raises(RuntimeError):
        with blas_threads(1):
            raise RuntimeError("inside")
    assert blas_thread_counts() == before
