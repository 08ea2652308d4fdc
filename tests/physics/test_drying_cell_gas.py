"""The drying's gas per cell from the CFD (docs/physics.md section 15, "Per-cell inputs from
the CFD"): the slip velocity and the gas state carried in the cell rows.

Closed form: two cells of one monodisperse wet population (no aggregation) at different slip
velocities, each in the constant-rate period: each cell's liquid falls linearly at the rate of
its own slip, b(t) = b0 - e_c(u_slip) t, e_c written out in ``test_drying._constant_rate`` (not
the physics module's code); M01, M10 and the evaporated liquid to 1e-8 (the integrator at rtol
1e-11 over ~10^2 steps, as ``test_drying``). The one point of every method's quadrature is
exact, so each method's drift is that of one granule.
"""
import math
import shutil

import meshio
import numpy as np
import pytest

from test_drying import AIR, N0, P0, TOL, _constant_rate, _scene
from pbe_cfd.io import openfoam as of
from pbe_cfd.physics import drying
from pbe_cfd.physics import parameters as P
from pbe_cfd.runs.batch import CellBatch
from pbe_cfd.runs.problem import problem_of
from pbe_cfd.scene.scene import SceneError, load_scene, resolve_scene_path

METHODS = {
    "qmom": {"name": "qmom", "nodes": 3},
    "cqmom": {"name": "cqmom", "nodes": 2, "binder_nodes": 2},
    "eqmom": {"name": "eqmom", "nodes": 2},
    "laguerre": {"name": "laguerre", "order": 3},
}
SLIPS = (0.3, 2.5)          # m/s: Sh 2.6 and 3.7 for the 100 um skeleton
Y0, X_CR = 0.2, 0.05


def _two_cells(method, air_rows=None):
    """A batch of two copies of the well-mixed cell, the first at slip SLIPS[0], the second
    at SLIPS[1] (cell rows, config DRYING_CELL_SLIP = 1); with ``air_rows`` (2 x 3: K,
    rho_g / mu_g, Sc) also the gas state per cell (DRYING_CELL_AIR = 1)."""
    problem = problem_of(_scene(Y0, 1.0, X_CR, method=METHODS[method]))
    config = problem.arrays.config.copy()
    config[P.DRYING_CELL_SLIP] = 1
    rows = np.repeat(problem.rows, 2, axis=0)
    rows[:, P.SLIP_VELOCITY] = SLIPS
    if air_rows is not None:
        config[P.DRYING_CELL_AIR] = 1
        rows[:, [P.GAS_DRIVING, P.GAS_REYNOLDS, P.GAS_SCHMIDT]] = air_rows
    states = np.repeat(problem.states, 2, axis=0)
    batch = CellBatch(params=problem.arrays.params, config=config, aux=problem.aux, rows=rows,
                      states=states, rtol=problem.rtol, atol=problem.atol,
                      steps=np.full(2, problem.first_step), source="two cells",
                      plan=problem.outputs.method_plan, arrays=problem.arrays)
    return batch, list(problem.arrays.state_names)


def _follow(batch, names, rates, end):
    """Advance the batch to ``end`` [s] in 8 outputs; at each, every cell's M01, M10 and E
    against b0 - e_c t of its own rate ``rates`` [kg/s] (ratios to the initial values)."""
    pre = "wet_" if "wet_M01" in names else ""
    i01, i10 = names.index(pre + "M01"), names.index(pre + "M10")
    ie = names.index("evaporated_liquid")
    s0 = batch.states.copy()
    b0, ms = Y0 * P0, (1.0 - Y0) * P0
    times = np.linspace(0.0, end, 9)
    for t0, t1 in zip(times[:-1], times[1:]):
        batch.advance(t0, t1)
        batch.raise_if_failed()
        for c, ec in enumerate(rates):
            b = b0 - ec * t1
            assert b > X_CR * ms                       # still the constant-rate period
            s = batch.states[c]
            assert s[i01] / s0[c, i01] == pytest.approx(b / b0, rel=TOL, abs=0.0)
            assert s[i10] / s0[c, i10] == pytest.approx((ms + b) / P0, rel=TOL, abs=0.0)
            assert s[ie] / s0[c, i01] == pytest.approx(ec * t1 / b0, rel=TOL, abs=0.0)


