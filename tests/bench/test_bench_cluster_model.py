"""The multi-machine model of ``pbe-cfd bench cluster`` (``bench.cluster_3d``): its scaling laws
and its answer checked by hand against runs made up here (no run of the bed is needed: the
model is arithmetic on measured numbers), and the report of a study that has no serial run."""
import math

import pytest

from pbe_cfd.bench.cluster_3d import cluster_markdown, multi_machine_model, one_layer_model

#: A serial transport run as the study records it: 1e6 active cells, 60 s of process.
SERIAL = {"transport": True, "workers": 0, "balance": True, "active_cells": 1_000_000,
          "bed_cells": 2_000_000, "end_time": 60.0, "accepted_steps": 6e8,
          "source_wall_s": 600.0, "transport_wall_s": 500.0,
          "phases": {"solve_s": 1100.0, "setup_s": 1.0}, "cell_steps_per_s": 5e5,
          "client_peak_rss": 2**30, "worker_peak_rss": [], "final_hash": "h",
          "client_sent_bytes_per_split_step": None}
#: The 2-block run of the same bed: halo 100 + 100 cells at depth 200 = the substeps per part.
TWO = {**SERIAL, "workers": 2, "halo_cells": [100, 100], "halo_depth": 200,
       "substeps_per_part": 200, "halo_bytes_per_transport_part": 200 * 7 * 8,
       "phases": {"solve_s": 1200.0, "setup_s": 1.0}, "worker_peak_rss": [2**29, 2**29],
       "client_sent_bytes_per_split_step": 8000.0}


def test_one_layer_model_divides_the_work_and_pays_every_exchange():
    # eight times the cells: cell size halves, so twice the substeps; the sources scale with
    # the cells (x 8), the transport with cells x substeps (x 16); both over 30x the process
    n = 8e6
    sources = 600.0 * 8 * 30
    transport = 500.0 * 8 * 2 * 30
    # free exchanges: the machines are the compute over an hour, rounded up
    free = one_layer_model(SERIAL, n, 1800.0, 0.25, 400, 7, network=math.inf, latency=0.0)
    assert free["machines_for_1_h"] == math.ceil((sources + transport) / 3600.0)
    assert free["wall_s"] <= 3600.0
    # latency alone: 1800/0.25 split steps x 2 parts x 400 substeps exchanges
    lat = one_layer_model(SERIAL, n, 1800.0, 0.25, 400, 7, network=math.inf, latency=1e-4)
    assert lat["exchanges"] == 1800.0 / 0.25 * 2 * 400
    m = lat["machines_for_1_h"]
    floor = lat["exchanges"] * 1e-4
    assert (sources + transport) / m + floor <= 3600.0 < (sources + transport) / (m - 1) + floor
    # an exchange latency past the hour on its own: no number of machines finishes
    slow = one_layer_model(SERIAL, n, 1800.0, 0.25, 400, 7, network=math.inf, latency=1e-3)
    assert slow["latency_floor_s"] > 3600.0 and slow["machines_for_1_h"] is None


def test_as_built_model_keeps_the_whole_bed_transport_on_every_machine():
    mod = multi_machine_model([SERIAL, TWO], n_cells=8e6, sim_time=1800.0)
    # the transport does not divide between the blocks: the hour is out of reach once the
    # whole bed's transport alone is past it
    assert mod["transport_whole_bed_s"] == pytest.approx(500.0 * 8 * 2 * 30, rel=1e-12, abs=0)
    assert mod["transport_whole_bed_s"] > 3600.0 and mod["machines_for_1_h"] is None
    assert mod["compute_s_one_machine"] == pytest.approx(600.0 * 8 * 30 + 500.0 * 8 * 2 * 30,
                                                      rel=1e-12, abs=0)
    assert mod["substeps_per_part"] == pytest.approx(200 * 2, rel=1e-12, abs=0)
    # a short batch: sources / m + whole-bed transport + exchanges within the hour
    short = multi_machine_model([SERIAL, TWO], n_cells=1e6, sim_time=60.0)
    m = short["machines_for_1_h"]
    fixed = short["transport_whole_bed_s"] + short["comm_s"]
    assert short["transport_whole_bed_s"] == pytest.approx(500.0, rel=1e-12, abs=0)
    assert 600.0 / m + fixed <= 3600.0
    assert m == 1 or 600.0 / (m - 1) + fixed > 3600.0
    assert len(mod["one_layer"]) == 4


def test_a_study_without_a_serial_run_reports_no_ratio_and_no_model():
    one = {**TWO, "workers": 1}
    assert multi_machine_model([one]) == {}
    res = {"machine": {}, "machine_after": {}, "end_time_s": 60.0, "outputs": 12,
           "runs": [{**one, "cell_steps_per_s": 4e5}], "model": {}}
    text = cluster_markdown(res)
    row = [ln for ln in text.splitlines() if "1 worker" in ln][0]
    assert "- (no serial run)" in row
    assert "| NO |" not in row and row.rstrip().endswith("| - |")
