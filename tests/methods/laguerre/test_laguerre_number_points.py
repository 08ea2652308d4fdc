"""The Laguerre ROM's wet-wet aggregation rows of order 0 and 2 on the wet class's point
measure (``methods.laguerre.number_points``, ``[method] number_closure = "points"``).

Closed forms, independent of the ROM's tensors: for the constant, sum and product kernels the
rates of W00, W20, W11, W02 depend only on moments the point measure reproduces (W00, W10,
W20, W01, W11, W02):

    constant  -1/2 k W00^2,  k W10^2,        k W10 W01,              k W01^2
    sum       -k W00 W10,    2 k W20 W10,    k (W20 W01 + W11 W10),  2 k W11 W01
    product   -1/2 k W10^2,  k W20^2,        k W20 W11,              k W11^2

The measure's nodes and weights are sums of a few products and every pair term has one sign,
so the rates hold to a few ulps: 1e-13 relative. Red if a pair is counted twice, the diagonal
not halved, a gain's factor 2 lost, or the nodes' masses or liquids wrong.
"""

import math

import numpy as np
import pytest

from pbe_cfd.methods.laguerre.drying import gamma_nodes
from pbe_cfd.methods.laguerre.layout import AUX_HEADER, AUX_ORDER
from pbe_cfd.methods.laguerre.number_points import add_point_terms
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.kernels import CONSTANT, PRODUCT, SUM

from test_laguerre import setup

M = 3
K = M * M
REL = 1e-13


def _wet_state(params):
    """A scaled wet class of shape 0.6 in p (SI mean 2e-9 kg, 3e9 granules per m3) holding
    binder b = 0.3 p."""
    pref, nref = params[P.MASS_SCALE], params[P.NUMBER_SCALE]
    s = np.zeros(K + M)
    n, mean, shape, y = 3e9 / nref, 2e-9 / pref, 0.6, 0.3
    for i in range(M):
        for j in range(M):
            s[i * M + j] = (n * y ** j * math.gamma(shape + i + j) / math.gamma(shape)
                            * (mean / shape) ** (i + j))
    return s


@pytest.mark.parametrize("kernel", [CONSTANT, SUM, PRODUCT], ids=["constant", "sum", "product"])
def test_wet_pair_rates_are_the_closed_forms(kernel):
    params, config = setup(M, kernel=kernel)
    pref, nref = params[P.MASS_SCALE], params[P.NUMBER_SCALE]
    # the kernels read SI masses: k0 p_ref per mass in the sum kernel, k0 p_ref^2 in the product
    k = params[P.RATE] * nref * (pref if kernel == SUM else pref * pref if kernel == PRODUCT
                                 else 1.0)
    s = _wet_state(params)
    s[K:] = (5.0, 2.0, 1.0)              # a dry class does not enter the wet-wet rows
    aux = np.zeros(AUX_HEADER)
    aux[AUX_ORDER] = M
    cell = np.zeros(P.N_CELL)
    cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY] = 0.3, 1e-3, 0.1
    w00, w10, w20, w01, w11, w02 = s[0], s[M], s[2 * M], s[1], s[M + 1], s[2]
    want = {CONSTANT: (-0.5 * k * w00 * w00, k * w10 * w10, k * w10 * w01, k * w01 * w01),
            SUM: (-k * w00 * w10, 2 * k * w20 * w10, k * (w20 * w01 + w11 * w10),
                  2 * k * w11 * w01),
            PRODUCT: (-0.5 * k * w10 * w10, k * w20 * w20, k * w20 * w11, k * w11 * w11)}
    out = np.zeros(int(config[P.N_STATE]))
    add_point_terms(s, out, cell, aux, params, config, 0.0, 0.0, 0.0, 0.0, False)
    got = (out[0], out[2 * M], out[M + 1], out[2])
    for name, g, w in zip(("W00", "W20", "W11", "W02"), got, want[kernel]):
        assert g == pytest.approx(w, rel=REL, abs=0), name
    assert got[0] < 0.0 < min(got[1:])


def test_gamma_nodes_reproduce_three_moments_and_stay_positive():
    """The two-node rule: nodes and weights > 0, moments 0, 1, 2 reproduced (and the gamma's
    third, which closes it); one node at the mean for a variance below the threshold."""
    for shape in (0.05, 0.6, 2.0, 50.0):
        n, mean = 2.5, 3.0
        w = [n * math.gamma(shape + k) / math.gamma(shape) * (mean / shape) ** k
             for k in range(4)]
        x1, x2, a1, a2 = gamma_nodes(w[0], w[1], w[2], True)
        assert min(x1, x2, a1, a2) > 0.0
        for k in range(4):
            assert a1 * x1 ** k + a2 * x2 ** k == pytest.approx(w[k], rel=1e-13, abs=0), k
    x1, x2, a1, a2 = gamma_nodes(2.0, 6.0, 18.0 * (1 + 1e-10), True)
    assert (x1, a1, x2, a2) == (3.0, 2.0, 0.0, 0.0)


