"""Gamma-EQMOM inversion, secondary quadrature and size distribution against references of
their own (no integrator): moments of gamma mixtures from the rising factorials
x (x + sigma) ... (x + (k-1) sigma) (the moments of a gamma density of mean x and variance
x sigma) checked by numerical integration of the density with scipy; the Gauss rule of a gamma
density against Gamma(l + k) / Gamma(l); Q3 of a mixture against scipy.stats.gamma.

Tolerances: the fit is a root of a smooth function solved to |J| <= 1e-11 (relative), so
recovered sigma, centres and weights of a well-separated mixture hold to ~1e-9 relative
(the conditioning of the Gauss rule of normalised moments of order <= 2N amplifies round-off
by at most ~1e4 here); 1e-8 is asserted.
"""
import math

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.special import gammaln, poch

from pbe_cfd.runs import model
from pbe_cfd.distribution import tables
from pbe_cfd.distribution.kernel_mixture import of_states
from pbe_cfd.methods.eqmom import entry, state as S
from pbe_cfd.methods.registry import method_plan
from pbe_cfd.methods.quadrature import gamma_inversion as I
from pbe_cfd.methods.eqmom.sources import eqmom_on_closure, eqmom_project, eqmom_realizable

from conftest import make_scene

MIXTURES = [  # (weights, centres, sigma), normalised units
    ([1.0], [2.0], 0.7),
    ([0.3, 0.7], [1.0, 4.0], 0.3),
    ([0.2, 0.5, 0.3], [0.5, 2.0, 6.0], 0.2),
]


def mixture_moments(w, x, sigma, count):
    """Moments by integrating the gamma densities numerically (scipy.integrate.quad), in
    units of the largest centre (quad's absolute scale)."""
    c = max(x)
    if c != 1.0:
        return mixture_moments(w, [xa / c for xa in x], sigma / c, count) * c ** np.arange(count)
    out = []
    for k in range(count):
        total = 0.0
        for wa, xa in zip(w, x):
            shape = xa / sigma
            dens = lambda p, s=shape: np.exp((s - 1) * np.log(p) - p / sigma  # noqa: E731
                                             - gammaln(s) - s * math.log(sigma))
            total += wa * integrate.quad(lambda p: p ** k * dens(p), 0, np.inf,
                                         epsabs=0, epsrel=1e-13, limit=400)[0]
        out.append(total)
    return np.array(out)


@pytest.mark.parametrize("mix", MIXTURES, ids=["1-kernel", "2-kernels", "3-kernels"])
def test_fit_recovers_a_gamma_mixture(mix):
    w, x, sigma = mix
    n = len(w)
    m = mixture_moments(w, x, sigma, 2 * n + 1)
    mean = m[1] / m[0]
    u = m / (m[0] * mean ** np.arange(2 * n + 1))
    nodes, weights, res, work = np.zeros(n), np.zeros(n), np.zeros(2), np.zeros(400)
    status, count = I.invert_normalised(u, n, nodes, weights, work, res)
    assert status == I.FIT and count == n
    assert res[0] * mean == pytest.approx(sigma, rel=1e-8, abs=0)
    order = np.argsort(nodes)
    assert nodes[order] * mean == pytest.approx(sorted(x), rel=1e-8, abs=0)
    assert weights[order] * m[0] == pytest.approx(np.array(w)[np.argsort(x)], rel=1e-8, abs=0)


def test_exponential_is_one_kernel_of_width_the_mean():
    """n(x) = e^(-x): m_k = k!; any N gives one kernel of shape 1 (sigma = mean)."""
    for n in (1, 2, 3):
        u = np.array([math.factorial(k) for k in range(2 * n + 1)], float)
        nodes, weights, res, work = np.zeros(n), np.zeros(n), np.zeros(2), np.zeros(400)
        status, count = I.invert_normalised(u, n, nodes, weights, work, res)
        assert status == I.FIT and count == 1
        assert res[0] == pytest.approx(1.0, rel=1e-10, abs=0)
        assert nodes[0] == pytest.approx(1.0, rel=1e-10, abs=0)


def test_discrete_and_boundary_sets_fall_back_to_qmom():
    """N deltas: m_2N on the boundary (DISCRETE, sigma = 0, N nodes); fewer deltas than
    kernels: REDUCED with that many nodes; M_2N below the Gauss rule's: not invertible."""
    x, w = np.array([0.5, 1.5]), np.array([0.5, 0.5])
    u = np.array([np.sum(w * x ** k) for k in range(5)])
    nodes, weights, res, work = np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(400)
    assert I.invert_normalised(u, 2, nodes, weights, work, res) == (I.DISCRETE, 2)
    assert res[0] == 0.0 and np.sort(nodes) == pytest.approx(x, rel=1e-12, abs=0)
    mono = np.ones(7)
    assert I.invert_normalised(mono, 3, np.zeros(3), np.zeros(3), work, res)[0] == I.REDUCED
    low = u.copy()
    low[4] *= 1.0 - 1e-6
    assert I.invert_normalised(low, 2, nodes, weights, work, res)[0] == I.FAILED


