"""Laguerre ROM from a dry start (issue 15): the dry class (granules with b = 0 exactly), its
cross terms with the wet ROM, adaptive wet weights, exact bookkeeping, outputs.

Why the tolerances are what they are
------------------------------------
Constant kernel: every aggregation and capture term factors into carried moments (the binomial
expansion of (p+p')^i (b+b')^j, with the dry partner at b = 0), and the moment-consistent
reconstructions of both classes reproduce every carried moment on their quadratures, so the
ROM's rates equal the closed forms to round-off amplified by the inversion of G:
rtol = 100 eps max(cond G_wet, cond G_dry), as in test_laguerre. Blending adaptive weight slices
keeps this (each slice is exact, the blend weights sum to 1).
Bookkeeping: the loss of dry mass D_1 by dry-wet aggregation is the negated gain of W_10 entry
by entry, and wet-wet aggregation has no W_10 or W_01 term at all, so without droplets
d(W10 + D1)/dt and dW01/dt are exactly 0.0. With droplets the capture terms add a handful of
rounded products: 1e-12 relative to the capture rate (as in test_laguerre).
"""
import dataclasses
import math
from math import comb

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.methods.laguerre import rhs as L
from pbe_cfd.methods.laguerre import layout as LL
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.methods.registry import method_plan
from pbe_cfd.physics import parameters as P
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene
from test_laguerre import (EPS, FRACTION, W3, gamma_moment, product_gamma_moments, rhs,
                           seed_efficiency, setup, si)

WET = product_gamma_moments(2e10, 3.0, 2e-9, 0.7, 0.3e-9)       # SI moments of a wet class
DRY_N, DRY_SHAPE, DRY_MEAN = 1.5e10, 6.0, 6e-10                 # a dry class (gamma in p)
W22 = dict(W3, lam=2.0, gam=2.0, c_dry=5.4e-10, lam_dry=10.0)
GRID = dict(FRACTION, n_dry=80)
#: an adaptive weight grid the 12 x 12 quadrature resolves (cond(G) <= 1e7 on every slice)
ADAPT = dict(points=3, c=(1e-9, 4e-9), d=(1.5e-10, 1.2e-9))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("laguerre_dry_cache"))


def dry_moment(k):
    return DRY_N * gamma_moment(k, DRY_SHAPE, DRY_MEAN)


def mixed_state(params, config, n_droplets=0.0):
    """Wet class WET plus dry class (moments D_k = dry_moment(k))."""
    m = int(config[P.ORDER])
    state = L.initial_state(WET, params, config, n_droplets=n_droplets)
    for k in range(m):
        state[m * m + k] = dry_moment(k) / (params[P.NUMBER_SCALE] * params[P.MASS_SCALE] ** k)
    return state


def tolerance(aux, state):
    """100 eps cond(G) of the weight slices the state's RHS blends, and of the dry class."""
    return 100 * EPS * max(LL.corner_condition(state, aux), aux[LL.AUX_COND_DRY])


def dry_si(out, k, m, params):
    return out[m * m + k] * params[P.NUMBER_SCALE] * params[P.MASS_SCALE] ** k


def closed_constant_kernel(m, k0):
    """Closed-form rates of the wet moments W_ij and dry moments D_e, constant kernel."""
    W, D = WET, dry_moment
    wet, dry = {}, {}
    for i in range(m):
        for j in range(m):
            if (i, j) == (0, 0):
                ww = -0.5 * W(0, 0) ** 2
            else:
                ww = 0.5 * sum(comb(i, e1) * comb(j, e2) * W(e1, e2) * W(i - e1, j - e2)
                               for e1 in range(i + 1) for e2 in range(j + 1)
                               if (e1, e2) not in ((0, 0), (i, j)))
            dw = sum(comb(i, e) * D(e) * W(i - e, j) for e in range(1, i + 1))
            wet[(i, j)] = k0 * (ww + dw)
    for e in range(m):
        dd = -0.5 * D(0) ** 2 if e == 0 else 0.5 * sum(comb(e, f) * D(f) * D(e - f)
                                                        for f in range(1, e))
        dry[e] = k0 * (dd - D(e) * W(0, 0))
    return wet, dry


