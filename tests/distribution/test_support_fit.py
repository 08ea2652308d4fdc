"""The size distribution on the granules' support [p_min, inf) (docs/physics.md section 11.1):
without breakage no granule is lighter than the smallest initial granule, so the gamma
kernels are fitted to the moments of p - p_min.

References written here, sharing no code with the package: the mass density (p_min + u)
n(u) of a gamma mixture in u = p - p_min integrated by scipy's adaptive quadrature (``quad``),
its percentiles by ``brentq`` on that integral, and the Gauss rule of test_distribution
(Golub and Welsch). Tolerances: quad's 1e-12 relative error on Q3 -> 1e-9 on a percentile
(Q3's slope in ln d is O(1)); the inversion's root tolerance 1e-11 (relative, on the highest
moment) -> 1e-8 on Q3 and sigma, as in test_distribution's unshifted exactness test.
"""
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.special import gamma as gamma_fn

from conftest import make_scene
from pbe_cfd.distribution import kernel_mixture as KM
from pbe_cfd.distribution import tables
from pbe_cfd.distribution.quantiles import bisect_quantiles
from pbe_cfd.scene.scene import SceneError
from test_distribution import _gauss_rule, _two_gamma_moments

N0, P0, RHO = 1.0e10, 1.0e-9, 1000.0
FRACTIONS = (0.1, 0.5, 0.9)


def _d(p):
    return (6.0 * np.asarray(p, float) / (math.pi * RHO)) ** (1.0 / 3.0)


def _mixture_q3(w, x, sigma, s):
    """Q3(p) [-] of sum_a w_a gamma(shape x_a / sigma, scale sigma) in u = p - s, by quad of
    the mass density (s + u) n(u) over u (masses in units of P0)."""
    def dens(u):
        return (s + u) * sum(wa * u ** (xa / sigma - 1) * math.exp(-u / sigma)
                             / (gamma_fn(xa / sigma) * sigma ** (xa / sigma))
                             for wa, xa in zip(w, x))
    total = float(np.sum(np.asarray(w) * (s + np.asarray(x))))

    def q3(p):
        if p <= s:
            return 0.0
        # split at the kernels' centres: quad resolves the u^(l-1) edge and the peaks
        cuts = [0.0] + sorted(xa for xa in x if xa < p - s) + [p - s]
        return sum(quad(dens, a, b, epsabs=0, epsrel=1e-12, limit=200)[0]
                   for a, b in zip(cuts[:-1], cuts[1:])) / total
    return q3


def _shifted_population(w, x, sigma, s, nodes):
    """The n-node Gauss rule of the mixture's moments in u, shifted to p = s + u [kg]."""
    weights, u = _gauss_rule(_two_gamma_moments(w, x, sigma, 2 * nodes), nodes)
    return weights * N0, (s + u) * P0


def test_the_support_fit_recovers_a_shifted_two_kernel_mixture():
    """QMOM N = 3 nodes of a two-kernel gamma mixture in u = p - s (s = 2 P0): the fit of 2
    kernels to the moments of p - s is that mixture: sigma, Q3 and the percentiles are the
    quadrature reference's."""
    w, x, sigma, s = np.array([0.6, 0.4]), np.array([1.0, 4.0]), 0.5, 2.0
    weights, nodes = _shifted_population(w, x, sigma, s, 3)
    mix = KM.of_nodes([(weights, nodes, np.zeros(3))], RHO, False, floor=s * P0)
    assert mix.notes == []
    assert mix.sigma[0] == pytest.approx(sigma * P0, rel=1e-8, abs=0)
    q3 = _mixture_q3(w, x, sigma, s)
    p = s + np.geomspace(0.01, 30.0, 25)
    assert mix.cdf(_d(p * P0))[0] == pytest.approx([q3(v) for v in p], rel=0, abs=1e-8)
    want = [brentq(lambda v: q3(v) - f, s * (1 + 1e-12), s + 200.0, xtol=1e-14, rtol=1e-13)
            for f in FRACTIONS]
    assert mix.quantiles(FRACTIONS)[0] == pytest.approx(_d(np.array(want) * P0), rel=1e-8,
                                                        abs=0)


