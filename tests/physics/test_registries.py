"""The registries (kernels, efficiency factors, methods) against the rest of the program.

Parametrized over the registry entries, so an entry added by the recipe of CONTRIBUTING.md is
checked without touching this file: its dispatch branch returns what its own function returns,
the property groups it declares are all it reads, the scene accepts its name, and codes are
unique. An unknown code must give NaN, never another kernel's value.
"""
import dataclasses
import math

import numpy as np
import pytest

from pbe_cfd.scene import scene as S
from pbe_cfd.methods import registry as M
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.efficiency import (EFFICIENCY_REGISTRY, pair_success_probability,
                                        success_probability)
from pbe_cfd.physics.kernels import (KERNEL_REGISTRY, collision_frequency, kernel_cell_factor,
                                     kernel_property_groups, kernel_uses_d43,
                                     pair_collision_frequency)
from pbe_cfd.physics.properties import ALL_GROUPS, N_PROPS, fill_properties
from test_physics_registry import avicel_params

KERNEL_NAMES = [k.name for k in KERNEL_REGISTRY]
FACTOR_NAMES = [e.name for e in EFFICIENCY_REGISTRY]
#: an integer no registry uses
UNKNOWN = 1 + max(k.code for k in KERNEL_REGISTRY)


def rows(pairs, params, groups):
    props = np.zeros((len(pairs), N_PROPS))
    for r, (p, b) in enumerate(pairs):
        fill_properties(p, b, params, groups, props, r)
    return props


# fixed draws, made once at import from their own generator: the same in every test whatever
# the order the tests run in (each test that draws more has its own seeded generator)
_PAIRS = np.random.default_rng(5)
MASSES = 10 ** _PAIRS.uniform(-11, -8, (40, 2))           # kg
BINDER_SHARE = _PAIRS.uniform(0.0, 0.5, (40, 2))
CELLS = [(0.3, 1e-3, 1.2e-4), (0.05, 1e-6, 3e-4), (0.55, 2e-4, 8e-5)]   # alpha, Theta, d43


# ------------------------------------------------------------------------------ kernels
def test_kernel_names_and_codes_are_unique_and_the_scene_takes_them():
    codes = [k.code for k in KERNEL_REGISTRY]
    assert len(set(codes)) == len(codes) and min(codes) >= 0
    assert len(set(KERNEL_NAMES)) == len(KERNEL_NAMES)
    assert S.KERNEL_NAMES == tuple(KERNEL_NAMES)


@pytest.mark.parametrize("name", KERNEL_NAMES)
def test_kernel_dispatch_is_its_own_function(name):
    """Every dispatcher's branch for the entry's code gives exactly what the entry declares."""
    k = next(e for e in KERNEL_REGISTRY if e.name == name)
    params = avicel_params()
    assert kernel_property_groups(k.code) == k.properties
    assert kernel_uses_d43(k.code) == k.uses_d43
    for alpha, theta, d43 in CELLS:
        factor = kernel_cell_factor(k.code, alpha, theta, d43, params)
        assert factor == k.cell_factor(alpha, theta, d43, params)
        assert math.isfinite(factor) and factor > 0
        for p1, p2 in MASSES:
            props = rows([(p1, 0.0), (p2, 0.0)], params, k.properties)
            beta = pair_collision_frequency(k.code, props, 0, 1, factor, params)
            assert beta == k.function(props, 0, 1, factor, params)
            assert beta == collision_frequency(k.code, p1, p2, alpha, theta, d43, params)
            assert math.isfinite(beta) and beta > 0
            swapped = rows([(p2, 0.0), (p1, 0.0)], params, k.properties)
            # abs=0: beta is ~1e-13 m3/s here, below approx's default abs of 1e-12
            assert k.function(swapped, 0, 1, factor, params) == pytest.approx(beta, rel=1e-14, abs=0)