# ---- closed forms -------------------------------------------------------------------------
@pytest.mark.parametrize("adaptive", [None, ADAPT], ids=["fixed", "adaptive"])
@pytest.mark.parametrize("m", [2, 3, 4])
def test_constant_kernel_dry_and_wet_classes(m, adaptive, cache):
    """dry + dry -> dry, dry + wet -> wet, wet + wet -> wet: every carried rate is the closed
    form (the dry class's count falls by dry-dry pairs and by every dry-wet pair)."""
    params, config = setup(m)
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                      adaptive=adaptive)
    state = mixed_state(params, config)
    out = rhs(state, aux, params, config)
    wet, dry = closed_constant_kernel(m, params[P.RATE])
    rtol = tolerance(aux, state)
    for (i, j), want in wet.items():
        if want == 0.0:
            assert si(out, i, j, m, params) == 0.0
        else:
            assert si(out, i, j, m, params) == pytest.approx(want, rel=rtol, abs=0), (i, j)
    for e, want in dry.items():
        assert dry_si(out, e, m, params) == pytest.approx(want, rel=rtol, abs=0), e


@pytest.mark.parametrize("m", [2, 3, 4])
def test_constant_kernel_droplet_capture_by_both_classes(m, cache):
    """Separate droplets, constant kernel: a droplet meets any granule at F k0. A dry granule
    (p, 0) becomes a wet one (p + p_d, p_d); a wet one moves from (p, b) to (p + p_d, b + p_d)."""
    params, config = setup(m, kernel=0, separate=True)
    F, k0, pd = params[P.DROPLET_FACTOR], params[P.RATE], params[P.DROPLET_MASS]
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                      adaptive=ADAPT)
    nd = 1.2e9
    with_drops = rhs(mixed_state(params, config, n_droplets=nd), aux, params, config)
    without = rhs(mixed_state(params, config, n_droplets=0.0), aux, params, config)
    d = with_drops - without
    rtol = tolerance(aux, mixed_state(params, config))
    W, D = WET, dry_moment
    for i in range(m):
        for j in range(m):
            wet = sum(comb(i, e1) * comb(j, e2) * pd ** (i - e1 + j - e2) * W(e1, e2)
                      for e1 in range(i + 1) for e2 in range(j + 1) if (e1, e2) != (i, j))
            drygain = sum(comb(i, e) * pd ** (i - e + j) * D(e) for e in range(i + 1))
            assert si(d, i, j, m, params) == pytest.approx(F * k0 * nd * (wet + drygain),
                                                           rel=rtol, abs=0), (i, j)
    for e in range(m):
        assert dry_si(d, e, m, params) == pytest.approx(-F * k0 * nd * D(e), rel=rtol, abs=0)
    assert d[m * m + m] * params[P.NUMBER_SCALE] == pytest.approx(
        -F * k0 * nd * (W(0, 0) + D(0)), rel=rtol, abs=0)


@pytest.mark.parametrize("adaptive", [None, ADAPT], ids=["fixed", "adaptive"])
@pytest.mark.parametrize("consistent", [True, False])
@pytest.mark.parametrize("m", [3, 4])
def test_mass_and_binder_exact_with_seed_physics(m, consistent, adaptive, cache):
    """eke + geometric + physical efficiency: granule mass W10 + D1 and binder W01 change only
    by what the droplets bring, to round-off; without droplets not at all (exactly 0.0)."""
    params, config = setup(m, kernel=3, separate=True, k0=2.5e-14)
    seed_efficiency(params, config)
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, consistent=consistent,
                      collision_velocity=5.5, cache_dir=cache, adaptive=adaptive)
    K = m * m
    out = rhs(mixed_state(params, config), aux, params, config)
    assert out[m] + out[K + 1] == 0.0 and out[1] == 0.0
    assert out[K] < 0.0 and out[0] != 0.0
    out = rhs(mixed_state(params, config, n_droplets=1.5e9), aux, params, config)
    xd = params[P.DROPLET_MASS] / params[P.MASS_SCALE]
    scale = abs(out[K + m]) * xd
    assert scale > 0
    assert abs(out[m] + out[K + 1] + out[K + m] * xd) <= 1e-12 * scale
    assert abs(out[1] + out[K + m] * xd) <= 1e-12 * scale


