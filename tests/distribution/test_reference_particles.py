"""The independent particle-list reference (tests/references/cnmc_particles.py) against closed
forms of its size distribution, before it is used to judge the methods (docs/results/psd.md).

* constant kernel k0 from an exponential start of mean P0: the number density stays
  exponential, mean P0 (1 + tau/2), tau = k0 N0 t (docs/physics.md section 10);
* linear selection S = s0 p / P0 with uniform daughters from the same start: the density stays
  exponential, mean P0 / (1 + s0 t) (Ziff and McGrady 1985; M_k = N0 P0^k k! (1 + s0 t)^(1-k),
  section 8).

For an exponential number density of mean m the mass density p n(p) is gamma of shape 2, so
Q3 = P(2, p / m) and the mass-based percentiles are p_x = m P^(-1)(2, x). The ensemble's mean
percentile must lie within two 95% half-widths of the closed form (for R = 8 replicas about the
99.9% band, t_{0.999,7} = 4.79 ~ 2 t_{0.975,7}); the estimator's finite-N bias (a sample
quantile, O(1/N) = 5e-4 relative for N = 2000) is far inside it.
"""
import math
import os
import sys

import numpy as np
import pytest
from scipy.special import gammaincinv

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "references"))
import cnmc_particles  # noqa: E402

N0, P0, RHO = 1.0e10, 1.0e-9, 1000.0
FRACTIONS = (0.1, 0.5, 0.9)
PARTICLES, REPLICAS = 2000, 8


def exponential_percentiles(mean):
    """Mass-based d10, d50, d90 [m] of an exponential number density of mean mass [kg]."""
    p = mean * gammaincinv(2.0, np.array(FRACTIONS))
    return cnmc_particles.diameter(p, RHO)


def start(**extra):
    return dict({"rho": RHO, "kernel": "constant", "k0": 0.0, "p_ref": P0,
                 "initial": {"distribution": "exponential", "mean": P0, "number_density": N0}},
                **extra)


CASES = {
    "constant kernel, tau = 2": (start(k0=1.0e-10), 2.0, P0 * 2.0, 41),
    "linear breakage, s0 t = 2": (start(breakage={"s0": 1.0, "exponent": 1.0, "p_ref": P0,
                                                  "daughters": "uniform"}),
                                  2.0, P0 / 3.0, 42),
}


@pytest.mark.parametrize("name", list(CASES))
def test_reference_percentiles_match_the_closed_form(name):
    spec, t, mean, seed = CASES[name]
    e = cnmc_particles.ensemble(spec, PARTICLES, REPLICAS, seed, [t])
    got, half = e["percentiles"][0][0], e["percentiles"][1][0]
    want = exponential_percentiles(mean)
    assert np.all(np.abs(got - want) <= 2.0 * half), (got / want - 1.0, half / want)
    # the band is informative: narrower than 3% of the percentile
    assert np.all(half < 0.03 * want), half / want


def test_reference_number_density_of_the_constant_kernel():
    """M00 = 2 N0 / (2 + tau) within two half-widths; M10 exact by the volume rule."""
    spec, t, _, seed = CASES["constant kernel, tau = 2"]
    e = cnmc_particles.ensemble(spec, PARTICLES, REPLICAS, seed, [t])
    m, half = e["moments"][0][0], e["moments"][1][0]
    assert abs(m[0] - N0 / 2.0) <= 2.0 * half[0], (m[0] / (N0 / 2) - 1, half[0] / m[0])
    assert m[1] == pytest.approx(N0 * P0, rel=1e-12, abs=0.0)


def test_reference_capture_keeps_the_mass_balance():
    """Constant kernel with droplets (factor 10, injection): the box volume follows the mass
    balance at every event, so granule mass + free droplets' mass = M10(0) + p_d (n_d(0) + R t)
    up to the injection expected between the last event and the output time, R p_d dt with dt
    the mean waiting time (the box's event rate is ~ 200 /s here: 1e-4 of the mass; the bound
    is 10 waiting times), and the free droplets stay a non-negative density."""
    p_d = 0.2 * P0
    spec = start(k0=1.0e-10, droplets={"p_d": p_d, "factor": 10.0, "rate": 1.0e9,
                                       "nd0": 1.0e9})
    for p, b, vol, nd in cnmc_particles.simulate(spec, 500, 7, [0.5, 1.0]):
        pass
    assert np.sum(p) / vol + nd * p_d == pytest.approx(N0 * P0 + p_d * (1e9 + 1e9 * 1.0),
                                                       rel=1e-3, abs=0.0)
    assert nd >= 0.0 and np.all(b <= p)
