"""The granule number's aggregation rate of the Laguerre ROM's reconstruction
(``guard.aggregation_number_rates``): for any positive population d(M00)/dt from aggregation
is -1/2 of the double integral of beta n n <= 0, so a positive value is a reconstruction that
is no population as the kernel sees it.

Scene (our choice, docs/results/laguerre.md "A well-mixed proxy of the batch"): the bundled
`fluid-bed-laguerre-batch` as one well-mixed cell at the active cells' volume means (alpha
0.38139, Theta 7.5256e-5 m2/s2), the spray zone's injection spread over the active volume
(share 0.17963: 3.5926e9 droplets/(m3 s)), following support to 1e6 x the initial mean mass,
m = 3, no breakage. States: that run's own states at 1020, 1200 and 1440 s (rtol 1e-6; the
run's granule number rises at 1200 and 1440 s, +3.9% over 1420-1440 s).
"""
import re
from importlib import resources

import numpy as np
import pytest

from pbe_cfd.methods.laguerre.guard import aggregation_number_rates
from pbe_cfd.methods.laguerre.number_watch import EPS, number_rate
from pbe_cfd.methods.laguerre.position import laguerre_d43
from pbe_cfd.methods.laguerre.rhs import laguerre_rhs
from pbe_cfd.physics import parameters as P
from pbe_cfd.physics.kernels import KTGF, kernel_cell_factor
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.runs.problem import problem_of
from pbe_cfd.scene.scene import load_scene

STATES = {
    1020.0: [0.0024109811919115764, 1.0641779546821142, 1162.863399415312, 2.064177954682088,
             2299.3423887542085, 3937089.977729335, 4527.989581866935, 7903104.226806181,
             18492952495.400772, 0.0, 0.0, 0.0, 0.000610105092650236],
    1200.0: [0.001317411095766498, 1.2520166847080645, 2877.9442345168254, 2.2520166847080683,
             5267.208295799744, 19004325.257790215, 9608.671856252282, 35482322.16961521,
             174839550517.8467, 0.0, 0.0, 0.0, 0.0005138832877450523],
    1440.0: [0.0007708534203947311, 1.5024629639073583, 8070.966473207051, 2.5024629639071514,
             13652.222851438191, 115391485.2058301, 23009.552598649687, 199905971.71167913,
             2300741977389.914, 0.0, 0.0, 0.0, 0.00041123271866688716],
}


def proxy_source():
    """The batch proxy's TOML text: the bundled ``fluid-bed-laguerre-batch`` as one well-mixed
    cell at the active cells' mean solids fraction and granular temperature, the spray zone's
    share of the spray, no transport (also scripts/batch_proxy.py's scene)."""
    src = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-laguerre-batch.toml").read_text()
    dom = ('[domain]\ntype = "well-mixed"\nsolids_fraction = 0.38139\n'
           'granular_temperature = 7.5256e-05\n')
    src = re.sub(r"^\[domain\].*?(?=\n\[material\])", dom, src, flags=re.S | re.M)
    p0 = 1021.0 * np.pi / 6.0 * 100.4e-6 ** 3
    src = src.replace("binder_fraction = 0.0\n", "binder_fraction = 0.0\nnumber_density = "
                      "%.6g\n" % (0.38139 * 1021.0 / p0), 1)
    src = src.replace("rate = 2.0e10 ", "rate = 3.5926e9 ")
    src = re.sub(r"^zone = \{.*?\}\n", "", src, flags=re.M)
    return re.sub(r"^\[transport\].*", "", src, flags=re.S | re.M)


def proxy_scene(path):
    src = proxy_source()
    # the tensors' rows, whose number rate this module checks (the following support's
    # default is the point measure's: test_the_points_closure_lowers_the_granule_number)
    assert "following_growth = 1e6 " in src
    src = src.replace("following_support = true", "following_support = true\n"
                      "number_closure = \"tensor\"")
    path.write_text(src)
    return load_scene(str(path))


@pytest.fixture(scope="module")
def proxy(tmp_path_factory):
    problem = problem_of(proxy_scene(tmp_path_factory.mktemp("proxy") / "proxy.toml"))
    assert problem.states.shape[1] == 13 and problem.rows.shape[0] == 1
    return problem


@pytest.mark.slow
@pytest.mark.parametrize("t", sorted(STATES))
def test_rate_is_the_rhs_granule_number_rate_over_its_multiplier(proxy, t):
    """Without breakage the RHS changes the granule number (W00 + D0) by aggregation alone
    (capture moves none, injection feeds the free droplets), so the RHS's rate is the cell's
    multiplier k0 N_ref g0 sqrt(Theta) d43^(3/2) times the one tensor slice's rate; red if
    the function leaves out the dry class, the dry-wet term or the weight blend."""
    s = np.array(STATES[t])
    out = np.zeros(s.size)
    cell = proxy.rows[0]
    a, params, config = proxy.aux, proxy.arrays.params, proxy.arrays.config
    laguerre_rhs(s, out, cell, a, params, config)
    mult = params[P.NUMBER_SCALE] * kernel_cell_factor(
        KTGF, cell[P.ALPHA], cell[P.THETA], laguerre_d43(s, a, params, config), params)
    rates = aggregation_number_rates(s, a)
    assert rates.shape == (1,)
    assert out[0] + out[9] == pytest.approx(mult * rates[0], rel=1e-10, abs=0.0)


