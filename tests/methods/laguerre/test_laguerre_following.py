"""The Laguerre ROM's following support ([method] following_support = true; docs/physics.md
section 9.2) on a case that broadens 10x in mass, against an independent reference.

Case (our choice, fixed before running): exponential start (N0 = 1e10 /m3, mean P0 = 1e-9 kg,
binder fraction y0 = 0.25 in every granule, no droplets), constant aggregation K = 1e-10 m3/s,
power-law breakage S = s0 p / P0 with s0 = 0.005 /s and uniform binary daughters, for 100 s.
The number density relaxes to sqrt(2 s0 M10 / (P0 K)) = N0 / 10: the mean mass grows 10x, past
the fixed support of table III (p_max = 1e-8 kg = 10 P0).

Closed forms used: M00 obeys the closed Riccati equation dM0/dt = -K/2 M0^2 + s0 M10 / P0 (the
breakage source of M00 is s0 M10 / P0, carried; the constant kernel's loss is K/2 M0^2), and
M10, M01 are invariant. The sectional reference (tests/references/sectional.py, numpy/scipy
only) is checked against the closed forms of pure power-law breakage and pure constant
aggregation below, and supplies M20 for the binder moments M_ij = y0^j M_(i+j),0 (b = y0 p for
every granule at all times: both processes keep the binder fraction).
"""
import math
import os
import sys

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.methods.laguerre import rhs as L
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.methods.laguerre.layout import AUX_FOLLOWING, weight_corners
from pbe_cfd.runs.simulate import run_well_mixed

from test_breakage import N0, P0, Y0, breakage_scene

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "references"))
import sectional  # noqa: E402

K_AGG = 1.0e-10          # m3/s
S0 = 0.005               # 1/s
END = 100.0              # s
EXACT = 1.0e-10          # M10, M01 (their rows are exactly zero)
# M00 closes (module doc): the integrator's 100 rtol (rtol 1e-8) bounds it
TOL = 1.0e-6


def riccati_m0(t):
    """Closed form of M00(t) [1/m3]: dM0/dt = K/2 (a^2 - M0^2), a^2 = 2 s0 M10 / (P0 K)."""
    a = math.sqrt(2.0 * S0 * N0 * P0 / (P0 * K_AGG))
    th = np.tanh(a * K_AGG * np.asarray(t, float) / 2.0)
    return a * (N0 + a * th) / (a + N0 * th)


def scene(following, order=3):
    method = {"name": "laguerre", "order": order}
    if following:
        method["following_support"] = True
    return breakage_scene(method, {"selection": "power", "rate": S0, "exponent": 1.0,
                                   "daughters": "uniform"}, END, outputs=4,
                          aggregation={"kernel": "constant", "rate": K_AGG})


@pytest.fixture(scope="module")
def reference():
    """(times, M_n(t) n <= 2) of the sectional reference on the case, 16 pivots per octave."""
    x = sectional.pivots(P0 * 1e-4, P0 * 3000.0, 16)
    t = np.linspace(0.0, END, 5)[1:]
    N = sectional.solve(x, sectional.initial_exponential(x, N0, P0), t, K_AGG, S0, 1.0, P0)
    # the grid holds the population: under 1e-3 of the mass on its top decade
    assert sectional.top_mass_share(x, N) < 1e-3
    return t, sectional.moments(x, N, 2)


# ---------------------------------------------------------------------------- the reference
def test_sectional_reference_against_closed_forms():
    """The reference itself: pure power-law breakage (M_n = N0 P0^n n! (1 + k P0 t)^(1 - n)),
    pure constant aggregation (M0 = 2 N0 / (2 + K N0 t), M2 = M2(0) + K M1^2 t) and the
    Riccati M0 of the case. Band 2e-3: the grid's own error on the initial exponential's
    moments (3e-4 in M2, 9e-4 in M3 at 16 pivots per octave) plus the 2e-5 loss below x_0."""
    x = sectional.pivots(P0 * 1e-4, P0 * 3000.0, 16)
    n_init = sectional.initial_exponential(x, N0, P0)
    t = np.array([5.0, 10.0])
    k = 0.1 / P0
    M = sectional.moments(x, sectional.solve(x, n_init, t, 0.0, 0.1, 1.0, P0), 3)
    exact = np.array([[N0 * P0 ** n * math.factorial(n) * (1 + k * P0 * tt) ** (1 - n)
                       for n in range(4)] for tt in t])
    assert np.max(np.abs(M / exact - 1.0)) < 2e-3
    M = sectional.moments(x, sectional.solve(x, n_init, t, K_AGG, 0.0, 1.0, P0), 2)
    assert np.max(np.abs(M[:, 0] / (2 * N0 / (2 + K_AGG * N0 * t)) - 1.0)) < 2e-3
    m2 = 2 * N0 * P0 ** 2 + K_AGG * (N0 * P0) ** 2 * t
    assert np.max(np.abs(M[:, 2] / m2 - 1.0)) < 2e-3


