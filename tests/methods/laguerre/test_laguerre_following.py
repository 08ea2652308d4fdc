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
from pbe_cfd.methods.laguerre.layout import AUX_FOLLOWING, corner_condition, weight_corners
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import AVICEL, make_scene
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
    method = {"name": "laguerre", "order": order, "following_support": bool(following)}
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


def _geometric_efficiency(y):
    """psi_g of two granules of binder fraction y [-] (docs/physics.md section 6, restated
    here with the AVICEL slopes): 1 - (1 - eta)^2, eta = 1 / (1 + exp(-35.1 (y - 0.129)))."""
    eta = 1.0 / (1.0 + math.exp(-35.1 * (y - 0.129)))
    return 1.0 - (1.0 - eta) ** 2


def _uniform_fraction_rates(y, psi, k=K_AGG, m=3):
    """Closed form [kg^(i+j)/(m3 s)] of dM_ij/dt, i, j < m, for constant aggregation k of
    success probability psi [-] on the exponential population (N0, mean P0) whose every
    granule holds the binder fraction y: M_ij = y^j M_(i+j), M_n = N0 P0^n n!, and
    dM_ij = psi k [1/2 sum_(a, b) C(i, a) C(j, b) M_ab M_(i-a)(j-b) - M00 M_ij]."""
    def mom(i, j):
        return y ** j * N0 * P0 ** (i + j) * math.factorial(i + j)
    out = {}
    for i in range(m):
        for j in range(m):
            gain = sum(math.comb(i, a) * math.comb(j, b) * mom(a, b) * mom(i - a, j - b)
                       for a in range(i + 1) for b in range(j + 1))
            out[(i, j)] = psi * k * (0.5 * gain - mom(0, 0) * mom(i, j))
    return out, mom