@pytest.mark.slow
def test_univariate_scene_runs_in_the_dry_class():
    """A scene without binder: every granule stays in the dry class, which is a univariate
    Laguerre ROM in p; constant kernel, M00 = 2 N0 / (2 + tau), M20 = M20(0) + k0 M10^2 t
    (integrator tolerance 1e-8 -> 1e-7 on the solution)."""
    scene = make_scene(scene={"end_time": 10.0, "output_interval": 2.0},
                       aggregation={"kernel": "constant", "rate": 1e-10},
                       method={"name": "laguerre", "order": 3, "_replace": True})
    res = run_well_mixed(scene)
    c = res.columns
    t = c["time_s"]
    n0, p0 = 1e10, 1e-9
    assert np.allclose(c["M00"], 2 * n0 / (2 + 1e-10 * n0 * t), rtol=1e-7, atol=0)
    assert np.allclose(c["M20"], n0 * p0 ** 2 + 1e-10 * (n0 * p0) ** 2 * t, rtol=1e-7, atol=0)
    assert np.allclose(c["dry_M00"], c["M00"], rtol=1e-12, atol=0)
    assert np.max(np.abs(c["M10"] / (n0 * p0) - 1)) < 1e-10


@pytest.mark.slow
def test_dry_start_with_injection_keeps_every_invariant():
    """The seed scenario without droplets at t = 0 for 30 s: M10 and M01 grow at exactly the
    injected rate, the dry granules only decrease, stored states stay realizable."""
    scene = load_scene("study-seed-dry")
    scene = dataclasses.replace(scene, end_time=30.0, output_interval=10.0)
    res = run_well_mixed(scene)
    c = res.columns
    t = c["time_s"]
    rate = scene.binder_injection.rate * model.pack(scene).droplet_mass
    assert np.max(np.abs(c["M10"] / (c["M10"][0] + rate * t) - 1)) < 1e-10
    assert c["M01"][0] == 0.0
    assert np.max(np.abs(c["M01"][1:] / (rate * t[1:]) - 1)) < 1e-10
    assert np.all(np.diff(c["dry_M00"]) < 0.0)
    assert c["dry_M00"][0] == pytest.approx(3.3e10, rel=1e-12, abs=0)
    assert 0.0 < c["dry_mass_fraction"][-1] < 1.0


# ---- projection, realizability ------------------------------------------------------------
def test_exhausted_dry_class_merges_into_the_wet_class(cache):
    m = 3
    K = m * m
    params, config = setup(m, separate=True)
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache)
    state = mixed_state(params, config, n_droplets=1e9)
    state[K:K + m] *= 1e-13 * state[0] / state[K]        # 1e-13 of the granules left dry
    before = state.copy()
    L.laguerre_project(state, aux, params, config)
    assert np.all(state[K:K + m] == 0.0)
    for k in range(m):
        assert state[k * m] == before[k * m] + before[K + k]
    keep = before.copy()
    keep[K:K + m] *= 1e3                                  # 1e-10: kept
    after = keep.copy()
    L.laguerre_project(after, aux, params, config)
    assert np.array_equal(after, keep)


def test_dry_class_realizability(cache):
    m = 3
    K = m * m
    params, config = setup(m)
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache)
    aux1 = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                       check_level=1)
    ok = mixed_state(params, config)
    assert L.laguerre_realizable(ok, aux, params, config)
    assert L.laguerre_realizable(ok, aux1, params, config)
    dry_only = ok.copy()
    dry_only[:K] = 0.0
    assert L.laguerre_realizable(dry_only, aux1, params, config)
    for idx in (K, K + 1, K + 2):
        bad = ok.copy()
        bad[idx] = -1e-3 * abs(ok).max()
        assert not L.laguerre_realizable(bad, aux, params, config), idx
    bad = ok.copy()
    bad[K + 2] = 0.99 * ok[K + 1] ** 2 / ok[K]            # D1^2 > D0 D2
    assert L.laguerre_realizable(bad, aux, params, config)
    assert not L.laguerre_realizable(bad, aux1, params, config)