@pytest.mark.parametrize("name", KERNEL_NAMES)
def test_kernel_reads_only_the_properties_it_declares(name):
    """With only its declared property groups filled the kernel gives the value it gives with
    every group filled: a column read but not declared would be 0 and change it."""
    k = next(e for e in KERNEL_REGISTRY if e.name == name)
    params = avicel_params()
    factor = k.cell_factor(*CELLS[0], params)
    for p1, p2 in MASSES:
        declared = rows([(p1, 0.0), (p2, 0.0)], params, k.properties)
        full = rows([(p1, 0.0), (p2, 0.0)], params, ALL_GROUPS)
        assert k.function(declared, 0, 1, factor, params) == k.function(full, 0, 1, factor,
                                                                         params)


def test_an_unknown_kernel_code_gives_nan():
    params = avicel_params()
    props = rows([(1e-9, 0.0), (2e-9, 0.0)], params, ALL_GROUPS)
    assert math.isnan(pair_collision_frequency(UNKNOWN, props, 0, 1, 1.0, params))
    assert math.isnan(kernel_cell_factor(UNKNOWN, 0.3, 1e-3, 1e-4, params))
    assert math.isnan(collision_frequency(UNKNOWN, 1e-9, 2e-9, 0.3, 1e-3, 1e-4, params))
    assert math.isnan(collision_frequency(-1, 1e-9, 2e-9, 0.3, 1e-3, 1e-4, params))
    assert kernel_property_groups(UNKNOWN) == 0 and not kernel_uses_d43(UNKNOWN)


# ------------------------------------------------------------------------------ efficiency
def test_factor_names_codes_and_switches_agree_with_the_scene_and_the_layout():
    codes = [e.code for e in EFFICIENCY_REGISTRY]
    assert sorted(codes) == list(range(len(codes)))
    assert len(codes) <= P.MAX_EFFICIENCIES
    assert S.EFFICIENCY_NAMES == tuple(FACTOR_NAMES)
    switches = {e.name: e.switch for e in EFFICIENCY_REGISTRY}
    assert (switches["geometric"], switches["physical"], switches["saturation"]) == (
        P.USE_GEOMETRIC, P.USE_PHYSICAL, P.USE_SATURATION)
    assert max(switches.values()) < P.N_CONFIG
    by_code = {e.code: e.name for e in EFFICIENCY_REGISTRY}   # the named switches: code order
    assert [name for name, _ in P.EFFICIENCY_FACTORS] == [
        f"USE_{by_code[k].upper()}" for k in range(len(P.EFFICIENCY_FACTORS))]
    assert sorted(single_config_slots().values()) == list(range(P.N_SWITCHES_START))
    material = {f.name for f in dataclasses.fields(S.Material)}
    for e in EFFICIENCY_REGISTRY:
        assert set(e.material) <= material, e.name


def single_config_slots():
    """The named single slots of ``config`` (the table ``physics.parameters.CONFIG``, numbered
    in its order): distinct, below the efficiency switches."""
    return {name: getattr(P, name) for name, _ in P.CONFIG}


def config_with(names):
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    for e in EFFICIENCY_REGISTRY:
        config[e.switch] = int(e.name in names)
    return config


@pytest.mark.parametrize("name", FACTOR_NAMES)
def test_each_switch_turns_on_its_own_factor(name):
    """With only its switch on, psi is the factor's own function of the pair; it is a
    probability, symmetric, and needs only the property groups it declares."""
    e = next(f for f in EFFICIENCY_REGISTRY if f.name == name)
    params = avicel_params()
    config = config_with([name])
    rng = np.random.default_rng(6)
    for (p1, p2), (y1, y2) in zip(MASSES, BINDER_SHARE):
        u0 = float(rng.uniform(0.0, 5.0))
        pair = [(p1, y1 * p1), (p2, y2 * p2)]
        full = rows(pair, params, ALL_GROUPS)
        value = e.function(full, 0, 1, u0, params)
        assert 0.0 <= value <= 1.0
        assert pair_success_probability(full, 0, 1, u0, params, config) == value
        assert success_probability(p1, y1 * p1, p2, y2 * p2, u0, params, config) == value
        assert e.function(rows(pair, params, e.properties), 0, 1, u0, params) == value
        swapped = rows(pair[::-1], params, ALL_GROUPS)
        assert e.function(swapped, 0, 1, u0, params) == pytest.approx(value, rel=1e-12,
                                                                      abs=1e-300)