def _end(rates):
    """0.9 of the constant-rate period of the faster cell [s]."""
    return 0.9 * (Y0 * P0 - X_CR * P0 * (1.0 - Y0)) / max(rates)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_each_cell_dries_at_the_rate_of_its_own_slip(method):
    rates = [_constant_rate(P0, Y0, {**AIR, "slip_velocity": u}) for u in SLIPS]
    assert rates[1] > 1.2 * rates[0]        # the two cells are told apart
    batch, names = _two_cells(method)
    _follow(batch, names, rates, _end(rates))


@pytest.mark.parametrize("method", ["qmom", "laguerre"])
def test_each_cell_dries_in_its_own_gas_temperature(method):
    """Gas at 300 K and 350 K (the scene's humidity and pressure): each cell's gas state from
    the vectorised ``gas_state_cells``, its rate written out from the scalar ``gas_state``."""
    temps = (300.0, 350.0)
    air_rows = np.column_stack(drying.gas_state_cells(np.array(temps), AIR["air_humidity"],
                                                      101325.0))
    rates = [_constant_rate(P0, Y0, {**AIR, "slip_velocity": u, "air_temperature": t})
             for u, t in zip(SLIPS, temps)]
    batch, names = _two_cells(method, air_rows)
    _follow(batch, names, rates, _end(rates))


# ---- the bed's air balance with a gas temperature per cell ------------------------------
TEMPS = (300.0, 350.0)       # K
VOLUMES = (2.0e-4, 1.0e-4)   # m3 of bed per cell


def _balanced_cells(method, flow):
    """``_two_cells`` at TEMPS with the bed's well-mixed air (dry-air flow ``flow`` [kg/s])
    over VOLUMES: each cell its own gas state from ``gas_parts_cells``."""
    from pbe_cfd.runs.air import BedAir
    unit, inlet, reynolds, schmidt = drying.gas_parts_cells(np.array(TEMPS),
                                                            AIR["air_humidity"], 101325.0)
    batch, names = _two_cells(method, np.column_stack([unit * inlet, reynolds, schmidt]))
    arrays = batch.arrays
    batch.air = BedAir(volumes=np.array(VOLUMES), flow=flow, inlet_driving=float(inlet[0]),
                       unit_driving=float(unit[0]), mixing="well-mixed", interval=0.05,
                       evaporated_index=names.index("evaporated_liquid"),
                       scale=arrays.number_scale * arrays.mass_scale,
                       inlet_temperature=AIR["air_temperature"],
                       inlet_humidity=AIR["air_humidity"], wet_bulb=math.nan,
                       cell_unit=unit, cell_inlet_driving=inlet,
                       cell_temperature=np.array(TEMPS))
    return batch, names


def _isolated():
    """(e_c [kg/s] of a granule alone in each cell's gas, dY_in,c [kg/kg], K_c [kg/s] of each
    cell's N0 V_c granules): the scalar ``gas_state`` and the formula of ``test_drying``."""
    rates = [_constant_rate(P0, Y0, {**AIR, "slip_velocity": u, "air_temperature": t})
             for u, t in zip(SLIPS, TEMPS)]
    inlet = [drying.gas_state(t, AIR["air_humidity"], 101325.0)[4] for t in TEMPS]
    cond = [N0 * v * e / d for v, e, d in zip(VOLUMES, rates, inlet)]
    return rates, inlet, cond


@pytest.mark.parametrize("method", ["qmom", "laguerre"])
def test_cells_of_their_own_temperature_share_the_beds_humidity(method):
    """Constant rate, both cells drying: the gas balance G x = sum K_c (dY_in,c - x) (written
    out here) gives x, and each cell's liquid falls linearly at e_c (dY_in,c - x) / dY_in,c
    (exact for the lagged pieces: every K_c is constant), to 1e-8 as ``_follow``."""
    rates, inlet, cond = _isolated()
    # the flow that puts the bed's humidity rise at 0.6 of the cold cell's dY_in
    flow = sum(k * d for k, d in zip(cond, inlet)) / (0.6 * inlet[0]) - sum(cond)
    rise = sum(k * d for k, d in zip(cond, inlet)) / (flow + sum(cond))
    assert 0.0 < flow and rise < min(inlet)         # both cells dry
    lowered = [e * (d - rise) / d for e, d in zip(rates, inlet)]
    assert lowered[0] < 0.5 * rates[0]              # told apart from the isolated rates
    batch, names = _balanced_cells(method, flow)
    _follow(batch, names, lowered, _end(lowered))
    pieces = batch.air.pieces
    bed = sum(N0 * v * r for v, r in zip(VOLUMES, lowered))
    assert pieces[-1][1] == pytest.approx(bed, rel=TOL, abs=0.0)
    col = batch.air.columns(np.array([pieces[-1][0]]))
    assert col["outlet_humidity"][0] == pytest.approx(AIR["air_humidity"] + rise, rel=TOL,
                                                      abs=0.0)
    assert "outlet_temperature_K" not in col
    # the rows are put back: the CFD's gas state at the inlet humidity
    unit, inlet_c, _, _ = drying.gas_parts_cells(np.array(TEMPS), AIR["air_humidity"],
                                                 101325.0)
    assert np.array_equal(batch.rows[:, P.GAS_DRIVING], unit * inlet_c)