def test_a_class_dried_below_the_lowest_fraction_aggregates_at_that_fraction():
    """A wet class dried below the following tables' lowest binder fraction y_lo (the
    falling-rate period of a batch takes it there) aggregates as the class scaled up to y_lo
    (``position.binder_shift``; docs/physics.md section 9.2). Constant kernel with the
    geometric efficiency, every granule at one fraction y: the efficiency is then one number
    psi_g(y) and the rates have a closed form. Below y_lo each rate's ratio to the closed form
    is the tables' own at y_lo (measured on the same class at y_lo) times the efficiency's
    change psi_g(y_lo) / psi_g(y) (under 0.35% at the drying grid's y_lo = 1e-4), to
    round-off: at y_lo / 10 through the scaled state, at y_lo 1e-5 (below LIQUID_FLOOR)
    through the class of that fraction; clamped at y_lo's tables instead, W02's rate is off by
    1.3% at y_lo / 10, 14% at y_lo / 100 and 13 times at y_lo / 1e4. Mass and liquid rates are 0 to round-off,
    and the realizability gap W00 W02 - W01^2 moves as the closed form's within those errors.
    At y = 1e-200 and 0 every rate is finite and the number and mass rates are y_lo's."""
    sc = make_scene(scene={"end_time": 1.0, "output_interval": 1.0},
                    material=AVICEL,
                    initial={"distribution": "exponential", "binder_fraction": 0.01},
                    aggregation={"kernel": "constant", "rate": K_AGG,
                                 "efficiency": ["geometric"]},
                    method={"_replace": True, "name": "laguerre", "order": 3,
                            "following_support": True})
    arrays = model.pack(sc)
    weights, support = LT.scene_weights_support(sc)
    # a grid of c_m around the exponential class's 2 P0 and the drying scenes' lowest fractions
    spec = dict(following=True, c=(P0, 4.0 * P0), y=(0.01, 1.0), points_y=3,
                y_below=[1e-4, 1e-3], shapes=None)
    aux = LT.build_aux(arrays.params, arrays.config, 3, weights=weights, support=support,
                       adaptive=spec, use_cache=False)
    lowest = math.exp(aux[int(aux[LT.AUX_OFF_LOGW]) + int(aux[LT.AUX_NWC])])
    assert lowest == pytest.approx(1.0e-4, rel=1e-12, abs=0.0)
    row = np.ascontiguousarray(model.well_mixed_cell(sc)[0], dtype=float)
    nref, pref = arrays.number_scale, arrays.mass_scale

    def rom_rates(y):
        exact, mom = _uniform_fraction_rates(y, _geometric_efficiency(y))
        state = LT.initial_state(mom, arrays.params, arrays.config)
        out = np.zeros_like(state)
        L.laguerre_rhs(state, out, row, aux, arrays.params, arrays.config)
        rom = {(i, j): out[i * 3 + j] * nref * pref ** (i + j) for i in range(3)
               for j in range(3)}
        return rom, exact, mom

    rom_lo, exact_lo, _ = rom_rates(lowest)
    # the output's particles (each slice's own nodes, its fraction support 100 y) reproduce
    # the carried moments on the low slices and between them
    for y in (lowest, 3.0 * lowest):
        _, mom = _uniform_fraction_rates(y, 1.0)
        state = LT.initial_state(mom, arrays.params, arrays.config)
        w, p, b = LT.wet_particles(state, aux)
        # the round-off of the slices' consistent inverses, 100 eps cond(G)
        tol = 100.0 * np.finfo(float).eps * corner_condition(state, aux)
        for i in range(3):
            for j in range(3):
                assert np.sum(w * p ** i * b ** j) * nref == pytest.approx(
                    mom(i, j), rel=tol, abs=0.0), (y, i, j, tol)
    for y in (lowest / 10.0, lowest * 1e-5):
        rom, exact, mom = rom_rates(y)
        efficiency_change = _geometric_efficiency(lowest) / _geometric_efficiency(y)
        assert efficiency_change - 1.0 < 0.0035    # the drying grid's y_lo keeps it small
        for a in exact:
            if exact[a] == 0.0:                    # mass and liquid: round-off of the gains
                assert abs(rom[a]) <= 1e-10 * abs(exact[(0, 0)]) * mom(*a) / mom(0, 0), \
                    (y, a, rom[a])
                continue
            # the tables' own closure error for this moment at y_lo, then the efficiency's
            closure = rom_lo[a] / exact_lo[a]
            assert rom[a] / exact[a] == pytest.approx(closure * efficiency_change, rel=1e-9,
                                                      abs=0.0), (y, a, rom[a], exact[a])
        # the realizability gap W00 W02 - W01^2: its rate (0 in the closed form of an
        # exponential class) within the rates' errors times the size of its terms
        gap = rom[(0, 0)] * mom(0, 2) + mom(0, 0) * rom[(0, 2)] - 2.0 * mom(0, 1) * rom[(0, 1)]
        gap_exact = (exact[(0, 0)] * mom(0, 2) + mom(0, 0) * exact[(0, 2)]
                     - 2.0 * mom(0, 1) * exact[(0, 1)])
        terms = abs(exact[(0, 0)] * mom(0, 2)) + abs(mom(0, 0) * exact[(0, 2)])
        error = max(abs(rom[a] / exact[a] - 1.0) for a in ((0, 0), (0, 2)))
        assert abs(gap - gap_exact) <= (error + 1e-9) * terms, (y, gap, gap_exact, terms)
    for y in (1e-200, 0.0):                        # exp(j ln(y_lo / y)) would overflow
        rom, exact, mom = rom_rates(y)
        assert all(np.isfinite(v) for v in rom.values()), (y, rom)
        for a in ((0, 0), (2, 0)):
            assert rom[a] / exact[a] == pytest.approx(
                rom_lo[a] / exact_lo[a] * _geometric_efficiency(lowest)
                / _geometric_efficiency(y), rel=1e-9, abs=0.0), (y, a)
        assert all(abs(rom[(i, j)]) <= 1e-150 * abs(rom[(i + j, 0)]) for i in range(3)
                   for j in range(1, 3) if i + j < 3), (y, rom)


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


