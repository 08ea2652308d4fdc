"""The shared bounds and references of tests/error_bounds.py against known answers."""
import numpy as np

from error_bounds import aggregation_moments, error_bound, hankel_realizable


def test_the_helpers_know_a_realizable_set_from_a_dented_one():
    """Two atoms are realizable (Hankel singular beyond n = 2, positive up to it); raising
    M2 by 1% above the two-atom value keeps it realizable, lowering it below M1^2 / M0 does
    not (Cauchy-Schwarz)."""
    x, w = np.array([1.0, 3.0]), np.array([2.0, 1.0])
    m = np.array([np.sum(w * x ** k) for k in range(4)])
    assert hankel_realizable(m)
    dented = m.copy()
    dented[2] = 0.99 * m[1] ** 2 / m[0]
    assert not hankel_realizable(dented)
    # the moment ODE: constant kernel M0 = 2 N0 / (2 + k0 N0 t), M1 constant, M2 linear
    t = np.linspace(0.0, 5.0, 6)
    ref = aggregation_moments("constant", 0.5, [1.0, 2.0, 5.0, 14.0], t)
    assert np.allclose(ref[0], 2.0 / (2.0 + 0.5 * t), rtol=1e-11, atol=0)
    assert np.allclose(ref[2], 5.0 + 0.5 * 4.0 * t, rtol=1e-11, atol=0)
    # sum kernel: M0 = N0 exp(-k0 M1 t), M2 = M2(0) exp(2 k0 M1 t)
    ref = aggregation_moments("sum", 0.5, [1.0, 2.0, 5.0, 14.0], t)
    assert np.allclose(ref[0], np.exp(-t), rtol=1e-11, atol=0)
    assert np.allclose(ref[2], 5.0 * np.exp(2.0 * t), rtol=1e-11, atol=0)


def test_the_bound_counts_the_reference_efolds_not_steps():
    assert error_bound(1e-8, np.ones(5)) == 10 * 1e-8
    assert error_bound(1e-8, np.exp(-np.linspace(0.0, 3.0, 7))) == 10 * 1e-8 * 4.0