def test_a_cell_below_the_beds_humidity_stops_drying_and_is_named():
    """A small air flow: the warm cell alone raises the bed's humidity above the cold cell's
    Y_s(T_wb): x = K_w dY_w / (G + K_w), the warm cell dries at e_w (dY_w - x) / dY_w, the
    cold one not at all (no condensation), and the run says so once."""
    rates, inlet, cond = _isolated()
    flow = 0.2 * cond[1] * (inlet[1] - inlet[0]) / inlet[0]
    rise = cond[1] * inlet[1] / (flow + cond[1])
    assert inlet[0] < rise < inlet[1]
    lowered = [0.0, rates[1] * (inlet[1] - rise) / inlet[1]]
    batch, names = _balanced_cells("qmom", flow)
    _follow(batch, names, lowered, 0.9 * (Y0 * P0 - X_CR * P0 * (1.0 - Y0)) / lowered[1])
    notes = [n for n in batch.notes if "condensation is not modelled" in n]
    assert len(notes) == 1 and "1 of 2 cells" in notes[0] and "300..300 K" in notes[0]


def test_cell_humidity_rise_is_the_root_of_the_gas_balance():
    """``cell_humidity_rise`` against the balance it solves, on random cells (seed fixed):
    G x = sum K_c max(0, dY_c - x) to round-off, and the equal-driving limit dY K / (G + K)
    of the bed's one-temperature balance."""
    from pbe_cfd.physics.air import cell_humidity_rise
    rng = np.random.default_rng(20261205)
    for _ in range(50):
        n = int(rng.integers(1, 40))
        k = rng.uniform(0.0, 2.0, n) * (rng.random(n) > 0.2)
        d = rng.uniform(-0.002, 0.03, n)
        flow = float(rng.uniform(0.01, 5.0))
        x = cell_humidity_rise(k, d, flow)
        gas = flow * x
        granules = float(np.sum(k * np.maximum(0.0, d - x)))
        assert x >= 0.0
        assert gas == pytest.approx(granules, rel=1e-12, abs=1e-15 * flow)
    k = rng.uniform(0.1, 1.0, 7)
    assert cell_humidity_rise(k, np.full(7, 0.02), 0.3) == pytest.approx(
        0.02 * k.sum() / (0.3 + k.sum()), rel=1e-14, abs=0.0)


def test_vectorised_gas_state_is_the_scalar_one():
    """``gas_state_cells`` against ``gas_state`` cell by cell, 260..440 K and a saturated
    cell: the wet bulb's bisections end within 1e-10 K of each other, so the driving force
    agrees to dY/dT 1e-10 K over dY (1e-8 relative at 260 K, where dY is smallest)."""
    temps = np.array([260.0, 283.15, 300.0, 333.15, 380.0, 440.0, 277.0])
    humidity = 0.005                 # saturated below 277.3 K: the first and last cells
    k, re, sc = drying.gas_state_cells(temps, humidity, 101325.0)
    for i, t in enumerate(temps):
        rho, mu, dv, _, dy = drying.gas_state(float(t), humidity, 101325.0)
        assert k[i] == pytest.approx(dv * rho * dy, rel=1e-8, abs=1e-15)
        assert re[i] == pytest.approx(rho / mu, rel=1e-14, abs=0.0)
        assert sc[i] == pytest.approx(mu / (rho * dv), rel=1e-14, abs=0.0)


# ---- a coupled run on a snapshot with the phases' velocities and temperatures ----------
BUNDLED = of.default_snapshot_path()


