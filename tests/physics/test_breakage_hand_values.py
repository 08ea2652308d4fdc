"""Hand values of every breakage selection function and daughter rule, in plain Python floats.

Each expected value is computed here from the formula as docs/physics.md ("Breakage") writes
it; the project's functions are only called to be checked. Sources: the selection and daughter
forms of docs/physics.md section 8 (issue 16); g0 of Sinclair & Jackson as OpenFOAM evaluates it (cap
at alpha_min_friction); u0 = 4 sqrt(Theta / pi) (Gidaspow 1994); the Stokes deformation number
St_def = rho_g u0^2 / (2 Y) of Tardos, Khan and Mort (1997).

Tolerance: each value is a handful of floating-point operations (a power, a square root, a
cube root) on inputs of condition number below 10, so the two evaluations agree to ~1e-15
relative; rel = 1e-12 leaves a margin and still catches any change of a constant or an exponent.
"""
import math

import numpy as np
import pytest

from pbe_cfd.methods.quadrature.breakage_sources import add_qmom_breakage
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.breakage import (COLLISIONAL, CONSTANT, EQUAL, POWER, UNIFORM,
                                      daughter_moment_factor, daughter_share,
                                      deformation_gate, selection_cell_factor,
                                      selection_function, selection_rate,
                                      stokes_deformation_number)

REL = 1e-12
S0 = 0.05                  # 1/s
P_REF = 5.4e-10            # kg, about a 100 um Avicel granule
A_POW = 1.5
THETA_REF = 0.01           # m2/s2
RHO_G = 1021.0             # kg/m3
ALPHA_MAX, ALPHA_CAP = 0.62, 0.5
Y = 1.0e3                  # Pa
ST_CRIT = 0.2


def packed(selection, daughters=UNIFORM, exponent=A_POW, gate=True):
    params = np.zeros(P.N_PARAMS)
    config = np.zeros(P.N_CONFIG, dtype=np.int64)
    params[P.DENSITY] = RHO_G
    params[P.ALPHA_MAX] = ALPHA_MAX
    params[P.ALPHA_MIN_FRICTION] = ALPHA_CAP
    params[P.BREAKAGE_RATE] = S0
    params[P.BREAKAGE_EXPONENT] = exponent
    params[P.BREAKAGE_REFERENCE_MASS] = P_REF
    params[P.BREAKAGE_REFERENCE_THETA] = THETA_REF
    params[P.YIELD_STRENGTH] = Y if gate else 0.0
    params[P.CRITICAL_DEFORMATION] = ST_CRIT if gate else 0.0
    params[P.MASS_SCALE] = 1e-9
    config[P.BREAKAGE] = 1
    config[P.BREAKAGE_SELECTION] = selection
    config[P.BREAKAGE_DAUGHTERS] = daughters
    return params, config


def g0(alpha):
    a = min(alpha, ALPHA_CAP)
    return 1.0 / (1.0 - (a / ALPHA_MAX) ** (1.0 / 3.0))


def u0_of(theta):
    return 4.0 * math.sqrt(theta / math.pi)


MASSES = (3.1e-11, 5.4e-10, 7.7e-9)                       # kg
CELLS = ((0.31, 0.04), (0.55, 0.09), (0.12, 0.02))        # alpha, Theta [m2/s2]


@pytest.mark.parametrize("p", MASSES)
def test_constant_and_power_selection(p):
    params, config = packed(CONSTANT)
    assert selection_rate(p, 0.3, 0.05, 0.4, params, config) == pytest.approx(S0, rel=REL,
                                                                              abs=0)
    params, config = packed(POWER)
    expected = S0 * (p / P_REF) ** 1.5
    assert selection_rate(p, 0.3, 0.05, 0.4, params, config) == pytest.approx(expected,
                                                                              rel=REL, abs=0)
    params, config = packed(POWER, exponent=1.0)
    assert selection_rate(p, 0.0, 0.0, 0.0, params, config) == pytest.approx(S0 * p / P_REF,
                                                                            rel=REL, abs=0)


@pytest.mark.parametrize("alpha,theta", CELLS)
@pytest.mark.parametrize("p", MASSES)
def test_collisional_selection_with_and_without_the_gate(p, alpha, theta):
    u0 = u0_of(theta)
    st_def = RHO_G * u0 ** 2 / (2.0 * Y)
    open_ = st_def > ST_CRIT
    plain = S0 * g0(alpha) * math.sqrt(theta / THETA_REF) * (p / P_REF) ** A_POW
    params, config = packed(COLLISIONAL, gate=False)
    assert selection_rate(p, alpha, theta, u0, params, config) == pytest.approx(plain, rel=REL,
                                                                                abs=0)
    params, config = packed(COLLISIONAL, gate=True)
    assert stokes_deformation_number(u0, params) == pytest.approx(st_def, rel=REL, abs=0)
    gated = selection_rate(p, alpha, theta, u0, params, config)
    assert gated == (pytest.approx(plain, rel=REL, abs=0) if open_ else 0.0)


