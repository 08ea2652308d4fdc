"""The per-cell time integrators (explicit, implicit, auto) against closed forms and each other.

Tolerances: every accepted step keeps its local error estimate below rtol of the state; a run is
checked against the exact solution to error_bound(rtol, exact) of tests/error_bounds.py (10 rtol
per e-fold of the exact solution, plus one), never a bound scaled by the run's own step count.
Two schemes compared with each other may differ by the sum of their two bounds, each computed
from the other run's curve. Linear invariants (granule and binder mass) must hold to 1e-10
relative in every scheme (they see no truncation error).
"""
import dataclasses
import json
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from pbe_cfd import integrate
from pbe_cfd.integrate import cell as cell_integrator
from pbe_cfd.runs import model
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.integrate import codes
from pbe_cfd.integrate.explicit import bs3_attempt
from pbe_cfd.integrate.exponential import capture_column, exp_bs3_attempt
from pbe_cfd.integrate.rosenbrock import jacobian, rodas3_attempt
from pbe_cfd.integrate.kernel_types import MethodFunctions
from pbe_cfd.methods.entry import WORK_SIZE
from pbe_cfd.methods.qmom import qmom_conserved, qmom_project, qmom_realizable, qmom_rhs
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.injection import droplet_mass
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.methods.registry import method_of
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene
from error_bounds import error_bound

N0, P0, K0 = 1.0e10, 1.0e-9, 2.0e-11     # 1/m3, kg, m3/s: k0 N0 = 0.2 /s
ND0, INJ = 5.0e8, 1.0e9                  # free droplets at t = 0 [1/m3], injection [1/(m3 s)]
D_DROP = 60e-6                           # droplet diameter [m]
SCHEMES = ("explicit", "implicit", "auto")


def capture_scene(factor, integrator, rtol=1e-8):
    """Constant kernel with separate droplets captured at factor x k0 per granule."""
    return make_scene(scene={"end_time": 10.0, "output_interval": 1.0},
                      initial={"binder_fraction": 0.1, "droplet_number_density": ND0},
                      aggregation={"kernel": "constant", "rate": K0, "droplet_factor": factor},
                      binder_injection={"rate": INJ, "droplet_diameter": D_DROP},
                      method={"nodes": 2, "integrator": integrator, "rtol": rtol,
                              "atol": 1e-14 * rtol / 1e-8})


def capture_exact(t, factor):
    """Closed form: granules M00 = N0 / (1 + b t), b = k0 N0 / 2; droplets captured at
    lambda(t) = factor k0 M00(t) = 2 factor b / (1 + b t), so with p = 2 factor
    n_d = n_d0 u^-p + I (u - u^-p) / (b (p + 1)), u = 1 + b t; granule mass
    M10 = N0 p0 + p_d (n_d0 + I t - n_d)."""
    b = K0 * N0 / 2.0
    p = 2.0 * factor
    u = 1.0 + b * t
    droplets = ND0 * u ** (-p) + INJ / (b * (p + 1.0)) * (u - u ** (-p))
    granule_mass = N0 * P0 + droplet_mass(D_DROP, 1000.0) * (ND0 + INJ * t - droplets)
    return N0 / u, droplets, granule_mass


def relative(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b)))


