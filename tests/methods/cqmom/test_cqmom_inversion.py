"""CQMOM inversion and right-hand side (methods/cqmom.py, methods/conditional.py).

Inversion: a population of N1 distinct masses, each holding at most N2 distinct binder
fractions, is exactly what an (N1, N2) conditional quadrature represents, so its moments must
give back its points (hypothesis over masses, fractions, weights and number scales 1e-30..1e30).
Degenerate sets (one fraction per mass, dry, pure binder, one mass) lose points, never give NaN.
Sets whose conditional moments are not realizable are replaced by the nearest realizable ones
(atoms on 0 or 1, fewer points): finite, b <= p, number, mass and binder mass kept.

Right-hand side: for such a population the quadrature is the population itself, so the CQMOM
sources must equal the exact moment sources of the discrete population, summed pair by pair
with pair rates written out in this file from the formulas of docs/physics.md (sections 4-6:
kernels, efficiency factors, droplet capture) with the scene's own numbers, in plain Python
floats (no function of pbe_cfd.physics is called), for every kernel and efficiency, separate
droplets and injection.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pbe_cfd.runs import model
from pbe_cfd.methods.cqmom import cqmom, sources as cqmom_sources
from pbe_cfd.methods.cqmom.conditional import gauss2_unit_interval, gauss_unit_interval
from pbe_cfd.physics import parameters as P

from conftest import AVICEL, make_scene


def config_of(n1, n2, bivariate=True, separate=False):
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.ORDER] = n1
    config[P.BINDER_NODES] = n2
    config[P.BIVARIATE] = int(bivariate)
    config[P.SEPARATE_DROPLETS] = int(separate)
    config[P.N_STATE] = cqmom.state_length(n1, n2, bivariate, separate)
    return config


def moments_of(p, b, w, n1, n2, droplets=None):
    """Moments in CQMOM state order of weighted points (p, b, w)."""
    names = cqmom.state_names(n1, n2, True, droplets is not None)
    out = [np.sum(w * p ** int(s[1]) * b ** int(s[2])) for s in names if s.startswith("M")]
    if droplets is not None:
        out.append(droplets)
    return np.array(out, dtype=float)


def tensor_population(masses, fractions, weights):
    """Points of a population with masses[a] and, per mass, fractions[a] (list) and weights."""
    p, b, w = [], [], []
    for a, x in enumerate(masses):
        for y, r in zip(fractions[a], weights[a]):
            p.append(x)
            b.append(y * x)
            w.append(r)
    return np.array(p), np.array(b), np.array(w)


def sorted_points(p, b, w):
    order = np.lexsort((b, p))
    return p[order], b[order], w[order]


def fresh_work(n1, n2):
    return np.zeros(cqmom.work_size(n1, n2))


# --------------------------------------------------------------------------- [0, 1] rules
@settings(max_examples=300, deadline=None)
@given(y0=st.floats(0.0, 1.0), y1=st.floats(0.0, 1.0), r=st.floats(0.01, 0.99))
def test_two_atoms_on_the_unit_interval_come_back(y0, y1, r):
    mu = [(1 - r) * y0 ** l + r * y1 ** l for l in range(4)]
    nodes = np.zeros(3)
    weights = np.zeros(3)
    n = gauss2_unit_interval(mu[1], mu[2], mu[3], nodes, weights)
    assert np.all((nodes[:n] >= 0.0) & (nodes[:n] <= 1.0))
    assert np.all(weights[:n] >= 0.0)
    back = [np.sum(weights[:n] * nodes[:n] ** l) for l in range(4)]
    # atoms closer than the degeneracy tolerance come back as one atom: moments still kept
    assert np.allclose(back, mu, rtol=0.0, atol=1e-9)
    if abs(y0 - y1) > 1e-3 and min(y0, y1) > 1e-3:
        assert n == 2
        assert sorted(nodes[:2]) == pytest.approx(sorted([y0, y1]), abs=1e-8)


@settings(max_examples=300, deadline=None)
@given(mu1=st.floats(-0.5, 1.5), mu2=st.floats(-0.5, 1.5), mu3=st.floats(-0.5, 1.5))
def test_any_fraction_moments_give_points_in_the_unit_interval(mu1, mu2, mu3):
    """Whatever the conditional moments, the rule has weights >= 0 summing to 1 and nodes in
    [0, 1]; where (mu1, mu2) are realizable (mu1^2 <= mu2 <= mu1) they are kept."""
    nodes = np.zeros(3)
    weights = np.zeros(3)
    n = gauss2_unit_interval(mu1, mu2, mu3, nodes, weights)
    assert 1 <= n <= 2
    assert np.all(np.isfinite(nodes[:n])) and np.all((nodes[:n] >= 0) & (nodes[:n] <= 1))
    assert np.all(weights[:n] >= 0) and np.sum(weights[:n]) == pytest.approx(1.0, abs=1e-14)
    if 0.0 < mu1 < 1.0:
        assert np.sum(weights[:n] * nodes[:n]) == pytest.approx(mu1, abs=1e-14)
        if mu1 * mu1 * (1 + 1e-9) < mu2 < mu1:
            assert np.sum(weights[:n] * nodes[:n] ** 2) == pytest.approx(mu2, rel=1e-10, abs=0)


def test_three_node_rule_and_its_reduction():
    y = np.array([0.1, 0.4, 0.8])
    r = np.array([0.2, 0.5, 0.3])
    mu = np.array([np.sum(r * y ** l) for l in range(6)])
    nodes, weights = np.zeros(3), np.zeros(3)
    assert gauss_unit_interval(mu, 3, nodes, weights, np.zeros(80)) == 3
    assert np.sort(nodes) == pytest.approx(y, abs=1e-10)
    for dent in (1.5, 0.5):            # mu5 above / below its range given mu0 .. mu4
        bad = mu.copy()
        bad[5] *= dent
        n = gauss_unit_interval(bad, 3, nodes, weights, np.zeros(80))
        # the principal representation: an atom on 1 (0) and mu0 .. mu4 kept
        assert n == 3 and np.all((nodes >= 0) & (nodes <= 1)) and np.all(weights >= 0)
        assert (1.0 if dent > 1 else 0.0) in nodes
        back = [np.sum(weights * nodes ** l) for l in range(5)]
        assert back == pytest.approx(list(mu[:5]), rel=1e-10, abs=0)
    bad = mu.copy()
    bad[3] *= 3.0                      # mu3 out of range: two nodes of mu0 .. mu3
    n = gauss_unit_interval(bad, 3, nodes, weights, np.zeros(80))
    assert n <= 2 and np.all((nodes[:n] >= 0) & (nodes[:n] <= 1))
    assert np.sum(weights[:n] * nodes[:n]) == pytest.approx(mu[1], rel=1e-12, abs=0)


# --------------------------------------------------------------------------- inversion
mass = st.floats(min_value=1e-2, max_value=1e2)
fraction = st.floats(min_value=0.0, max_value=1.0)
weight = st.floats(min_value=1e-2, max_value=1e2)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n1=st.integers(1, 3), n2=st.integers(1, 3), data=st.data(),
       scale=st.sampled_from([1e-30, 1.0, 1e30]))
def test_tensor_populations_are_recovered(n1, n2, data, scale):
    masses = sorted(set(data.draw(st.lists(mass, min_size=n1, max_size=n1))))
    if min(np.diff(masses), default=1.0) < 0.05 * max(masses):
        masses = [masses[0] * 3.0 ** a for a in range(len(masses))]     # well separated
    fractions = [data.draw(st.lists(fraction, min_size=n2, max_size=n2)) for _ in masses]
    weights = [data.draw(st.lists(weight, min_size=n2, max_size=n2)) for _ in masses]
    p, b, w = tensor_population(masses, fractions, weights)
    w = w * scale
    config = config_of(n1, n2)
    state = moments_of(p, b, w, n1, n2)
    work = fresh_work(n1, n2)
    assert cqmom.cqmom_realizable(state, np.zeros(1), np.zeros(P.N_PARAMS), config, work)
    assert cqmom.representation_error(state, config, fresh_work(n1, n2)) < 1e-7
    x, ww, bb = cqmom.quadrature_of(state, config)
    assert np.all(np.isfinite(x)) and np.all(ww > 0) and np.all((bb >= 0) & (bb <= x))
    # every carried moment is reproduced (within the conditioning of the spread weights)
    back = moments_of(x, bb, ww, n1, n2)
    bound = moments_of(x, x, ww, n1, n2)            # sum w p^(k+l): the b <= p bound
    assert np.all(np.abs(back - state) <= 1e-7 * bound)
    # abs=0: the number scale reaches 1e-30, where a default abs of 1e-12 accepts any value
    assert back[0] == pytest.approx(state[0], rel=1e-12, abs=0)
    assert back[1] == pytest.approx(state[1], rel=1e-10, abs=0)
    assert back[2 * n1] == pytest.approx(state[2 * n1], rel=1e-9, abs=0)       # M01
    before = state.copy()
    cqmom.cqmom_project(state, np.zeros(1), np.zeros(P.N_PARAMS), config, work)
    assert state[0] == before[0] and state[1] == before[1] and state[2 * n1] == before[2 * n1]
    assert np.all(np.abs(state - before) <= 1e-7 * bound)


def test_distinct_points_come_back_exactly():
    p, b, w = tensor_population([0.5, 1.0, 3.0], [[0.0, 0.3], [0.1, 0.6], [0.25, 1.0]],
                                [[2.0, 1.0], [0.5, 0.7], [0.3, 0.1]])
    state = moments_of(p, b, w, 3, 2)
    x, ww, bb = cqmom.quadrature_of(state, config_of(3, 2))
    assert len(x) == 6
    for got, want in zip(sorted_points(x, bb, ww), sorted_points(p, b, w)):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("case", ["one fraction per mass", "dry", "pure binder", "one mass",
                                  "dry and wet atoms"])
@pytest.mark.parametrize("n1,n2", [(2, 2), (3, 2), (3, 3)])
def test_degenerate_sets_lose_points_not_finiteness(case, n1, n2):
    masses = [0.5, 1.0, 2.5][:n1] if case != "one mass" else [1.0]
    if case == "one fraction per mass":
        fr = [[0.2] for _ in masses]
    elif case == "dry":
        fr = [[0.0] for _ in masses]
    elif case == "pure binder":
        fr = [[1.0] for _ in masses]
    elif case == "one mass":
        fr = [[0.1, 0.6][:n2]]
    else:
        fr = [[0.0, 0.4] for _ in masses]
    wts = [[1.0] * len(f) for f in fr]
    p, b, w = tensor_population(masses, fr, wts)
    state = moments_of(p, b, w, n1, n2)
    config = config_of(n1, n2)
    work = fresh_work(n1, n2)
    assert cqmom.cqmom_realizable(state, np.zeros(1), np.zeros(P.N_PARAMS), config, work)
    x, ww, bb = cqmom.quadrature_of(state, config)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(ww)) and np.all(np.isfinite(bb))
    for got, want in zip(sorted_points(x, bb, ww), sorted_points(p, b, w)):
        assert got == pytest.approx(want, rel=1e-8, abs=1e-12)


def test_empty_state_is_realizable_and_stays_zero():
    config = config_of(3, 2, separate=True)
    state = np.zeros(config[P.N_STATE])
    state[-1] = 0.5                             # droplets only
    work = fresh_work(3, 2)
    assert cqmom.cqmom_realizable(state, np.zeros(1), np.zeros(P.N_PARAMS), config, work)
    cqmom.cqmom_project(state, np.zeros(1), np.zeros(P.N_PARAMS), config, work)
    assert np.all(state[:-1] == 0.0) and state[-1] == 0.5


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n1=st.integers(2, 3), n2=st.integers(2, 3), atoms=st.integers(1, 12),
       seed=st.integers(0, 2 ** 31), dent=st.floats(0.3, 3.0), which=st.integers(0, 30))
def test_any_population_and_dented_sets_give_bounded_points(n1, n2, atoms, seed, dent, which):
    """General populations (more atoms than points) and sets with one mixed moment pushed off:
    the conditional moments may not be realizable; the inversion still gives finite points
    with b <= p and weights >= 0, keeps M00, M10 and M01 where they are consistent, and the
    projection lands on a realizable state."""
    rng = np.random.default_rng(seed)
    p = rng.lognormal(0.0, 1.0, atoms)
    y = rng.uniform(0.0, 1.0, atoms) * (rng.random(atoms) > 0.3)
    w = rng.lognormal(0.0, 1.0, atoms)
    state = moments_of(p, y * p, w, n1, n2)
    k = 2 * n1 + 1 + which % (len(state) - 2 * n1 - 1)         # a mixed moment, not M01
    state[k] *= dent
    config = config_of(n1, n2)
    x, ww, bb = cqmom.quadrature_of(state, config)
    assert len(x) >= 1
    assert np.all(np.isfinite(x)) and np.all(x > 0)
    assert np.all(np.isfinite(ww)) and np.all(ww >= 0)
    assert np.all((bb >= 0) & (bb <= x))
    assert np.sum(ww) == pytest.approx(state[0], rel=1e-10, abs=0)
    assert np.sum(ww * bb) == pytest.approx(state[2 * n1], rel=1e-8, abs=0)
    work = fresh_work(n1, n2)
    params = np.zeros(P.N_PARAMS)
    realizable = cqmom.cqmom_realizable(state, np.zeros(1), params, config, work)
    # realizable = the conditions any population with 0 <= b <= p meets
    names = cqmom.state_names(n1, n2, True, False)
    bounded = all(state[i] >= 0 and (int(s[1]) + int(s[2]) >= 2 * n1 or state[i] <= state[
        int(s[1]) + int(s[2])] * (1 + 1e-8)) for i, s in enumerate(names) if s[2] != "0")
    assert realizable == bounded
    if not realizable:
        return
    before = state.copy()
    cqmom.cqmom_project(state, np.zeros(1), params, config, work)
    assert cqmom.cqmom_realizable(state, np.zeros(1), params, config, fresh_work(n1, n2))
    # M00, M10, M01 kept; with every size node present nothing changes (the mixed moments
    # stay as carried); with size nodes lost, the other moments become the points'
    assert state[0] == before[0] and state[1] == before[1] and state[2 * n1] == before[2 * n1]
    if len(np.unique(x)) == n1:
        assert np.array_equal(state, before)
    else:
        points = moments_of(x, bb, ww, n1, n2)
        keep = [0, 1, 2 * n1]
        rest = [k for k in range(len(state)) if k not in keep]
        assert state[rest] == pytest.approx(points[rest], rel=1e-10, abs=1e-300)


# --------------------------------------------------------------------------- right-hand side
def _cqmom_arrays(scene, n1, n2):
    """Packed arrays of a scene with the CQMOM configuration (local until cqmom is wired)."""
    arrays = model.pack(scene)
    arrays.config[P.METHOD] = -2
    arrays.config[P.ORDER] = n1
    arrays.config[P.BINDER_NODES] = n2
    arrays.state_names = cqmom.state_names(n1, n2, scene.bivariate, scene.separate_droplets)
    arrays.config[P.N_STATE] = len(arrays.state_names)
    return arrays


def _diameter(p, scene):
    """Particle diameter [m] from its total mass at the particle density (docs/physics.md,
    "sizes": a free droplet too)."""
    return (6.0 * p / (math.pi * scene.material.density)) ** (1.0 / 3.0)


def _kernel(scene, p1, p2, alpha, theta, d43):
    """beta [m3/s] of docs/physics.md section 4, written out from the scene's numbers."""
    agg = scene.aggregation
    k0 = agg.rate
    if agg.kernel == "constant":
        return k0
    if agg.kernel == "sum":
        return k0 * (p1 + p2)
    if agg.kernel == "product":
        return k0 * p1 * p2
    d1, d2 = _diameter(p1, scene), _diameter(p2, scene)
    if agg.kernel == "eke":          # Hounslow 1998: x = d / d_ref, d_ref of the mean mass
        d_ref = (agg.reference_diameter if agg.reference_diameter is not None
                 else _diameter(scene.initial.mean_mass, scene))
        x1, x2 = d1 / d_ref, d2 / d_ref
        return k0 * (x1 + x2) ** 2 * math.sqrt(1.0 / x1 ** 3 + 1.0 / x2 ** 3)
    assert agg.kernel == "ktgf"      # Goldschmidt; g0 of Sinclair & Jackson at min(alpha, cap)
    cap = scene.domain.alpha_min_friction
    a = min(alpha, cap) if cap is not None else alpha
    g0 = 1.0 / (1.0 - (a / scene.domain.alpha_max) ** (1.0 / 3.0))
    return (k0 * g0 * math.sqrt(theta) * d43 ** 1.5 * (d1 + d2) ** 2
            * math.sqrt(1.0 / d1 ** 3 + 1.0 / d2 ** 3))


