"""The following weight's gamma shape in p follows the carried variance (docs/physics.md
section 9.2, ``[method] following_shape``, on by default with the following support).

Checked without running a case: the shape read from the carried moments, the closure of a
gamma population whose weight matches it (m = 3: the expansion is then the gamma itself, so
the reconstruction's M30 is the gamma's), and that M10 and M01 stay exact while the RHS blends
the four corners of the simplex in (c_m, y, lambda) that holds the state.
"""
import math

import numpy as np
import pytest
from scipy.special import gammaincc, gammaln

from pbe_cfd.methods.laguerre import rhs as L
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.methods.laguerre.layout import (AUX_COND_G, AUX_NWC, AUX_NWD, AUX_NWL, AUX_OFF_LOGW,
                                             N_CORNERS, carried_shape, weight_corner,
                                             weight_corners)
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs import model

from test_breakage import N0, P0, Y0, breakage_scene

#: the module's fixture builds the shape-axis tensors (about 12 s on a warm cache)
pytestmark = pytest.mark.slow


def scene(shape=True):
    method = {"name": "laguerre", "order": 3, "following_support": True,
              "following_shape": shape}
    return breakage_scene(method, {"selection": "power", "rate": 0.01, "exponent": 1.0,
                                   "daughters": "uniform"}, 10.0, outputs=2,
                          aggregation={"kernel": "sum", "rate": 0.05})


def gamma_moments(n, k, cm):
    """M_ij [kg^(i+j)/m3] of n granules (1/m3) with gamma masses of shape k and
    mass-weighted mean cm [kg], binder fraction Y0: n theta^s Gamma(k + s) / Gamma(k) Y0^j."""
    theta = cm / (k + 1.0)

    def mom(i, j):
        s = i + j
        return n * theta ** s * math.exp(gammaln(k + s) - gammaln(k)) * Y0 ** j
    return mom


@pytest.fixture(scope="module")
def built():
    sc = scene()
    arrays = model.pack(sc)
    return sc, arrays, LT.aux_for_scene(sc, arrays)


def grids(aux):
    o, nwc, nwd, nwl = (int(aux[s]) for s in (AUX_OFF_LOGW, AUX_NWC, AUX_NWD, AUX_NWL))
    return (np.exp(aux[o:o + nwc]), np.exp(aux[o + nwc:o + nwc + nwd]),
            np.exp(aux[o + nwc + nwd:o + nwc + nwd + nwl]))


def test_carried_shape_of_a_gamma_population():
    for k in (0.3, 1.0, 5.0):
        mom = gamma_moments(N0, k, 7.0 * P0)
        assert carried_shape(mom(0, 0), mom(1, 0), mom(2, 0)) == pytest.approx(k, rel=1e-12,
                                                                               abs=0)
    assert carried_shape(1.0, 2.0, 4.0) == math.inf          # a delta
    assert carried_shape(0.0, 2.0, 4.0) == 0.0


