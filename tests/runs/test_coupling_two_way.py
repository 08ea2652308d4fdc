"""Two-way coupling on the real case: two segments of the bundled small mesh with 0.05 s of
flow each (the template from its packed bed, then continued with the bed's d32), a resume
after a kill during segment 2, and a failed segment named."""
import shutil
import tomllib
from importlib import resources

import numpy as np
import pytest

from pbe_cfd.runs.batch import SimulationError
from pbe_cfd.io.openfoam import rerun
from pbe_cfd.runs.coupling import initial_diameter, run_two_way
from pbe_cfd.runs.coupling_output import combined_result, segment_rows
from pbe_cfd.runs.coupling_store import SegmentStore
from pbe_cfd.scene.scene import scene_from_dict

pytestmark = [pytest.mark.openfoam,
              pytest.mark.skipif(shutil.which("twoPhaseEulerFoam") is None,
                                 reason="needs OpenFOAM")]

FLOW = 0.05          # s of flow per segment
WINDOW = 0.02        # s after a segment's start where its average begins


def ci_scene(tmp_path, **coupling):
    """The bundled transport scene over 4 s in two segments of 2 s, its spray zone moved into
    the packed bed (0.05 s of flow from the packed bed has not expanded it yet)."""
    text = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-transport.toml").read_text()
    data = tomllib.loads(text)
    data["scene"].update(name="two-way-ci", end_time=4.0, output_interval=1.0)
    data["binder_injection"]["zone"].update(alpha_high=0.6, box_min=[0.0, 0.1, -1.0],
                                            box_max=[0.15, 0.3, 1.0])
    data["coupling"] = {"interval": 2.0, "flow_time": FLOW, "average_from": WINDOW,
                        **coupling}
    return scene_from_dict(data, tmp_path / "two-way-ci.toml")


def bed_totals(seg, k):
    vol = np.asarray(seg.domain.cells.cell_volume)[seg.idx]
    return np.sum(np.asarray(seg.history[k]) * vol[:, None], axis=0)


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """An uninterrupted two-segment run (its store kept)."""
    tmp = tmp_path_factory.mktemp("straight")
    scene = ci_scene(tmp)
    store = SegmentStore(tmp / "out.coupling").open(scene, resume=False)
    return scene, store, run_two_way(scene, store)


def test_segment_2_runs_with_segment_1s_d32(straight):
    scene, store, run = straight
    s0, s1 = run.segments
    assert (s0.t_start, s0.t_end, s1.t_start, s1.t_end) == (0.0, 2.0, 2.0, 4.0)
    d0 = initial_diameter(scene)
    # the copied cases' own dictionaries: the template's diameter, then the bed's d32
    assert rerun.read_diameter(store.case_dir(0), "particles") == pytest.approx(d0, rel=1e-12,
                                                                               abs=0)
    d_read = rerun.read_diameter(store.case_dir(1), "particles")
    assert d_read == pytest.approx(s0.d32_end, rel=1e-12, abs=0)
    assert d_read > d0 * (1 + 1e-3)          # the granules grew in segment 1
    # segment 2 continued the flow: CFD from 0.05 s to 0.1 s, averaged over [0.07, 0.1] s
    assert (s0.cfd_time, s1.cfd_time) == pytest.approx((FLOW, 2 * FLOW), abs=1e-9)
    assert s1.cfd_window == pytest.approx((FLOW + WINDOW, 2 * FLOW), abs=1e-9)
    a0, a1 = np.asarray(s0.domain.cells.alpha), np.asarray(s1.domain.cells.alpha)
    t0, t1 = np.asarray(s0.domain.cells.theta), np.asarray(s1.domain.cells.theta)
    assert np.max(np.abs(a1 - a0)) > 1e-2 and np.max(np.abs(t1 - t0) / t0.max()) > 1e-2
    log = (store.case_dir(1) / "log.twoPhaseEulerFoam").read_text()
    assert "Create time" in log and "\nEnd" in log


def test_the_bed_population_is_carried_over_whole(straight):
    """The bed totals of every state component at segment 2's start equal segment 1's end,
    though the solids field changed (conservation of carry_over)."""
    _, _, run = straight
    s0, s1 = run.segments
    end, start = bed_totals(s0, -1), bed_totals(s1, 0)
    assert np.allclose(start, end, rtol=1e-12, atol=0.0)
    assert not np.array_equal(s0.idx, s1.idx) or not np.array_equal(
        np.asarray(s0.domain.cells.alpha), np.asarray(s1.domain.cells.alpha))


def test_outputs_across_segments(straight):
    scene, _, run = straight
    result = combined_result(run, 1.0)
    assert result.times.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]   # the boundary once
    cfd = [f["cfd_time_s"][0] for f in result.cell_fields]
    assert cfd == pytest.approx([FLOW, FLOW, FLOW, 2 * FLOW, 2 * FLOW], abs=1e-12)
    cols = segment_rows(run)
    assert cols["diameter_m"][1] == pytest.approx(run.segments[0].d32_end, rel=1e-15, abs=0)
    assert np.all(cols["theta_p10_m2_s2"] <= cols["theta_p90_m2_s2"])
    assert np.all((cols["mean_alpha"] > 0) & (cols["mean_alpha"] < scene.domain.alpha_max))


def test_resume_after_a_kill_in_segment_2_equals_the_straight_run(straight, tmp_path):
    scene, _, run = straight
    store = SegmentStore(tmp_path / "out.coupling").open(scene, resume=False)

    class Killed(KeyboardInterrupt):
        pass

    def kill_in_segment_2(line):
        if "running to t = 0.1 s" in line:   # segment 2's solver started (said at once)
            raise Killed()

    with pytest.raises(Killed):
        run_two_way(scene, store, log=kill_in_segment_2)
    assert store.cfd(1) is None and store.granulation(0) is not None
    assert not store.case_dir(1).exists()     # the half-run case removed, its files only
    broken = tmp_path / "broken.coupling"
    shutil.copytree(store.path, broken)

    resumed = run_two_way(scene, SegmentStore(store.path).open(scene, resume=True))
    for a, b in zip(run.segments, resumed.segments):
        assert np.array_equal(np.asarray(a.domain.cells.alpha), np.asarray(b.domain.cells.alpha))
        assert len(a.history) == len(b.history)
        for x, y in zip(a.history, b.history):
            assert np.array_equal(x, y)

    # a failing segment is named: segment 1's flow state lost a field it needs
    st = SegmentStore(broken).open(scene, resume=True)
    (st.case_dir(0) / rerun.latest_time_name(st.case_dir(0)) / "p_rgh").unlink()
    with pytest.raises(SimulationError) as err:
        run_two_way(scene, st)
    text = str(err.value)
    assert text.startswith("two-way segment 1 (process time 2 s, CFD from t = 0.05 s) failed")
    assert "p_rgh" in text and "twoPhaseEulerFoam" in text
    assert (st.case_dir(1) / "log.twoPhaseEulerFoam").is_file()    # its log kept