def test_switched_factors_multiply():
    params = avicel_params()
    config = config_with(FACTOR_NAMES)
    for (p1, p2), (y1, y2) in zip(MASSES, BINDER_SHARE):
        full = rows([(p1, y1 * p1), (p2, y2 * p2)], params, ALL_GROUPS)
        product = 1.0
        for e in EFFICIENCY_REGISTRY:
            product *= e.function(full, 0, 1, 0.5, params)
        assert pair_success_probability(full, 0, 1, 0.5, params, config) == pytest.approx(
            product, rel=1e-15, abs=0.0)
    none = config_with([])
    assert pair_success_probability(full, 0, 1, 0.5, params, none) == 1.0


# ------------------------------------------------------------------------------ methods
def test_method_registry_agrees_with_the_scene_and_dispatch():
    assert M.METHOD_NAMES == tuple(m.name for m in M.METHOD_REGISTRY)
    with pytest.raises(S.SceneError, match="qmom"):    # the scene asks the registry
        S._method("<scene>", {"name": "nonsense"})
    codes = [m.code for m in M.METHOD_REGISTRY if m.integrated]
    assert len(set(codes)) == len(codes)
    assert set(M.MOMENT_METHODS) == {m.name for m in M.METHOD_REGISTRY if m.integrated}


@pytest.mark.parametrize("name", [m.name for m in M.METHOD_REGISTRY if m.integrated])
def test_a_moment_method_packs_its_code_order_and_state(name):
    from conftest import make_scene

    from pbe_cfd.runs import model
    entry = M.METHODS[name]
    scene = make_scene(method={"name": name, "_replace": True},
                       initial={"binder_fraction": 0.1})
    arrays = model.pack(scene)
    assert arrays.config[P.METHOD] == entry.code
    assert arrays.config[P.ORDER] == entry.order(scene.method)
    assert arrays.state_names == entry.state_names(scene)
    assert arrays.config[P.N_STATE] == len(arrays.state_names)
    assert entry.plan_line(scene)


# ------------------------------------------------------------------------------ breakage
from pbe_cfd.physics import breakage as B  # noqa: E402

SELECTION_NAMES = [s.name for s in B.SELECTION_REGISTRY]
DAUGHTER_NAMES = [d.name for d in B.DAUGHTER_REGISTRY]


def breakage_params(exponent):
    params = avicel_params()
    params[P.BREAKAGE_RATE] = 0.07
    params[P.BREAKAGE_EXPONENT] = exponent
    params[P.BREAKAGE_REFERENCE_MASS] = 5e-10
    params[P.BREAKAGE_REFERENCE_THETA] = 1e-3
    return params


def test_breakage_names_codes_and_slots_agree_with_the_scene_and_the_layout():
    for registry, names in ((B.SELECTION_REGISTRY, S.SELECTION_NAMES),
                            (B.DAUGHTER_REGISTRY, S.DAUGHTER_NAMES)):
        codes = [e.code for e in registry]
        assert len(set(codes)) == len(codes) and min(codes) >= 0
        assert names == tuple(e.name for e in registry)
    fields = {f.name for f in dataclasses.fields(S.Breakage)}
    for s in B.SELECTION_REGISTRY:
        assert set(s.keys) <= fields & set(S._BREAKAGE_KEYS), s.name
        assert set(s.cell_fields) <= {"solids_fraction", "granular_temperature"}
    singles = single_config_slots()
    for name in ("BREAKAGE", "BREAKAGE_SELECTION", "BREAKAGE_DAUGHTERS"):
        assert singles[name] == getattr(P, name)