def test_the_shape_axis_is_built_and_blended(built):
    sc, arrays, aux = built
    cg, yg, lg = grids(aux)
    assert len(lg) >= 2 and lg[0] < 1.0 < lg[-1]
    # a state between two shapes blends both: the corners' shapes straddle the carried one
    k = math.sqrt(lg[1] * lg[2])
    state = LT.scene_initial_state(sc, arrays, gamma_moments(N0, k, 1.3 * cg[2]))
    corners = weight_corners(state, aux)
    nwc, nwd = len(cg), len(yg)
    shapes = {int(w // (nwc * nwd)) for w, _ in corners}
    assert shapes == {1, 2}
    assert sum(f for _, f in corners) == pytest.approx(1.0, rel=0, abs=1e-14)
    # without following_shape there is one shape (the fixed weight_shape_mass)
    fixed = LT.aux_for_scene(scene(False), arrays)
    assert int(fixed[AUX_NWL]) == 1


@pytest.mark.parametrize("k_index", [0, 2, 4])
def test_a_matching_gamma_is_reproduced_on_every_carried_moment(built, k_index):
    """On a grid point of (c_m, lambda) the blend is one shape; the reconstruction returns
    every carried moment M_ij (i, j < 3) to 100 eps cond(G)."""
    sc, arrays, aux = built
    cg, yg, lg = grids(aux)
    k, cm = lg[k_index], cg[3]
    mom = gamma_moments(N0, k, cm)
    state = LT.scene_initial_state(sc, arrays, mom)
    on_shape = sum(f for w, f in weight_corners(state, aux)
                   if int(w // (len(cg) * len(yg))) == k_index)
    assert on_shape == pytest.approx(1.0, rel=0, abs=1e-9)
    for i in range(3):
        for j in range(3):
            got = L.reconstructed_moment(state, aux, arrays.params, arrays.config, i, j)
            assert got == pytest.approx(mom(i, j), rel=1e-8, abs=0), (k, i, j)


@pytest.mark.parametrize("k_index", [0, 2, 3, 5, 8])
def test_the_closure_of_a_matching_gamma_is_the_gamma(built, k_index):
    """On a grid point of (c_m, lambda) the weight is the population's own gamma, so with
    m = 3 the exact expansion is the gamma itself and its M30 (the closure of S ~ p that the
    ROM does not carry) is the gamma's. The graded rule integrates u^k g exactly for k < 6
    (M30 of the expansion: u^3 times a quadratic), so what is left is the support: the
    consistent reconstruction puts the carried moments, those of the whole gamma, on
    p <= 8 c_m, and its M30 differs from the gamma's by less than the gamma's M30 beyond
    8 c_m (tail), plus the round-off 100 eps cond(G)."""
    sc, arrays, aux = built
    cg, yg, lg = grids(aux)
    k, cm = lg[k_index], cg[3]
    mom = gamma_moments(N0, k, cm)
    state = LT.scene_initial_state(sc, arrays, mom)
    tail = gammaincc(k + 3, 8.0 * (k + 1.0))         # the gamma's M3 beyond p <= 8 c_m
    got = L.reconstructed_moment(state, aux, arrays.params, arrays.config, 3, 0)
    rel = tail + 100 * np.finfo(float).eps * float(aux[AUX_COND_G])
    assert got == pytest.approx(mom(3, 0), rel=rel, abs=0), (k, got / mom(3, 0))


def test_mass_and_binder_rates_are_exactly_zero_over_a_full_simplex(built):
    """No droplets, no injection: the RHS's M10 and M01 rows are 0.0 for a state whose blend
    has all four corners of its simplex, each on another shape, mass and binder slice
    (aggregation rows D_a = 0 for i + j = 1, breakage F(1) = 1)."""
    sc, arrays, aux = built
    cg, yg, lg = grids(aux)
    state = LT.scene_initial_state(sc, arrays, gamma_moments(N0, math.sqrt(lg[2] * lg[3]),
                                                             1.4 * cg[3]))
    state[1] *= 1.3                      # binder fraction between two grid points as well
    state[4] *= 1.3
    state[7] *= 1.3
    assert len(weight_corners(state, aux)) == 4
    out = np.zeros_like(state)
    L.laguerre_rhs(state, out, np.zeros(P.N_CELL), aux, arrays.params, arrays.config)
    assert out[0] < 0.0 and out[6] != 0.0           # the other moments do move
    assert out[3] == 0.0 and out[1] == 0.0


def test_the_simplex_blend_is_exact_for_linear_functions():
    """weight_corner with a shape axis: four non-negative weights summing to one whose blend
    of the corners' grid coordinates is the point itself (exact for any function linear in
    the three logs), on random points, ties and faces; without it (il = -1) the bilinear
    weights (1 - t or t per axis, multiplied)."""
    rng = np.random.default_rng(26)
    nwc, nwd, nwl = 7, 5, 6
    for trial in range(500):
        ic, jd, il = (int(x) for x in rng.integers(0, (nwc - 1, nwd - 1, nwl - 1)))
        tc, td, tl = rng.random(3)
        if trial % 5 == 0:
            tl = 0.0                      # on a grid shape: a face of the cell
        if trial % 7 == 0:
            td = tc                       # a tie
        total, point = 0.0, np.zeros(3)
        for q in range(N_CORNERS):
            w, f = weight_corner(q, (ic, tc, jd, td, il, tl), nwc, nwd)
            assert f >= 0.0
            g, rest = divmod(w, nwc * nwd)
            total += f
            point += f * np.array([rest // nwd, rest % nwd, g])
        assert total == pytest.approx(1.0, rel=0, abs=4e-16)
        assert np.allclose(point, [ic + tc, jd + td, il + tl], rtol=0, atol=1e-13)
        bilinear = {(ic + a) * nwd + jd + b: (tc if a else 1 - tc) * (td if b else 1 - td)
                    for a in (0, 1) for b in (0, 1)}
        for q in range(N_CORNERS):
            w, f = weight_corner(q, (ic, tc, jd, td, -1, 0.0), nwc, nwd)
            assert f == bilinear[w]