def test_the_gate_opens_above_the_critical_number():
    """St_def = 1021 u0^2 / 2000 = 0.2 at u0 = 0.6259 m/s (Theta = 0.0769 m2/s2): closed just
    below, open just above; CELLS hold both sides (St_def 0.104, 0.234, 0.052)."""
    params, _ = packed(COLLISIONAL, gate=True)
    u_crit = math.sqrt(2.0 * Y * ST_CRIT / RHO_G)
    assert deformation_gate(u_crit * (1 - 1e-9), params) == 0.0
    assert deformation_gate(u_crit * (1 + 1e-9), params) == 1.0
    params[P.YIELD_STRENGTH] = 0.0
    assert deformation_gate(0.0, params) == 1.0          # no yield strength: no gate
    assert {deformation_gate(u0_of(th), packed(COLLISIONAL)[0]) for _, th in CELLS} == {0.0, 1.0}


def test_collisional_cell_factor_at_no_motion_and_no_solids():
    params, _ = packed(COLLISIONAL, gate=False)
    assert selection_cell_factor(COLLISIONAL, 0.3, 0.0, 0.0, params) == 0.0
    # alpha = 0: g0 = 1 (dilute limit)
    assert selection_cell_factor(COLLISIONAL, 0.0, THETA_REF, 1.0, params) == pytest.approx(
        S0, rel=REL, abs=0)


@pytest.mark.parametrize("k", range(7))
def test_daughter_moment_factors(k):
    assert daughter_moment_factor(UNIFORM, float(k)) == pytest.approx(2.0 / (k + 1), rel=REL,
                                                                      abs=0)
    assert daughter_moment_factor(EQUAL, float(k)) == pytest.approx(2.0 * 0.5 ** k, rel=REL,
                                                                    abs=0)


def test_daughter_shares():
    for r in (1e-9, 0.1234, 0.5, 0.999):
        assert daughter_share(UNIFORM, r) == r
        assert daughter_share(EQUAL, r) == 0.5


def test_qmom_breakage_sources_of_two_nodes():
    """QMOM's breakage sources (``add_qmom_breakage``, what its right-hand side calls) of two
    nodes (scaled: masses x, number weights w, binder b), power selection a = 1.5, uniform and
    equal daughters: dM_ij/dt = sum_a w_a S(x_a) (F(i+j) - 1) x_a^i b_a^j for the layout of a
    bivariate 2-node state (M00..M30, then M01, M11)."""
    x = np.array([0.3, 2.5])
    w = np.array([0.7, 0.2])
    b = np.array([0.05, 0.9])
    cell = np.zeros(P.N_CELL)               # power selection: the cell factor is s0
    for code, F in ((UNIFORM, lambda k: 2.0 / (k + 1)), (EQUAL, lambda k: 2.0 ** (1 - k))):
        params, config = packed(POWER, daughters=code)
        config[P.ORDER], config[P.BIVARIATE] = 2, 1
        out = np.zeros(6)
        add_qmom_breakage(out, x, w, b, 2, cell, params, config)
        slots = [((k, 0), k) for k in range(4)] + [((k, 1), 4 + k) for k in range(2)]
        for (i, j), slot in slots:
            expected = 0.0
            for a in range(2):
                s = S0 * (x[a] * 1e-9 / P_REF) ** 1.5
                expected += w[a] * s * (F(i + j) - 1.0) * x[a] ** i * b[a] ** j
            if i + j == 1:
                assert out[slot] == 0.0                 # mass and binder: exactly nothing
            else:
                assert out[slot] == pytest.approx(expected, rel=REL, abs=0), (i, j)
    params, config = packed(POWER)
    config[P.ORDER], config[P.BIVARIATE] = 2, 1
    config[P.BREAKAGE] = 0                  # no breakage table: the sources stay untouched
    out = np.zeros(6)
    add_qmom_breakage(out, x, w, b, 2, cell, params, config)
    assert np.all(out == 0.0)


def test_no_breakage_table_means_no_rate():
    params, config = packed(POWER)
    config[P.BREAKAGE] = 0
    assert selection_rate(1e-9, 0.3, 0.05, 0.4, params, config) == 0.0
    assert math.isnan(selection_function(99, 1e-9, S0, params))