# ---- tabulation, cache ----------------------------------------------------------------------
def test_theta_grid_hits_its_nodes_and_collapses_when_saturated(cache):
    """Tensors on a Theta grid reproduce the fixed-u0 tensors at a grid node; over a Theta
    range where the physical efficiency is saturated (u0 far below the Stokes limit) the grid
    collapses to one slice, identical to a fixed-u0 build."""
    m = 3
    params, config = setup(m, kernel=3, separate=True, k0=2.5e-14)
    seed_efficiency(params, config)
    state = mixed_state(params, config, n_droplets=1e9)
    thetas = np.geomspace(0.1, 10.0, 5)
    grid = L.build_aux(params, config, m, weights=W22, support=GRID, theta_grid=thetas,
                       cache_dir=cache, adaptive=ADAPT)
    assert grid[LL.AUX_NSLICE] == 5
    fixed = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                        collision_velocity=float(L.theta_to_u0(thetas[2])),
                        adaptive=ADAPT)
    cell = np.zeros(P.N_CELL)
    cell[P.THETA] = thetas[2]
    a, b = rhs(state, grid, params, config, cell), rhs(state, fixed, params, config, cell)
    assert np.allclose(a, b, rtol=1e-9, atol=1e-12 * np.abs(b).max())
    slow = np.geomspace(1e-6, 1e-4, 4)
    flat = L.build_aux(params, config, m, weights=W22, support=GRID, theta_grid=slow,
                       cache_dir=cache)
    assert flat[LL.AUX_NSLICE] == 1
    one = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                      collision_velocity=float(L.theta_to_u0(slow[0])))
    cell[P.THETA] = slow[2]
    assert np.array_equal(rhs(state, flat, params, config, cell),
                          rhs(state, one, params, config, cell))


def test_adaptive_blend_is_the_bilinear_blend_of_fixed_weights(cache):
    """The RHS with adaptive weights equals, to round-off, the bilinear blend (in ln c, ln d)
    of fixed-weight builds at the four grid means around the wet class's mean mass and
    binder: an independent check of the corner arithmetic of the numba RHS."""
    m = 3
    params, config = setup(m, kernel=3, separate=True, k0=2.5e-14)
    seed_efficiency(params, config)
    spec = dict(points=4, c=(1e-9, 8e-9), d=(1e-10, 8e-10))
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache,
                      collision_velocity=5.5, adaptive=spec)
    state = mixed_state(params, config, n_droplets=1e9)
    mean_p, mean_b = WET(1, 0) / WET(0, 0), WET(0, 1) / WET(0, 0)
    cg, dg = np.geomspace(1e-9, 8e-9, 4), np.geomspace(1e-10, 8e-10, 4)
    i = int(np.searchsorted(cg, mean_p)) - 1
    j = int(np.searchsorted(dg, mean_b)) - 1
    tc = math.log(mean_p / cg[i]) / math.log(cg[i + 1] / cg[i])
    td = math.log(mean_b / dg[j]) / math.log(dg[j + 1] / dg[j])
    want = 0.0
    for a, wa in ((0, 1 - tc), (1, tc)):
        for b, wb in ((0, 1 - td), (1, td)):
            w = dict(W22, c=cg[i + a], d=dg[j + b])
            fixed = L.build_aux(params, config, m, weights=w, support=GRID, cache_dir=cache,
                                collision_velocity=5.5)
            want = want + wa * wb * rhs(state, fixed, params, config)
    got = rhs(state, aux, params, config)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-13 * np.abs(want).max())
    corners = LL.weight_corners(state, aux)
    assert sum(f for _, f in corners) == pytest.approx(1.0, rel=1e-15, abs=0)


