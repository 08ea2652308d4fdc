"""The transport's substeps into two buffers (pbe_cfd.transport.substeps): bitwise the k
products B @ S that scipy computes, and no fresh array per substep (counted as the page
faults of the process under a Dask worker's malloc setting, not timed)."""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import scipy.sparse as sp

from pbe_cfd.transport import substeps
from pbe_cfd.transport.substeps import apply_substeps


def _step_matrix(m, rng, index_dtype):
    """A random row-substochastic upwind-like B = I + dt L (nonnegative, unsorted within
    no row), with the given index dtype."""
    offsets = [0, 1, -1, 7, -7, 31]
    mat = sp.diags([rng.uniform(0.0, 0.2, m - abs(o)) for o in offsets], offsets,
                   format="csr")
    mat.indices = mat.indices.astype(index_dtype)
    mat.indptr = mat.indptr.astype(index_dtype)
    return mat


def _products(mat, states, k):
    work = np.ascontiguousarray(states)
    for _ in range(k):
        work = mat @ work
    return work


@pytest.mark.parametrize("k", [1, 2, 5])
@pytest.mark.parametrize("n_state", [1, 7])
@pytest.mark.parametrize("index_dtype", [np.int32, np.int64])
def test_substeps_are_bitwise_the_scipy_products(k, n_state, index_dtype):
    rng = np.random.default_rng(11)
    mat = _step_matrix(400, rng, index_dtype)
    states = rng.uniform(-1.0, 2.0, size=(400, n_state))
    got = apply_substeps(mat, states, k)
    assert got.flags.c_contiguous and got.shape == states.shape
    assert np.array_equal(got, _products(mat, states, k))
    assert not np.shares_memory(got, states)


def test_zero_substeps_copy_and_fallback_agree(monkeypatch):
    rng = np.random.default_rng(12)
    mat = _step_matrix(200, rng, np.int32)
    states = rng.uniform(0.0, 1.0, size=(200, 3))
    same = apply_substeps(mat, states, 0)
    assert np.array_equal(same, states) and not np.shares_memory(same, states)
    fast = apply_substeps(mat, states, 4)
    monkeypatch.setattr(substeps, "_csr_matvecs", None)
    assert np.array_equal(apply_substeps(mat, states, 4), fast)


def test_a_wrong_size_step_matrix_is_refused():
    mat = sp.identity(5, format="csr")
    with pytest.raises(ValueError, match="step matrix"):
        apply_substeps(mat, np.ones((4, 2)), 1)


_FAULTS = textwrap.dedent("""
    import resource, sys
    import numpy as np, scipy.sparse as sp
    from pbe_cfd.transport.substeps import apply_substeps
    m, k = 60000, 40
    mat = sp.diags([np.full(m, 0.5), np.full(m - 1, 0.25)], [0, 1], format="csr")
    states = np.ones((m, 7))
    def faults():
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    apply_substeps(mat, states, 1)
    f0 = faults(); apply_substeps(mat, states, k); f1 = faults()
    work = states
    for _ in range(k):
        work = mat @ work
    f2 = faults()
    print(f1 - f0, f2 - f1)
""")


def test_the_substeps_do_not_map_a_fresh_array_per_substep():
    """Under glibc's trim threshold a Dask nanny sets, every (60000, 7) product maps fresh
    pages (3.4 MB: ~820 faults of 4 kB each); the buffered substeps fault on their two
    buffers at most, whatever k."""
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")
    out = subprocess.run([sys.executable, "-c", _FAULTS], env=env, capture_output=True,
                         text=True, check=True)
    buffered, products = (int(x) for x in out.stdout.split())
    pages = 60000 * 7 * 8 // 4096
    assert products >= 20 * pages          # the effect exists where the test runs
    assert buffered <= 3 * pages           # two buffers and the input copy, not k arrays
