"""The package works when installed, not only from a checkout: the wheel carries the OpenFOAM
case template, the bundled scenes and the CFD snapshot, and `pbe-cfd case run` copies the
template from the installed package (run from a directory far from any checkout, with the
checkout off the Python path)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "pbe_cfd" / "data" / "openfoam_case"


def _clean_env(**extra):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PBE_CFD_CASE")}
    env.update(extra)
    return env


def _fake_openfoam(root: Path) -> dict:
    """Stand-ins for the OpenFOAM tools (the solver writes the 1.5 s time directory), so that
    the copied template's Allrun runs end to end without OpenFOAM."""
    bin_dir = root / "fake-bin"
    bin_dir.mkdir()
    for tool in ("blockMesh", "setFields", "foamToVTK", "postProcess"):
        (bin_dir / tool).write_text("#!/bin/sh\nexit 0\n")
    (bin_dir / "twoPhaseEulerFoam").write_text("#!/bin/sh\nmkdir -p 1.5\nexit 0\n")
    for p in bin_dir.iterdir():
        p.chmod(0o755)
    project = root / "fake-foam"
    (project / "etc").mkdir(parents=True)
    (project / "etc" / "controlDict").write_text("// fake\n")
    return {"PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
            "WM_PROJECT_DIR": str(project)}


@pytest.mark.slow
def test_wheel_ships_the_case_template_and_case_run_works_installed(tmp_path):
    src = tmp_path / "src"                 # build from a copy: the checkout stays untouched
    for name in ("pbe_cfd", "pyproject.toml", "README.md"):
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(ROOT / name, src / name)
    wheels = tmp_path / "wheels"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                            str(wheels), str(src)], capture_output=True, text=True,
                           env=_clean_env())
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = wheels.glob("pbe_cfd-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        for p in TEMPLATE.rglob("*"):
            if p.is_file():
                rel = "pbe_cfd/data/openfoam_case/" + p.relative_to(TEMPLATE).as_posix()
                assert rel in names, rel
                assert z.read(rel) == p.read_bytes(), rel
    assert {"pbe_cfd/data/fluid_bed_small.vtu", "pbe_cfd/scenes/fluid-bed.toml"} <= names

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)],
                   check=True)
    py = venv / "bin" / "python"
    # --force-reinstall: the venv sees the system site-packages, where pbe_cfd of the same
    # version may already be installed (CI installs it), and pip would then skip the wheel
    subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "--force-reinstall", "-q",
                    str(wheel)],
                   check=True, env=_clean_env())
    away = tmp_path / "elsewhere"
    away.mkdir()
    where = subprocess.run([str(py), "-c", "import pbe_cfd; print(pbe_cfd.__file__)"],
                           cwd=away, capture_output=True, text=True, env=_clean_env())
    assert Path(where.stdout.strip()).is_relative_to(venv), where.stdout
    env = _clean_env(**_fake_openfoam(tmp_path))
    run = subprocess.run([str(venv / "bin" / "pbe-cfd"), "case", "run", "--dir", "bed"],
                         cwd=away, capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    case = away / "bed"
    for rel in ("Allrun", "Allclean", "system/blockMeshDict.small", "system/controlDict",
                "constant/phaseProperties", "0.orig/alpha.particles", "0/alpha.particles"):
        assert (case / rel).is_file(), rel
    assert (case / "pbe-cfd-manifest.json").is_file()
    scenes = subprocess.run([str(venv / "bin" / "pbe-cfd"), "scenes"], cwd=away,
                            capture_output=True, text=True, env=_clean_env())
    assert scenes.returncode == 0 and "fluid-bed" in scenes.stdout
