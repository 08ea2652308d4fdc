"""The Laguerre ROM's output-time guard (``methods/laguerre/guard.py``): a cell whose carried
moments are not those of a positive population, or whose reconstruction gives no positive
d43, stops the run with one line naming the cell, the time, the condition and the weight.

States (our choice): wet gamma populations in p with b = Y0 p (M_ij = N theta^(i+j)
Gamma(k+i+j)/Gamma(k) Y0^j), a monodisperse one (on the Hankel equalities), and a bimodal
one -- 99.99% of the granules exponential of mean 0.3 P0, 0.01% of mean 1000 P0 -- whose
moments are realizable (a positive measure) but whose carried gamma shape (8e-4) is far below
the following grid's narrowest (1/4): its signed reconstruction has a negative M_(4/3), so
the output column d43 comes out negative (checked below from the reconstruction's weighted
particles, the path the outputs take, not from the guard's functional).
"""
import math

import numpy as np
import pytest

from pbe_cfd.methods.laguerre import guard
from pbe_cfd.methods.laguerre import tensor as LT
from pbe_cfd.runs import model
from pbe_cfd.runs.batch import CellBatch, SimulationError
from pbe_cfd.runs.executor import SerialExecutor
from pbe_cfd.runs.problem import problem_of

from test_breakage import N0, P0, Y0
from test_laguerre_following import gamma_state, scene


@pytest.fixture(scope="module")
def case():
    sc = scene(True)
    arrays = model.pack(sc)
    return sc, arrays, LT.aux_for_scene(sc, arrays)


def mixture_state(sc, arrays, parts):
    """Scaled state of a sum of exponentials in p ((number [1/m3], mean [kg]) each), b = Y0 p."""
    return LT.scene_initial_state(sc, arrays, lambda i, j: sum(
        n * c ** (i + j) * math.factorial(i + j) for n, c in parts) * Y0 ** j)


BIMODAL = ((0.9999 * N0, 0.3 * P0), (1e-4 * N0, 1000.0 * P0))


def test_realizable_states_pass(case):
    sc, arrays, aux = case
    states = [gamma_state(sc, arrays, c * P0, k) for c in (1.0, 30.0) for k in (0.5, 2.0, 20.0)]
    states.append(LT.scene_initial_state(sc, arrays, lambda i, j: N0 * P0 ** i * (Y0 * P0) ** j))
    assert guard.output_check(np.array(states), aux, arrays) is None


@pytest.mark.parametrize("entry, factor, condition", [
    ((0, 0), -1.0, "M00 > 0 (wet class)"),
    ((2, 0), 0.9, "M20 M00 >= M10^2 (wet class)"),
    ((0, 2), 0.9, "M02 M00 >= M01^2 (wet class)"),
])
def test_each_broken_moment_condition_is_named(case, entry, factor, condition):
    """A gamma state (shape 2, c_m = 3 P0) with one moment moved out of the realizable set:
    for shape 2, W20 W00 / W10^2 = (k + 1) / k = 1.5, so W20 x 0.9 keeps it; at shape 1e3 it is
    1.001 and W20 x 0.9 breaks it (likewise W02)."""
    sc, arrays, aux = case
    shape = 2.0 if entry == (0, 0) else 1e3
    state = gamma_state(sc, arrays, 3.0 * P0, shape)
    i, j = entry
    state[i * 3 + j] *= factor
    row, text = guard.output_check(np.array([gamma_state(sc, arrays, P0, 2.0), state]), aux,
                                   arrays)
    assert row == 1
    assert text.startswith(f"the Laguerre ROM broke {condition}"), text
    if entry != (0, 0):                    # the ratio that broke, (k + 1) / k x 0.9
        ratio = (shape + 1.0) / shape * factor
        assert f"= {ratio:.6g}" in text, text
    assert "c_m = W20/W10" in text and "p_max" in text and "use qmom" in text


def test_dry_class_hankel_condition(case):
    """A dry class (D_k of an exponential, D2 D0 / D1^2 = 2) with D2 x 0.4 breaks it."""
    sc, arrays, aux = case
    state = gamma_state(sc, arrays, P0, 2.0)
    state[9:12] = [1.0, 1.0, 2.0 * 0.4]
    text = guard.output_check(state, aux, arrays)[1]
    assert "M20 M00 >= M10^2 (dry class)" in text and "= 0.8" in text, text


def test_negative_reconstructed_d43_is_caught(case):
    """The bimodal state: realizable moments, but the reconstruction's weighted particles
    (the output path) give sum w p^(4/3) < 0 and a negative output d43 -- the silent wrong
    answer the guard exists for; the guard's tabulated functional agrees with the particles."""
    sc, arrays, aux = case
    state = mixture_state(sc, arrays, BIMODAL)
    w, p, _ = LT.population_for_output(state, aux, arrays)
    m43_particles = float(np.sum(w * p ** (4.0 / 3.0)))
    m43_guard = (guard.reconstructed_m43(state, aux) * arrays.number_scale
                 * arrays.mass_scale ** (4.0 / 3.0))
    assert m43_particles < 0.0
    # the same integral, F43 tabulated on the same nodes: equal up to summation order
    assert m43_guard == pytest.approx(m43_particles, rel=1e-9, abs=0.0)
    cols = LT.output_columns(state, aux, arrays, True, sc.material.density)
    assert cols["d43_m"][0] < 0.0
    text = guard.output_check(state, aux, arrays)[1]
    assert text.startswith("the Laguerre ROM broke d43 > 0: the reconstruction's M_(4/3) = "
                           f"{m43_guard:.4g} kg^(4/3)/m3"), text


def test_the_run_stops_at_the_output_time_naming_the_cell(case):
    """Three cells (numbered 4, 9, 17), the last in the bimodal state: the serial executor
    stops at the first output time with one line naming cell 17, its fields and the time."""
    sc, arrays, aux = case
    problem = problem_of(sc)
    rows = np.repeat(problem.rows[:1], 3, axis=0)
    states = np.array([gamma_state(sc, arrays, P0, 2.0), gamma_state(sc, arrays, 2 * P0, 1.0),
                       mixture_state(sc, arrays, BIMODAL)])
    batch = CellBatch.for_scene(sc, arrays, problem.aux, rows, states,
                                cell_ids=np.array([4, 9, 17]))
    with pytest.raises(SimulationError) as err:
        SerialExecutor().run(batch, np.array([0.0, 1e-3]))
    message = str(err.value)
    assert "\n" not in message
    assert ": cell 17 (alpha " in message and "at t = 0.001 s: the Laguerre ROM broke d43 > 0" \
        in message, message
