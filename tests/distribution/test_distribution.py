"""Size distributions (pbe_cfd.distribution) against references of their own: closed-form
percentiles, and constant-kernel aggregation from an exponential start, whose number density
stays exponential, n(p, t) = N(t)^2 / M1 exp(-p N(t) / M1) with N = 2 N0 / (2 + k0 N0 t)
(docs/physics.md sections 10 and 11.1). Its mass density p n(p) is a gamma density of shape
2, so the mass-based cumulative is Q3 = 1 - (1 + z) e^(-z), z = p N / M1, solved here by
Newton's method (no code shared with the package)."""
import math
from statistics import NormalDist

import numpy as np
import pytest

from pbe_cfd.runs import model
from pbe_cfd.distribution import reconstruct as R
from pbe_cfd.distribution import tables
from pbe_cfd.distribution.quantiles import DistributionError, bisect_quantiles, log_grid
from pbe_cfd.methods.registry import method_of
from pbe_cfd.runs.simulate import run_well_mixed

from conftest import make_scene

N0, P0, RHO, K0 = 1.0e10, 1.0e-9, 1000.0, 1.0e-10   # 1/m3, kg, kg/m3, m3/s
FRACTIONS = (0.1, 0.5, 0.9)


def _z_of_fraction(x):
    """z with 1 - (1 + z) e^-z = x (Newton from z = 1; the derivative is z e^-z)."""
    z = 1.0
    for _ in range(100):
        z -= (1.0 - (1.0 + z) * math.exp(-z) - x) / (z * math.exp(-z))
    return z


def _q3_exponential(d, mean_mass):
    z = math.pi / 6.0 * RHO * np.asarray(d) ** 3 / mean_mass
    return 1.0 - (1.0 + z) * np.exp(-z)


def _d_of_mass(p):
    return (6.0 * p / (math.pi * RHO)) ** (1.0 / 3.0)


def _exact_percentiles(t):
    mean_mass = P0 * (2.0 + K0 * N0 * t) / 2.0         # M1 / N(t), M1 = N0 P0 constant
    return np.array([_d_of_mass(_z_of_fraction(x) * mean_mass) for x in FRACTIONS]), mean_mass


def _scene(method, end=10.0, **method_keys):
    return make_scene(scene={"end_time": end, "output_interval": end / 4},
                      material={"density": RHO},
                      initial={"distribution": "exponential", "number_density": N0,
                               "mean_mass": P0},
                      aggregation={"kernel": "constant", "rate": K0},
                      method={"_replace": True, "name": method, **method_keys})


# ---------------------------------------------------------------------------- percentiles
def test_percentiles_of_a_log_uniform_class_table_are_exact():
    """q3 constant per ln d on [d1, d2]: d_x = d1 (d2/d1)^x; the table's Q3 is linear in ln
    d inside a class, so the only error is the bisection's (2^-60 of the bracket)."""
    d1, d2, n = 50e-6, 500e-6, 37
    edges = np.linspace(math.log(d1), math.log(d2), n + 1)
    table = R.ClassTable(edges, np.ones((1, n)))
    got = table.quantiles(FRACTIONS)[0]
    want = d1 * (d2 / d1) ** np.array(FRACTIONS)
    assert got == pytest.approx(want, rel=1e-12, abs=0)


def test_bisection_finds_lognormal_percentiles_and_a_step():
    """Q3 lognormal (d_g = 120 um, sigma = 0.4) and a step at 80 um (a monodisperse row):
    d_x = d_g exp(sigma Phi^-1(x)) and 80 um, to the bisection's 2^-60 of ln(1e10)."""
    dg, s, d_step = 120e-6, 0.4, 80e-6
    phi = np.vectorize(NormalDist().cdf)

    def cdf(d):
        d = np.asarray(d, float)
        return np.vstack([phi((np.log(d[0]) - math.log(dg)) / s), (d[1] >= d_step) * 1.0])

    got = bisect_quantiles(cdf, FRACTIONS, rows=2)
    want = [dg * math.exp(s * NormalDist().inv_cdf(x)) for x in FRACTIONS]
    assert got[0] == pytest.approx(want, rel=1e-12, abs=0)
    assert got[1] == pytest.approx([d_step] * 3, rel=1e-12, abs=0)