@pytest.mark.slow
def test_the_population_at_1020_s_loses_granules(proxy):
    assert aggregation_number_rates(np.array(STATES[1020.0]), proxy.aux)[0] < 0.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured (docs/results/laguerre.md, bed proxy): the "
                   "reconstruction's granule-number aggregation rate is positive at 1200 s "
                   "(+1.4e-7) and 1440 s (+9.5e-8, against -1.3e-7 at 1020 s): the m = 3 "
                   "signed density, not a population, raises M00 by 29% over QMOM N = 3 at 30 min")
@pytest.mark.parametrize("t", [1200.0, 1440.0])
def test_aggregation_never_raises_the_granule_number(proxy, t):
    assert aggregation_number_rates(np.array(STATES[t]), proxy.aux)[0] <= 0.0


QMOM_RELATIVE_RATE = {1020.0: -3.51e-3, 1200.0: -3.06e-3, 1440.0: -2.61e-3}


@pytest.mark.slow
@pytest.mark.parametrize("t", sorted(STATES))
def test_the_points_closure_lowers_the_granule_number(proxy, t):
    """With number_closure = "points" the RHS's granule-number rate at the three states is
    negative, where the tensors' turns positive at 1200 and 1440 s, and within a factor 1.5 of
    QMOM N = 3's relative rate at the same time of the same scene (its moments.csv, centred
    differences over +-10 s: QMOM_RELATIVE_RATE [1/s]; measured 1.10, 1.08, 1.20 times it;
    the bound is ours: the two closures of one population, the ROM's state itself 4-17% off
    QMOM's number there). Red if the points' rate is not used (positive at 1200 s) or the
    kernel's multiplier is lost (orders of magnitude off)."""
    from pbe_cfd.methods.laguerre.layout import AUX_NUMBER_POINTS
    s = np.array(STATES[t])
    a = proxy.aux.copy()
    a[AUX_NUMBER_POINTS] = 1.0
    out = np.zeros(s.size)
    laguerre_rhs(s, out, proxy.rows[0], a, proxy.arrays.params, proxy.arrays.config)
    relative = (out[0] + out[9]) / (s[0] + s[9])
    assert relative < 0.0
    assert 1.0 / 1.5 < relative / QMOM_RELATIVE_RATE[t] < 1.5


@pytest.mark.slow
@pytest.mark.parametrize("t", sorted(STATES))
def test_watch_rate_is_the_rhs_granule_number_rate(proxy, t):
    """The output watch's rate is the RHS's own d(W00 + D0)/dt of the cell (no breakage:
    aggregation alone moves the granule number), to round-off of its terms: red if the watch
    leaves out a class, the dry-wet term, a blend weight or the multiplier."""
    s = np.array(STATES[t])
    out = np.zeros(s.size)
    a, params, config = proxy.aux, proxy.arrays.params, proxy.arrays.config
    laguerre_rhs(s, out, proxy.rows[0], a, params, config)
    rate, total, n = number_rate(s, proxy.rows[0], a, params, config)
    assert rate == pytest.approx(out[0] + out[9], rel=0.0, abs=(n + 8) * EPS * total)
    assert (rate > (n + 8) * EPS * total) == (t != 1020.0)   # the measured signs


def _watched(proxy, t0, dt):
    """A batch of the proxy cell started from the proxy run's state at t0 [s], advanced by
    dt [s] and checked at t0 + dt as a run's output time: (notes, stats)."""
    batch = CellBatch.for_problem(proxy)
    batch.states[0] = STATES[t0]
    if dt > 0.0:
        batch.step(t0, t0 + dt)
    batch.check_output(t0 + dt)
    batch.check_output(t0 + 2 * dt)           # a second output time: still one line
    return batch.notes, batch.stats()


@pytest.mark.slow
def test_a_run_through_a_positive_number_rate_warns_once(proxy):
    """Ten seconds of the proxy from its state at 1440 s (M00 rising, +3.9% over
    1420-1440 s in the full run): the run gives one warning line naming the method, the
    well-mixed cell, the time and the relative rate, and its summary counts it; red if the
    watch is not called (batch._watch) or the flag's sign is reversed."""
    notes, stats = _watched(proxy, 1440.0, 10.0)
    lines = [n for n in notes if "granule number M00" in n]
    assert len(lines) == 1
    assert lines[0].startswith("laguerre:") and "well-mixed at t = 1450 s" in lines[0]
    assert "not a population" in lines[0] and "M00 is not trustworthy" in lines[0]
    assert stats["positive_number_rate_cells"] == 1
    assert stats["positive_number_rate_output_times"] == 2
    assert stats["positive_number_rate_first_time_s"] == pytest.approx(1450.0, abs=1e-9)
    assert stats["positive_number_rate_largest_per_s"] > 0.0


@pytest.mark.slow
def test_a_population_that_loses_granules_gives_no_warning(proxy):
    """The proxy's state at 1020 s (rate -1.3e-7 per unit multiplier): no line, no summary
    entry (so scenes without the flaw keep their summary.json bitwise)."""
    notes, stats = _watched(proxy, 1020.0, 0.0)
    assert not any("granule number M00" in n for n in notes)
    assert not any(k.startswith("positive_number_rate") for k in stats)