def _success(scene, p1, b1, p2, b2, u0):
    """psi [-] of docs/physics.md section 6: the product of the switched-on factors."""
    m = scene.material
    psi = 1.0
    y1, y2 = b1 / p1, b2 / p2
    if "geometric" in scene.aggregation.efficiency:
        eta = [1.0 / (1.0 + math.exp(-m.accessible_binder_slope
                                     * (y - m.accessible_binder_centre))) for y in (y1, y2)]
        psi *= 1.0 - (1.0 - eta[0]) * (1.0 - eta[1])
    if "physical" in scene.aggregation.efficiency:
        d1, d2 = _diameter(p1, scene), _diameter(p2, scene)
        st = (4.0 * m.density * u0 * d1 * d2 * (d1 + d2) ** 2
              / (9.0 * m.binder_viscosity * (d1 ** 3 + d2 ** 3)))
        lam = m.gyration_radius * sum(math.exp(m.binder_layer_slope
                                               * (y - m.binder_layer_centre)) ** (1.0 / 3.0)
                                      for y in (y1, y2))
        st_crit = max(0.0, 2.0 * math.log(lam / m.asperity))
        w = m.stokes_switch_width
        if w > 0.0 and st_crit > 0.0:
            psi *= 0.5 * (1.0 - math.tanh((st - st_crit) / (w * st_crit)))
        else:
            psi *= 1.0 if st <= st_crit else 0.0
    if "saturation" in scene.aggregation.efficiency:
        solid = p1 + p2 - b1 - b2
        if solid > 0.0:
            sat = ((b1 + b2) / solid * m.density * (1.0 - m.porosity)
                   / (m.binder_density * m.porosity))
            psi *= min(1.0, sat / m.saturation_max)
    return psi


