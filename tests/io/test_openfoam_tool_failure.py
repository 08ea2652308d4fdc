"""A failing foamToVTK: one line, no partial VTK output left behind, the exit code the README
promises (2 for a user's case pbe-cfd cannot read, 1 for a run that could not finish).

The fake foamToVTK on PATH does what the real one does on a corrupt field: it creates
``VTK/case_100/internal.vtu``, writes the first bytes of it, prints OpenFOAM's banner and a
FOAM FATAL IO ERROR, and exits 1. The real-OpenFOAM variant (marked ``openfoam``) corrupts
one field of a meshed case so that the real tool fails.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import textwrap
import time
from pathlib import Path

import pytest

from pbe_cfd.cli import main
from pbe_cfd.io import output
from pbe_cfd.io import openfoam as of
from pbe_cfd.io.openfoam import rerun
from pbe_cfd.io.openfoam.case import remove_new_vtk, vtk_files
from pbe_cfd.scene.scene import resolve_scene_path

FATAL = "Bad token - could not get scalar value"
FAKE_VTK = textwrap.dedent(f"""\
    #!/bin/sh
    mkdir -p VTK/case_100
    printf '<?xml version="1.0"?>\\n<VTKFile type="UnstructuredGrid"' > VTK/case_100/internal.vtu
    cat <<'X'
    /*---------------------------------------------------------------------------*\\
      =========                 |
      \\\\      /  F ield         | OpenFOAM: The Open Source CFD Toolbox
    Create time

    --> FOAM FATAL IO ERROR: (openfoam-1912)
    {FATAL}

    file: case/1.5/alpha.particlesMean at line 23.

        From function Foam::Istream& Foam::operator>>(Foam::Istream&, Foam::doubleScalar&)
        in file lnInclude/Scalar.C at line 154.

    FOAM exiting

    X
    exit 1
    """)


def tree(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def failing_vtk(tmp_path, monkeypatch):
    """OpenFOAM stand-ins on PATH (every tool succeeds but foamToVTK, which fails as above)
    and a cache of pbe-cfd's own under tmp_path."""
    bin_dir = tmp_path / "fake-bin"
    bin_dir.mkdir()
    for tool in ("blockMesh", "setFields", "twoPhaseEulerFoam", "postProcess",
                 "foamFormatConvert", "reconstructPar"):
        (bin_dir / tool).write_text("#!/bin/sh\nexit 0\n")
        (bin_dir / tool).chmod(0o755)
    (bin_dir / "foamToVTK").write_text(FAKE_VTK)
    (bin_dir / "foamToVTK").chmod(0o755)
    project = tmp_path / "fake-foam"
    (project / "etc").mkdir(parents=True)
    (project / "etc" / "controlDict").write_text("// fake\n")
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("WM_PROJECT_DIR", str(project))
    monkeypatch.setenv("PBE_CFD_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def one_line_error(capsys, code, argv, *phrases):
    capsys.readouterr()
    assert main(argv) == code
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ln.startswith("pbe-cfd: error: ")]
    assert len(errors) == 1, err
    # nothing but progress lines ("Allrun: running TOOL") besides the error: no log tail
    assert all(ln.startswith("Allrun: running ") for ln in err.splitlines()
               if not ln.startswith("pbe-cfd: error: ")), err
    for phrase in ("foamToVTK", FATAL, *phrases):
        assert phrase in errors[0], err
    return errors[0]


def _user_case(root: Path) -> Path:
    """A user's case with a mesh and a written time (contents only the fake tools read)."""
    case = root / "users-case"
    (case / "constant" / "polyMesh").mkdir(parents=True)
    for name in ("points", "faces", "owner", "neighbour", "boundary"):
        (case / "constant" / "polyMesh" / name).write_text("the user's mesh\n")
    (case / "system").mkdir()
    (case / "system" / "controlDict").write_text("endTime 1.5;\n")
    (case / "1.5").mkdir()
    for field in ("alpha.particlesMean", "Theta.particlesMean"):
        (case / "1.5" / field).write_text("the user's field\n")
    (case / "VTK").mkdir()
    (case / "VTK" / "notes.txt").write_text("the user's own file in VTK/\n")
    return case


def test_couple_on_a_case_whose_foamtovtk_fails_writes_nothing_into_it(failing_vtk, capsys):
    case = _user_case(failing_vtk)
    before = tree(case)
    text = resolve_scene_path("fluid-bed").read_text().replace(
        'case = "bundled:fluid_bed_small"', f'case = "{case}"')
    (failing_vtk / "s.toml").write_text(text)
    one_line_error(capsys, 2, ["couple", "s.toml", "--out", "o"], str(case))
    assert tree(case) == before
    assert not (failing_vtk / "o").exists()
    cache = failing_vtk / "cache"
    assert not list(cache.glob(".build-*"))            # no half-made readable copy
    assert [p.name.endswith(".log.foamToVTK") for p in (cache / "failed").iterdir()] == [True]


def test_case_run_whose_foamtovtk_fails_leaves_no_partial_vtk(failing_vtk, capsys):
    line = one_line_error(capsys, 1, ["case", "run", "--dir", "k"], str(failing_vtk / "k"))
    assert "log.foamToVTK" in line
    case = failing_vtk / "k"
    assert not (case / "VTK").exists()
    files = output.read_manifest(case)["files"]
    assert not [f for f in files if f.startswith("VTK")]
    assert all((case / f).is_file() for f in files)   # the manifest lists only what is there
    assert "log.foamToVTK" in files                    # the log is kept


def test_a_failing_tool_in_a_segment_removes_only_what_it_wrote(failing_vtk):
    """The coupled rerun's foamToVTK (``rerun._run_tool``) in a segment case: a VTK file that
    was there before is kept, byte for byte; what the failing tool wrote is removed."""
    case = failing_vtk / "segment"
    (case / "VTK" / "earlier").mkdir(parents=True)
    (case / "VTK" / "earlier" / "internal.vtu").write_text("an earlier conversion\n")
    before = tree(case)
    install = of.find_openfoam(("foamToVTK",))
    with pytest.raises(of.OpenFOAMError) as err:
        rerun._run_tool(case, "foamToVTK", ["-latestTime"], install.env(), lambda m: None, None)
    message = str(err.value)
    assert "\n" not in message and FATAL in message and str(case) in message, message
    assert "FOAM FATAL" in err.value.log_tail          # the tail stays on the error
    assert tree(case) == {**before, "log.foamToVTK": tree(case)["log.foamToVTK"]}


def test_remove_new_vtk_keeps_a_file_it_did_not_write(tmp_path):
    """Only files new since the listing, or modified since the tool started, go; an untouched
    file listed before stays, and so do directories that existed."""
    case = tmp_path / "c"
    (case / "VTK" / "old").mkdir(parents=True)
    (case / "VTK" / "old" / "keep.vtu").write_text("kept\n")
    before = vtk_files(case)
    started = time.time_ns()
    (case / "VTK" / "new").mkdir()
    (case / "VTK" / "new" / "internal.vtu").write_text("<VTKFile")
    (case / "VTK" / "old" / "extra.vtu").write_text("<VTKFile")
    assert remove_new_vtk(case, before, started) == 2
    assert sorted(p.relative_to(case).as_posix() for p in case.rglob("*")) == [
        "VTK", "VTK/old", "VTK/old/keep.vtu"]


@pytest.mark.openfoam
@pytest.mark.skipif(shutil.which("foamToVTK") is None or shutil.which("blockMesh") is None,
                    reason="OpenFOAM not installed")
def test_real_foamtovtk_failure_on_a_corrupt_field(tmp_path, monkeypatch, capsys):
    """The bundled case template meshed by the real blockMesh, with a time whose solids field
    has the wrong number of cell values: reading it fails in an OpenFOAM tool, in one line,
    exit 2, and the case is byte for byte as it was."""
    monkeypatch.setenv("PBE_CFD_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    case = of.copy_case(of.default_case_dir(), tmp_path / "users-case")
    import subprocess
    subprocess.run(["blockMesh", "-dict", "system/blockMeshDict.small"], cwd=case,
                   check=True, capture_output=True)
    (case / "1.5").mkdir()
    header = ("FoamFile\n{\n    version 2.0;\n    format ascii;\n    class volScalarField;\n"
              "    object %s;\n}\ndimensions [0 0 0 0 0 0 0];\n")
    for field, value in (("alpha.particlesMean", "0.5"), ("Theta.particlesMean", "0.01")):
        body = ("internalField nonuniform List<scalar> 3(" + " ".join([value] * 3) + ");\n"
                "boundaryField { \".*\" { type zeroGradient; } }\n")
        (case / "1.5" / field).write_text(header % field + body)
    before = tree(case)
    text = resolve_scene_path("fluid-bed").read_text().replace(
        'case = "bundled:fluid_bed_small"', f'case = "{case}"')
    (tmp_path / "s.toml").write_text(text)
    capsys.readouterr()
    assert main(["couple", "s.toml", "--out", "o"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pbe-cfd: error: "), err
    assert " failed on t = 1.5 s of " in err[0] and str(case) in err[0], err
    assert tree(case) == before
    assert not list((tmp_path / "cache").glob(".build-*"))
