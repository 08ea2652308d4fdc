"""A scene becomes a run's arrays in one pass (``runs.problem.problem_of``): after it, a run
reads the Problem and its plans, never the scene.

The scene handed to the run is a watched copy: a subclass of ``Scene`` that records every
attribute read once the pass has returned (the run's own ``problem_of`` is wrapped to arm
it). Any function after the pass that reads the scene -- a hook handed the scene, a field
looked up on it -- leaves its attribute in the record, which must stay empty. The runs are
short (a few output times) so the record, not the physics, is what is checked; the physics
of the same runs is checked in test_couple.py, test_batch_inventory.py and the method tests.
"""
import dataclasses

import pytest

from pbe_cfd.runs import couple, simulate
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene


def watched(scene):
    """(a copy of ``scene`` that records attribute reads once armed, the record, arm())."""
    record, armed = [], [False]

    class Watched(type(scene)):
        def __getattribute__(self, name):
            if armed[0] and not name.startswith("__"):
                record.append(name)
            return super().__getattribute__(name)

    copy = Watched(**{f.name: getattr(scene, f.name) for f in dataclasses.fields(scene)})
    return copy, record, lambda: armed.__setitem__(0, True)


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