def test_reference_case_broadens_tenfold(reference):
    t, M = reference
    assert np.max(np.abs(M[:, 0] / riccati_m0(t) - 1.0)) < 2e-3
    assert M[-1, 1] / M[-1, 0] / P0 == pytest.approx(10.0, rel=0.01, abs=0)


# ---------------------------------------------------------------------------- the ROM
@pytest.mark.slow
def test_support_messages_name_the_keys():
    """A stop or warning for mass beyond the support names the [method] keys that set it: the
    fixed support's support_mass / support_binder (and the following support as the way out),
    the following support's following_growth (wet) and support_mass (dry)."""
    arrays = model.pack(scene(False))
    nn = N0 / 30.0                         # the case's population grown 30x: beyond p_max

    def mom(i, j):
        return nn * (30.0 * P0) ** (i + j) * math.factorial(i + j) * Y0 ** j

    for following, keys in ((False, ("support_mass", "support_binder", "following_support")),
                            (True, ("following_growth", "support_mass"))):
        sc = scene(following)
        aux = LT.aux_for_scene(sc, arrays)
        state = LT.scene_initial_state(sc, arrays, mom)
        hint = LT.failure_hint(state, aux, arrays)
        # the fixed support lost the grown population; the following support holds it, and
        # its stop message says the support was not the cause (naming the keys all the same)
        assert ("inside the Laguerre support" if following
                else "left the Laguerre support") in hint, hint
        assert all(k in hint for k in keys), hint
    fixed = LT.aux_for_scene(scene(False), arrays)
    share, text = LT.escaped_share_report(LT.scene_initial_state(scene(False), arrays, mom),
                                          fixed, arrays)
    assert share > 0.1 and "support_mass" in text and "following_support" in text


def test_a_too_small_support_key_is_named_by_key():
    """Binder beyond support_binder, mass inside support_mass (fixed support): the warning and
    the stop name support_binder as too small, with the share of the granule mass beyond it,
    and not support_mass. The population: exponential in p (mean P0), b = 0.9 p, so the mass
    share beyond b_max is that of p > b_max / 0.9 under the mass-weighted gamma of shape 2,
    (1 + x) exp(-x) at x = b_max / (0.9 P0); the mass share beyond p_max is (1 + x) exp(-x) at
    x = p_max / P0 (5e-4, under the warning's 0.1%)."""
    y = 0.9
    arrays = model.pack(scene(False))
    aux = LT.aux_for_scene(scene(False), arrays)

    def mom(i, j):
        return N0 * P0 ** (i + j) * math.factorial(i + j) * y ** j

    state = LT.scene_initial_state(scene(False), arrays, mom)
    parts = LT.escaped_mass_parts(state, aux, arrays.params, arrays.config)
    xb = float(aux[LT.AUX_B_MAX]) / (y * P0)
    xp = float(aux[LT.AUX_P_MAX]) / P0
    assert parts["support_binder"] == pytest.approx((1 + xb) * math.exp(-xb), rel=1e-9, abs=0)
    assert parts["support_mass"] == pytest.approx((1 + xp) * math.exp(-xp), rel=1e-9, abs=0)
    _, text = LT.escaped_share_report(state, aux, arrays)
    hint = LT.failure_hint(state, aux, arrays)
    for message in (text, hint):
        assert f"support_binder ({aux[LT.AUX_B_MAX]:.3g} kg) is too small: " \
               f"{parts['support_binder']:.1%}" in message, message
        assert "support_mass (" not in message, message
        assert "widen" not in message, message


def gamma_state(sc, arrays, c_m, shape, number=N0):
    """Scaled state of a wet gamma population in p (shape k, mass-weighted mean c_m [kg]),
    b = Y0 p: M_ij = N theta^(i+j) Gamma(k + i + j) / Gamma(k) Y0^j, theta = c_m / (k + 1)."""
    theta = c_m / (shape + 1.0)

    def mom(i, j):
        n = i + j
        return number * theta ** n * math.exp(math.lgamma(shape + n) - math.lgamma(shape)) * Y0 ** j
    return LT.scene_initial_state(sc, arrays, mom)   # binder in every granule: no dry class