def _direct_sources(p, b, w, nd, scene, cell, names):
    """Exact moment sources [SI] of the discrete population (and free droplets nd [1/m3]),
    and the sum of the magnitudes of their terms (the scale of round-off). Pair rates from the
    formulas above; droplets pure binder (b = p_d) of the injection's diameter at the binder
    density, captured at droplet_factor x beta psi (docs/physics.md, "droplets")."""
    alpha, theta, u0, inj = cell[P.ALPHA], cell[P.THETA], cell[P.COLLISION_VELOCITY], \
        cell[P.INJECTION]
    pd = 0.0
    if scene.binder_injection is not None:
        pd = (scene.material.binder_density * math.pi / 6.0
              * scene.binder_injection.droplet_diameter ** 3)
    d43 = 0.0
    if scene.aggregation.kernel == "ktgf":
        d = np.array([_diameter(pi, scene) for pi in p])
        d43 = np.sum(w * d ** 4) / np.sum(w * d ** 3)

    def rate(p1, b1, p2, b2):
        return _kernel(scene, p1, p2, alpha, theta, d43) * _success(scene, p1, b1, p2, b2, u0)

    def capture(pi, bi):
        return scene.aggregation.droplet_factor * rate(pi, bi, pd, pd)

    src = np.zeros(len(names))
    mag = np.zeros(len(names))
    for s, name in enumerate(names):
        if name == "droplet_number_density":
            src[s] += inj
            mag[s] += inj
            for i in range(len(p)):
                flux = nd * w[i] * capture(p[i], b[i])
                src[s] -= flux
                mag[s] += flux
            continue
        k, l = int(name[1]), int(name[2])
        for i in range(len(p)):
            for j in range(len(p)):
                r = rate(p[i], b[i], p[j], b[j])
                birth = (p[i] + p[j]) ** k * (b[i] + b[j]) ** l
                death = p[i] ** k * b[i] ** l + p[j] ** k * b[j] ** l
                src[s] += 0.5 * w[i] * w[j] * r * (birth - death)
                mag[s] += 0.5 * w[i] * w[j] * r * (birth + death)
            if nd is not None:
                flux = nd * w[i] * capture(p[i], b[i])
                birth = (p[i] + pd) ** k * (b[i] + pd) ** l
                src[s] += flux * (birth - p[i] ** k * b[i] ** l)
                mag[s] += flux * (birth + p[i] ** k * b[i] ** l)
        if nd is None:
            src[s] += inj * pd ** (k + l)
            mag[s] += inj * pd ** (k + l)
    return src, mag