@pytest.mark.parametrize("factor", [100.0, 1.0e5], ids=["capture-20-per-s", "capture-2e4-per-s"])
def test_droplet_capture_closed_form_in_every_scheme(factor):
    """Granules aggregating while they capture droplets: exact in every scheme to the step
    bound; with capture at 2e4 /s (stiff: 5.7e4 steps for the explicit pair) auto takes a
    tenth of the explicit pair's right-hand sides or fewer, and implicit a twentieth of its
    steps or fewer (measured 4.1%). Each Rosenbrock step costs 2 n + 3 right-hand sides (a
    central-difference Jacobian, n = 7 here) against the pair's 3, so that is at most
    (2 n + 3) / 3 / 20 = 28% of the pair's right-hand sides (measured 23%)."""
    pd = droplet_mass(D_DROP, 1000.0)
    calls, steps = {}, {}
    for integrator in SCHEMES:
        res = run_well_mixed(capture_scene(factor, integrator))
        c, t = res.columns, res.columns["time_s"]
        granules, droplets, granule_mass = capture_exact(t, factor)
        bound = error_bound(1e-8, granules, droplets, granule_mass)
        nd = c["droplet_number_density"]
        assert relative(c["M00"] - nd, granules) < bound, integrator
        assert relative(nd, droplets) < bound, integrator
        assert relative(c["M10"] - nd * pd, granule_mass) < bound, integrator
        # total mass and binder grow at exactly the injected rate (M10 and M01 include droplets)
        assert relative(c["M10"], c["M10"][0] + INJ * pd * t) < 1e-10, integrator
        assert relative(c["M01"], c["M01"][0] + INJ * pd * t) < 1e-10, integrator
        calls[integrator] = res.stats["rhs_calls"]
        steps[integrator] = res.stats["accepted_steps"]
    if factor > 1e4:
        assert calls["auto"] < 0.1 * calls["explicit"]
        assert steps["implicit"] < 0.05 * steps["explicit"]
        assert calls["implicit"] < 0.28 * calls["explicit"]


def test_auto_keeps_the_explicit_results_and_cost_on_non_stiff_scenes():
    """Seed scenario and the ktgf study scene: auto may change results by at most the step
    bound and must not cost more than 10% extra right-hand-side evaluations (a deterministic
    measure of cost)."""
    for name in ("seed-wurster", "study-ktgf"):
        scene = load_scene(name)
        runs = {}
        for integrator in ("explicit", "auto"):
            runs[integrator] = run_well_mixed(dataclasses.replace(
                scene, method=dataclasses.replace(scene.method, integrator=integrator)))
        ex, au = runs["explicit"], runs["auto"]
        for key in ("M00", "M10", "M20", "M01", "M11", "d43_m"):
            bound = 2.0 * error_bound(scene.method.rtol, ex.columns[key])
            assert relative(au.columns[key], ex.columns[key]) < bound, (name, key)
        assert au.stats["rhs_calls"] <= 1.10 * ex.stats["rhs_calls"], name


@numba.njit
def _one_step(which, y, h, buf, jac, lu, piv, pivots, coefs, phis, cell, aux, params,
              config, work):
    """One step of size h [s] of the explicit pair (0), RODAS3 (1) or the exponential pair
    (2) for QMOM (its functions called directly); the result in buf[YNEW]."""
    n = y.shape[0]
    qmom = MethodFunctions(qmom_rhs, qmom_realizable, qmom_project, qmom_conserved)
    qmom.rhs(y, buf[codes.F0], cell, aux, params, config, work)
    if which == 0:
        return bs3_attempt(qmom, y, h, buf, cell, aux, params, config, work, 1.0, 1.0, n)[0]
    if which == 1:
        n_inv = qmom.conserved(config, params, pivots, coefs)
        jacobian(qmom, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config, work,
                 1e-8, 1e-14, n)
        return rodas3_attempt(qmom, y, h, buf, jac, lu, piv, cell, aux, params, config, work,
                              1.0, 1.0, n)[0]
    capture_column(qmom, y, buf, cell, aux, params, config, work, n - 1, n)
    return exp_bs3_attempt(qmom, y, h, buf, phis, cell, aux, params, config, work, 1.0, 1.0,
                           n - 1, n)[0]