@pytest.mark.parametrize("kernel", [CONSTANT, SUM], ids=["constant", "sum"])
def test_the_rhs_takes_the_rows_of_order_0_and_2_from_the_points_and_nothing_else(kernel, tmp_path):
    """The ROM's RHS with number_closure = "points" against the tensors' own: every row but
    W00, W20, W11, W02 identical to the bit, and those four the closed forms, which the
    consistent tensors also give for these kernels (docs/physics.md 9: exact on any grid),
    within 100 eps cond(G) of the aux (the tensors' round-off,
    tests/methods/laguerre/test_laguerre.py). Red if the tensors' rows are not left out
    (counted twice) or another row is touched."""
    from pbe_cfd.methods.laguerre import rhs as L
    from pbe_cfd.methods.laguerre.layout import AUX_COND_G, AUX_NUMBER_POINTS
    from pbe_cfd.methods.laguerre.tensor import build_aux
    params, config = setup(M, kernel=kernel)
    aux = build_aux(params, config, M, weights=dict(c=1e-9, d=1e-9, lam=1.0, gam=0.2),
                    support=dict(p_max=1e-8, b_max=4e-9, n_p=10, n_b=10), consistent=True,
                    cache_dir=str(tmp_path))
    s = _wet_state(params)
    s[:K] *= 1e-3                        # a class well inside the support
    cell = np.zeros(P.N_CELL)
    out = {}
    for flag in (0.0, 1.0):
        a = aux.copy()
        a[AUX_NUMBER_POINTS] = flag
        out[flag] = np.zeros(int(config[P.N_STATE]))
        L.laguerre_rhs(s, out[flag], cell, a, params, config)
    tol = 100 * np.finfo(float).eps * aux[AUX_COND_G]
    points = [0, 2, M + 1, 2 * M]        # W00, W02, W11, W20
    others = [a for a in range(out[0.0].size) if a not in points]
    assert np.array_equal(out[0.0][others], out[1.0][others])
    for a in points:
        assert out[1.0][a] == pytest.approx(out[0.0][a], rel=tol, abs=0), a
    assert out[1.0][0] < 0.0


def test_points_with_order_2_is_refused_naming_the_key(scene_factory):
    """The rows of order 2 of an m = 2 class are W11 alone: "points" needs order >= 3."""
    from pbe_cfd.scene.scene import SceneError
    with pytest.raises(SceneError, match=r"\[method\.number_closure\].*order >= 3"):
        scene_factory(method={"name": "laguerre", "order": 2, "number_closure": "points",
                              "_replace": True})
    ok = scene_factory(method={"name": "laguerre", "order": 3, "number_closure": "points",
                               "_replace": True})
    assert ok.method.options.number_closure == "points"


def _dry_class(params, shape=4.0, n=2e9, mean=8e-10):
    """Scaled D0, D1, D2 of a gamma dry class (SI: n [1/m3], mean mass [kg])."""
    pref, nref = params[P.MASS_SCALE], params[P.NUMBER_SCALE]
    return [n / nref * math.gamma(shape + k) / math.gamma(shape) * (mean / pref / shape) ** k
            for k in range(M)]