def _snapshot(tmp, fields=("U.air", "U.particles", "T.air")):
    """A copy of the bundled snapshot (and its flux file) with ``fields`` added: U.air =
    (0, 0.2 + 2 y / m, 0) m/s, U.particles = (0.05, 0, 0) m/s, T.air = 300 + 200 x K/m."""
    mesh = meshio.read(BUNDLED)
    centre = np.asarray(mesh.cell_data["cell_centre"][0], dtype=float)
    n = len(centre)
    values = {"U.air": np.column_stack([np.zeros(n), 0.2 + 2.0 * centre[:, 1], np.zeros(n)]),
              "U.particles": np.column_stack([np.full(n, 0.05), np.zeros(n), np.zeros(n)]),
              "T.air": 300.0 + 200.0 * centre[:, 0]}
    for name in fields:
        mesh.cell_data[name] = [values[name]]
    out = tmp / "snap.vtu"
    meshio.write(out, mesh)
    shutil.copyfile(BUNDLED.with_name(BUNDLED.stem + "_flux.npz"), tmp / "snap_flux.npz")
    return out


def _coupled_scene(tmp, snap, end=1.0):
    """fluid-bed-batch on ``snap``: no transport, no air balance, 1 s, the slip velocity and
    the gas temperature from the CFD."""
    text = resolve_scene_path("fluid-bed-batch").read_text()
    text = text.split("[transport]")[0]
    text = text.replace('case = "bundled:fluid_bed_small"', f'case = "{snap.name}"')
    text = text.replace("end_time = 1800.0", f"end_time = {end}")
    text = text.replace("output_interval = 30.0", f"output_interval = {end / 2}")
    lines = []
    for line in text.splitlines():
        key = line.split("=")[0].strip()
        if key in ("air_balance", "air_mass_flow", "air_interval"):
            continue
        if key == "slip_velocity":
            line = 'slip_velocity_source = "cfd"\nair_temperature_source = "cfd"'
        lines.append(line)
    path = tmp / "s.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_coupled_rows_hold_the_case_fields(tmp_path):
    """The cell rows of a coupled problem hold |U.air - U.particles| and the gas state of
    T.air per OpenFOAM cell (the snapshot's cellID order), and the plan gives their ranges."""
    from pbe_cfd.runs.domain import load_domain
    from pbe_cfd.runs.plan import describe_plan
    scene = load_scene(_coupled_scene(tmp_path, _snapshot(tmp_path)))
    domain = load_domain(scene)
    problem = problem_of(scene, domain)
    cells = domain.cells
    idx = np.flatnonzero(np.asarray(cells.alpha) >= scene.domain.alpha_min)
    y, x = cells.cell_centre[idx, 1], cells.cell_centre[idx, 0]
    slip = np.hypot(0.05, 0.2 + 2.0 * y)
    assert np.allclose(problem.rows[:, P.SLIP_VELOCITY], slip, rtol=1e-12, atol=0.0)
    for row, xi in zip(problem.rows[:5], x[:5]):
        rho, mu, dv, _, dy = drying.gas_state(300.0 + 200.0 * xi, 0.005, 101325.0)
        assert row[P.GAS_DRIVING] == pytest.approx(dv * rho * dy, rel=1e-8, abs=0.0)
        assert row[P.GAS_REYNOLDS] == pytest.approx(rho / mu, rel=1e-12, abs=0.0)
    assert problem.arrays.config[P.DRYING_CELL_SLIP] == 1
    assert problem.arrays.config[P.DRYING_CELL_AIR] == 1
    text = describe_plan(scene)
    assert f"{slip.min():.4g}..{slip.max():.4g} over the {idx.size} active cells" in text
    assert "U.air - U.particles" in text and "(T.air," in text


def test_a_coupled_run_reads_them(tmp_path, monkeypatch):
    """``couple`` on the snapshot with the fields: exit 0, the bed evaporates, and the sprayed
    liquid is held or evaporated to 1e-12 (M01 + E is an invariant of the per-cell
    integration whatever each cell's rate: round-off of the sums over 540 cells)."""
    from pbe_cfd.cli import main
    scene = _coupled_scene(tmp_path, _snapshot(tmp_path))
    monkeypatch.chdir(tmp_path)
    assert main(["couple", str(scene), "--out", "o"]) == 0
    import csv
    with open(tmp_path / "o" / "bed_moments.csv") as fh:
        rows = list(csv.DictReader(fh))
    last = {k: float(v) for k, v in rows[-1].items()}
    assert last["liquid_evaporated_kg"] > 0.0
    held = sum(last[f"liquid_{k}_kg"] for k in ("granules", "droplets", "evaporated"))
    assert held == pytest.approx(last["liquid_sprayed_kg"], rel=1e-12, abs=0.0)