@pytest.mark.parametrize("which", [0, 1, 2], ids=["explicit", "rodas3", "exponential"])
@pytest.mark.slow
def test_each_step_is_third_order(which):
    """Local error of one step from an exponential start on the closed-form capture problem
    (capture at 20 /s): order 3 means the one-step error falls as h^4, by 16 when h halves
    (log2 of the ratio measured: explicit 4.1-4.2, RODAS3 3.9, exponential 4.0; the last
    with a thousand times smaller errors, the capture being integrated exactly)."""
    scene = dataclasses.replace(capture_scene(100.0, "auto"), initial=dataclasses.replace(
        capture_scene(100.0, "auto").initial, distribution="exponential"))
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    y0 = model.initial_moments(scene, arrays, arrays.state_names)
    cell = model.well_mixed_cell(scene)[0]
    n = y0.size
    nd_scale = arrays.number_scale
    errors = []
    for h in (0.02, 0.01, 0.005):
        buf = np.zeros((codes.N_BUF, n))
        outcome = _one_step(which, y0.copy(), h, buf, np.zeros((n, n)), np.zeros((n, n)),
                            np.zeros(n, dtype=np.int64), np.zeros(2, dtype=np.int64),
                            np.zeros((2, n)), np.zeros((3, 6)), cell, aux, arrays.params,
                            arrays.config, np.zeros(WORK_SIZE))
        assert outcome == codes.ACCEPT
        granules, droplets, _ = capture_exact(np.array([h]), 100.0)
        y = buf[codes.YNEW]
        errors.append(max(abs(y[0] * nd_scale / granules[0] - 1),
                          abs(y[-1] * nd_scale / droplets[0] - 1)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.5) & (orders < 4.6)), (errors, orders)


@numba.njit
def _rodas3_step(y, h, buf, jac, pivots, coefs, cell, aux, params, config, work, rtol, atol):
    """One RODAS3 step of size h [s] for QMOM at the given rtol, atol [scaled units]:
    (outcome, error norm); buf[STAGE] holds the embedded solution, buf[YNEW] the step."""
    n = y.shape[0]
    qmom = MethodFunctions(qmom_rhs, qmom_realizable, qmom_project, qmom_conserved)
    qmom.rhs(y, buf[codes.F0], cell, aux, params, config, work)
    n_inv = qmom.conserved(config, params, pivots, coefs)
    jacobian(qmom, y, buf, jac, pivots, coefs, n_inv, cell, aux, params, config, work, 1e-8,
             1e-14, n)
    out = rodas3_attempt(qmom, y, h, buf, jac, np.zeros((n, n)), np.zeros(n, dtype=np.int64),
                         cell, aux, params, config, work, rtol, atol, n)
    return out[0], out[1]


@pytest.mark.slow
def test_rodas3_error_norm_is_the_embedded_solutions_local_error_over_the_tolerance():
    """The number RODAS3 compares with 1 is max_i |y_i - yhat_i| / (atol + rtol max(|y0_i|,
    |y_i|)): y the third-order step, yhat the second-order embedded solution (the stage
    y0 + 2 k1 + k3 that y adds k4 to). Checked on one step of the closed-form capture problem
    (capture at 20 /s, exponential start as in test_each_step_is_third_order: a monodisperse
    start puts the QMOM nodes on the realizability boundary): (1) the norm written out here
    from the two solutions equals the one returned, to rounding; (2) y - yhat is the local
    error of yhat in the free droplets against the closed form within a factor 2 (yhat's
    error is O(h^3), y's O(h^4): at h = 0.005 s, a tenth of the capture time, y - yhat and
    yhat - exact differ by y's own error, measured 5% of it); (3) the step is accepted exactly
    when the norm is <= 1 (one tolerance pair accepts it, the other rejects it)."""
    base = capture_scene(100.0, "implicit")
    scene = dataclasses.replace(base, initial=dataclasses.replace(base.initial,
                                                                  distribution="exponential"))
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    y0 = model.initial_moments(scene, arrays, arrays.state_names)
    cell = model.well_mixed_cell(scene)[0]
    n = y0.size
    h = 0.005
    droplets = capture_exact(np.array([h]), 100.0)[1][0] / arrays.number_scale
    outcomes = set()
    for rtol, atol in ((1e-4, 1e-10), (1e-6, 1e-12)):
        buf = np.zeros((codes.N_BUF, n))
        outcome, err = _rodas3_step(y0.copy(), h, buf, np.zeros((n, n)),
                                    np.zeros(2, dtype=np.int64), np.zeros((2, n)), cell, aux,
                                    arrays.params, arrays.config, np.zeros(WORK_SIZE), rtol,
                                    atol)
        y, yhat = buf[codes.YNEW], buf[codes.STAGE]
        by_hand = np.max(np.abs(y - yhat) / (atol + rtol * np.maximum(np.abs(y0), np.abs(y))))
        # y = fl(yhat + k4) rounds by eps |y| / 2: y - yhat differs from the k4 the code
        # divides by up to eps |y|, i.e. eps / rtol in the norm (weight >= rtol |y|)
        rounding = 2.0 * np.finfo(float).eps / rtol
        assert err == pytest.approx(by_hand, rel=1e-12, abs=rounding), (rtol, err, by_hand)
        ratio = abs(yhat[n - 1] - droplets) / abs(y[n - 1] - yhat[n - 1])
        assert 0.5 < ratio < 2.0, (rtol, ratio)
        assert (outcome == codes.ACCEPT) == (by_hand <= 1.0), (rtol, outcome, by_hand)
        outcomes.add(outcome)
    assert outcomes == {codes.ACCEPT, codes.REJECT_ERROR}


