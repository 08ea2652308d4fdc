"""A scene becomes a run's arrays in one pass (``runs.problem.problem_of``): after it, a run
reads the Problem and its plans, never the scene.

The scene handed to the run is a watched copy: a subclass of ``Scene`` that records every
attribute read once the pass has returned (the run's own ``problem_of`` is wrapped to arm
it). Any function after the pass that reads the scene -- a hook handed the scene, a field
looked up on it -- leaves its attribute in the record, which must stay empty. The runs are
short (a few output times) so the record, not the physics, is what is checked; the physics
of the same runs is checked in test_couple.py, test_batch_inventory.py and the method tests.

The two-way run makes the pass once per CFD segment (``coupling.segment_problem``) after its
``coupling.two_way_plan``; the watch is off inside those and on everywhere else.
"""
import dataclasses
import shutil
import tomllib
from importlib import resources

import pytest

from pbe_cfd.runs import couple, coupling, simulate
from pbe_cfd.runs.coupling_output import combined_result, segment_rows
from pbe_cfd.runs.coupling_store import SegmentStore
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene, scene_from_dict


def watched(scene):
    """(a copy of ``scene`` that records attribute reads once armed, the record, arm(on))."""
    record, armed = [], [False]

    class Watched(type(scene)):
        def __getattribute__(self, name):
            if armed[0] and not name.startswith("__"):
                record.append(name)
            return super().__getattribute__(name)

    copy = Watched(**{f.name: getattr(scene, f.name) for f in dataclasses.fields(scene)})
    return copy, record, lambda on=True: armed.__setitem__(0, on)


def arm_after_the_pass(monkeypatch, module, arm):
    """Wrap ``module.problem_of`` so that ``arm()`` runs when the one pass returns."""
    real = module.problem_of

    def problem_of(*args, **kwargs):
        problem = real(*args, **kwargs)
        arm()
        return problem

    monkeypatch.setattr(module, "problem_of", problem_of)


def test_the_watch_records_a_read_after_it_is_armed():
    """The instrument itself: reads before arming are not recorded, reads after are, and
    the watched copy is the scene (same fields, so the run is the same run)."""
    scene = load_scene("seed-wurster")
    copy, record, arm = watched(scene)
    assert copy.method.name == scene.method.name and record == []
    arm()
    assert copy.bivariate == scene.bivariate
    assert "bivariate" in record


@pytest.mark.slow
def test_a_coupled_run_reads_no_scene_after_the_pass(monkeypatch):
    """The fluid-bed batch scene: transport, drying with the bed's air balance, a spray
    schedule (the air, transport, inventory, per-cell outputs, size distribution and labels
    of a coupled run all run after the pass)."""
    scene = load_scene("fluid-bed-batch")
    scene = dataclasses.replace(scene, end_time=2.0, output_interval=1.0)
    domain = load_domain(scene, need_flux=True)
    copy, record, arm = watched(scene)
    arm_after_the_pass(monkeypatch, couple, arm)
    result = couple.run_coupled(copy, domain, threads=1)
    assert len(result.times) == 3 and "moisture_content" in result.bed_columns
    assert record == [], f"read of the scene after the one pass: {sorted(set(record))}"


@pytest.mark.parametrize("name", ["seed-wurster", "seed-wurster-cnmc"])
def test_a_well_mixed_run_reads_no_scene_after_the_pass(monkeypatch, name):
    """The well-mixed QMOM seed scene (bivariate, spray, separate droplets) and the cNMC
    ensemble (a method with a run of its own), each shortened to two output intervals."""
    scene = load_scene(name)
    scene = dataclasses.replace(scene, end_time=2.0 * scene.output_interval)
    if name.endswith("cnmc"):
        scene = scene.with_method(particles=200, replicas=2)
    copy, record, arm = watched(scene)
    arm_after_the_pass(monkeypatch, simulate, arm)
    result = simulate.run_well_mixed(copy)
    assert len(result.columns["time_s"]) == 3
    assert record == [], f"read of the scene after the one pass: {sorted(set(record))}"


def watch_outside(monkeypatch, module, name, arm):
    """Wrap ``module.name`` so that the watch is off while it runs and on once it returns."""
    real = getattr(module, name)

    def wrapped(*args, **kwargs):
        arm(False)
        try:
            return real(*args, **kwargs)
        finally:
            arm(True)

    monkeypatch.setattr(module, name, wrapped)


@pytest.mark.slow
@pytest.mark.openfoam
@pytest.mark.skipif(shutil.which("twoPhaseEulerFoam") is None, reason="needs OpenFOAM")
def test_a_two_way_run_reads_no_scene_outside_its_passes(monkeypatch, tmp_path):
    """The transport scene in two segments of 1 s (0.05 s of flow each on the template's
    small mesh, as test_coupling_two_way.py): the CFD runs, the granulation, the segment
    ends, the carry-over, the defluidisation check and the outputs across the segments read
    the run's plan and the segments' problems only."""
    text = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-transport.toml").read_text()
    data = tomllib.loads(text)
    data["scene"].update(name="two-way-watch", end_time=2.0, output_interval=1.0)
    data["binder_injection"]["zone"].update(alpha_high=0.6, box_min=[0.0, 0.1, -1.0],
                                            box_max=[0.15, 0.3, 1.0])
    data["coupling"] = {"interval": 1.0, "flow_time": 0.05, "average_from": 0.02}
    scene = scene_from_dict(data, tmp_path / "two-way-watch.toml")
    copy, record, arm = watched(scene)
    store = SegmentStore(tmp_path / "out.coupling").open(copy, resume=False)
    watch_outside(monkeypatch, coupling, "two_way_plan", arm)
    watch_outside(monkeypatch, coupling, "segment_problem", arm)
    passes = []
    real = coupling.segment_problem
    monkeypatch.setattr(coupling, "segment_problem",
                        lambda *a, **k: (passes.append(a[3]), real(*a, **k))[1])
    run = coupling.run_two_way(copy, store, warn=lambda text: None)
    result = combined_result(run, 1.0)
    cols = segment_rows(run)
    assert passes == [0, 1] and result.times.tolist() == [0.0, 1.0, 2.0]
    assert cols["process_end_s"].tolist() == [1.0, 2.0]
    assert record == [], f"read of the scene outside the passes: {sorted(set(record))}"