def test_dry_wet_and_capture_rows_on_the_points_are_the_closed_forms_of_the_constant_kernel():
    """With the constant kernel k (scaled k0 N_ref) and a droplet-capture rate c = f k n_d
    (f the droplet factor, n_d scaled), every row the points give depends only on moments the
    two measures reproduce (dry D0..D2; wet W00, W10, W20, W01, W11, W02):

        D_e     -k D_e W00 - c D_e                            (dry-wet loss, dry capture)
        W00     -1/2 k W00^2 + c D0
        W10     k D1 W00 + c (D1 + x_d D0) + c x_d W00
        W01     c x_l D0 + c x_l W00
        W20     k W10^2 + k (D2 W00 + 2 D1 W10) + c (D2 + 2 x_d D1 + x_d^2 D0)
                + c (2 x_d W10 + x_d^2 W00)
        W11     k W10 W01 + k D1 W01 + c x_l (D1 + x_d D0) + c (x_l W10 + x_d W01 + x_d x_l W00)
        W02     k W01^2 + c x_l^2 D0 + c (2 x_l W01 + x_l^2 W00)
        W21, W12, W22   the dry capture's c x_l^j sum_e C(i, e) x_d^(i - e) D_e alone,

    droplets lost c (D0 + W00). Red if a pair or a capture is counted twice or not at all,
    the dry loss and wet gain disagree (mass), the droplet's liquid is not x_l, or a dry
    moment is not mapped to every wet row."""
    params, config = setup(M, kernel=CONSTANT, separate=True)
    pref, nref = params[P.MASS_SCALE], params[P.NUMBER_SCALE]
    k = params[P.RATE] * nref
    s = np.zeros(int(config[P.N_STATE]))
    s[:K] = _wet_state(params)[:K]
    s[K:K + M] = _dry_class(params)
    nd = 3e8 / nref
    pd, bd = 1.1e-10, 0.9e-10                # an evaporated droplet: liquid below its mass
    xd, xl = pd / pref, bd / pref
    c = params[P.DROPLET_FACTOR] * k * nd
    aux = np.zeros(AUX_HEADER)
    aux[AUX_ORDER] = M
    cell = np.zeros(P.N_CELL)
    cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY] = 0.3, 1e-3, 0.1
    out = np.zeros_like(s)
    lost = add_point_terms(s, out, cell, aux, params, config, 0.0, nd, pd, bd, True)
    w00, w10, w20, w01, w11, w02 = s[0], s[M], s[2 * M], s[1], s[M + 1], s[2]
    d0, d1, d2 = s[K:K + M]
    want = np.zeros_like(s)
    for e, de in enumerate((d0, d1, d2)):
        want[K + e] = -k * de * w00 - c * de
    want[0] = -0.5 * k * w00 ** 2 + c * d0
    want[M] = k * d1 * w00 + c * (d1 + xd * d0) + c * xd * w00
    want[1] = c * xl * d0 + c * xl * w00
    want[2 * M] = (k * w10 ** 2 + k * (d2 * w00 + 2 * d1 * w10)
                   + c * (d2 + 2 * xd * d1 + xd ** 2 * d0) + c * (2 * xd * w10 + xd ** 2 * w00))
    want[M + 1] = (k * w10 * w01 + k * d1 * w01 + c * xl * (d1 + xd * d0)
                   + c * (xl * w10 + xd * w01 + xd * xl * w00))
    want[2] = k * w01 ** 2 + c * xl ** 2 * d0 + c * (2 * xl * w01 + xl ** 2 * w00)
    for i in range(M):
        for j in range(M):
            if i + j > 2:
                want[i * M + j] = c * xl ** j * sum(math.comb(i, e) * xd ** (i - e) * de
                                                    for e, de in enumerate((d0, d1, d2))
                                                    if e <= i)
    for a in range(s.size):
        assert out[a] == pytest.approx(want[a], rel=REL, abs=0), a
    assert lost == pytest.approx(c * (d0 + w00), rel=REL, abs=0)
    # mass and liquid: what the dry class and the droplets lose, the wet class gains
    assert out[M] + out[K + 1] == pytest.approx(xd * lost, rel=1e-12, abs=0)
    assert out[1] == pytest.approx(xl * lost, rel=REL, abs=0)


def test_a_dry_class_at_one_mass_captures_into_a_wet_class_at_one_mass():
    """A dry class at one mass x (D0 D2 = D1^2) capturing droplets on its points gives the
    wet class gains of one point (x + x_d, x_l) whatever the kernel's dependence on mass, so
    a young wet class is born on the boundary W00 W20 = W10^2, not outside it (the tensors
    on the dry reconstruction gave L0 L2 / L1^2 = 0.78 with the ktgf kernel and the
    physical efficiency, docs/results/batch.md). Red if the dry loss moments are taken
    anywhere but at the class's mass."""
    from test_laguerre import seed_efficiency
    from pbe_cfd.physics.kernels import KTGF
    params, config = setup(M, kernel=KTGF, separate=True)
    seed_efficiency(params, config)
    pref, nref = params[P.MASS_SCALE], params[P.NUMBER_SCALE]
    s = np.zeros(int(config[P.N_STATE]))
    x = 5.4e-10 / pref
    s[K:K + M] = [7.5e11 / nref * x ** e for e in range(M)]
    nd = 1.5e9 / nref
    pd, bd = params[P.DROPLET_MASS], params[P.DROPLET_MASS]
    aux = np.zeros(AUX_HEADER)
    aux[AUX_ORDER] = M
    cell = np.zeros(P.N_CELL)
    cell[P.ALPHA], cell[P.THETA] = 0.32, 1.24e-4
    out = np.zeros_like(s)
    lost = add_point_terms(s, out, cell, aux, params, config, 1e-4, nd, pd, bd, True)
    assert lost > 0.0
    xd = pd / pref
    assert out[0] * out[2 * M] == pytest.approx(out[M] ** 2, rel=1e-13, abs=0)
    assert out[M] / out[0] == pytest.approx(x + xd, rel=1e-14, abs=0)
    for e in range(M):
        assert -out[K + e] == pytest.approx(lost * x ** e, rel=1e-14, abs=0)


