"""A method is one package plus one registration: a toy method defined here (numba functions
and a ``MethodEntry``, nothing else) and registered from the test suite is picked up by the
scene parser (its own ``[method]`` key into its own options dataclass), ``model.pack``, the
per-cell integrator (literal dispatch), ``pbe-cfd plan`` and the bench's method list, with no
edit of the package.

The toy is the monodisperse two-moment closure of constant-kernel aggregation: state
(m0, m1) = (M0 / N_ref, M1 / (N_ref p_ref)), dm0/dt = -k0 N_ref m0^2 / 2, dm1/dt = 0. For the
constant kernel that closure is exact for M0 and M1 (Smoluchowski: dM0/dt = -k0 M0^2 / 2,
dM1/dt = 0), so the run must follow M0(t) = M0(0) / (1 + k0 M0(0) t / 2) and keep M1. The
toy's own key ``rate_factor`` f [-] scales its kernel (k0 -> f k0, handed to the kernel
through its aux), so the same run at f = 2 follows M0(0) / (1 + f k0 M0(0) t / 2)."""
import dataclasses
import inspect
import zlib

import numba as nb
import numpy as np
import pytest

from pbe_cfd.methods import registry
from pbe_cfd.methods.entry import MethodEntry, no_diagnostics, no_hint
from pbe_cfd.physics import parameters as P
from pbe_cfd.scene.scene import load_scene, scene_from_dict


@nb.njit(cache=False)
def toy_rhs(state, out, cell, aux, params, config, work):
    """d(m0, m1)/dt [1/s] of the constant kernel, k0 = params[RATE] [m3/s]."""
    out[0] = -0.5 * aux[0] * params[P.RATE] * params[P.NUMBER_SCALE] * state[0] * state[0]
    out[1] = 0.0


@nb.njit(cache=False)
def toy_realizable(state, aux, params, config, work):
    """A number and a mass, both non-negative."""
    return state[0] >= 0.0 and state[1] >= 0.0


@nb.njit(cache=False)
def toy_project(state, aux, params, config, work):
    """Every non-negative pair is on the set: nothing to do."""
    return


@nb.njit(cache=False)
def toy_conserved(config, params, pivots, coefs):
    """The granule mass m1 is invariant: one row, pivot 1."""
    coefs[0, 0] = 0.0
    coefs[0, 1] = 1.0
    pivots[0] = 1
    return 1


def _population(state, aux, arrays):
    """One node: number m0 N_ref [1/m3] of mass (m1 / m0) p_ref [kg], no binder."""
    w = state[0] * arrays.number_scale
    p = state[1] / state[0] * arrays.mass_scale if state[0] > 0 else 0.0
    return np.array([w]), np.array([p]), np.zeros(1)


#: the toy's code follows its source, so an edited toy never meets a kernel compiled (and
#: cached on disk by the integrator) for an earlier toy
_SOURCE = "".join(inspect.getsource(f.py_func) for f in (toy_rhs, toy_realizable, toy_project,
                                                          toy_conserved))
TOY_CODE = 1000 + zlib.crc32(_SOURCE.encode()) % 1_000_000

@dataclasses.dataclass(frozen=True)
class ToyOptions:
    """The toy's own [method] key: rate_factor [-], the factor on the kernel's rate."""
    rate_factor: float = 1.0


def _toy_keys(t, defaults):
    return {"rate_factor": t.number("rate_factor", defaults.rate_factor, positive=True)}


def _toy_aux(scene, arrays, theta_grid=None):
    """[rate_factor]: the toy's method data."""
    return np.array([scene.method.options.rate_factor])


TOY = MethodEntry(
    name="toy", code=TOY_CODE, scene_keys=_toy_keys, options=ToyOptions, order_key=None,
    order_label="toy", state_names=lambda scene: ["M00", "M10"], aux=_toy_aux,
    tabulates_theta=False, population=_population, failure_hint=no_hint,
    diagnostics=no_diagnostics, plan_line=lambda scene: "toy two-moment closure",
    rhs=toy_rhs, realizable=toy_realizable, project=toy_project, conserved=toy_conserved,
    bench_orders=int, bench_scene=lambda scene, order: scene, bench_quick=("1",),
    bench_full=("1", "2"))


@pytest.fixture
def toy():
    registry.register(TOY)
    yield TOY
    registry.unregister(TOY.name)


def _toy_scene(**keys):
    data = dict(load_scene("constant-kernel").raw)
    data["method"] = {"name": "toy", "rtol": 1e-9} | keys
    return scene_from_dict(data)


def test_the_scene_parser_and_pack_take_a_registered_method(toy):
    scene = _toy_scene()
    assert scene.method.name == "toy"
    assert scene.method.options == ToyOptions(rate_factor=1.0)
    assert _toy_scene(rate_factor=2.5).method.options == ToyOptions(rate_factor=2.5)
    from pbe_cfd.runs import model
    arrays = model.pack(scene)
    assert arrays.config[P.METHOD] == TOY_CODE
    assert arrays.state_names == ["M00", "M10"]
    assert arrays.config[P.N_STATE] == 2


def test_an_unregistered_method_is_refused(toy):
    registry.unregister(TOY.name)
    from pbe_cfd.scene.scene import SceneError
    with pytest.raises(SceneError, match="toy"):
        _toy_scene()
    registry.register(TOY)


