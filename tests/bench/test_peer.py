"""``pbe-cfd bench peer``: the moment extraction from OpenFOAM's size-group fields, the class
method against the constant-aggregation closed form, the fine fixed-pivot reference against the
closed forms, and the exit-2 path without OpenFOAM."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pbe_cfd.bench import peer, peer_case as PC, peer_reference as PR


def _write_scalar(path, values):
    values = np.atleast_1d(values)
    body = (f"uniform {values[0]!r}" if values.size == 1 else
            "nonuniform List<scalar>\n" + f"{values.size}\n(\n"
            + "\n".join(repr(float(v)) for v in values) + "\n)\n")
    path.write_text("FoamFile\n{\n    version 2.0;\n    format ascii;\n    class volScalarField;"
                    "\n}\ndimensions [0 0 0 0 0 0 0];\n\ninternalField " + body + ";\n\n"
                    "boundaryField\n{\n    walls { type zeroGradient; }\n}\n")


def test_moment_extraction_on_a_synthetic_field(tmp_path):
    """Number densities chosen first (two cells, an exponential and a two-group population on
    a ratio-2^(1/2) grid) are written as alpha and f_i = n_i x_i / alpha; the extraction must
    return sum n_i x_i^k to round-off (relative 1e-13: 15 written digits, sums of <= 12
    terms)."""
    x = PR.geometric_grid(0.5, 32.0, 2)                       # 13 groups [m3]
    n = np.stack([np.exp(-x / 3.0), np.where((x == 1.0) | (x == 8.0), 0.25, 0.0)])  # [1/m3]
    alpha = (n * x).sum(axis=1)                                # each cell's volume fraction
    case = PC.ClassCase(volumes=tuple(x), fractions=tuple(np.ones(x.size) / x.size),
                        alpha=0.1, coalescence_rate=1.0, breakup_power=None, dt=0.1,
                        end_time=1.0, cells=2)
    tdir = tmp_path / "1.5"
    tdir.mkdir()
    _write_scalar(tdir / "alpha.air", alpha)
    for i in range(x.size):
        _write_scalar(tdir / f"f{i}.air.bubbles", n[:, i] * x[i] / alpha)
    (tmp_path / "0").mkdir()
    got = PC.read_class_moments(case, tmp_path)
    assert got["time_s"] == 1.5
    for k in (0, 1, 2):
        expect = np.array([sum(ni * xi ** k for ni, xi in zip(row, x)) for row in n])
        assert np.allclose(got[f"M{k}"], expect, rtol=1e-13, atol=0.0)
    assert np.allclose(got["sum_f"], 1.0, rtol=1e-13, atol=0.0)


def test_extraction_rejects_a_field_of_the_wrong_size(tmp_path):
    _write_scalar(tmp_path / "f.air", np.array([0.1, 0.2, 0.3]))
    with pytest.raises(ValueError, match="3 values, expected 2"):
        PC.read_internal_field(tmp_path / "f.air", 2)


def test_fixed_pivot_reference_against_the_closed_forms():
    """The extrapolated fixed-pivot reference (8 and 16 pivots per doubling) against the closed
    forms of constant aggregation and constant breakage and the Riccati M0 of aggregation with
    S = x: M0 and M1 are kept by the pivot weights (the solver's rtol 1e-10 leaves 1e-6; under
    breakage also the lower end of the grid, checked by its scaling), M2's remaining error must be below the correction the
    extrapolation made (a second-order error leaves a remainder far below it)."""
    n0, x0 = peer.N_START, peer.X_START
    agg = PR.extrapolated_reference(1.0, 2.0 ** 8, x0, n0, 2.0, aggregation_rate=10.0)
    exact = PR.constant_aggregation_moments(n0, x0, 10.0, 2.0)
    brk = PR.extrapolated_reference(2.0 ** -24, 1.0, x0, n0, 1.0, breakage_power=0.0)
    exact_b = PR.constant_breakage_moments(n0, x0, 1.0, 1.0)
    mix = PR.extrapolated_reference(2.0 ** -24, 2.0 ** 6, x0, n0, 2.0, aggregation_rate=10.0,
                                    breakage_power=1.0)
    assert agg["M0"] == pytest.approx(exact["M0"], rel=1e-6, abs=0.0)
    # breakage: daughters below the first pivot x_low go to it with their volume kept, so
    # about x_low / x_k of a daughter is lost per break; summed over parents that reach down
    # towards x_low the loss falls more slowly than x_low: at least as sqrt(x_low) (16x lower
    # end, at least 4x less error; measured 7x)
    err = abs(brk["M0"] / exact_b["M0"] - 1.0)
    higher = PR.extrapolated_reference(2.0 ** -20, 1.0, x0, n0, 1.0, breakage_power=0.0)
    assert err < 1e-4 and err < abs(higher["M0"] / exact_b["M0"] - 1.0) / 4.0
    for got, ref in ((agg, exact), (brk, exact_b)):
        assert got["M1"] == pytest.approx(ref["M1"], rel=1e-9, abs=0.0)
        assert abs(got["M2"] / ref["M2"] - 1.0) < got["spread_M2"]
        assert got["spread_M2"] < 1e-3          # 16 pivots per doubling: O(1e-4) corrections
    m0 = PR.linear_breakage_aggregation_m0(n0, x0, 10.0, 2.0)
    assert mix["M0"] == pytest.approx(m0, rel=1e-6, abs=0.0)


def _class_m0_recursion(n0, rate, dt, steps):
    """The class method's own M0 for constant aggregation, derived from its step: births of
    step n explicit (rate M0^2 / 2 in number), deaths implicit (each group dies at rate M0_n
    applied to its new value): M0_{n+1} = (M0_n + dt rate M0_n^2 / 2) / (1 + dt rate M0_n),
    exact while no pair reaches beyond the largest group."""
    m0 = n0
    for _ in range(steps):
        m0 = (m0 + 0.5 * dt * rate * m0 * m0) / (1.0 + dt * rate * m0)
    return m0


@pytest.mark.openfoam
@pytest.mark.skipif(PC.openfoam_missing() is not None, reason="OpenFOAM is not installed")
def test_class_method_constant_aggregation(tmp_path):
    """One small class run (9 groups, ratio 2, 250 steps of 2 ms to t = 0.5 s, beta n0 = 1/s):
    * M1 is kept to the solver tolerance (relative 1e-10; fractions solved to 1e-14);
    * M0 equals the recursion of its own semi-implicit step to 1e-8 (the same tolerance, over
      250 steps) and lies off the closed form by that recursion's first-order time error;
    * M2 exceeds the closed form (each aggregate's volume v is shared between the pivots
      x_i <= v <= x_i+1 keeping number and volume, which adds (v - x_i)(x_i+1 - v) <= (r - 1)^2
      v^2 / 4 to M2 per event) by at most (r - 1)^2 / 4 int beta (M0 M2 + M1^2) dt, the
      integral taken from the closed form; allowing below it the time-step error, the M0
      one times M2."""
    case = peer.class_case("aggregation", 1, end_time=0.5)
    info = PC.run_case(case, tmp_path / "case")
    got = PC.read_class_moments(case, info["case_dir"])
    n0, x0, rate = peer.N_START, peer.X_START, peer.AGG_RATE
    exact = PR.constant_aggregation_moments(n0, x0, rate, 0.5)
    assert got["M1"][0] == pytest.approx(exact["M1"], rel=1e-10, abs=0.0)
    rec = _class_m0_recursion(n0, rate, case.dt, info["steps"])
    assert got["M0"][0] == pytest.approx(rec, rel=1e-8, abs=0.0)
    time_error = abs(rec / exact["M0"] - 1.0)
    assert 1e-6 < time_error < case.dt * rate * n0      # first order: below beta n0 dt
    t = np.linspace(0.0, 0.5, 2001)
    m = PR.constant_aggregation_moments(n0, x0, rate, t)
    integrand = rate * (m["M0"] * m["M2"] + m["M1"] ** 2)
    bound = (2.0 - 1.0) ** 2 / 4.0 * float(np.sum(0.5 * (integrand[1:] + integrand[:-1])
                                                  * np.diff(t)))
    excess = got["M2"][0] - exact["M2"]
    assert -time_error * exact["M2"] < excess < bound


def test_peer_without_openfoam_exits_2(tmp_path):
    """With OpenFOAM's tools off PATH the study says so on one line, exit 2, writes nothing."""
    env = dict(os.environ, PATH=str(Path(sys.executable).parent))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-c", "import sys; from pbe_cfd.cli import main; "
                           "sys.exit(main())", "bench", "peer", "--out", str(out)],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "OpenFOAM is not installed" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists()
    with pytest.raises(PC.PeerUnavailable):
        import unittest.mock as um
        with um.patch.object(PC.shutil, "which", return_value=None):
            peer.peer_study(tmp_path / "out2", quick=True, quiet=True)
    assert not (tmp_path / "out2").exists()
