"""Lognormal EQMOM (``[method] kernel = "lognormal"``): inversion, Gauss-Hermite secondary
quadrature and size distribution against references of their own (no integrator).

References: the moments of a lognormal mixture by numerical integration of its density
(scipy.integrate.quad in ln x), the moments of order q (fractional and negative too) of a
lognormal kernel likewise, and Q3 and percentiles of the mass distribution from
scipy.stats.lognorm of the mass density p n(p).

Tolerances: the fit is a root solved to |J| <= 1e-11, so the recovered sigma, medians and
weights of a well-separated mixture hold to ~1e-9 (as the gamma fit,
test_eqmom_inversion.py); 1e-8 is asserted. The Gauss-Hermite rule of 20 nodes integrates
e^(c t) against the normal density to a relative 3.6e-12 at c = 3 and less below (evaluated
with numpy's hermegauss, the relative error of sum h_j e^(c t_j) against e^(c^2/2)), so the
particles' moments of order q with |q| sigma <= 2.8 hold to the 1e-10 asserted. Q3 and percentiles
are closed forms in scipy's normal functions on both sides: 1e-12 and the Newton search's
precision QUANTILE_PRECISION = 1e-13 in mass (1e-12 asserted, in diameter 1e-12 too).
"""
import math

import numpy as np
import pytest
from scipy import integrate, stats

from pbe_cfd.distribution.lognormal_mixture import LognormalMixture
from pbe_cfd.methods.eqmom import state as S
from pbe_cfd.methods.quadrature import gamma_inversion as I
from pbe_cfd.runs import model

from conftest import make_scene

MIXTURES = [  # (weights, medians, sigma of ln x), normalised units
    ([1.0], [2.0], 0.5),
    ([0.3, 0.7], [0.5, 4.0], 0.3),
    ([0.2, 0.5, 0.3], [0.3, 2.0, 9.0], 0.25),
]


def lognormal_moment(q, median, sigma):
    """int x^q n(x) dx of a unit lognormal density by quadrature in s = ln x."""
    dens = lambda s: np.exp(q * s - 0.5 * ((s - math.log(median)) / sigma) ** 2) / (  # noqa
        sigma * math.sqrt(2.0 * math.pi))
    c = math.log(median) + q * sigma ** 2
    return integrate.quad(dens, c - 40 * sigma, c + 40 * sigma, epsabs=0, epsrel=1e-13,
                          limit=400)[0]


def mixture_moments(w, x, sigma, count):
    return np.array([sum(wa * lognormal_moment(k, xa, sigma) for wa, xa in zip(w, x))
                     for k in range(count)])


@pytest.mark.parametrize("mix", MIXTURES, ids=["1-kernel", "2-kernels", "3-kernels"])
def test_fit_recovers_a_lognormal_mixture(mix):
    w, x, sigma = mix
    n = len(w)
    m = mixture_moments(w, x, sigma, 2 * n + 1)
    mean = m[1] / m[0]
    u = m / (m[0] * mean ** np.arange(2 * n + 1))
    nodes, weights, res, work = np.zeros(n), np.zeros(n), np.zeros(2), np.zeros(400)
    status, count = I.invert_normalised(u, n, nodes, weights, work, res, 0.0, I.LOGNORMAL)
    assert status == I.FIT and count == n
    assert res[0] == pytest.approx(sigma, rel=1e-8, abs=0)
    order = np.argsort(nodes)
    assert nodes[order] * mean == pytest.approx(sorted(x), rel=1e-8, abs=0)
    assert weights[order] * m[0] == pytest.approx(np.array(w)[np.argsort(x)], rel=1e-8, abs=0)


def test_one_lognormal_kernel_fits_any_three_moments():
    """One kernel: exp(sigma^2) = u_2 (the exponential's u_2 = 2: sigma = sqrt(ln 2)); the
    fewer-kernel fallback of N = 3 on a set of one kernel's moments gives that kernel."""
    u = np.array([1.0, 1.0, 2.0])
    nodes, weights, res, work = np.zeros(1), np.zeros(1), np.zeros(2), np.zeros(400)
    status, count = I.invert_normalised(u, 1, nodes, weights, work, res, 0.0, I.LOGNORMAL)
    assert status == I.FIT and count == 1
    assert res[0] == pytest.approx(math.sqrt(math.log(2.0)), rel=1e-10, abs=0)
    assert nodes[0] == pytest.approx(math.exp(-0.5 * math.log(2.0)), rel=1e-10, abs=0)


def test_discrete_set_is_qmom():
    x, w = np.array([0.5, 1.5]), np.array([0.5, 0.5])
    u = np.array([np.sum(w * x ** k) for k in range(5)])
    nodes, weights, res, work = np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(400)
    assert I.invert_normalised(u, 2, nodes, weights, work, res, 0.0, I.LOGNORMAL) == \
        (I.DISCRETE, 2)
    assert res[0] == 0.0 and np.sort(nodes) == pytest.approx(x, rel=1e-12, abs=0)


@pytest.mark.parametrize("q", [-0.5, 1.0 / 3.0, 1.0, 4.0, 7.0])
def test_hermite_particles_integrate_fractional_moments(q):
    """The secondary particles of one kernel (median 2, sigma 0.4) against the kernel's
    moment of order q by quadrature (|q| sigma <= 2.8)."""
    scene = make_scene(method={"_replace": True, "name": "eqmom", "nodes": 1,
                               "kernel": "lognormal"})
    arrays = model.pack(scene)
    aux = S.aux_array(1, "lognormal")
    median, sigma = 2.0, 0.4
    state = np.array([lognormal_moment(k, median, sigma) for k in range(3)])
    X, W, _ = S.particles_of(state, arrays.config, aux)
    assert len(X) == S.secondary_nodes(1, "lognormal")
    assert np.sum(W * X ** q) == pytest.approx(lognormal_moment(q, median, sigma), rel=1e-10,
                                               abs=0)


def test_mass_distribution_and_percentiles_against_scipy():
    """Two kernels (SI): Q3 against the mass-weighted sum of scipy's lognormal distribution
    functions of the mass densities (ln-mean ln x_a + sigma^2), and d50 against its root."""
    rho, sigma = 1000.0, 0.35
    x, w = np.array([2e-10, 3e-9]), np.array([4e9, 1e9])
    mix = LognormalMixture([(sigma, x, w, np.zeros(2), I.FIT)], rho, False, I.STATUS_TEXT)
    mass = w * x * math.exp(0.5 * sigma ** 2)
    dists = [stats.lognorm(s=sigma, scale=xa * math.exp(sigma ** 2)) for xa in x]

    def q3(p):
        return sum(m * d.cdf(p) for m, d in zip(mass, dists)) / mass.sum()
    d = np.geomspace(3e-5, 3e-4, 7)
    p = rho * math.pi / 6.0 * d ** 3
    assert mix.cdf(d)[0] == pytest.approx(q3(p), rel=0, abs=1e-12)
    from scipy.optimize import brentq
    p50 = brentq(lambda v: q3(v) - 0.5, 1e-12, 1e-6, xtol=1e-25, rtol=1e-15)
    d50 = (6.0 * p50 / (math.pi * rho)) ** (1.0 / 3.0)
    assert mix.quantiles([0.5])[0, 0] == pytest.approx(d50, rel=1e-12, abs=0)