@pytest.mark.parametrize("shape", [0.3, 1.0, 7.5, 4.0e4])
def test_secondary_rule_integrates_gamma_moments(shape):
    n_sec = 5
    pts, wts, work = np.zeros(n_sec), np.zeros(n_sec), np.zeros(2 * n_sec)
    assert I.gamma_rule(shape, n_sec, pts, wts, work)
    for k in range(2 * n_sec):
        exact = math.exp(gammaln(shape + k) - gammaln(shape))
        assert np.sum(wts * pts ** k) == pytest.approx(exact, rel=1e-9, abs=0), k


@pytest.mark.parametrize("nodes", [1, 2, 3, 4])
def test_the_secondary_rule_is_exact_to_the_degree_the_sources_need(nodes):
    """The sources of the top moment M_(2N)0 reach degree 2N + 1 in a kernel's variable (the
    sum kernel) and 2N + 2 (power-law selection with a = 2); ``secondary_nodes(N)`` Gauss
    points per gamma kernel must integrate every power up to 2N + 2 exactly (docs/physics.md
    section 16). A rule of n points is exact to degree 2n - 1, so N + 1 points miss x^(2N+2)
    by a relative amount of order one; round-off of the rule is ~1e-13."""
    n_sec = S.secondary_nodes(nodes)
    pts, wts, work = np.zeros(n_sec), np.zeros(n_sec), np.zeros(2 * n_sec)
    for shape in (0.3, 7.5):
        assert I.gamma_rule(shape, n_sec, pts, wts, work)
        for k in range(2 * nodes + 3):
            exact = math.exp(gammaln(shape + k) - gammaln(shape))
            assert np.sum(wts * pts ** k) == pytest.approx(exact, rel=1e-9, abs=0), (shape, k)


def _scene(bivariate=True, nodes=2):
    return make_scene(initial={"distribution": "exponential", "number_density": 1e10,
                               "mean_mass": 1e-9, "binder_fraction": 0.2 if bivariate else 0.0},
                      method={"_replace": True, "name": "eqmom", "nodes": nodes})


def _state(arrays, w, x, sigma, y=None):
    """Scaled state of a gamma mixture (SI weights [1/m3], centres and sigma [kg]) with binder
    fraction y per kernel."""
    n = int(arrays.config[4])
    mom = mixture_moments(w, x, sigma, 2 * n + 1)
    scale = arrays.number_scale * arrays.mass_scale ** np.arange(2 * n + 1)
    parts = [mom / scale]
    if y is not None:
        mk1 = [sum(wa * ya * np.prod([xa + j * sigma for j in range(k + 1)])
                   for wa, xa, ya in zip(w, x, y)) for k in range(n)]
        parts.append(np.array(mk1) / (arrays.number_scale
                                      * arrays.mass_scale ** (np.arange(n) + 1)))
    return np.concatenate(parts)


def test_binder_fraction_per_kernel_is_recovered_and_bounded():
    scene = _scene()
    arrays = model.pack(scene)
    aux = entry.aux(scene, arrays)
    w, x, sigma = [4e9, 6e9], [0.6e-9, 2.5e-9], 0.2e-9
    state = _state(arrays, w, x, sigma, y=[0.1, 0.3])
    sig, xs, ws, ys, status = entry.kernels_si(state, aux, arrays)
    assert status == I.FIT
    assert ys[np.argsort(xs)] == pytest.approx([0.1, 0.3], rel=1e-7, abs=0)
    work = np.zeros(4096)
    assert eqmom_realizable(state, aux, arrays.params, arrays.config, work)
    # a binder moment past its bound (b <= p in every particle: M_k1 <= M_(k+1)0): not
    # realizable, for M01 and for M11
    for k in (0, 1):
        bad = state.copy()
        bad[5 + k] = 1.01 * bad[1 + k]
        assert not eqmom_realizable(bad, aux, arrays.params, arrays.config, work), k
    # binder moments within their bounds that no kernel fractions in [0, 1] reproduce (M11
    # raised to 1.2 M10 in scaled units, 0.49 of M20): the closure's limit, realizable but
    # off the closure (what the repair after transport re-projects); the projection puts them
    # on the bounded fractions, keeping M01, and then on the closure
    assert eqmom_on_closure(state, aux, arrays.params, arrays.config, work)
    odd = state.copy()
    odd[6] = 1.2 * odd[1]
    assert odd[6] < odd[2]
    assert eqmom_realizable(odd, aux, arrays.params, arrays.config, work)
    assert not eqmom_on_closure(odd, aux, arrays.params, arrays.config, work)
    projected = odd.copy()
    eqmom_project(projected, aux, arrays.params, arrays.config, work)
    assert projected[5] == odd[5] and projected[:5].tolist() == odd[:5].tolist()
    assert projected[6] != odd[6]
    assert eqmom_on_closure(projected, aux, arrays.params, arrays.config, work)
    sig, xs, ws, ys, _ = entry.kernels_si(projected, aux, arrays)
    assert np.all((ys >= 0.0) & (ys <= 1.0))