def test_a_dried_class_s_last_liquid_is_spread_over_its_mass():
    """Below LIQUID_FLOOR the post-step fix (``laguerre_project``) gives the wet class's
    liquid moments those of its liquid fraction y = W01 / W10 in every granule, y^j M_(i+j)
    (M_3, M_4 of the gamma of W00, W10, W20): W01, the mass moments and the invariants are
    kept, and moments left below any tolerance by the falling rate (here W02 at 1e-3 of its
    Hankel bound) become realizable. Above the floor, and without the following support,
    nothing changes, bitwise."""
    from pbe_cfd.methods.laguerre.admissible import laguerre_project
    from pbe_cfd.methods.laguerre.position import LIQUID_FLOOR
    sc = scene(True)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    base = gamma_state(sc, arrays, 3.0 * P0, 2.0)          # shape 2, b = Y0 p
    m = 3
    for y, spread in ((0.1 * LIQUID_FLOOR, True), (10.0 * LIQUID_FLOOR, False)):
        state = base.copy()
        for i in range(m):
            for j in range(1, m):
                state[i * m + j] *= (y / Y0) ** j
        state[2] *= 1e-3                        # W02 far below W01^2 / W00: noise
        before = state.copy()
        laguerre_project(state, aux, arrays.params, arrays.config)
        if not spread:
            assert np.array_equal(state, before)
            continue
        assert np.array_equal(state[[0, 1, m, 2 * m]], before[[0, 1, m, 2 * m]])
        assert np.array_equal(state[m * m:], before[m * m:])
        w00, w10, w20 = before[0], before[m], before[2 * m]
        mean, var = w10 / w00, w20 / w00 - (w10 / w00) ** 2
        theta, shape = var / mean, mean * mean / var
        moments = [w00, w10, w20, w20 * theta * (shape + 2.0),
                   w20 * theta ** 2 * (shape + 2.0) * (shape + 3.0)]
        yy = before[1] / before[m]
        for i in range(m):
            for j in range(1, m):
                assert state[i * m + j] == pytest.approx(yy ** j * moments[i + j], rel=1e-13,
                                                         abs=0.0), (i, j)
        assert state[0] * state[2] >= state[1] ** 2
    # fixed support: the fix is the following support's alone
    sc = scene(False)
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    state = base.copy()
    for i in range(m):
        for j in range(1, m):
            state[i * m + j] *= (0.1 * LIQUID_FLOOR / Y0) ** j
    before = state.copy()
    laguerre_project(state, aux, arrays.params, arrays.config)
    assert np.array_equal(state, before)


def test_a_round_off_of_negative_liquid_returns_from_the_evaporated_liquid():
    """The falling rate's last step can leave W01 a round-off below 0 (-5.8e-13 of W10 in
    the bed batch): the post-step fix returns it from the evaporated liquid E (M01 + E, the
    liquid balance's invariant, unchanged to the bit) and the class then holds no liquid."""
    from pbe_cfd.methods.laguerre.admissible import laguerre_project
    from pbe_cfd.methods.laguerre.layout import evaporated_entry
    from test_drying import _scene as drying_scene
    sc = drying_scene(0.05, 1.0, 0.2, method={"name": "laguerre", "order": 3,
                                              "following_support": True,
                                              "following_shape": False})
    arrays = model.pack(sc)
    aux = LT.aux_for_scene(sc, arrays)
    m = 3
    state = gamma_state(sc, arrays, 3.0 * P0, 2.0)[:m * m + m]
    state = np.concatenate([state, np.zeros(len(arrays.state_names) - state.size)])
    e = evaporated_entry(arrays.config)
    state[e] = 0.37 * state[m]
    for i in range(m):
        for j in range(1, m):
            state[i * m + j] *= (-1e-13 / Y0) ** j
    invariant = state[1] + state[e]
    laguerre_project(state, aux, arrays.params, arrays.config)
    assert state[1] == 0.0 and state[1] + state[e] == invariant
    assert all(state[i * m + j] == 0.0 for i in range(m) for j in range(1, m))
