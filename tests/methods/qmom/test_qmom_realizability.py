"""QMOM's two state tests: what a step must keep (``qmom_realizable``: a moment set of some
population with 0 <= b <= p in every particle) and what a state needs to go without the
projection (``qmom_on_closure``: binder moments the clipped per-node binder reproduces),
docs/physics.md section 9.

The states are mixtures of monodisperse populations written out here, so every one is the
moment set of a real population with b <= p."""
import numpy as np

from pbe_cfd.methods.dispatch import WORK_SIZE
from pbe_cfd.methods.qmom.qmom import qmom_on_closure, qmom_project, qmom_realizable
from pbe_cfd.runs.model import pack

from conftest import make_scene

P0 = 1.0e-9      # kg
N0 = 1.0e10      # 1/m3


def _arrays(nodes):
    scene = make_scene(initial={"binder_fraction": 0.01}, method={"nodes": nodes})
    return pack(scene)


def _mixture(arrays, populations):
    """Scaled state of a sum of monodisperse populations (n [1/m3], p [kg], b [kg])."""
    out = np.zeros(len(arrays.state_names))
    for k, name in enumerate(arrays.state_names):
        if not (name.startswith("M") and len(name) == 3):
            continue
        i, j = int(name[1]), int(name[2])
        out[k] = sum(n * p ** i * b ** j for n, p, b in populations) / (
            arrays.number_scale * arrays.mass_scale ** (i + j))
    return out


def _tests(state, arrays):
    work = np.zeros(WORK_SIZE)
    aux = np.zeros(1)
    return (bool(qmom_realizable(state, aux, arrays.params, arrays.config, work)),
            bool(qmom_on_closure(state, aux, arrays.params, arrays.config, work)))


def test_binder_the_nodes_cannot_hold_is_realizable_and_off_the_closure():
    """Dry granules of P0 and 2 P0 with pure-binder granules of 3 P0: a real population (b <=
    p everywhere). Its 2-node quadrature (nodes near 1.18 P0 and 2.82 P0) must give the small
    node negative binder to reproduce M01 and M11 with all the binder at the largest size, so
    the per-node binder leaves [0, p_a]. A step may keep it; the projection moves M11 onto the
    clipped binder and keeps M00, M10 and M01, after which it is on the closure."""
    arrays = _arrays(2)
    names = arrays.state_names
    state = _mixture(arrays, [(N0, P0, 0.0), (N0, 2 * P0, 0.0), (N0, 3 * P0, 3 * P0)])
    assert _tests(state, arrays) == (True, False)
    projected = state.copy()
    qmom_project(projected, np.zeros(1), arrays.params, arrays.config, np.zeros(WORK_SIZE))
    keep = [names.index(k) for k in ("M00", "M10", "M01")]
    assert np.array_equal(projected[keep], state[keep])
    m11 = names.index("M11")
    assert projected[m11] != state[m11]
    assert _tests(projected, arrays) == (True, True)


def test_a_population_the_nodes_hold_passes_both_tests():
    """Two monodisperse populations are exactly a 2-node quadrature: its binder per node is
    theirs, within [0, p_a]."""
    arrays = _arrays(2)
    state = _mixture(arrays, [(N0, P0, 0.2 * P0), (0.5 * N0, 3 * P0, 0.9 * 3 * P0)])
    assert _tests(state, arrays) == (True, True)


def test_binder_past_its_bound_is_not_realizable():
    """b <= p in every particle gives 0 <= M_k1 <= M_(k+1)0; a state past either bound (M01
    below 0, M01 above M10, M11 above M20) is no population's and fails both tests."""
    arrays = _arrays(2)
    names = arrays.state_names
    state = _mixture(arrays, [(N0, P0, 0.5 * P0), (0.5 * N0, 3 * P0, 0.9 * 3 * P0)])
    for name, bound in (("M01", "M10"), ("M11", "M20")):
        bad = state.copy()
        bad[names.index(name)] = 1.01 * state[names.index(bound)]
        assert _tests(bad, arrays) == (False, False), name
    bad = state.copy()
    bad[names.index("M01")] = -1e-3 * state[names.index("M01")]
    assert _tests(bad, arrays) == (False, False)