def test_a_stop_below_the_grids_lowest_binder_fraction_says_so():
    """A wet class dried below the following weight's lowest tabulated binder fraction (the
    drying's end of fluid-bed-batch: the tables' weight is then far wider in b than the class)
    is named in the stop's hint with its fraction and the grid's; at the lowest fraction and
    above, nothing is added."""
    sc = scene(True)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    o, nwc = int(aux[LT.AUX_OFF_LOGW]), int(aux[LT.AUX_NWC])
    lowest = math.exp(aux[o + nwc])
    c_m = math.exp(aux[o + 1])
    state = gamma_state(sc, arrays, c_m, 1.0)
    for scale, named in ((1.0, False), (0.9 * lowest / Y0, True), (1.1 * lowest / Y0, False)):
        dried = state.copy()
        m = 3
        for i in range(m):
            for j in range(1, m):
                dried[i * m + j] *= scale ** j          # b = scale Y0 p
        hint = LT.failure_hint(dried, aux, arrays)
        assert ("lies below the lowest binder fraction" in hint) == named, (scale, hint)
        if named:
            assert f"W01 / W10 = {0.9 * lowest:.3g}" in hint and f"({lowest:.3g})" in hint


@pytest.mark.slow
def test_mass_beyond_the_span_inside_the_range_is_not_blamed_on_following_growth():
    """A broad wet population (gamma shape 0.02) whose c_m lies inside the following grid,
    95% of the way from one grid point to the next: the smallest blended slice's support is
    8 c_m / 10^(0.95/3), and the gamma fit puts ~2% of the mass beyond it. That mass is the
    population's breadth, not the grid's range: the report must not tell the user to raise
    following_growth. The same population with c_m 10x above the grid's top (clamped to its
    last slice) is the range's fault: there following_growth is named too small."""
    from scipy.special import gammaincc
    sc = scene(True)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    o, nwc = int(aux[LT.AUX_OFF_LOGW]), int(aux[LT.AUX_NWC])
    grid = aux[o:o + nwc]
    k = 0.02
    c_in = math.exp(grid[2] + 0.95 * (grid[3] - grid[2]))
    state = gamma_state(sc, arrays, c_in, k)
    assert not LT.beyond_following_range(state, aux)
    parts = LT.escaped_mass_parts(state, aux, arrays.params, arrays.config)
    limit = min(LT.wet_support(aux, w)[0] for w, _ in weight_corners(state, aux))
    assert limit == pytest.approx(8.0 * c_in / math.exp(0.95 * (grid[3] - grid[2])),
                                  rel=1e-9, abs=0)
    # the gamma's mass beyond the limit in p, Q(k + 1, limit / theta) with theta = c_m / (k + 1),
    # and in b = Y0 p (the only bound in b is b <= limit), Q(k + 1, limit / (Y0 theta))
    theta = c_in / (k + 1.0)
    expected = gammaincc(k + 1.0, limit / theta) + gammaincc(k + 1.0, limit / (Y0 * theta))
    assert parts[LT.FOLLOWING_SPAN_KEY] == pytest.approx(expected, rel=1e-6, abs=0)
    assert parts[LT.FOLLOWING_SPAN_KEY] > LT.ESCAPE_WARN_SHARE
    assert "following_growth" not in parts
    hint = LT.failure_hint(state, aux, arrays)
    _, text = LT.escaped_share_report(state, aux, arrays)
    for message in (hint, text):
        assert "broader than the following weight's support" in message, message
        assert "is too small" not in message, message
    c_out = 10.0 * math.exp(grid[-1])
    state = gamma_state(sc, arrays, c_out, k)
    assert LT.beyond_following_range(state, aux)
    parts = LT.escaped_mass_parts(state, aux, arrays.params, arrays.config)
    limit = min(LT.wet_support(aux, w)[0] for w, _ in weight_corners(state, aux))
    assert limit == pytest.approx(8.0 * math.exp(grid[-1]), rel=1e-9, abs=0)
    theta = c_out / (k + 1.0)
    expected = gammaincc(k + 1.0, limit / theta) + gammaincc(k + 1.0, limit / (Y0 * theta))
    assert parts["following_growth"] == pytest.approx(expected, rel=1e-6, abs=0)
    assert LT.FOLLOWING_SPAN_KEY not in parts
    assert "following_growth (the following range) is too small" in \
        LT.failure_hint(state, aux, arrays)


@pytest.fixture(scope="module")
def following_run():
    return run_well_mixed(scene(True)).columns