@pytest.mark.parametrize("fractions", [(0.0,), (1.0,), (0.5, 1.5), (-0.1,)])
def test_a_percentile_outside_0_1_says_so(fractions):
    table = R.ClassTable(np.log([1e-6, 2e-6]), np.ones((1, 1)))
    with pytest.raises(DistributionError, match="strictly between 0 and 1"):
        table.quantiles(fractions)


def test_a_grid_the_data_cannot_support_says_so():
    with pytest.raises(DistributionError, match="0 < d_min < d_max"):
        log_grid(2e-4, 1e-4, 10)
    with pytest.raises(DistributionError, match="at least 2"):
        log_grid(1e-4, 2e-4, 1)
    empty = R.GammaFit(np.zeros(3), np.zeros(3), np.zeros(3), RHO)
    with pytest.raises(DistributionError, match="no granules"):
        tables.auto_grid(empty)


EMPTY_SCENE = """
[scene]
name = "empty-start"
end_time = 4.0
output_interval = 2.0
[domain]
type = "well-mixed"
[material]
density = 1000.0
binder_density = 1000.0
[initial]
distribution = "monodisperse"
number_density = 0.0
mean_mass = 2e-9
[aggregation]
kernel = "constant"
rate = 1e-12
droplet_factor = 1.0
[binder_injection]
rate = 1e9
droplet_diameter = 60e-6
[method]
name = "{method}"
"""


@pytest.mark.parametrize("method", ["qmom", "laguerre"])
def test_a_run_without_granules_writes_no_size_distribution_and_says_so(tmp_path, capsys,
                                                                        method):
    """Droplets sprayed into a cell with no granules stay droplets: no output time holds a
    granule, there is nothing to reconstruct. The run finishes (the droplets' moments are
    its answer), d10/d50/d90/span are 0, and psd.csv and psd.png are not written, which
    the run's warnings and its last line say; columns.json lists no psd.csv. (Before: a
    traceback from the PSD grid.)"""
    from pbe_cfd.cli import main
    from pbe_cfd.io import output
    import json
    scene = tmp_path / "empty.toml"
    scene.write_text(EMPTY_SCENE.format(method=method))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert "psd.csv" not in last and "columns.json" in last
    cols = output.read_columns_csv(out / "moments.csv")
    droplets = np.asarray(cols["droplet_number_density"])
    assert np.all(droplets[1:] > 0.0)
    # every particle is a free droplet: the moments count them, the granules' PSD is empty
    assert np.array_equal(np.asarray(cols["M00"]), droplets)
    for name in ("d10_m", "d50_m", "d90_m", "span"):
        assert np.all(np.asarray(cols[name]) == 0.0), name
    assert not (out / "psd.csv").exists() and not (out / "psd.png").exists()
    assert "psd.csv" not in json.loads((out / "columns.json").read_text())
    warnings = json.loads((out / "summary.json").read_text())["warnings"]
    assert tables.NO_GRANULES in warnings


def test_the_cnmc_refuses_a_start_without_particles(tmp_path, capsys):
    """The constant-number Monte Carlo samples the particles of the start: an empty start is
    refused with exit 2 naming the key, before anything is written."""
    from pbe_cfd.cli import main
    scene = tmp_path / "empty.toml"
    scene.write_text(EMPTY_SCENE.format(method="cnmc"))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "initial.number_density" in err and "cnmc" in err
    assert not out.exists()


def test_an_unrealizable_row_is_named_and_falls_back_to_a_delta():
    """M20 < M10^2 / M00 (no distribution has these moments): named, delta at the mean."""
    m0, m1 = np.array([N0, N0]), np.array([N0 * P0, N0 * P0])
    m2 = np.array([2 * N0 * P0 ** 2, 0.5 * N0 * P0 ** 2])
    fit = R.GammaFit(m0, m1, m2, RHO, labels=lambda r: f"cell {r + 40}")
    cols, notes = tables.size_columns(fit)
    assert any("cell 41" in n and "delta at the mean" in n for n in notes)
    assert cols["d50_m"][1] == pytest.approx(_d_of_mass(P0), rel=1e-12, abs=0)
    assert cols["span"][1] == 0.0
    assert np.all(np.isfinite(cols["d10_m"]))


