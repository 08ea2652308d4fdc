"""``pbe-cfd plan`` opens the CFD case and says what a run would use, writing nothing."""
from __future__ import annotations

import json
import re
import shutil

from test_data_safety import _fake_case, box, tiny_couple_text, tree  # noqa: F401 - fixture

from pbe_cfd.cli import main


def _plan(capsys, scene) -> str:
    capsys.readouterr()
    assert main(["plan", str(scene)]) == 0
    return capsys.readouterr().out


def _window(text: str) -> str:
    return re.search(r"averaging window: (.*)$", text, flags=re.M).group(1).strip()


def _numbers(text: str) -> dict:
    cells = re.search(r"cells: (\d+); active (\d+) \(alpha >= alpha_min = [\d.]+; (\d+) below",
                      text)
    spray = re.search(r"spray zone: (\d+) of the (\d+) active cells; removed (\d+) outside the "
                      r"box, (\d+) above alpha_high = [\d.]+, (\d+) below alpha_low", text)
    assert cells and spray, text
    n, active, below = map(int, cells.groups())
    s, s_active, box_out, high, low = map(int, spray.groups())
    assert n == active + below and s_active == active
    assert s + box_out + high + low == active          # every active cell counted once
    return {"cells": n, "active_cells": active, "spray_cells": s}


def test_plan_says_what_the_run_uses_and_writes_nothing(box, capsys):
    case = _fake_case(box)
    (box / "s.toml").write_text(tiny_couple_text("case"))
    before = tree(box)
    text = _plan(capsys, box / "s.toml")
    assert tree(box) == before                  # nothing written: case, cwd, anywhere below
    assert "CFD time 1.5 s" in text
    assert "fields: alpha.particlesMean and Theta.particlesMean, time-averaged" in text
    assert "averaging window: unknown (no system/controlDict" in text
    planned = _numbers(text)
    # the run's own count of the same cells
    assert main(["couple", "s.toml", "--out", "c"]) == 0
    stats = json.loads((box / "c" / "summary.json").read_text())["stats"]
    assert planned == {k: stats[k] for k in planned}
    # a fieldAverage without timeStart averages the whole run, start-up included
    (case / "system").mkdir()
    (case / "system" / "controlDict").write_text("startTime 0;\nfunctions\n{\n}\n")
    assert "averaging window: 0 to 1.5 s (fieldAverage has no timeStart" in _plan(
        capsys, box / "s.toml")
    # the case template's controlDict takes avgStart from an included override (Allrun END
    # AVG_START writes it): the window is the override's
    (case / "system" / "controlDict").write_text(
        'avgStart 0.5;\n#includeIfPresent "controlDict.override"\nfunctions\n{\n'
        '  fieldAverage1\n  {\n    timeStart $avgStart;\n  }\n}\n')
    assert _window(_plan(capsys, box / "s.toml")) == "0.5 to 1.5 s"
    (case / "system" / "controlDict.override").write_text("avgStart 1;\n")
    assert _window(_plan(capsys, box / "s.toml")) == "1 to 1.5 s"


def test_plan_of_an_unconverted_case_says_so_and_writes_nothing(box, capsys):
    case = _fake_case(box)
    shutil.rmtree(case / "VTK")                 # fields not converted by foamToVTK yet
    (box / "s.toml").write_text(tiny_couple_text("case"))
    before = tree(box)
    text = _plan(capsys, box / "s.toml")
    assert tree(box) == before
    assert "case not opened: its fields at t = 1.5 s are not converted yet" in text


def test_plan_of_the_bundled_snapshot_names_its_window(capsys):
    text = _plan(capsys, "fluid-bed")
    assert "averaging window: 0.5 to 1.5 s" in text and "bundled snapshot" in text
    _numbers(text)


def test_plan_states_the_sprayed_flow_in_both_units(capsys):
    """fluid-bed-batch gives the nozzle's flow (kg/s): the plan states it and the droplets per
    m3 and s its 97 spray cells receive; fluid-bed gives droplets/(m3 s) and the plan states
    the flow that makes."""
    flow = re.compile(r"sprayed at the peak: ([\d.e+-]+) kg/s of solution = ([\d.e+-]+) "
                      r"droplets/\(m3 s\) over the ([\d.e+-]+) m3")
    batch = flow.search(_plan(capsys, "fluid-bed-batch"))
    assert batch, "no flow line"
    assert float(batch.group(1)) == 1.053e-4                # the scene's 1.05261e-4, 4 digits
    assert float(batch.group(2)) == 4.75e9                  # the rate it replaced, 4 digits
    bed = flow.search(_plan(capsys, "fluid-bed"))
    assert bed and float(bed.group(3)) == float(batch.group(3))     # the same zone
