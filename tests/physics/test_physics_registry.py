"""The physics registry: every kernel and efficiency factor, by name, against hand values."""
import math

import numpy as np
import pytest

from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.efficiency import (EFFICIENCIES, critical_stokes_number, stokes_number,
                                        success_probability)
from pbe_cfd.physics.kernels import (KERNELS, collision_frequency, kernel_cell_factor,
                                     radial_distribution)
from pbe_cfd.physics.properties import N_PROPS
from pbe_cfd.physics.rates import particle_properties
from pbe_cfd.physics.rates import aggregation_rate, droplet_capture_rate


def all_on(kernel_code=0):
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.KERNEL] = kernel_code
    config[P.USE_GEOMETRIC] = 1
    config[P.USE_PHYSICAL] = 1
    return config


def props_of(pairs, params, config):
    props = np.zeros((len(pairs), N_PROPS))
    for row, (p, b) in enumerate(pairs):
        particle_properties(p, b, params, config, props, row)
    return props


def kernel(name, p1, p2, alpha, theta, d43, params):
    """A registry kernel evaluated through its own function (not the dispatcher)."""
    code, fn, _ = KERNELS[name]
    props = props_of([(p1, 0.0), (p2, 0.0)], params, all_on(code))
    return fn(props, 0, 1, kernel_cell_factor(code, alpha, theta, d43, params), params)


def factor(name, p1, b1, p2, b2, u0, params):
    """A registry efficiency factor evaluated through its own function."""
    props = props_of([(p1, b1), (p2, b2)], params, all_on())
    return EFFICIENCIES[name][1](props, 0, 1, u0, params)


def avicel_params():
    params = np.zeros(P.N_PARAMS)
    params[P.RATE] = 2.5e-14
    params[P.DENSITY] = 1021.0
    params[P.BINDER_DENSITY] = 1000.0
    params[P.BINDER_VISCOSITY] = 0.762
    params[P.REFERENCE_VOLUME] = math.pi / 6 * (100.4e-6) ** 3
    params[P.ALPHA_MAX] = 0.62
    params[P.GEO_SLOPE] = 35.1
    params[P.GEO_CENTRE] = 0.129
    params[P.PHI_SLOPE] = 25.9
    params[P.PHI_CENTRE] = 0.327
    params[P.ASPERITY] = 6.3e-6
    params[P.GYRATION_RADIUS] = 60e-6
    params[P.POROSITY] = 0.4
    params[P.SATURATION_MAX] = 1.0
    params[P.DROPLET_FACTOR] = 100.0
    params[P.DROPLET_MASS] = 1000.0 * math.pi / 6 * (60e-6) ** 3
    return params


P1, P2 = 5.4e-10, 2.0e-9          # kg
B1, B2 = 0.05e-10, 0.6e-9         # kg


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_dispatch_matches_registry_and_is_symmetric(name):
    code, fn, _ = KERNELS[name]
    params = avicel_params()
    direct = kernel(name, P1, P2, 0.3, 1e-3, 1.2e-4, params)
    via = collision_frequency(code, P1, P2, 0.3, 1e-3, 1.2e-4, params)
    assert via == direct
    assert direct > 0 and math.isfinite(direct)
    assert kernel(name, P2, P1, 0.3, 1e-3, 1.2e-4, params) == pytest.approx(direct, rel=1e-15,
                                                                             abs=0)


def test_kernel_hand_values():
    params = avicel_params()
    k0 = params[P.RATE]
    assert kernel("constant", P1, P2, 0, 0, 0, params) == k0
    assert kernel("sum", P1, P2, 0, 0, 0, params) == pytest.approx(k0 * (P1 + P2), rel=1e-12,
                                                                  abs=0)
    assert kernel("product", P1, P2, 0, 0, 0, params) == pytest.approx(k0 * P1 * P2, rel=1e-12,
                                                                      abs=0)
    # eke of two reference particles: k0 (1 + 1)^2 sqrt(2)
    vref_mass = params[P.REFERENCE_VOLUME] * params[P.DENSITY]
    assert kernel("eke", vref_mass, vref_mass, 0, 0, 0, params) == pytest.approx(
        k0 * 4 * math.sqrt(2), rel=1e-12, abs=0)
    # ktgf of two equal particles of diameter d43: k0 g0 sqrt(T) (2d)^2 sqrt(2)
    d = (6 * P1 / (math.pi * 1021.0)) ** (1 / 3)
    alpha, theta = 0.3, 1e-3
    g0 = 1 / (1 - (alpha / 0.62) ** (1 / 3))
    expected = k0 * g0 * math.sqrt(theta) * (2 * d) ** 2 * math.sqrt(2)
    assert kernel("ktgf", P1, P1, alpha, theta, d, params) == pytest.approx(expected,
                                                                               rel=1e-12, abs=0)