def test_following_support_finishes_with_exact_mass_binder_and_number(following_run):
    c = following_run
    t = c["time_s"]
    assert t[-1] == pytest.approx(END, rel=0, abs=1e-9)
    assert np.max(np.abs(c["M10"] / (N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M01"] / (Y0 * N0 * P0) - 1.0)) < EXACT
    assert np.max(np.abs(c["M00"] / riccati_m0(t) - 1.0)) < TOL
    assert c["M10"][-1] / c["M00"][-1] / P0 == pytest.approx(10.0, rel=0.01, abs=0)


def reference_errors(run, reference):
    """|ROM / reference - 1| [-] at the reference's times for M00, M20, M11, M02 (the binder
    moments from M_ij = y0^j M_(i+j),0 of the reference)."""
    t, M = reference
    out = {}
    for name, (i, j) in (("M00", (0, 0)), ("M20", (2, 0)), ("M11", (1, 1)), ("M02", (0, 2))):
        rom = np.interp(t, run["time_s"], run[name])
        out[name] = float(np.max(np.abs(rom / (Y0 ** j * M[:, i + j]) - 1.0)))
    return out


def test_following_support_binder_moments_within_5_percent_of_the_reference(following_run,
                                                                           reference):
    """The issue's aim, 5% of an independent reference, at 25, 50, 75 and 100 s: M00, M11
    and M02 (measured, max over the four times: 6e-6, 0.44%, 0.81%; with the former 20
    midpoint cells in p 1e-6, 0.04%, 2.1%)."""
    errs = reference_errors(following_run, reference)
    assert max(errs[n] for n in ("M00", "M11", "M02")) < 0.05, errs


def test_following_support_m20_within_5_percent_of_the_reference(following_run, reference):
    """M20 needs the reconstruction's M30 (the closure of S ~ p): 6.2% low at 100 s with the
    former 20 midpoint cells in p, 1.6% with the graded rule (exact for u^k g, k < 6)."""
    assert reference_errors(following_run, reference)["M20"] < 0.05


def test_following_support_holds_the_mass_and_blends_complete_closures():
    """At the end state of the case the escaped mass share is negligible (the support
    followed the population), and the reconstruction blended over the weight corners, each
    on its own support and nodes, returns every carried moment (to 100 eps cond(G))."""
    sc = scene(True)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    assert aux[AUX_FOLLOWING] == 1.0
    c_end = 10.0 * P0 * 1.37                 # between two grid points of c
    nn = N0 * P0 / c_end

    def mom(i, j):
        return nn * c_end ** (i + j) * math.factorial(i + j) * Y0 ** j

    state = LT.scene_initial_state(sc, arrays, mom)
    # the exponential's shape 1 is a grid point of the shape axis, c_m and y lie between
    # grid points: the simplex's face on that shape, the triangle of three (c_m, y) corners
    assert sum(f > 1e-12 for _, f in weight_corners(state, aux)) == 3
    assert L.escaped_mass_share(state, aux, arrays.params, arrays.config) < 1e-3
    m = 3
    for i in range(m):
        for j in range(m):
            got = L.reconstructed_moment(state, aux, arrays.params, arrays.config, i, j)
            assert got == pytest.approx(mom(i, j), rel=1e-6, abs=0)
    # today's fixed support loses most of this state's mass
    fixed = LT.aux_for_scene(scene(False), arrays)
    assert L.escaped_mass_share(state, fixed, arrays.params, arrays.config) > 0.1


def test_d43_of_a_broad_population_stays_within_the_bounds_of_its_moments():
    """d43 [m] of the following support comes from int p^(4/3) n of the signed reconstruction;
    for a broad population (90% of the granules exponential of mean 0.5 P0, 10% of mean 10 P0)
    that integral fell, with the former 20 midpoint cells in p, outside what any positive
    measure with the carried M0, M1, M2 allows (ln M_s is convex in s: M1 (M1/M0)^(1/3) <=
    M_(4/3) <= M1^(2/3) M2^(1/3); measured 1.04 against 1.64). With the graded rule it lies
    inside (measured 3.15 in [1.64, 3.50]), and the ROM's d43 is the reconstruction's."""
    from pbe_cfd.methods.laguerre.layout import AUX_OFF_F43
    from pbe_cfd.physics import parameters as P
    sc = scene(True)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    parts = ((0.9 * N0, 0.5 * P0), (0.1 * N0, 10.0 * P0))

    def mom(i, j):
        return sum(n * c ** (i + j) * math.factorial(i + j) for n, c in parts) * Y0 ** j

    state = LT.scene_initial_state(sc, arrays, mom)
    K = 9
    raw = sum(frac * aux[int(aux[AUX_OFF_F43]) + w * K:int(aux[AUX_OFF_F43]) + (w + 1) * K]
              @ state[:K] for w, frac in weight_corners(state, aux))
    m0, m1, m2 = state[0], state[3], state[6]
    lo, hi = m1 * (m1 / m0) ** (1.0 / 3.0), m1 ** (2.0 / 3.0) * m2 ** (1.0 / 3.0)
    assert lo <= raw <= hi
    pref, rho = arrays.params[P.MASS_SCALE], arrays.params[P.DENSITY]
    d43 = L.laguerre_d43(state, aux, arrays.params, arrays.config)
    m43 = d43 * m1 / (6.0 * pref / (math.pi * rho)) ** (1.0 / 3.0)
    assert lo * (1 - 1e-12) <= m43 <= hi * (1 + 1e-12)