def test_distribution_is_the_gamma_mixture_and_names_a_failed_cell():
    scene = _scene(bivariate=False)
    arrays = model.pack(scene)
    aux = entry.aux(scene, arrays)
    w, x, sigma = [4e9, 6e9], [0.6e-9, 2.5e-9], 0.2e-9
    good = _state(arrays, w, x, sigma)
    broken = good.copy()
    broken[4] = 0.5 * broken[4]                 # M40 below the Gauss rule's
    recon = of_states(np.vstack([good, broken]), aux, arrays, 1000.0, False,
                      labels=lambda r: f"cell {r + 7}")
    d = np.geomspace(50e-6, 300e-6, 9)
    p = math.pi / 6 * 1000.0 * d ** 3
    want = sum(wa * xa * stats.gamma.cdf(p, xa / sigma + 1.0, scale=sigma)
               for wa, xa in zip(w, x)) / sum(wa * xa for wa, xa in zip(w, x))
    assert recon.cdf(d)[0] == pytest.approx(want, rel=1e-9, abs=1e-12)
    cols, notes = tables.size_columns(recon, labels=lambda r: f"cell {r + 7}")
    assert any("cell 8" in n and "not invertible" in n for n in notes), notes
    assert np.all(np.isfinite(cols["d50_m"])) and cols["d50_m"][1] == 0.0
    assert cols["d50_m"][0] > 0.0
    hint = entry.failure_hint(method_plan(scene), arrays, broken, aux)
    assert "not invertible" in hint


def test_projection_keeps_number_and_mass_and_puts_a_reduced_set_on_its_fit():
    scene = _scene(bivariate=False, nodes=3)
    arrays = model.pack(scene)
    aux = entry.aux(scene, arrays)
    x = 1e-9 / arrays.mass_scale
    state = np.array([1.0, x, x ** 2 * (1 + 1e-13), x ** 3, x ** 4, x ** 5, x ** 6 * 1.5])
    work = np.zeros(4096)
    before = state.copy()
    eqmom_project(state, aux, arrays.params, arrays.config, work)
    assert state[0] == before[0] and state[1] == before[1]
    assert state[6] == pytest.approx(x ** 6, rel=1e-9, abs=0)


# ---- the fewer-kernel fallback --------------------------------------------------------------
#: a fewer-kernel fit reproduces the moments it fits: m_0 .. m_(2n-1) by its Gauss rule (round-off
#: amplified by at most ~1e4 here, 1e-12), m_2n to the root acceptance 1e3 ROOT_TOLERANCE
FIT_TOLERANCE = 1.0e3 * I.ROOT_TOLERANCE


def gamma_mixture_moments(w, x, sigma, count):
    """Closed-form moments of a gamma mixture: sum_a w_a sigma^k Gamma(l_a + k) / Gamma(l_a),
    l_a = x_a / sigma (scipy's Pochhammer symbol)."""
    return np.array([sum(wa * sigma ** k * poch(xa / sigma, k) for wa, xa in zip(w, x))
                     for k in range(count)])


def _normalised(m):
    mean = m[1] / m[0]
    return m / (m[0] * mean ** np.arange(m.size)), mean


def _invert(u, n, min_shape):
    nodes, weights, res, work = np.zeros(n), np.zeros(n), np.zeros(2), np.zeros(400)
    status, count = I.invert_normalised(u, n, nodes, weights, work, res, min_shape)
    return status, res[0], nodes[:count], weights[:count]


def _fit_moments(sigma, nodes, weights, count):
    return np.array([np.sum(weights * np.array([I.kernel_moment(x, sigma, k) for x in nodes]))
                     for k in range(count)])