# ---------------------------------------------------------------------------- the methods
def test_qmom_reconstruction_is_exact_on_the_exponential_solution():
    """QMOM N = 3 carries M00, M10, M20 to the integrator's 1e-6 (test_qmom_analytic); the
    exponential is a gamma density of shape 1, so the one-kernel gamma fit is the exact
    solution and d_x = d(z_x M1/N) holds to 1e-6 / 3 in d (d ~ p^(1/3)); 1e-5 leaves the
    variance's cancellation (var/mean^2 = 1 here) a factor 10."""
    res = run_well_mixed(_scene("qmom", nodes=3))
    cols, t = res.columns, res.columns["time_s"]
    for k in range(len(t)):
        want, mean_mass = _exact_percentiles(t[k])
        got = [cols["d10_m"][k], cols["d50_m"][k], cols["d90_m"][k]]
        assert got == pytest.approx(want, rel=1e-5, abs=0)
        sel = res.psd["time_s"] == t[k]
        q3 = _q3_exponential(res.psd["d_m"][sel], mean_mass)
        assert res.psd["Q3"][sel] == pytest.approx(q3, rel=0, abs=1e-5)
    assert cols["span"] == pytest.approx((want[2] - want[0]) / want[1] * np.ones(len(t)),
                                         rel=1e-5, abs=0)


def _mass_quantile_sigma(x, mean_mass, n):
    """Standard deviation [m] of the mass-weighted sample quantile d_x of n exponential
    masses (delta method: Var F_hat = E[(p/mu)^2 (1{p < p_x} - x)^2] / n, divided by the
    density dQ3/dd at d_x), by quadrature of the closed form."""
    px = _z_of_fraction(x) * mean_mass
    p = np.linspace(0.0, 60 * mean_mass, 200001)
    f = np.exp(-p / mean_mass) / mean_mass
    g = (p / mean_mass) ** 2 * ((p < px) - x) ** 2 * f
    var = np.sum(0.5 * (g[1:] + g[:-1]) * np.diff(p)) / n
    z = px / mean_mass
    dq_dp = z * math.exp(-z) / mean_mass                  # d/dp of 1 - (1 + z) e^-z
    dd_dp = _d_of_mass(px) / (3.0 * px)
    return math.sqrt(var) / dq_dp * dd_dp


def test_cnmc_histogram_and_percentiles_follow_the_exponential_solution():
    """The cNMC's exact particle-list percentiles (mean of R replicas of N particles) within
    4 sigma of the delta-method sampling error plus the method's O(1/N) bias (|bias| <= 6.3/N
    relative on M20, test_cnmc; a third of it in d); its histogram's Q3 at the class
    centres within the DKW bound sqrt(ln(2/1e-6) / (2 n_eff)) at n_eff = N R / 2 (Kish's
    effective size of mass weights for exponential masses, E p^2 = 2 E[p]^2), plus the
    table's linear interpolation in a class (h^2/8 max Q3'', h = ln 10 / 50: < 1e-3)."""
    n, reps = 2000, 8
    res = run_well_mixed(_scene("cnmc", end=5.0, particles=n, replicas=reps, seed=11))
    cols, t = res.columns, res.columns["time_s"]
    eps = math.sqrt(math.log(2.0 / 1e-6) / (2.0 * n * reps / 2.0)) + 1e-3
    for k in range(len(t)):
        want, mean_mass = _exact_percentiles(t[k])
        for q, name in enumerate(("d10_m", "d50_m", "d90_m")):
            sigma = _mass_quantile_sigma(FRACTIONS[q], mean_mass, n * reps)
            band = 4.0 * sigma + 6.3 / n / 3.0 * want[q]
            assert abs(cols[name][k] - want[q]) <= band, (name, t[k])
        sel = res.psd["time_s"] == t[k]
        q3 = _q3_exponential(res.psd["d_m"][sel], mean_mass)
        assert np.max(np.abs(res.psd["Q3"][sel] - q3)) <= eps
        assert np.all(res.psd["q3_lo"][sel] <= res.psd["q3_per_ln_d"][sel] + 1e-15)