def test_implicit_error_is_proportional_to_rtol():
    """Tolerance proportionality of the implicit scheme on the closed-form capture problem
    (capture at 20 /s). RODAS3 propagates its third-order solution and sizes steps on the
    second-order estimate: h ~ rtol^(1/3), the propagated local error ~ h^4 and the step count
    ~ 1/h, so the global error ~ h^3 ~ rtol. From rtol 1e-6 to 1e-8 the error must shrink by
    100, within a factor 3 either way (step-size rounding at the output times, the opening
    step); each error within error_bound of the closed form (tests/error_bounds.py)."""
    pd = droplet_mass(D_DROP, 1000.0)
    errors = {}
    for rtol in (1e-6, 1e-8):
        res = run_well_mixed(capture_scene(100.0, "implicit", rtol=rtol))
        c, t = res.columns, res.columns["time_s"]
        granules, droplets, granule_mass = capture_exact(t, 100.0)
        nd = c["droplet_number_density"]
        errors[rtol] = max(relative(c["M00"] - nd, granules), relative(nd, droplets),
                           relative(c["M10"] - nd * pd, granule_mass))
        assert errors[rtol] < error_bound(rtol, granules, droplets, granule_mass), rtol
    ratio = errors[1e-6] / errors[1e-8]
    assert 100.0 / 3.0 < ratio < 300.0, (errors, ratio)


@pytest.mark.parametrize("integrator", ["explicit", "implicit"])
def test_rejected_steps_are_rare_on_a_smooth_scene(integrator):
    """The step controller proposes h_new = h 0.9 err^(-1/3) (growth at most 5x): if the
    error constant of the next step is that of the last, its estimate is 0.9^3 = 0.73 of the
    tolerance, and a rejection needs that constant to grow by 1 / 0.73 = 1.37 within one step.
    On the capture problem at rtol 1e-8 (hundreds of steps per e-fold: the constant changes by
    about 1% per step) that happens only at the opening guess and after output times, so at
    most a tenth of the accepted steps may be rejected (measured 0.1% explicit, 0.8%
    implicit). A controller that overshoots its own prediction is rejected after nearly every
    accepted step: the rejections, the wasted right-hand sides, are what it costs."""
    res = run_well_mixed(capture_scene(100.0, integrator))
    st = res.stats
    assert st["rejected_error"] <= 0.1 * st["accepted_steps"], st