@pytest.mark.parametrize("name", SELECTION_NAMES)
@pytest.mark.parametrize("exponent", [0.0, 0.5, 1.0, 2.0])
def test_selection_dispatch_is_its_own_function_and_monotone(name, exponent):
    """Each dispatcher branch gives the entry's own functions; S >= 0, finite, and monotone in
    p (the cNMC bounds S on a mass interval by its ends)."""
    s = B.SELECTION_BY_NAME[name]
    params = breakage_params(exponent)
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.BREAKAGE], config[P.BREAKAGE_SELECTION] = 1, s.code
    masses = np.sort(10 ** np.random.default_rng(7).uniform(-13, -7, 60))
    for alpha, theta, _ in CELLS:
        u0 = 4.0 * math.sqrt(theta / math.pi)
        factor = B.selection_cell_factor(s.code, alpha, theta, u0, params)
        assert factor == s.cell_factor(alpha, theta, u0, params)
        assert math.isfinite(factor) and factor > 0
        values = []
        for p in masses:
            rate = B.selection_function(s.code, p, factor, params)
            assert rate == s.function(p, factor, params)
            assert rate == B.selection_rate(p, alpha, theta, u0, params, config)
            assert math.isfinite(rate) and rate >= 0
            values.append(rate)
        steps = np.diff(values)
        assert np.all(steps >= 0) or np.all(steps <= 0)


@pytest.mark.parametrize("name", DAUGHTER_NAMES)
def test_daughter_rule_dispatch_counts_mass_and_sampling(name):
    """F(0) = 2 daughters and F(1) = 1 (mass kept) exactly; the Monte Carlo share u(r), r
    uniform in (0, 1), reproduces F: int_0^1 (u^k + (1 - u)^k) dr = F(k). The integral by the
    midpoint rule on n and 2n cells (n = 20,000): whatever the rule's order (u(r) may be
    singular at the ends, e.g. an inverse distribution function), the error of the 2n sum is
    at most the difference of the two sums once the rule converges (order >= 1); tolerance
    twice that, plus round-off. A share that samples another distribution converges to
    another value and fails."""
    d = B.DAUGHTERS_BY_NAME[name]
    assert B.daughter_moment_factor(d.code, 0.0) == 2.0 == d.moments(0.0)
    assert B.daughter_moment_factor(d.code, 1.0) == 1.0 == d.moments(1.0)
    sums = []
    for n in (20000, 40000):
        r = (np.arange(n) + 0.5) / n
        u = np.array([B.daughter_share(d.code, x) for x in r])
        assert np.all((u > 0) & (u < 1))
        assert np.array_equal(u, np.array([d.share(x) for x in r]))
        sums.append([np.mean(u ** k + (1 - u) ** k) for k in range(7)])
    for k in range(7):
        tol = 2.0 * abs(sums[1][k] - sums[0][k]) + 1e-12
        assert sums[1][k] == pytest.approx(B.daughter_moment_factor(d.code, float(k)),
                                           abs=tol), k


def test_an_unknown_breakage_code_gives_nan():
    params = breakage_params(1.0)
    unknown = 1 + max(s.code for s in B.SELECTION_REGISTRY)
    assert math.isnan(B.selection_function(unknown, 1e-9, 0.1, params))
    assert math.isnan(B.selection_cell_factor(unknown, 0.3, 1e-3, 0.1, params))
    unknown = 1 + max(d.code for d in B.DAUGHTER_REGISTRY)
    assert math.isnan(B.daughter_moment_factor(unknown, 2.0))
    assert math.isnan(B.daughter_share(unknown, 0.3))


@pytest.mark.slow
def test_an_unknown_method_code_gives_nan_not_another_methods_numbers():
    """The run-time method dispatch has no fallback: a code no method owns yields NaN rates
    (which stop the cell) and an unrealizable state, never QMOM's numbers."""
    from pbe_cfd.methods.dispatch import WORK_SIZE, method_realizable, method_rhs
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.METHOD] = 99
    config[P.ORDER] = 2
    config[P.N_STATE] = 4
    params = np.ones(P.N_PARAMS)
    state = np.array([1.0, 1.0, 1.1, 1.3])
    out = np.zeros(4)
    method_rhs(state, out, np.zeros(P.N_CELL), np.zeros(1), params, config, np.zeros(WORK_SIZE))
    assert np.all(np.isnan(out))
    assert not method_realizable(state, np.zeros(1), params, config, np.zeros(WORK_SIZE))