def test_radial_distribution_limits():
    assert radial_distribution(0.0, 0.62) == 1.0
    assert radial_distribution(0.62, 0.62) == math.inf
    assert radial_distribution(0.62 * (1 - 1e-6), 0.62) > 1e6


@pytest.mark.parametrize("name", sorted(EFFICIENCIES))
def test_efficiency_is_a_symmetric_probability(name):
    params = avicel_params()
    rng = np.random.default_rng(3)
    for _ in range(200):
        p1, p2 = 10 ** rng.uniform(-11, -8, 2)
        b1, b2 = p1 * rng.uniform(0, 1), p2 * rng.uniform(0, 1)
        u0 = rng.uniform(0, 10)
        value = factor(name, p1, b1, p2, b2, u0, params)
        assert 0.0 <= value <= 1.0
        assert factor(name, p2, b2, p1, b1, u0, params) == pytest.approx(value, rel=1e-12,
                                                                          abs=1e-300)


def test_geometric_factor_dry_and_wet():
    params = avicel_params()
    eta_dry = 1 / (1 + math.exp(35.1 * 0.129))
    assert factor("geometric", P1, 0.0, P2, 0.0, 1.0, params) == pytest.approx(
        1 - (1 - eta_dry) ** 2, rel=1e-12, abs=0)
    # a pure binder droplet always offers a wet contact
    assert factor("geometric", P1, 0.0, P2, P2, 1.0, params) == pytest.approx(1.0, abs=1e-9)


def test_stokes_criterion_hand_values():
    params = avicel_params()
    d1, d2 = 100.4e-6, 60e-6
    p1 = 1021 * math.pi / 6 * d1 ** 3
    p2 = 1021 * math.pi / 6 * d2 ** 3
    st = 4 * 1021 * 5.5 * d1 * d2 * (d1 + d2) ** 2 / (9 * 0.762 * (d1 ** 3 + d2 ** 3))
    props = props_of([(p1, 0.0), (p2, p2)], params, all_on())
    assert stokes_number(props, 0, 1, 5.5, params) == pytest.approx(st, rel=1e-12, abs=0)
    phi1 = math.exp(25.9 * (0 - 0.327))
    phi2 = math.exp(25.9 * (1 - 0.327))
    lam = 60e-6 * (phi1 ** (1 / 3) + phi2 ** (1 / 3))
    assert critical_stokes_number(props, 0, 1, params) == pytest.approx(
        2 * math.log(lam / 6.3e-6), rel=1e-12, abs=0)
    assert factor("physical", p1, 0.0, p2, p2, 5.5, params) == 1.0   # droplet on a dry granule
    assert factor("physical", p1, 0.0, p1, 0.0, 5.5, params) == 0.0  # two dry granules rebound


def test_smooth_stokes_switch_tends_to_the_step():
    params = avicel_params()
    d = 100.4e-6
    p = 1021 * math.pi / 6 * d ** 3
    b = 0.3 * p
    props = props_of([(p, b), (p, b)], params, all_on())
    st_crit = critical_stokes_number(props, 0, 1, params)
    # the velocity at which St = St*
    u_edge = 5.5 * st_crit / stokes_number(props, 0, 1, 5.5, params)
    params[P.STOKES_WIDTH] = 0.05
    assert factor("physical", p, b, p, b, u_edge, params) == pytest.approx(0.5, rel=1e-12, abs=0)
    assert factor("physical", p, b, p, b, 1.5 * u_edge, params) < 1e-4
    assert factor("physical", p, b, p, b, 0.5 * u_edge, params) > 1 - 1e-4


def test_saturation_factor():
    params = avicel_params()
    # H = 0.1: S = 0.1 * 1021 * 0.6 / (1000 * 0.4)
    p, b = 1.1e-9, 0.1e-9
    s = 0.1 * 1021 * 0.6 / (1000 * 0.4)
    assert factor("saturation", p, b, p, b, 1.0, params) == pytest.approx(s, rel=1e-12, abs=0)
    assert factor("saturation", p, 0.0, p, 0.0, 1.0, params) == 0.0


def test_rates_combine_kernel_efficiency_and_droplet_factor():
    params = avicel_params()
    config = all_on(KERNELS["eke"][0])
    pd = params[P.DROPLET_MASS]
    beta = kernel("eke", P1, pd, 0, 0, 0, params)
    psi = success_probability(P1, B1, pd, pd, 5.5, params, config)
    assert droplet_capture_rate(P1, B1, 0, 0, 5.5, 0, params, config) == pytest.approx(
        100.0 * beta * psi, rel=1e-14, abs=0)
    assert aggregation_rate(P1, B1, P2, B2, 0, 0, 5.5, 0, params, config) == pytest.approx(
        kernel("eke", P1, P2, 0, 0, 0, params)
        * success_probability(P1, B1, P2, B2, 5.5, params, config), rel=1e-14, abs=0)
