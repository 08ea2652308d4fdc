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


def _bed_mixtures(times, rows, seed):
    """One bed mixture (``reconstruct.Mixture``) per output time of random two-node rows
    (granule masses 1e-9 kg x [0.3, 3], weights 1e9 / m3 x [0.1, 2]) on random cell
    volumes [m3], the spread of the nodes growing with the time index."""
    from pbe_cfd.distribution import kernel_mixture as KM
    from pbe_cfd.distribution.reconstruct import Mixture
    rng = np.random.default_rng(seed)
    out = []
    for k in range(times):
        pops = []
        for _ in range(rows):
            p = 1e-9 * np.sort(rng.uniform(0.3, 3.0 * (1 + k), 2))
            pops.append((1e9 * rng.uniform(0.1, 2.0, 2), p, 0.1 * p))
        recon = KM.of_nodes(pops, 1500.0, True)
        out.append(Mixture(recon, recon.mass * rng.uniform(1e-6, 2e-6, rows)))
    return out


def test_object_items_come_back_equal_and_the_bed_distribution_is_the_same():
    """The bed's mixtures of a coupled run are spooled as objects: the Stack over the spool
    gives bitwise the percentiles, Q3 and class binder of the Stack over the list."""
    from pbe_cfd.distribution.reconstruct import Stack
    mixtures = _bed_mixtures(4, 60, 3)
    spool = Spool()
    for m in mixtures:
        spool.append(m)
    assert len(spool) == 4 and spool.nbytes > 0
    assert sorted(p.suffix for p in spool.path.iterdir()) == [".pkl"] * 4
    listed, spooled = Stack(mixtures), Stack(spool)
    assert spooled.items is spool                      # read one item at a time, not copied
    assert np.array_equal(listed.mass, spooled.mass) and listed.notes == spooled.notes
    d = np.geomspace(1e-5, 5e-3, 40)
    assert np.array_equal(listed.cdf(d), spooled.cdf(d))
    f = np.array([0.1, 0.5, 0.9])
    assert np.array_equal(listed.quantiles(f), spooled.quantiles(f))
    lo, hi = d[:-1], d[1:]
    assert np.array_equal(listed.class_binder(lo, hi), spooled.class_binder(lo, hi))
    path = spool.path
    spool.close()
    assert not path.exists()


def test_spooled_mixtures_hold_one_output_time():
    """13 output times of 2e4-row bed mixtures: the bytes alive at the peak while they are
    appended and read back are those of about one output time's mixture, not 13."""
    from pbe_cfd.distribution.reconstruct import Stack
    template = _bed_mixtures(1, 20_000, 5)[0]
    tracemalloc.start()
    try:
        spool = Spool()
        base, _ = tracemalloc.get_traced_memory()
        for k in range(13):
            spool.append(template)
        stack = Stack(spool)
        total = float(stack.mass.sum())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    one = spool.nbytes / 13
    assert total == 13 * float(template.mass[0])
    assert peak - base < 2.5 * one, (peak - base, one)
