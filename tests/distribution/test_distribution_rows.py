"""The gamma fit of all rows' quadrature nodes at once (``kernel_mixture.of_nodes``) equals
the row-by-row loop (tests/references/of_nodes_loop.py) to round-off, row class by row class:
two distinct nodes (closed form), one node, an empty row, a node not finite, equal nodes, and
with a floor a row of no spread and a row whose mean is not above the floor; three-node rows
take the general fit in both.

Band: the closed form's sigma = (u2 - 1) mean loses digits as u2 - 1 -> 0; the rows here have
u2 - 1 >= 1e-3, so a few roundings of 1.1e-16 each are amplified at most 1e3-fold: rtol 1e-11.
Masses ~ P0 = 1e-9 kg (atol 1e-11 * P0), weights ~ 1e9 / m3 (atol 1e-11 * 1e9)."""
import numpy as np
import pytest

from pbe_cfd.distribution import kernel_mixture as KM
from pbe_cfd.distribution.reconstruct import DELTA_REL_VAR
from pbe_cfd.methods.quadrature import gamma_inversion as I
from references.of_nodes_loop import fit_rows

P0, N0, RTOL = 1.0e-9, 1.0e9, 1.0e-11


def _populations(seed, nodes, rows, floor):
    """Random node sets (masses P0 * [0.3, 3] above the floor, weights N0 * [0.1, 2]) and the
    special rows listed in the module docstring."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(rows):
        p = floor + P0 * np.sort(rng.uniform(0.3, 3.0, nodes))
        out.append((N0 * rng.uniform(0.1, 2.0, nodes), p, 0.1 * p))
    z = np.zeros(nodes)
    one = z.copy(); one[0] = 1.7 * P0 + floor
    out.append((np.where(one > 0, N0, 0.0), one, 0.1 * one))                 # one node
    out.append((z.copy(), z.copy(), z.copy()))                               # empty
    bad = floor + P0 * np.linspace(1.0, 2.0, nodes); bad[-1] = np.nan
    out.append((np.full(nodes, N0), bad, 0.1 * np.nan_to_num(bad)))          # not finite
    same = np.full(nodes, floor + 1.1 * P0)
    out.append((np.full(nodes, N0), same, 0.1 * same))                       # equal nodes
    flat = floor + P0 * (1.0 + 1.0e-7 * np.arange(nodes))
    out.append((np.full(nodes, N0), flat, 0.1 * flat))                       # no spread
    if floor > 0:
        low = floor * np.linspace(0.5, 0.9, nodes)
        out.append((np.full(nodes, N0), low, 0.1 * low))                     # mean below floor
    return out


def _reference(pops, floor):
    return fit_rows([w for w, _, _ in pops], [p for _, p, _ in pops], floor, DELTA_REL_VAR,
                    I.ROOT_TOLERANCE, (I.FIT, I.DISCRETE, I.FAILED),
                    lambda x, w, n: KM._fit_row(x, w, n))


@pytest.mark.parametrize("nodes", [2, 3])
@pytest.mark.parametrize("floor", [0.0, 0.4 * P0])
def test_all_rows_at_once_equal_the_row_loop(nodes, floor):
    pops = _populations(3 + nodes, nodes, 25, floor)
    mix = KM.of_nodes(pops, 1500.0, True, floor=floor)
    ref, floors, flags = _reference(pops, floor)
    assert mix.rows == len(ref)
    assert np.array_equal(mix.floor, floors)
    for r, (sigma, x, w, status) in enumerate(ref):
        k = x.size
        assert int(np.sum(mix.w[r] > 0)) == int(np.sum(w > 0)), r
        np.testing.assert_allclose(mix.sigma[r], sigma, rtol=RTOL, atol=RTOL * P0)
        np.testing.assert_allclose(mix.x[r, :k], x, rtol=RTOL, atol=RTOL * P0)
        np.testing.assert_allclose(mix.w[r, :k], w, rtol=RTOL, atol=RTOL * N0)
        assert not np.any(mix.w[r, k:])
    text = " ".join(mix.notes)
    assert (KM.NOT_FINITE in text) == bool(flags["bad"])
    assert (KM.BELOW_FLOOR in text) == bool(flags["below"])
    assert (KM.DELTA_FALLBACK in text) == bool(flags["delta"])
    assert bool(flags["bad"]) and (bool(flags["below"]) == (floor > 0))


@pytest.mark.parametrize("floor", [0.0, 0.4 * P0])
def test_the_distribution_of_all_rows_at_once_is_the_row_loops(floor):
    """Q3 of the fitted rows at the same diameters: the row loop's kernels through the same
    mixture class against the fit of all rows at once."""
    pops = _populations(17, 2, 40, floor)
    mix = KM.of_nodes(pops, 1500.0, False, floor=floor)
    ref, floors, _ = _reference(pops, floor)
    loop = KM.KernelMixture([(s, x, w, np.zeros(x.size), st) for s, x, w, st in ref], 1500.0,
                            False, I.STATUS_TEXT, floor=np.array(floors))
    d = np.geomspace(5e-5, 5e-3, 30)
    np.testing.assert_allclose(mix.cdf(d), loop.cdf(d), rtol=0.0, atol=1e-9)


def test_node_binder_groups_nodes_of_one_mass_as_a_pairwise_comparison_does():
    """``reconstruct.node_binder`` gives the nodes that share one mass (CQMOM's binder nodes
    of a size node) their group's mass-mean binder fraction. Against the definition written
    out pair by pair (sum over j with p_j == p_i), on rows with shared masses, a node of no
    weight, a negative weight and a zero mass: the masses, sorted, equal to the bit; the
    binder fractions of the weighted nodes to round-off (16 eps: the group sums are added in
    another order)."""
    from pbe_cfd.distribution.reconstruct import node_binder
    rng = np.random.default_rng(20261206)
    rows = []
    for _ in range(40):
        masses = rng.choice([1e-10, 2e-10, 5e-10, 1e-9], size=9)
        weights = rng.uniform(0.0, 1e9, 9)
        weights[rng.integers(9)] = 0.0
        weights[rng.integers(9)] = -1e8
        masses[rng.integers(9)] = 0.0
        rows.append((weights, masses, rng.uniform(0.0, 0.3, 9) * masses))
    x, y = node_binder(rows)
    for r, (w, p, b) in enumerate(rows):
        valid = (w > 0) & (p > 0)
        wv = np.where(valid, w, 0.0)
        expect_x = np.sort(np.where(valid, p, np.inf))
        mean = []
        for i in range(p.size):
            group = p == p[i]
            mass = np.sum(wv[group] * p[group])
            mean.append(np.sum(wv[group] * b[group]) / mass if mass > 0 else 0.0)
        order = np.argsort(np.where(valid, p, np.inf), kind="stable")[:valid.sum()]
        assert np.array_equal(x[r], expect_x)
        finite = np.isfinite(x[r])                 # the nodes of no weight last, at inf
        assert np.allclose(y[r][finite], np.array(mean)[order], rtol=16 * np.finfo(float).eps,
                           atol=0.0)