def test_the_scene_routes_method_keys_to_the_toy_and_refuses_the_others(toy):
    """A key of another method (QMOM's nodes) given to the toy, and the toy's key given to
    the QMOM, are refused naming the key, the method that owns it and the keys it takes."""
    from pbe_cfd.scene.scene import SceneError
    with pytest.raises(SceneError, match=r"\[method.nodes\] a key of the qmom, cqmom, eqmom "
                       r"methods, not of toy; toy takes: name, rtol, atol, integrator, "
                       r"size_distribution, rate_factor"):
        _toy_scene(nodes=3)
    data = dict(load_scene("constant-kernel").raw)
    data["method"] = {"name": "qmom", "rate_factor": 2.0}
    with pytest.raises(SceneError, match=r"\[method.rate_factor\] a key of the toy method, not "
                       r"of qmom; qmom takes: name, rtol, atol, integrator, size_distribution, "
                       r"nodes"):
        scene_from_dict(data)
    with pytest.raises(SceneError, match=r"\[method.rate_factr\] unknown key for the toy "
                       r"method; toy takes: .*rate_factor"):
        _toy_scene(rate_factr=2.0)
    assert _toy_scene().with_method(rate_factor=3.0).method.options.rate_factor == 3.0


def test_plan_and_bench_list_name_the_registered_method(toy):
    from pbe_cfd.cli_bench import method_list as _method_list
    from pbe_cfd.runs.plan import describe_plan
    assert "toy two-moment closure" in describe_plan(_toy_scene())
    assert _method_list("toy:1,qmom:2") == (("toy", 1), ("qmom", 2))
    from pbe_cfd.bench.throughput import default_methods
    assert default_methods(quick=True)[-1] == ("toy", 1)
    assert default_methods(quick=False)[-2:] == (("toy", 1), ("toy", 2))


def test_the_integrator_runs_the_registered_method_to_the_analytic_solution(toy):
    from pbe_cfd.runs.simulate import run_well_mixed
    scene = _toy_scene()
    res = run_well_mixed(scene)
    t = res.columns["time_s"]
    n0 = scene.initial.number_density
    k0 = scene.aggregation.rate
    exact = n0 / (1.0 + 0.5 * k0 * n0 * t)
    # error of an adaptive RK3(2) run at rtol 1e-9 over <= ~1e3 steps of a contracting ODE:
    # at most the sum of the local errors, ~1e3 x 1e-9 of M0
    assert res.columns["M00"] == pytest.approx(exact, rel=1e-6, abs=0.0)
    m1 = n0 * scene.initial.mean_mass
    assert res.columns["M10"] == pytest.approx(np.full_like(t, m1), rel=1e-12, abs=0.0)
    assert res.stats["accepted_steps"] > 0


@pytest.mark.parametrize("factor", [2.0])
def test_the_toys_own_key_reaches_its_kernel(toy, factor):
    """rate_factor f, read by the toy's options only, scales the decay: M0 follows
    M0(0) / (1 + f k0 M0(0) t / 2) (same error budget as above)."""
    from pbe_cfd.runs.simulate import run_well_mixed
    scene = _toy_scene(rate_factor=factor)
    res = run_well_mixed(scene)
    t = res.columns["time_s"]
    n0, k0 = scene.initial.number_density, scene.aggregation.rate
    exact = n0 / (1.0 + 0.5 * factor * k0 * n0 * t)
    assert res.columns["M00"] == pytest.approx(exact, rel=1e-6, abs=0.0)


def test_the_toys_output_hook_takes_its_plan_not_the_scene(toy):
    """A method's own ``columns`` hook is handed the run's ``MethodPlan`` (its options, the
    coordinates, the density), never the scene: a toy whose hook records what it is given
    and writes its SI moments from the scaled states (M_k = state_k N_ref p_ref^k)."""
    from pbe_cfd.methods.entry import MethodPlan
    from pbe_cfd.runs.simulate import run_well_mixed
    from pbe_cfd.scene.scene import Scene
    given = []

    def columns(plan, arrays, states, aux, populations=None):
        given.append(plan)
        n_ref, p_ref = arrays.number_scale, arrays.mass_scale
        return {"M00": states[:, 0] * n_ref, "M10": states[:, 1] * n_ref * p_ref}

    registry.unregister(TOY.name)
    registry.register(TOY._replace(columns=columns))
    try:
        scene = _toy_scene(rate_factor=2.0)
        res = run_well_mixed(scene)
    finally:
        registry.unregister(TOY.name)
        registry.register(TOY)
    assert len(given) == 1 and isinstance(given[0], MethodPlan)
    assert not isinstance(given[0], Scene)
    assert given[0].options == ToyOptions(rate_factor=2.0)
    assert given[0].density == scene.material.density
    t = res.columns["time_s"]
    n0, k0 = scene.initial.number_density, scene.aggregation.rate
    # the hook's columns are the run's: the same analytic M0 and error budget as above
    exact = n0 / (1.0 + 0.5 * 2.0 * k0 * n0 * t)
    assert res.columns["M00"] == pytest.approx(exact, rel=1e-6, abs=0.0)