def test_no_granule_is_drawn_below_the_floor_and_the_moments_are_kept():
    """Primaries p0 and aggregates (QMOM N = 2 nodes p0 and 3 p0, 90% / 10% by number): with
    the floor p0 the reconstruction holds no mass below p0 (Q3 = 0 there, d10 >= d(p0)),
    where the fit on [0, inf) of the same nodes puts mass below it; and its density carries
    the nodes' M00, M10, M20 (quad of p^k n(p) over [p0, inf), 1e-9)."""
    w, p = np.array([0.9, 0.1]) * N0, np.array([1.0, 3.0]) * P0
    support = KM.of_nodes([(w, p, np.zeros(2))], RHO, False, floor=P0)
    free = KM.of_nodes([(w, p, np.zeros(2))], RHO, False)
    below = _d(P0) * (1 - 1e-9)
    assert support.cdf(np.array([below]))[0, 0] == 0.0
    assert free.cdf(np.array([below]))[0, 0] > 0.01
    assert support.quantiles(FRACTIONS)[0, 0] >= _d(P0)
    assert free.quantiles(FRACTIONS)[0, 0] < _d(P0)
    sig, x, cw = support.sigma[0] / P0, support.x[0, 0] / P0, support.w[0, 0]   # in P0
    shape = x / sig

    def n(u):                                       # number density per unit u / P0
        return cw * u ** (shape - 1) * math.exp(-u / sig) / (gamma_fn(shape) * sig ** shape)
    for k in range(3):
        got = sum(quad(lambda u: (1.0 + u) ** k * n(u), a, b, epsabs=0, epsrel=1e-12,
                       limit=200)[0] for a, b in ((0.0, x), (x, np.inf))) * P0 ** k
        assert got == pytest.approx(np.sum(w * p ** k), rel=1e-9, abs=0), k


def test_percentiles_on_a_floor_are_the_bisection_of_their_own_q3():
    """Rows of 2 and 3 nodes above a floor (random, seed 2027, drawn before looking): Newton's
    percentiles equal a 60-halving bisection of the row's own Q3 over 1 nm .. 10 m (2^-60 of
    23 decades is 5e-17 in ln d) to 1e-12 in d; a row at the floor (a delta, also with a
    round-off spread of its nodes) is d(floor), without a fallback note."""
    rng = np.random.default_rng(2027)
    for n in (2, 3):
        pops = []
        for _ in range(40):
            wr = rng.uniform(0.05, 1.0, n) * N0
            pr = (1.0 + np.sort(rng.uniform(0.01, 8.0, n))) * P0
            pops.append((wr, pr, np.zeros(n)))
        pops.append((np.full(n, N0), np.full(n, P0), np.zeros(n)))
        # a monodisperse row with round-off spread about the floor (nodes 1e-13 apart)
        pops.append((np.full(n, N0), P0 * (1.0 + 1e-13 * np.arange(n)), np.zeros(n)))
        mix = KM.of_nodes(pops, RHO, False, floor=P0, labels=lambda r: f"row {r};")
        last = (f"row {len(pops) - 2};", f"row {len(pops) - 1};")
        assert not [note for note in mix.notes if any(r in note for r in last)]
        wide = bisect_quantiles(mix.cdf, FRACTIONS, mix.rows)
        assert mix.quantiles(FRACTIONS) == pytest.approx(wide, rel=1e-12, abs=0), n
        for row in (-2, -1):
            assert mix.quantiles(FRACTIONS)[row] == pytest.approx([_d(P0)] * 3, rel=1e-12,
                                                                  abs=0)


def test_signed_weights_keep_their_moments():
    """The Laguerre ROM's points carry negative weights; their moments are the carried ones.
    One kernel on the moments of p - s of a signed set is the closed form: mean_s = M1s/M0,
    sigma = (u2 - 1) mean_s, u2 = M2s M0 / M1s^2."""
    w = np.array([0.5, 0.8, -0.1, 0.3]) * N0
    p = np.array([1.2, 2.0, 2.5, 4.0]) * P0
    s = P0
    mix = KM.of_nodes([(w, p, np.zeros(4))], RHO, False, floor=s, kernels=1, signed=True)
    m = [np.sum(w * (p - s) ** k) for k in range(3)]
    u2 = m[2] * m[0] / m[1] ** 2
    assert mix.sigma[0] == pytest.approx((u2 - 1.0) * m[1] / m[0], rel=1e-12, abs=0)
    assert mix.w[0, 0] == pytest.approx(m[0], rel=1e-12, abs=0)
    unsigned = KM.of_nodes([(w, p, np.zeros(4))], RHO, False, floor=s, kernels=1)
    assert unsigned.w[0, 0] == pytest.approx(np.sum(w[w > 0]), rel=1e-12, abs=0)