def test_no_three_kernel_root_falls_back_to_two_kernels_of_sigma_above_zero():
    """Two gamma kernels with M50 lowered 1%: the three-kernel J has no root on the range
    where the star moments have a three-node rule; the closest sigma misses M60 by 3.6%. The
    fallback is two kernels of sigma > 0 fitted to M00 .. M40: the two kernels themselves
    (their M00 .. M40 determine them), M00 .. M40 reproduced, positive weights; they miss the
    moments they drop (M50 by 1%) by less than the closest sigma misses M60. Without the
    fallback: the closest sigma."""
    w, x, sigma = [0.3, 0.7], [1.0, 4.0], 0.3
    m = gamma_mixture_moments(w, x, sigma, 7)
    m[5] *= 0.99
    u, mean = _normalised(m)
    status, s, nodes, weights = _invert(u, 3, 0.0)
    assert status == I.FEWER and nodes.size == 2
    assert s > 0.0 and np.all(weights > 0.0) and np.all(nodes > 0.0)
    assert s * mean == pytest.approx(sigma, rel=1e-8, abs=0)
    assert np.sort(nodes) * mean == pytest.approx(x, rel=1e-8, abs=0)
    fit = _fit_moments(s, nodes, weights, 7)
    assert fit[:5] == pytest.approx(u[:5], rel=FIT_TOLERANCE, abs=0)
    fewer_miss = np.max(np.abs(fit[5:] / u[5:] - 1.0))
    res = np.zeros(2)
    assert I.invert_normalised(u, 3, np.zeros(3), np.zeros(3), np.zeros(400), res)[0] \
        == I.CLOSEST
    assert fewer_miss == pytest.approx(1.0 / 0.99 - 1.0, rel=1e-6, abs=0)
    assert fewer_miss < abs(res[1])


def test_a_kernel_narrower_than_the_aggregation_kernel_allows_is_not_used():
    """Three kernels, one of shape l = 0.2: fitted as they are for a kernel finite at small
    partners (min_shape 0); for EKE (beta ~ x^(-1/2): infinite M00 sources for l <= 1/2) the
    three-kernel root is refused and two kernels of shape > 1/2 fit M00 .. M40."""
    w, x, sigma = [0.2, 0.5, 0.3], [0.06, 2.0, 6.0], 0.3
    u, mean = _normalised(gamma_mixture_moments(w, x, sigma, 7))
    status, s, nodes, weights = _invert(u, 3, 0.0)
    assert status == I.FIT and s * mean == pytest.approx(sigma, rel=1e-8, abs=0)
    assert np.sort(nodes) * mean == pytest.approx(x, rel=1e-8, abs=0)
    status, s, nodes, weights = _invert(u, 3, 0.5)
    assert status == I.FEWER and nodes.size == 2
    assert s > 0.0 and np.all(weights > 0.0) and np.all(nodes / s > 0.5)
    assert _fit_moments(s, nodes, weights, 5) == pytest.approx(u[:5], rel=FIT_TOLERANCE, abs=0)


def test_eke_state_takes_the_fewer_kernel_fit_projects_the_rest_and_names_it():
    """The narrow three-kernel state of an EKE scene: the inversion takes two kernels, the
    state is realizable, the projection keeps M00 .. M40 and writes M50, M60 of the two
    kernels (rising factorials, closed form), and the diagnostics name the fallback."""
    scene = make_scene(initial={"distribution": "exponential", "number_density": 1e10,
                                "mean_mass": 1e-9},
                       aggregation={"kernel": "eke", "rate": 1.77e-11,
                                    "reference_diameter": 1.24e-4},
                       method={"_replace": True, "name": "eqmom", "nodes": 3})
    arrays = model.pack(scene)
    aux = entry.aux(scene, arrays)
    w, x, sigma = [2e9, 5e9, 3e9], [0.06e-9, 2e-9, 6e-9], 0.3e-9
    state = gamma_mixture_moments(w, x, sigma, 7) / (arrays.number_scale
                                                      * arrays.mass_scale ** np.arange(7))
    sig, xs, ws, _, status = entry.kernels_si(state, aux, arrays)
    assert status == I.FEWER and xs.size == 2 and sig > 0.0 and np.all(ws > 0.0)
    assert np.all(xs / sig > 0.5)
    work = np.zeros(S.work_size(3, state.size))
    assert eqmom_realizable(state, aux, arrays.params, arrays.config, work)
    before = state.copy()
    eqmom_project(state, aux, arrays.params, arrays.config, work)
    assert state[:5] == pytest.approx(before[:5], rel=FIT_TOLERANCE, abs=0)
    want = gamma_mixture_moments(ws, xs, sig, 7)[5:] / (
        arrays.number_scale * arrays.mass_scale ** np.arange(5, 7))
    assert state[5:] == pytest.approx(want, rel=1e-10, abs=0)
    assert abs(state[6] / before[6] - 1.0) > 1e-3          # M60 was not the fit's
    _, notes = entry.diagnostics(np.vstack([before, before]), aux, arrays)
    assert any("2 of 2" in n and "fewer kernels" in n for n in notes), notes