@pytest.mark.slow
def test_rodas3_stays_third_order_near_the_realizability_boundary():
    """The study-ktgf cell at 10 s (QMOM N = 3, aggregated from a monodisperse start: its
    moment set lies near the boundary, where the RHS is strongly curved and its Jacobian's
    columns are large and cancel along the trajectory). One RODAS3 step against the explicit
    pair at rtol 1e-13: order 3 means the one-step error falls by 16 when h halves (log2 of the
    ratio measured 3.6-3.7). With forward differences the Jacobian's bias made J f wrong by
    2.6% and the step second order locally (ratio 2.0, errors 50-500 times larger), which made
    the implicit scheme first order: 7.1e-6 off at rtol 1e-8 on this scene."""
    scene = load_scene("study-ktgf")
    tight = dataclasses.replace(scene, method=dataclasses.replace(
        scene.method, integrator="explicit", rtol=1e-13, atol=1e-20))
    arrays = model.pack(tight)
    aux = method_of(tight).aux(tight, arrays, None)
    rows = model.well_mixed_cell(tight)
    y0 = model.initial_moments(tight, arrays, arrays.state_names)
    batch = CellBatch.for_scene(tight, arrays, aux, rows, y0[None, :].copy())
    batch.step(0.0, 10.0)
    y = batch.states[0].copy()
    n = y.size
    errors = []
    for h in (0.4, 0.2, 0.1):
        buf = np.zeros((codes.N_BUF, n))
        outcome = _one_step(1, y.copy(), h, buf, np.zeros((n, n)), np.zeros((n, n)),
                            np.zeros(n, dtype=np.int64), np.zeros(2, dtype=np.int64),
                            np.zeros((2, n)), np.zeros((3, 6)), rows[0], aux, arrays.params,
                            arrays.config, np.zeros(WORK_SIZE))
        assert outcome == codes.ACCEPT
        ref = CellBatch.for_scene(tight, arrays, aux, rows, y[None, :].copy())
        ref.step(10.0, 10.0 + h)
        errors.append(float(np.max(np.abs(buf[codes.YNEW] - ref.states[0])
                                   / np.abs(ref.states[0]))))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.3), (errors, orders)


def test_droplets_captured_to_nothing_end_at_exactly_zero():
    """Without injection the droplets decay as (1 + b t)^(-2 factor); below the absolute
    tolerance (atol of the scaled state, i.e. atol N_ref per m3) auto and implicit hand them to
    the granules, which keeps mass and binder exact and leaves exactly zero instead of a
    number creeping through denormals. Every scheme follows the closed form (bound below)."""
    scene = capture_scene(100.0, "auto")
    scene = dataclasses.replace(scene, binder_injection=dataclasses.replace(
        scene.binder_injection, rate=0.0))
    n_ref = N0 + ND0                        # model.scales: the number scale of this scene
    b, p = K0 * N0 / 2.0, 200.0
    for integrator in SCHEMES:
        run = dataclasses.replace(scene, method=dataclasses.replace(scene.method,
                                                                    integrator=integrator))
        res = run_well_mixed(run)
        c, t = res.columns, res.columns["time_s"]
        for key in ("M10", "M01"):
            assert relative(c[key], np.full_like(c[key], c[key][0])) < 1e-10, integrator
        exact = ND0 * (1.0 + b * t) ** (-p)
        # n_d = n_d0 u^-p: a relative error e of the granules shifts ln n_d by about p e, so
        # the droplets' relative bound is p times the granules' bound plus their own (rtol per
        # e-fold of n_d while above the absolute tolerance atol N_ref); where atol governs the
        # step (n_d below atol / rtol in scaled units) the same e-folds times atol N_ref
        granules = N0 / (1.0 + b * t)
        floor = 1e-14 * n_ref
        own = error_bound(1e-8, np.maximum(exact, floor))
        slack = np.maximum((p * error_bound(1e-8, granules) + own) * exact, own / 1e-8 * floor)
        assert np.all(np.abs(c["droplet_number_density"] - exact) <= slack), integrator
        if integrator != "explicit":
            assert c["droplet_number_density"][-1] == 0.0, integrator