def test_laguerre_density_gives_the_exponential_it_represents_exactly():
    """A dry class whose weight is the exponential of the initial mean (shape 1): the
    expansion of an exponential start is its leading term alone, so the ROM's own density is
    the exponential and d_x = d(z_x P0). The class table (150 classes per decade of d, 2
    Gauss points in ln p) interpolates Q3 linearly in ln d: error <= h^2/8 max|Q3''| with h =
    ln 10 / 150 and |Q3''| < 4 (in ln d), 1.2e-4 in Q3, i.e. < 1e-3 in d_x with q3 > 0.3;
    the support p_max = 20 P0 drops a mass share 21 e^-20 = 4e-8."""
    scene = _scene("laguerre", dry_class=True, dry_weight_mean_mass=P0,
                   dry_weight_shape_mass=1.0, support_mass=20 * P0)
    arrays = model.pack(scene)
    aux = method_of(scene).aux(scene, arrays, None)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    table = R.laguerre_table(state[None, :], aux, arrays, scene.bivariate)
    want, _ = _exact_percentiles(0.0)
    assert table.quantiles(FRACTIONS)[0] == pytest.approx(want, rel=1e-3, abs=0)
    assert table.notes == []


def test_the_bed_mixture_weights_rows_by_granule_mass():
    """Two monodisperse cells, 30% and 70% of the mass at 100 um and 200 um: the mixture's
    d10 is 100 um, its d50 and d90 200 um (the smallest d with Q3 >= x), to the bisection's
    2^-20 of ln 2 (the cells' range; 6.6e-7) plus the bracket's 1e-9 margin."""
    pa, pb = (math.pi / 6 * RHO * d ** 3 for d in (100e-6, 200e-6))
    fit = R.GammaFit(np.array([1.0, 1.0]), np.array([pa, pb]), np.array([pa ** 2, pb ** 2]),
                     RHO)
    mix = R.Mixture(fit, np.array([0.3, 0.7]))        # the rows' granule masses
    assert mix.quantiles(FRACTIONS)[0] == pytest.approx([100e-6, 200e-6, 200e-6], rel=1e-6,
                                                        abs=0)


# ------------------------------------------------- QMOM/CQMOM: gamma kernels fitted to nodes
def _gauss_rule(m, n):
    """n-node Gauss rule (weights, nodes) of moments m[0 .. 2n] (Golub and Welsch 1969: the
    Cholesky factor of the Hankel matrix gives the Jacobi matrix), written in the test."""
    H = np.array([[m[i + j] for j in range(n + 1)] for i in range(n + 1)])
    R_ = np.linalg.cholesky(H).T
    a = np.zeros(n)
    b = np.zeros(n - 1)
    for j in range(n):
        a[j] = R_[j, j + 1] / R_[j, j] - (R_[j - 1, j] / R_[j - 1, j - 1] if j else 0.0)
        if j < n - 1:
            b[j] = R_[j + 1, j + 1] / R_[j, j]
    x, v = np.linalg.eigh(np.diag(a) + np.diag(b, 1) + np.diag(b, -1))
    return m[0] * v[0] ** 2, x


def _two_gamma_moments(w, x, sigma, k_max):
    """Moments m_0 .. m_(k_max) of sum_a w_a gamma(mean x_a, variance x_a sigma): rising
    factorials x (x + sigma) ... (x + (k - 1) sigma) (Yuan, Laurent and Fox 2012)."""
    return np.array([sum(wa * np.prod([xa + j * sigma for j in range(k)])
                         for wa, xa in zip(w, x)) for k in range(k_max + 1)])


def test_node_fit_is_exact_on_a_mixture_of_two_gamma_kernels():
    """The nodes of QMOM N = 3 of a two-kernel gamma mixture of one width carry its M00..M50;
    the fit of N - 1 = 2 kernels to M00..M40 recovers the mixture, so Q3 and the percentiles
    are the mixture's (P(l + 1, p / sigma) per kernel, scipy) to the inversion's root
    tolerance (|J| <= 1e-11 relative on M40; Q3 to 1e-8 leaves the Gauss rule's round-off in
    the Hankel factor of moments up to 4^5 ~ 1e3, eps 2e-16, a factor 100)."""
    from scipy.special import gammainc
    from pbe_cfd.distribution import kernel_mixture as KM
    w, x, sigma = np.array([0.6, 0.4]) * N0, np.array([1.0, 4.0]), 0.5     # x, sigma in P0
    weights, nodes = _gauss_rule(_two_gamma_moments(w / N0, x, sigma, 6), 3)
    pops = [(weights * N0, nodes * P0, np.zeros(3))]
    mix = KM.of_nodes(pops, RHO, False)
    assert mix.notes == []
    d = _d_of_mass(np.geomspace(0.05, 40.0, 30) * P0)
    p = math.pi / 6 * RHO * d ** 3 / P0
    want = sum(wa * xa * gammainc(xa / sigma + 1.0, p / sigma) for wa, xa in zip(w, x))
    want = want / np.sum(w * x)
    assert mix.cdf(d)[0] == pytest.approx(want, rel=0, abs=1e-8)
    assert mix.sigma[0] == pytest.approx(sigma * P0, rel=1e-8, abs=0)


