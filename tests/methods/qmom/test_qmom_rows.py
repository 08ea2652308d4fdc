"""All cells' QMOM quadratures in one compiled pass equal the per-cell Python loop entry by
entry (the loop, ``quadrature_of`` per row as the output assembly ran it, is the reference).
Rows: random realizable two- and three-node states, a monodisperse row (one node), an empty
row, with and without binder."""
import numpy as np
import pytest

from pbe_cfd.methods.qmom.qmom import quadrature_of, quadrature_rows_of
from pbe_cfd.methods.registry import method_of
from pbe_cfd.runs import model
from pbe_cfd.scene.scene import load_scene


def _scene(nodes):
    scene = load_scene("fluid-bed-transport").with_method(nodes=nodes)
    assert scene.bivariate                              # the binder solve is exercised
    return scene


def _states(names, nodes, rows, seed):
    """Scaled states of random node sets (masses ~ 1, weights ~ 1, binder below the mass but
    in row 0, where the node-wise binder is clipped to the mass):
    M_ij = sum_a w_a p_a^i b_a^j; then one monodisperse row and one empty row."""
    rng = np.random.default_rng(seed)
    out = np.zeros((rows + 2, len(names)))
    for r in range(rows + 2):
        p = rng.uniform(0.2, 3.0, nodes) if r < rows + 1 else np.zeros(nodes)
        if r == rows:
            p[:] = 1.3                                  # one node
        w = rng.uniform(0.1, 2.0, nodes) * (r < rows + 1)
        b = p * (rng.uniform(0.0, 0.5, nodes) if r else 1.5)   # row 0: b > p, clipped
        for c, name in enumerate(names):
            if name.startswith("M"):
                i, j = int(name[1]), int(name[2])
                out[r, c] = np.sum(w * p ** i * b ** j)
    return out


@pytest.mark.parametrize("nodes", [2, 3])
def test_qmom_rows_equal_the_per_cell_quadrature(nodes):
    scene = _scene(nodes)
    arrays = model.pack(scene)
    states = _states(arrays.state_names, nodes, 40, seed=11 + nodes)
    x, w, b, counts = quadrature_rows_of(states, arrays.config)
    assert counts[-2] == 1 and counts[-1] == 0 and np.all(counts[:-2] == nodes)
    for r, state in enumerate(states):
        xr, wr, br = quadrature_of(state, arrays.config)
        n = counts[r]
        assert n == xr.size
        assert np.array_equal(x[r, :n], xr) and np.array_equal(w[r, :n], wr)
        assert np.array_equal(b[r, :n], br)
        assert not np.any(w[r, n:]) and not np.any(x[r, n:])


def test_the_output_columns_equal_those_of_the_per_cell_populations():
    scene = _scene(2)
    arrays = model.pack(scene)
    states = _states(arrays.state_names, 2, 30, seed=5)
    entry = method_of(scene)
    rows, padded = model._population_rows(entry, states, None, arrays)
    loop_rows, loop_padded = model._population_rows(entry._replace(populations=None), states,
                                                    None, arrays)
    assert padded is None and loop_padded is None        # one row of one node, one empty
    for (w, p, b), (wl, pl, bl) in zip(rows, loop_rows, strict=True):
        assert np.array_equal(w, wl) and np.array_equal(p, pl) and np.array_equal(b, bl)
    full, full_padded = model._population_rows(entry, states[:-2], None, arrays)
    loop_full = model._population_rows(entry._replace(populations=None), states[:-2], None,
                                       arrays)[1]
    for k in range(3):
        assert np.array_equal(full_padded[k], loop_full[k])