@pytest.mark.parametrize("integrator", ["implicit", "auto"])
def test_laguerre_keeps_mass_and_binder_exact(integrator):
    """The ROM's linear invariants (laguerre_conserved) under both new schemes, seed physics
    with injection: M10 and M01 grow at exactly the injected rate; the moments agree with the
    explicit pair to the step bound."""
    scene = load_scene("seed-wurster-laguerre")
    scene = dataclasses.replace(scene, end_time=60.0, output_interval=10.0)
    runs = {}
    for name in ("explicit", integrator):
        runs[name] = run_well_mixed(dataclasses.replace(
            scene, method=dataclasses.replace(scene.method, integrator=name)))
    c, t = runs[integrator].columns, runs[integrator].columns["time_s"]
    rate = scene.binder_injection.rate * droplet_mass(scene.binder_injection.droplet_diameter,
                                                      scene.material.binder_density)
    for key in ("M10", "M01"):
        assert relative(c[key], c[key][0] + rate * t) < 1e-10
    for key in ("M00", "M20", "M11"):
        bound = 2.0 * error_bound(scene.method.rtol, runs["explicit"].columns[key])
        assert relative(c[key], runs["explicit"].columns[key]) < bound, key


def test_failure_reason_names_the_cause():
    """A stalled controller that rejects as often as it accepts sits on a jump of the rates;
    with the sharp Stokes criterion the message says which switch to soften. An explicit
    cell that ran out of steps without rejections is stiff: the message points to auto."""
    params = np.zeros(P.N_PARAMS)
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    config[P.USE_PHYSICAL] = 1
    stats = np.zeros(integrate.N_STATS, dtype=np.int64)
    stats[integrate.ACCEPTED], stats[integrate.REJECTED_ERROR] = 300_000, 700_000
    text = integrate.failure_reason(integrate.TOO_MANY_STEPS, stats, params, config)
    assert "rates jump" in text and "stokes_switch_width" in text
    params[P.STOKES_WIDTH] = 0.05
    text = integrate.failure_reason(integrate.TOO_MANY_STEPS, stats, params, config)
    assert "rates jump" in text and "stokes_switch_width" not in text
    stats[integrate.REJECTED_ERROR] = 10
    config[P.INTEGRATOR] = integrate.EXPLICIT
    text = integrate.failure_reason(integrate.TOO_MANY_STEPS, stats, params, config)
    assert 'integrator = "auto"' in text
    assert integrate.failure_reason(integrate.NOT_FINITE, stats, params, config) == \
        integrate.STATUS_TEXT[integrate.NOT_FINITE]