def test_cache_key_covers_the_dry_class_and_the_adaptive_grid(tmp_path):
    m = 2
    params, config = setup(m)
    d = str(tmp_path)
    L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=d)
    L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=d)
    assert len(list(tmp_path.iterdir())) == 1
    L.build_aux(params, config, m, weights=dict(W22, lam_dry=4.0), support=GRID, cache_dir=d)
    L.build_aux(params, config, m, weights=W22, support=dict(GRID, n_dry=40), cache_dir=d)
    L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=d, adaptive=ADAPT)
    assert len(list(tmp_path.iterdir())) == 4


# ---- scene level ------------------------------------------------------------------------------
def test_initial_state_places_granules_by_binder():
    base = load_scene("study-seed-dry").with_method(order=2)
    arrays = model.pack(base)
    K = 4
    dry = model.initial_moments(base, arrays, arrays.state_names)
    assert np.all(dry[:K] == 0.0) and dry[K] > 0.0
    wet = model.initial_moments(base.with_method(dry_class=False), arrays, arrays.state_names)
    assert wet[0] == dry[K] and np.all(wet[K:K + 2] == 0.0)
    y = dataclasses.replace(base, initial=dataclasses.replace(base.initial, binder_fraction=0.1))
    assert model.initial_moments(y, model.pack(y), arrays.state_names)[K] == 0.0
    assert arrays.state_names[:K + 2] == ["wet_M00", "wet_M01", "wet_M10", "wet_M11",
                                           "dry_M00", "dry_M10"]


def test_output_columns_add_the_classes_and_the_droplets(cache):
    scene = load_scene("study-seed-dry").with_method(grid_mass=12, grid_binder=12,
                                                     dry_grid_mass=60)
    arrays = model.pack(scene)
    aux = LT.aux_for_scene(scene, arrays, cache_dir=cache)
    m = 3
    state = L.initial_state(WET, arrays.params, arrays.config, n_droplets=2e8)
    for k in range(m):
        state[m * m + k] = dry_moment(k) / (arrays.number_scale * arrays.mass_scale ** k)
    cols = model.moment_outputs(method_plan(scene), arrays, state[None, :], aux)
    pd = arrays.droplet_mass
    for i in range(m):
        for j in range(m):
            want = WET(i, j) + (dry_moment(i) if j == 0 else 0.0) + 2e8 * pd ** (i + j)
            assert cols[f"M{i}{j}"][0] == pytest.approx(want, rel=1e-12, abs=0), (i, j)
    assert cols["dry_M00"][0] == pytest.approx(DRY_N, rel=1e-12, abs=0)
    assert cols["dry_mass_fraction"][0] == pytest.approx(dry_moment(1) / cols["M10"][0],
                                                         rel=1e-12, abs=0)
    w, p, b = LT.population_for_output(state, aux, arrays)
    tol = tolerance(aux, state)
    for i in range(m):
        for j in range(m):
            want = WET(i, j) + (dry_moment(i) if j == 0 else 0.0)
            assert np.sum(w * p ** i * b ** j) == pytest.approx(want, rel=tol, abs=0), (i, j)


def test_escaped_share_counts_the_dry_class(cache):
    m = 3
    params, config = setup(m)
    aux = L.build_aux(params, config, m, weights=W22, support=GRID, cache_dir=cache)
    state = np.zeros(L.state_size(m, False))
    big = 2e-8                                             # a dry delta beyond p_max = 1e-8
    for k in range(m):
        state[m * m + k] = 1e9 * (big / params[P.MASS_SCALE]) ** k / params[P.NUMBER_SCALE]
    assert L.escaped_mass_share(state, aux, params, config) == 1.0
    state[m * m:] *= 1e-3
    state[:m * m] = L.initial_state(WET, params, config)[:m * m]
    share = L.escaped_mass_share(state, aux, params, config)
    dry_mass = 1e6 * big
    assert share >= dry_mass / (dry_mass + WET(1, 0)) * 0.999
