"""The bed's psd.csv from one evaluation of its rows' Q3 (``reconstruct.Mixture.psd_rows``):
the Q3 and q3 columns equal to those of ``cdf`` (the same evaluation and sums), and the
classes' binder fraction within the bound its class edges allow: the mass of a class is now
taken between the edges psd.csv's q3 uses (``lo[0], hi``), where ``class_binder`` took
``[lo, hi]``, and lo[k] and hi[k - 1] are the same diameter to a few ulps. With the binder
fraction a mass-weighted mean of values in [0, 1], a change of every row's class mass by
dm_r moves it by at most sum_r |dm_r| / sum_r m_r."""
import numpy as np

from pbe_cfd.distribution import kernel_mixture as K
from pbe_cfd.distribution import reconstruct as R
from pbe_cfd.distribution import tables as T


class _Plain:
    """The same rows without ``psd_rows``: psd_columns takes ``cdf`` and ``class_binder``."""

    def __init__(self, stack):
        self.stack = stack
        self.empty, self.mass, self.rows, self.notes = (stack.empty, stack.mass, stack.rows,
                                                        stack.notes)

    def cdf(self, d):
        return self.stack.cdf(d)

    def class_binder(self, d_lo, d_hi):
        return self.stack.class_binder(d_lo, d_hi)


def _mixtures(seed=20261205, rows=400, times=3):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(times):
        sigma = rng.uniform(1e-11, 1e-10, rows)
        x = rng.uniform(1e-10, 1e-8, (rows, 2))
        w = rng.uniform(0.1, 1.0, (rows, 2))
        y = rng.uniform(0.0, 0.3, (rows, 2))
        floor = np.where(rng.random(rows) > 0.5, rng.uniform(1e-11, 1e-10, rows), 0.0)
        mix = K.KernelMixture.of_arrays(sigma, x, w, y, np.zeros(rows, int), 1000.0, True,
                                        ["ok"], floor=floor)
        out.append(R.Mixture(mix, mix.mass * rng.uniform(1e-6, 1e-5, rows)))
    return out


def test_bed_psd_of_one_evaluation():
    items = _mixtures()
    stack = R.Stack(items)
    times = np.arange(len(items), dtype=float)
    grid = T.auto_grid(stack)
    once, _ = T.psd_columns(times, stack, grid)
    plain, _ = T.psd_columns(times, _Plain(stack), grid)
    for name in ("d_m", "Q3", "q3_per_ln_d"):
        assert np.array_equal(once[name], plain[name]), name
    # the bound of the module docstring, per class and output time
    h = np.log(grid[1] / grid[0])
    lo, hi = grid * np.exp(-0.5 * h), grid * np.exp(0.5 * h)
    edges = np.concatenate([lo[:1], hi])
    bound = []
    for it in items:
        f_edges = it.parts.cdf(edges)
        f_lo, f_hi = it.parts.cdf(lo), it.parts.cdf(hi)
        moved = it.weights[:, None] * np.abs(f_edges[:, :-1] - f_lo)
        mass = it.weights[:, None] * (f_hi - f_lo)
        total = mass.sum(axis=0)
        bound.append(np.where(total > 0, moved.sum(axis=0) / np.where(total > 0, total, 1.0),
                              0.0))
    bound = np.concatenate(bound)
    diff = np.abs(once["binder_fraction"] - plain["binder_fraction"])
    assert np.all(diff <= bound + 4 * np.finfo(float).eps)
    assert np.any(once["binder_fraction"] > 0.05)       # the classes hold binder


def test_an_empty_mixture_gives_zeros():
    mix = _mixtures(times=1)[0]
    empty = R.Mixture(mix.parts, np.zeros(mix.parts.rows))
    d = np.geomspace(1e-5, 1e-3, 9)
    at, binder = empty.psd_rows(d, d[:-1], d[1:], np.arange(9))
    assert np.array_equal(at, np.zeros((1, 9))) and np.array_equal(binder, np.zeros((1, 8)))