def test_a_coupled_run_holds_the_beds_air_with_the_cfds_temperature(tmp_path, monkeypatch):
    """``couple`` with the CFD's gas temperature and the well-mixed bed air, against the same
    run without the balance: exit 0, the sprayed liquid held or evaporated to 1e-12, less
    evaporated (the air limits: the bed's humidity lowers every cell's driving force), the
    outlet humidity Y_in + E / G of the bed's rate, and no outlet temperature column."""
    import csv
    from pbe_cfd.cli import main
    path = _coupled_scene(tmp_path, _snapshot(tmp_path))
    text = path.read_text().replace("[drying]", "[drying]\nair_balance = \"well-mixed\"\n"
                                    "air_mass_flow = 5e-5\nair_interval = 0.25")
    balanced = tmp_path / "b.toml"
    balanced.write_text(text)
    monkeypatch.chdir(tmp_path)
    last = {}
    for name, scene in (("free", path), ("held", balanced)):
        assert main(["couple", str(scene), "--out", name]) == 0
        with open(tmp_path / name / "bed_moments.csv") as fh:
            rows = list(csv.DictReader(fh))
        last[name] = {k: float(v) for k, v in rows[-1].items()}
    held = last["held"]
    total = sum(held[f"liquid_{k}_kg"] for k in ("granules", "droplets", "evaporated"))
    assert total == pytest.approx(held["liquid_sprayed_kg"], rel=1e-12, abs=0.0)
    assert 0.0 < held["liquid_evaporated_kg"] < 0.5 * last["free"]["liquid_evaporated_kg"]
    assert held["outlet_humidity"] == pytest.approx(
        0.005 + held["evaporation_rate_kg_s"] / 5e-5, rel=1e-12, abs=0.0)
    assert "outlet_temperature_K" not in held


@pytest.mark.parametrize("missing,key", [("U.particles", "slip_velocity_source"),
                                         ("T.air", "air_temperature_source")])
def test_a_case_without_the_field_is_one_line_exit_2(tmp_path, capsys, monkeypatch, missing,
                                                     key):
    from pbe_cfd.cli import main
    fields = [f for f in ("U.air", "U.particles", "T.air") if f != missing]
    scene = _coupled_scene(tmp_path, _snapshot(tmp_path, fields))
    monkeypatch.chdir(tmp_path)
    assert main(["couple", str(scene), "--out", "o"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"drying.{key}" in err[0] and missing in err[0] and "snap.vtu" in err[0], err[0]
    assert "t = 1.5 s" in err[0], err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("edit,key", [
    ({"slip_velocity_source": 'slip_velocity = 0.3\nslip_velocity_source = "cfd"'},
     "drying.slip_velocity"),
    ({"air_temperature_source": 'air_temperature_source = "cfd"\nair_balance = "plug-flow"'
                                '\nair_mass_flow = 5e-3'}, "drying.air_temperature_source"),
    ({"slip_velocity_source": 'slip_velocity_source = "sky"'}, "drying.slip_velocity_source")])
def test_bad_source_keys_are_refused(tmp_path, edit, key):
    """slip_velocity beside slip_velocity_source = "cfd", the CFD's gas temperature with the
    plug-flow air balance (its granules see the height's average), an unknown source."""
    path = _coupled_scene(tmp_path, _snapshot(tmp_path))
    lines = []
    for line in path.read_text().splitlines():
        k = line.split("=")[0].strip()
        lines.append(edit.get(k, line))
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert f"[{key}]" in str(err.value), str(err.value)


def test_cfd_keys_in_a_well_mixed_domain_are_refused():
    from conftest import make_scene
    air = {k: v for k, v in AIR.items() if k != "slip_velocity"}
    with pytest.raises(SceneError) as err:
        make_scene(material={"density": 1021.0, "binder_density": 1000.0},
                   initial={"mean_mass": P0, "number_density": 1e10, "binder_fraction": 0.2},
                   drying={**air, "critical_moisture": 0.05, "slip_velocity_source": "cfd"})
    assert "drying.slip_velocity_source" in str(err.value)
    assert "well-mixed domain has no CFD fields" in str(err.value)