def test_the_rhs_takes_the_cross_rows_from_the_points_once(tmp_path):
    """The ROM's RHS with number_closure = "points" against the tensors' own, with a dry class and free droplets: for the constant kernel
    both are exact (docs/physics.md 9: the consistent tensors on any grid; the points by the
    closed forms above), so every entry agrees within 100 eps cond(G) of the aux, the
    droplets lost included. Red if a tensor row the points give is not left out (counted
    twice), or one they do not give is left out."""
    from pbe_cfd.methods.laguerre import rhs as L
    from pbe_cfd.methods.laguerre.layout import AUX_COND_G, AUX_NUMBER_POINTS
    from pbe_cfd.methods.laguerre.tensor import build_aux
    params, config = setup(M, kernel=CONSTANT, separate=True)
    aux = build_aux(params, config, M, weights=dict(c=1e-9, d=1e-9, lam=1.0, gam=0.2),
                    support=dict(p_max=1e-8, b_max=4e-9, n_p=10, n_b=10), consistent=True,
                    cache_dir=str(tmp_path))
    s = np.zeros(int(config[P.N_STATE]))
    s[:K] = _wet_state(params)[:K] * 1e-3          # well inside the support
    s[K:K + M] = _dry_class(params)
    s[-1] = 3e8 / params[P.NUMBER_SCALE]
    cell = np.zeros(P.N_CELL)
    out = {}
    for flag in (0.0, 1.0):
        a = aux.copy()
        a[AUX_NUMBER_POINTS] = flag
        out[flag] = np.zeros(s.size)
        L.laguerre_rhs(s, out[flag], cell, a, params, config)
    tol = 100 * np.finfo(float).eps * aux[AUX_COND_G]
    for a in range(s.size):
        assert out[1.0][a] == pytest.approx(out[0.0][a], rel=tol, abs=0), a
    assert out[1.0][-1] < 0.0 and out[1.0][K] < 0.0


@pytest.mark.parametrize("every_row", [False, True], ids=["points", "points-all"])
def test_the_point_sums_hold_the_integrators_stokes_decisions(every_row):
    """Under the sharp viscous Stokes step the integrator hands the rates params extended by
    the switch memory (physics.parameters.HELD), and every pair of property rows keeps the
    decision it first took until the step ends (docs/physics.md 6.2). The point sums are such
    rates: with the memory empty they give the fresh sums to the bit and record a decision for
    every pair of points they evaluate; with every decision held at 0 (no pair sticks) every
    row of aggregation and capture is exactly 0 and the evaluation marks a crossing; held at
    1 the sums are those without the Stokes criterion. Red if the point sums evaluate the
    criterion anew (the held memory ignored)."""
    from test_laguerre import seed_efficiency
    params, config = setup(M, kernel=CONSTANT, separate=True)
    seed_efficiency(params, config)
    s = np.zeros(int(config[P.N_STATE]))
    s[:K] = _wet_state(params)[:K]
    s[K:K + M] = _dry_class(params)
    nd = 3e8 / params[P.NUMBER_SCALE]
    pd, bd = params[P.DROPLET_MASS], params[P.DROPLET_MASS]
    aux = np.zeros(AUX_HEADER)
    aux[AUX_ORDER] = M
    cell = np.zeros(P.N_CELL)
    cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY] = 0.3, 1e-3, 0.1

    def sums(p, cfg=config):
        out = np.zeros_like(s)
        lost = add_point_terms(s, out, cell, aux, p, cfg, 0.0, nd, pd, bd, True, every_row)
        return out, lost

    fresh, fresh_lost = sums(params)
    assert fresh_lost > 0.0 and np.any(fresh[:K] != 0.0)     # some pairs stick
    held = np.zeros(P.N_PARAMS_HELD)
    held[:P.N_PARAMS] = params
    held[P.STOKES_HOLD] = 1.0
    memory = held[P.STOKES_HELD:].reshape(P.HELD_ROWS, P.HELD_ROWS)
    memory[:] = -1.0
    first, first_lost = sums(held)
    assert np.array_equal(first, fresh) and first_lost == fresh_lost
    assert held[P.STOKES_CROSSED] == 0.0
    recorded = memory >= 0.0
    assert recorded.sum() >= 6 and np.all(memory[recorded] <= 1.0)   # the pairs of points
    assert np.any(memory[recorded] == 1.0)
    memory[recorded] = 0.0
    none, none_lost = sums(held)
    assert np.all(none == 0.0) and none_lost == 0.0
    assert held[P.STOKES_CROSSED] == 1.0
    memory[recorded] = 1.0
    held[P.STOKES_CROSSED] = 0.0
    every, every_lost = sums(held)
    plain = config.copy()
    plain[P.USE_PHYSICAL] = 0
    want, want_lost = sums(params, plain)
    assert np.array_equal(every, want) and every_lost == want_lost