def test_node_fit_with_two_nodes_is_the_one_gamma_fit():
    """QMOM N = 2: one kernel on M00, M10, M20, the gamma density of GammaFit (same
    moments, closed-form percentiles) to the bisection's 2^-60 in ln d."""
    from pbe_cfd.distribution import kernel_mixture as KM
    w, p = np.array([0.7, 0.3]) * N0, np.array([1.0, 3.5]) * P0
    mix = KM.of_nodes([(w, p, 0.2 * p)], RHO, True)
    fit = R.GammaFit(w.sum()[None], (w * p).sum()[None], (w * p * p).sum()[None], RHO)
    assert mix.quantiles(FRACTIONS) == pytest.approx(fit.quantiles(FRACTIONS), rel=1e-12,
                                                     abs=0)
    edges = np.geomspace(50e-6, 300e-6, 6)
    assert mix.class_binder(edges[:-1], edges[1:]) == pytest.approx(0.2, rel=0, abs=1e-12)


def test_a_node_set_without_a_distribution_is_named_with_its_fallback():
    """A row with a non-finite node (a failed quadrature) is drawn empty and named; a
    monodisperse row (one node) is a delta, d10 = d50 = d90 = its diameter."""
    from pbe_cfd.distribution import kernel_mixture as KM
    pops = [(np.array([N0, np.nan, N0]), np.array([1.0, 2.0, 3.0]) * P0, np.zeros(3)),
            (np.array([N0]), np.array([P0]), np.zeros(1))]
    mix = KM.of_nodes(pops, RHO, False, labels=lambda r: f"cell {r + 7}")
    cols, notes = tables.size_columns(mix)
    assert any("cell 7" in n and "not finite" in n and "no granules drawn" in n for n in notes)
    assert cols["d50_m"][0] == 0.0
    assert [cols[k][1] for k in ("d10_m", "d50_m", "d90_m")] == pytest.approx(
        [_d_of_mass(P0)] * 3, rel=1e-12, abs=0)


def test_two_node_rows_in_closed_form_are_the_general_fit_and_its_percentiles():
    """Rows of two nodes take the one-gamma fit in closed form (sigma = (u2 - 1) mean) and
    their percentiles from P^-1; rows of three nodes bisect between their kernels'
    percentiles. Both must equal the general inversion (``_fit_row``) and a bisection of the
    row's own Q3 over the widest bracket (1 nm .. 10 m) to round-off: 1e-13 relative on the
    fit (a few ulps through u2), 1e-12 on a diameter (2^-60 of 23 decades in ln d is 5e-17;
    P^-1 to ~1e-14)."""
    from pbe_cfd.distribution import kernel_mixture as KM
    rng = np.random.default_rng(2027)
    for n in (2, 3):
        pops = []
        for _ in range(60):
            w = rng.uniform(0.05, 1.0, n) * N0
            p = np.sort(rng.uniform(0.2, 8.0, n)) * P0
            pops.append((w, p, np.zeros(n)))
        pops.append((np.full(n, N0), P0 * (1.0 + 1e-7 * np.arange(n)), np.zeros(n)))
        mix = KM.of_nodes(pops, RHO, False)
        for r, (w, p, _) in enumerate(pops):
            sigma, c, cw, _ = KM._fit_row(p, w, n - 1)
            assert mix.sigma[r] == pytest.approx(sigma, rel=1e-13, abs=1e-30 * P0), (n, r)
            k = c.size
            assert mix.x[r, :k] == pytest.approx(c, rel=1e-13, abs=0), (n, r)
            assert mix.w[r, :k] == pytest.approx(cw, rel=1e-13, abs=0), (n, r)
        wide = bisect_quantiles(mix.cdf, FRACTIONS, mix.rows)
        assert mix.quantiles(FRACTIONS) == pytest.approx(wide, rel=1e-12, abs=0), n
