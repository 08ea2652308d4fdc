"""Outputs streamed to disk per output time (``io.spool.Spool``): items come back bitwise, the
client holds one output time at a time, the spool's directory is the program's own and goes
away; and the run's result reads the same fields from its spool."""
import tracemalloc

import numpy as np

from pbe_cfd.io.spool import Spool


def test_items_round_trip_bitwise_and_directory_removed():
    rng = np.random.default_rng(7)
    spool = Spool()
    items = [{"M00": rng.standard_normal(50), "active": (rng.random(50) > 0.5).astype(float)}
             for _ in range(4)]
    states = [rng.standard_normal((30, 7)) for _ in range(4)]
    hist = Spool()
    for it, st in zip(items, states):
        spool.append(it)
        hist.append(st)
        st[...] = 0.0               # the spool keeps what was appended, not a view of it
    assert len(spool) == 4 and len(hist) == 4
    for k in range(4):
        got = spool[k]
        assert list(got) == ["M00", "active"]
        assert all(np.array_equal(got[n], items[k][n]) for n in got)
    assert np.array_equal(spool[-1]["M00"], items[-1]["M00"])
    assert [np.asarray(h).shape for h in hist] == [(30, 7)] * 4
    assert not np.any(hist[2] == 0.0)
    path = spool.path
    assert path.is_dir()
    spool.close()
    assert not path.exists()


def test_memory_holds_one_output_time():
    """13 output times of a 1e5-cell field set: the bytes held at the peak are those of one
    output time (what is being written or read), not 13 of them."""
    n, n_fields, n_times = 100_000, 10, 13
    one = n * n_fields * 8
    spool = Spool()
    tracemalloc.start()
    try:
        for k in range(n_times):
            spool.append({f"f{j}": np.full(n, float(k + j)) for j in range(n_fields)})
        total = 0.0
        for fields in spool:
            total += float(fields["f0"][0])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert total == sum(range(n_times))
    assert spool.nbytes == n_times * one
    # at most two output times alive (the one read and the next being built) plus slack
    assert peak < 2.5 * one, (peak, one)