CASES = {
    "constant": dict(aggregation={"kernel": "constant", "rate": 1e-10}),
    "sum": dict(aggregation={"kernel": "sum", "rate": 1.0}),
    "product": dict(aggregation={"kernel": "product", "rate": 1e8}),
    "eke geometric physical": dict(
        material=AVICEL, domain={"collision_velocity": 0.5},
        aggregation={"kernel": "eke", "rate": 1e-11, "efficiency": ["geometric", "physical"]}),
    "ktgf saturation": dict(
        material=AVICEL, domain={"granular_temperature": 1e-3, "solids_fraction": 0.3},
        aggregation={"kernel": "ktgf", "rate": 1e-5, "efficiency": ["saturation"]}),
    "eke droplets injected": dict(
        material=AVICEL, domain={"collision_velocity": 0.5},
        aggregation={"kernel": "eke", "rate": 1e-11, "efficiency": ["geometric", "physical"],
                     "droplet_factor": 100.0},
        initial={"droplet_number_density": 3e8},
        binder_injection={"rate": 1e8, "droplet_diameter": 60e-6}),
    "constant injected as particles": dict(
        aggregation={"kernel": "constant", "rate": 1e-10},
        binder_injection={"rate": 1e8, "droplet_diameter": 60e-6}),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("n1,n2", [(2, 2), (3, 2), (2, 3)])
def test_rhs_equals_the_exact_sources_of_a_represented_population(case, n1, n2):
    scene = make_scene(initial={"binder_fraction": 0.1, **CASES[case].get("initial", {})},
                       **{k: v for k, v in CASES[case].items() if k != "initial"})
    arrays = _cqmom_arrays(scene, n1, n2)
    m0 = scene.initial.mean_mass
    masses = [m0 * f for f in (0.6, 1.7, 4.0)[:n1]]
    fractions = [[0.02, 0.15, 0.4][:n2], [0.0, 0.3, 0.7][:n2], [0.1, 0.25, 0.05][:n2]][:n1]
    weights = [[3e9, 1e9, 2e9][:n2], [2e9, 5e8, 1e9][:n2], [4e8, 2e8, 1e8][:n2]][:n1]
    p, b, w = tensor_population(masses, fractions, weights)
    separate = scene.separate_droplets
    nd = 3e8 if separate else None
    names = arrays.state_names
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    state = moments_of(p / p_ref, b / p_ref, w / n_ref, n1, n2,
                       droplets=nd / n_ref if separate else None)
    cell = model.well_mixed_cell(scene)[0]
    out = np.zeros_like(state)
    work = fresh_work(n1, n2)
    cqmom_sources.cqmom_rhs(state, out, cell, np.zeros(1), arrays.params, arrays.config, work)
    expected, magnitude = _direct_sources(p, b, w, nd, scene, cell, names)
    unit = np.array([n_ref * p_ref ** (int(s[1]) + int(s[2])) if s.startswith("M") else n_ref
                     for s in names])
    got = out * unit
    # the quadrature is the population: equal up to round-off of the inversion (its
    # conditioning with three masses spread by 7x and weights by 40x: ~1e-10 measured)
    assert np.all(np.abs(got - expected) <= 1e-9 * magnitude), np.abs(got - expected) / magnitude
    # number, mass and binder bookkeeping exact
    if not separate and scene.binder_injection is None:
        assert out[1] == 0.0 and out[2 * n1] == 0.0
