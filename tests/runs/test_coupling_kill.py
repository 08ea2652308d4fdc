"""Two-way coupling killed for real: ``pbe-cfd couple`` is killed with SIGKILL (its whole
process group, OpenFOAM included) while segment 2's CFD runs, then ``--resume`` finishes it.
Its outputs equal those of an uninterrupted run byte for byte, and nothing of the killed
process is left half-written in the output directory."""
import os
import shutil
import signal
import subprocess
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.openfoam, pytest.mark.slow,
              pytest.mark.skipif(shutil.which("twoPhaseEulerFoam") is None,
                                 reason="needs OpenFOAM")]

# the same two-segment scene as test_coupling_two_way.ci_scene: 4 s of granulation in two
# segments of 2 s, 0.05 s of flow each, the spray zone moved into the packed bed
EDITS = [('name = "fluid-bed-transport"', 'name = "two-way-kill"'),
         ("end_time = 60.0", "end_time = 4.0"),
         ("output_interval = 5.0", "output_interval = 1.0"),
         ("alpha_high = 0.45, box_min = [0.0, 0.28, -1.0], box_max = [0.15, 0.40, 1.0]",
          "alpha_high = 0.6, box_min = [0.0, 0.1, -1.0], box_max = [0.15, 0.3, 1.0]")]
COUPLING = "\n[coupling]\ninterval = 2.0\nflow_time = 0.05\naverage_from = 0.02\n"
COMPARED = ["bed_moments.csv", "psd.csv"]          # byte for byte
WALL = ("cfd_wall_s", "pbe_wall_s")                  # segments.csv: all but its wall seconds


def scene_file(tmp: Path) -> Path:
    text = (resources.files("pbe_cfd") / "scenes" / "fluid-bed-transport.toml").read_text()
    for old, new in EDITS:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp / "two-way-kill.toml"
    path.write_text(text + COUPLING)
    return path


def couple(*args, **kw):
    return subprocess.run([sys.executable, "-m", "pbe_cfd.cli", "couple", *map(str, args)],
                          capture_output=True, text=True, **kw)


def test_sigkill_in_segment_2_then_resume_gives_the_uninterrupted_outputs(tmp_path):
    scene = scene_file(tmp_path)
    straight = couple(scene, "--out", tmp_path / "straight")
    assert straight.returncode == 0, straight.stderr

    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "pbe_cfd.cli", "couple", str(scene),
                             "--out", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    log = tmp_path / "killed.coupling" / "segment_001" / "log.twoPhaseEulerFoam"
    deadline = time.monotonic() + 900
    while not (log.is_file() and "Time = " in log.read_text(errors="replace")):
        assert proc.poll() is None, "the run ended before segment 2's CFD started"
        assert time.monotonic() < deadline
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists()                      # nothing of the killed run under --out

    resumed = couple("--resume", out)
    assert resumed.returncode == 0, resumed.stderr
    for name in COMPARED:
        assert (out / name).read_bytes() == (tmp_path / "straight" / name).read_bytes(), name
    a, b = (np.genfromtxt(d / "segments.csv", delimiter=",", names=True)
            for d in (out, tmp_path / "straight"))
    kept = [n for n in a.dtype.names if n not in WALL]
    assert len(kept) > 5 and len(a) == 2
    for n in kept:
        assert np.array_equal(a[n], b[n], equal_nan=True), n
    vtk = sorted(p.relative_to(out) for p in out.rglob("*.vtu"))
    assert vtk and vtk == sorted(p.relative_to(tmp_path / "straight")
                                 for p in (tmp_path / "straight").rglob("*.vtu"))
    for rel in vtk:
        assert (out / rel).read_bytes() == (tmp_path / "straight" / rel).read_bytes(), rel
    assert not (tmp_path / "killed.coupling").exists()   # the store is removed once written
