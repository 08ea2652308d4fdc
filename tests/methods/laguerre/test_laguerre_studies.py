"""Laguerre ROM from a dry start against independent references (issue 15): the seed scenario
without droplets at t = 0 against a cNMC ensemble, and the fluid bed against QMOM N = 3.

Tolerances: the issue's aim, 10% on every carried moment (the population's M_ij, i, j < m, and
the dry class's M_k0), plus the reference's own 95% half-width (its replicas' spread); the
ensemble (3e4 particles x 8 replicas per output time, seed fixed before looking) is independent
code (methods.cnmc). On the fluid bed, 10% of QMOM N = 3 on the bed means the issue names.
"""
import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from pbe_cfd.runs import model
from pbe_cfd.runs.couple import run_coupled
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.methods.cnmc import ensemble as cnmc
from pbe_cfd.methods.cnmc.box import MAX_TRIALS, N_QUANTITIES, run_box
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.runs.simulate import run_well_mixed

TIMES = (60.0, 300.0, 600.0)
PARTICLES, REPLICAS, SEED = 30_000, 8, 2024


def cnmc_moments(scene, times, particles, replicas, seed, order=4):
    """{t: {name: (mean, 95% half-width)}} of M_ij (whole population, free droplets included)
    and dry_M{k}0 (granules with b = 0) from the final boxes of independent replicas run to
    each time; the box volume from its mass and the exact M10 (the cNMC keeps M10 exact)."""
    arrays = model.pack(scene)
    cell = model.well_mixed_cell(scene)[0]
    initial = dataclasses.asdict(scene.initial)
    out = {}
    for t in times:
        rows = []
        for child in np.random.SeedSequence([seed, int(t)]).spawn(replicas):
            rng = np.random.default_rng(child)
            p, b, isdrop, vol0 = cnmc.initial_box(arrays.params, arrays.config, initial,
                                                  particles, rng)
            res = np.empty((2, N_QUANTITIES))
            status = run_box(p, b, isdrop, vol0, np.array([0.0, t]), cell, arrays.params,
                             arrays.config, int(rng.integers(0, 2 ** 31 - 1)), 0, MAX_TRIALS,
                             res)[4]
            assert status == 0
            vol = p.sum() / res[-1, 1]
            dry = (isdrop == 0) & (b == 0.0)
            row = {f"M{i}{j}": np.sum(p ** i * b ** j) / vol
                   for i in range(order) for j in range(order)}
            row.update({f"dry_M{k}0": np.sum(p[dry] ** k) / vol for k in range(order)})
            rows.append(row)
        q = stats.t.ppf(0.975, replicas - 1) / math.sqrt(replicas)
        out[t] = {k: (float(np.mean([r[k] for r in rows])),
                      float(q * np.std([r[k] for r in rows], ddof=1))) for k in rows[0]}
    return out


@pytest.fixture(scope="module")
def seed_dry_reference():
    return cnmc_moments(load_scene("study-seed-dry"), TIMES, PARTICLES, REPLICAS, SEED)


@pytest.mark.slow
@pytest.mark.parametrize("order, knobs", [
    (3, {}),
    (4, {"grid_mass": 30, "grid_binder": 30, "adaptive_points": 13}),
], ids=["m3", "m4"])
def test_seed_scenario_from_a_dry_start_against_the_cnmc(order, knobs, seed_dry_reference):
    """Every carried moment of the ROM (M_ij, i, j < m, and the dry class's M_k0) within 10% of
    the cNMC (plus its 95% half-width) at 60, 300 and 600 s. m = 4 needs the finer quadrature
    (30 x 30) and weight grid (13 x 13): its highest moments at 60 s come from the first wet
    granules, a narrow population that 20 x 20 nodes under-resolve (14% on M33 there)."""
    scene = load_scene("study-seed-dry").with_method(order=order, **knobs)
    scene = dataclasses.replace(scene, output_interval=60.0)
    cols = run_well_mixed(scene).columns
    names = [f"M{i}{j}" for i in range(order) for j in range(order)]
    names += [f"dry_M{k}0" for k in range(order)]
    bad = []
    for t in TIMES:
        k = int(np.argmin(np.abs(cols["time_s"] - t)))
        for q in names:
            ref, half = seed_dry_reference[t][q]
            err = cols[q][k] / ref - 1.0
            if abs(err) > 0.10 + half / ref:
                bad.append(f"{q} at {t:g} s: {err:+.1%} (reference +-{half / ref:.1%})")
    assert bad == []


@pytest.mark.slow
def test_fluid_bed_from_a_dry_start_against_qmom():
    """The bundled fluid bed with the Laguerre ROM and no droplets at t = 0 runs to the end;
    its bed means at 60 s (M00, d43, binder fraction) within 10% of QMOM N = 3, and mass and
    binder exact."""
    scene = load_scene("fluid-bed-laguerre")
    scene = dataclasses.replace(scene, output_interval=30.0)
    domain = load_domain(scene)
    lag = run_coupled(scene, domain)
    qmom = run_coupled(scene.with_method(name="qmom", nodes=3), domain)
    assert lag.times[-1] == scene.end_time
    for q in ("M00", "d43_m", "binder_fraction"):
        assert lag.bed_columns[q][-1] == pytest.approx(qmom.bed_columns[q][-1], rel=0.10, abs=0), q
    for q in ("M10", "M01"):
        assert lag.bed_columns[q][-1] == pytest.approx(qmom.bed_columns[q][-1], rel=1e-10, abs=0), q


@pytest.mark.slow
@pytest.mark.study
def test_bed_batch_within_5_percent_of_qmom_and_cqmom():
    """The bundled fluid-bed-laguerre-batch (30 min with [transport]; the following support
    with the wet rows of order 0 and 2 on the points) finishes, and its bed M00, d43 and
    binder fraction are within 5% (issue 26's aim) of QMOM N = 3 and of CQMOM 3 x 3 on the same
    scene at 15 and 30 min; at 5 min, where QMOM and CQMOM differ by 20% on M00, within 5% of
    the interval between them. M10 and M01 as QMOM's to 1e-10. Measured 2026-12-06: largest
    3.5% (M00 against CQMOM at 15 min); 11.6 min of wall on 2 cores. Red with
    following_growth = 1000: the run stops at 1061 s (1080 s with the tensors' rows;
    docs/results/laguerre.md)."""
    scene = load_scene("fluid-bed-laguerre-batch")
    domain = load_domain(scene, need_flux=True)
    runs = {"laguerre": run_coupled(scene, domain),
            "qmom": run_coupled(scene.with_method(name="qmom", nodes=3), domain),
            "cqmom": run_coupled(scene.with_method(name="cqmom", nodes=3, binder_nodes=3),
                                 domain)}
    assert runs["laguerre"].times[-1] == scene.end_time

    def at(name, q, t):
        r = runs[name]
        return r.bed_columns[q][int(np.argmin(np.abs(np.asarray(r.times) - t)))]

    for q in ("M00", "d43_m", "binder_fraction"):
        for t in (900.0, 1800.0):
            for ref in ("qmom", "cqmom"):
                assert at("laguerre", q, t) == pytest.approx(at(ref, q, t), rel=0.05,
                                                             abs=0), (q, t, ref)
        low, high = sorted((at("qmom", q, 300.0), at("cqmom", q, 300.0)))
        assert 0.95 * low <= at("laguerre", q, 300.0) <= 1.05 * high, q
    for q in ("M10", "M01"):
        assert at("laguerre", q, 1800.0) == pytest.approx(at("qmom", q, 1800.0), rel=1e-10,
                                                          abs=0), q