def _floor_scene(**tables_):
    return make_scene(**tables_)


def test_the_floor_is_the_smallest_granule_the_physics_allows():
    """p_min: a monodisperse start without breakage keeps every granule at or above p0 (with
    drying, above its solids (1 - y0) p0); droplets counted as particles lower it to p_d;
    breakage or an exponential start give 0."""
    base = _floor_scene()
    assert tables.support_floor(base) == pytest.approx(1e-9, rel=1e-15, abs=0)
    expo = _floor_scene(initial={"distribution": "exponential"})
    assert tables.support_floor(expo) == 0.0
    broken = _floor_scene(aggregation={"kernel": "constant", "rate": 1e-11},
                          breakage={"selection": "constant", "rate": 0.1})
    assert tables.support_floor(broken) == 0.0
    p_d = math.pi / 6 * 1000.0 * (60e-6) ** 3
    drops = _floor_scene(aggregation={"kernel": "constant", "rate": 1e-11},
                         binder_injection={"rate": 1e8, "droplet_diameter": 60e-6})
    assert not drops.separate_droplets
    assert tables.support_floor(drops) == pytest.approx(p_d, rel=1e-12, abs=0)
    own = _floor_scene(aggregation={"kernel": "constant", "rate": 1e-11,
                                    "droplet_factor": 100.0},
                       binder_injection={"rate": 1e8, "droplet_diameter": 60e-6})
    assert own.separate_droplets
    assert tables.support_floor(own) == pytest.approx(1e-9, rel=1e-15, abs=0)
    wet = _floor_scene(initial={"binder_fraction": 0.2},
                       drying={"air_temperature": 330.0, "air_humidity": 0.005,
                               "slip_velocity": 1.0, "critical_moisture": 0.1})
    assert tables.support_floor(wet) == pytest.approx(0.8e-9, rel=1e-12, abs=0)


def test_the_reconstruction_is_chosen_in_the_method_table():
    """[method] size_distribution: "semi-infinite" is the fit on [0, inf) (the former
    reconstruction), "support" the default; a choice the method lacks is refused naming the
    key, as is the key for the cNMC, which has none to choose."""
    scene = make_scene(method={"_replace": True, "name": "qmom", "nodes": 2})
    assert tables.size_distribution(scene) == "support"
    old = make_scene(method={"_replace": True, "name": "qmom", "nodes": 2,
                             "size_distribution": "semi-infinite"})
    assert tables.size_distribution(old) == "semi-infinite"
    assert "[0, inf)" in tables.distribution_text(old)
    assert "p_min = 1e-09 kg" in tables.distribution_text(scene)
    with pytest.raises(SceneError, match="method.size_distribution"):
        make_scene(method={"_replace": True, "name": "qmom", "size_distribution": "expansion"})
    with pytest.raises(SceneError, match="method.size_distribution"):
        make_scene(method={"_replace": True, "name": "cnmc", "size_distribution": "support"})
    lag = make_scene(method={"_replace": True, "name": "laguerre",
                             "size_distribution": "expansion"})
    assert tables.size_distribution(lag.with_method(name="qmom", nodes=2)) == "support"


def test_the_seed_scenes_d10_stays_at_or_above_the_primary_granule():
    """The default run (seed-wurster, QMOM N = 2, no breakage): no granule is lighter than the
    dry primary of 100.4 um, so d10 >= 100.4 um at every output time; the former fit on
    [0, inf) of the same run's moments puts d10 below it (94.6 um at 130 s)."""
    from pbe_cfd.runs.simulate import run_well_mixed
    from pbe_cfd.scene.scene import load_scene
    scene = load_scene("seed-wurster")
    d0 = scene.initial.mean_mass
    d_primary = (6.0 * d0 / (math.pi * scene.material.density)) ** (1.0 / 3.0)
    res = run_well_mixed(scene)
    d10 = np.asarray(res.columns["d10_m"])
    assert np.all(d10 >= d_primary * (1.0 - 1e-12)), d10.min()
    former = run_well_mixed(scene.with_method(size_distribution="semi-infinite"))
    assert np.asarray(former.columns["d10_m"]).min() < 0.97 * d_primary