@pytest.mark.slow
def test_a_scene_compiles_only_its_method_and_scheme(tmp_path):
    """In a fresh process with an empty kernel cache, an explicit QMOM scene compiles the QMOM
    kernel with the explicit pair only: neither the Laguerre right-hand side nor the Rosenbrock
    or exponential steps are compiled (a loaded cache would compile nothing, hence the fresh
    cache directory). The schemes' attempts are inlined into the kernel, so what is checked
    are the helpers only they call, compiled as functions of their own: the LU factorisation
    and solve (Rosenbrock) and the phi functions (exponential). The kernel takes the method's
    functions as arguments: a CQMOM scene with the same scheme then compiles CQMOM's
    functions and no second kernel."""
    code = """
import json, dataclasses
from pbe_cfd import integrate
from pbe_cfd.runs import model
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.methods.registry import method_of
scene = load_scene("seed-wurster")
scene = dataclasses.replace(scene, method=dataclasses.replace(scene.method, integrator="explicit"))
arrays = model.pack(scene)
aux = method_of(scene).aux(scene, arrays, None)
integrate.compile_kernels(aux, arrays.params, arrays.config)
from pbe_cfd.methods import laguerre, qmom
from pbe_cfd.integrate import rosenbrock, exponential, cell, explicit
sigs = list(cell.integrate_cells_kernel.signatures)
from pbe_cfd.methods import cqmom
other = load_scene("seed-wurster-cqmom")
other = dataclasses.replace(other, method=dataclasses.replace(other.method, integrator="explicit"))
arrays = model.pack(other)
integrate.compile_kernels(method_of(other).aux(other, arrays, None), arrays.params, arrays.config)
print(json.dumps({"laguerre": len(laguerre.laguerre_rhs.signatures),
                  "qmom": len(qmom.qmom_rhs.signatures),
                  "cqmom": len(cqmom.cqmom_rhs.signatures),
                  "kernels_after_cqmom": len(cell.integrate_cells_kernel.signatures),
                  "lu_factor": len(rosenbrock.lu_factor.signatures),
                  "lu_solve": len(rosenbrock.lu_solve.signatures),
                  "phi": len(exponential.phi_functions.signatures),
                  "combine": len(explicit._combine.signatures),
                  "kernels": [str(s[4]) for s in sigs]}))
"""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, check=True, timeout=1800)
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["laguerre"] == 0 and seen["lu_factor"] == 0 and seen["lu_solve"] == 0
    assert seen["phi"] == 0
    assert seen["combine"] == 1                 # the explicit pair's helper: it was compiled
    assert seen["qmom"] == 1                    # the method's right-hand side, once
    assert seen["kernels"] == ["Literal[int](0)"]    # one kernel, the explicit scheme's
    # a second method with the same scheme: its own functions, the same kernel
    assert seen["cqmom"] == 1 and seen["kernels_after_cqmom"] == 1


def test_the_droplets_liquid_counts_with_the_droplets_in_the_capture_test():
    """With [drying] the droplets carry their liquid L_d (an entry of its own). The capture
    column moves it with n_d, so what is left of its rate after the capture is the sprayed
    droplets' liquid R b_d: relative to L_d = n_d b_d that is R / n_d, at least the capture
    rate kappa wherever n_d is at or below its steady R / kappa. Counted among the other
    entries it made the test ``rate_d > CAPTURE_DOMINANCE rate_g`` fail in every droplet
    transient of a sprayed cell (the spray cells of fluid-bed-batch took 1 exponential step
    per cell in 60 s, against 633 without the entry). A state in a transient: droplets at a
    tenth of steady, granules changing at 1e-3 kappa; the droplets' relative rate 9 kappa
    passes against the granules' (it is the droplet population's own transient) and fails
    against R / n_d = 10 kappa."""
    kappa, R, bd = 100.0, 1e8, 0.5              # 1/s, droplets/(m3 s), liquid per droplet
    nd = 0.1 * R / kappa
    # entries: two granule moments, the droplets' liquid, the evaporated liquid, n_d
    state = np.array([1.0, 2.0, nd * bd, 0.0, nd])
    g = np.array([0.0, 0.0, -kappa * bd, 0.0, -kappa])        # d f / d n_d (capture)
    f0 = np.array([-1e-3 * kappa, 2e-3 * kappa, R * bd - kappa * nd * bd, 0.0, R - kappa * nd])
    d, liquid, n = 4, 2, 5
    rate_d, rate_g = cell_integrator._droplet_rates(state, f0, g, d, liquid, n, 1e-8, 1e-20)
    assert rate_d == pytest.approx(9.0 * kappa, rel=1e-12, abs=0)
    assert rate_g == pytest.approx(1e-3 * kappa, rel=1e-12, abs=0)
    assert cell_integrator._capture_pays(state, f0, g, d, liquid, n, 1e-8, 1e-20)
    # the liquid counted as another entry (no liquid entry named): R / n_d = 10 kappa
    _, counted = cell_integrator._droplet_rates(state, f0, g, d, -1, n, 1e-8, 1e-20)
    assert counted == pytest.approx(10.0 * kappa, rel=1e-12, abs=0)
    assert not cell_integrator._capture_pays(state, f0, g, d, -1, n, 1e-8, 1e-20)
