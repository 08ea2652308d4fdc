"""Property-based fuzz of CFD input through the command line: an OpenFOAM case's field files
(alpha, Theta and the solids face flux alphaPhi, as ascii lists) and a snapshot's face-flux
file, with random cells or faces made negative, non-finite or out of range, lists cut short,
or the file truncated. Every one is refused by ``pbe-cfd couple`` with exit 2 and one line
(``pbe-cfd: error: ...``), no traceback, and no output directory; the unmodified inputs are
read (the controls), so a refusal is the corruption's doing. (Snapshot cell fields:
tests/test_cfd_input_checks.py.)"""
from __future__ import annotations

import gzip
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pbe_cfd.io import openfoam as of
from pbe_cfd.cli import main
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import load_scene
from test_data_safety import tiny_couple_text

TUTORIAL = Path("/usr/share/doc/openfoam-examples/examples/multiphase/twoPhaseEulerFoam/"
                "RAS/fluidisedBed")
if not TUTORIAL.is_dir():
    TUTORIAL = Path("/usr/share/openfoam/tutorials/multiphase/twoPhaseEulerFoam/RAS/"
                    "fluidisedBed")
TIME = "0.5"                      # s, the time directory the fuzzed fields are written to
N_CELLS = 30 * 200                # the tutorial's blockMesh


def _header(cls: str, obj: str, dims: str) -> str:
    return ("FoamFile\n{\n    version 2.0;\n    format ascii;\n"
            f"    class {cls};\n    location \"{TIME}\";\n    object {obj};\n}}\n\n"
            f"dimensions {dims};\n\n")


def _field_text(cls: str, obj: str, dims: str, values, patches) -> str:
    """An ascii OpenFOAM field file: ``values`` (strings) as the nonuniform internal field,
    ``patches`` (name -> type) with uniform 0 values (empty patches without)."""
    body = "\n".join(values)
    out = [_header(cls, obj, dims),
           f"internalField nonuniform List<scalar>\n{len(values)}\n(\n{body}\n)\n;\n\n",
           "boundaryField\n{\n"]
    for name, kind in patches.items():
        if kind == "empty":
            out.append(f"    {name}\n    {{\n        type empty;\n    }}\n")
        else:
            out.append(f"    {name}\n    {{\n        type calculated;\n"
                       "        value uniform 0;\n    }\n")
    out.append("}\n")
    return "".join(out)


def _patches(case: Path) -> dict:
    text = (case / "constant" / "polyMesh" / "boundary").read_text()
    return dict(re.findall(r"^\s*(\w+)\s*\{\s*type\s+(\w+);", text, flags=re.M))


def _n_internal_faces(case: Path) -> int:
    text = (case / "constant" / "polyMesh" / "owner").read_text()
    return int(re.search(r"nInternalFaces:\s*(\d+)", text).group(1))


def _fields(n_faces: int) -> dict:
    """Plausible values: alpha between 0.05 and 0.55 [-], Theta 1e-3 m2/s2, a small face
    flux [m3/s], as strings in OpenFOAM's ascii."""
    rng = np.random.default_rng(28)
    return {"alpha.particles": [f"{a:.6g}" for a in rng.uniform(0.05, 0.55, N_CELLS)],
            "Theta.particles": [f"{t:.6g}" for t in rng.uniform(1e-4, 1e-2, N_CELLS)],
            "alphaPhi.particles": [f"{f:.6g}" for f in rng.normal(0.0, 1e-7, n_faces)]}


KIND = {"alpha.particles": ("volScalarField", "[0 0 0 0 0 0 0]"),
        "Theta.particles": ("volScalarField", "[0 2 -2 0 0 0 0]"),
        "alphaPhi.particles": ("surfaceScalarField", "[0 3 -1 0 0 0 0]")}


def _write_time(case: Path, fields: dict):
    tdir = case / TIME
    tdir.mkdir(exist_ok=True)
    patches = _patches(case)
    for name, values in fields.items():
        cls, dims = KIND[name]
        (tdir / name).write_text(_field_text(cls, name, dims, values, patches))


def _scene(root: Path, case: str) -> Path:
    text = tiny_couple_text(case).replace(
        'time = "latest"', f"time = {TIME}\naccept_material_mismatch = true")
    path = root / "s.toml"
    path.write_text(text + "\n[transport]\ncourant = 0.5\n")
    return path


@pytest.fixture(scope="module")
def tutorial_mesh(tmp_path_factory):
    """The tutorial fluidisedBed with its mesh (blockMesh) and no time run: the fields of
    time 0.5 are written by the tests."""
    if shutil.which("blockMesh") is None or not TUTORIAL.is_dir():
        pytest.skip("needs OpenFOAM and openfoam-examples")
    case = tmp_path_factory.mktemp("fuzz-case") / "bed"
    shutil.copytree(TUTORIAL, case)
    for gz in case.rglob("*.gz"):
        gz.with_suffix("").write_bytes(gzip.decompress(gz.read_bytes()))
        gz.unlink()
    r = subprocess.run(["blockMesh"], cwd=case, capture_output=True, text=True,
                       env={**__import__("os").environ,
                            "WM_PROJECT_DIR": "/usr/share/openfoam"})
    assert r.returncode == 0, r.stdout[-2000:]
    return case


def _refused_in_one_line(capsys, scene: Path, out: Path, names: str) -> str:
    """``couple SCENE --out OUT``: exit 2, one line naming ``names`` (the file or the field
    made bad), no output directory."""
    capsys.readouterr()
    code = main(["couple", str(scene), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith("pbe-cfd: error: "), err
    assert "Traceback" not in err[0]
    assert names in err[0], err
    assert not out.exists()
    return err[0]


def test_the_unmodified_case_is_read(tutorial_mesh, tmp_path):
    """The control: the fields as written are accepted, 6000 cells with their face flux."""
    case = tmp_path / "bed"
    shutil.copytree(tutorial_mesh, case)
    _write_time(case, _fields(_n_internal_faces(case)))
    dom = load_domain(load_scene(_scene(tmp_path, str(case))), need_flux=True)
    assert dom.cells.n_cells == N_CELLS and dom.flux.n_cells == N_CELLS
    assert np.allclose(dom.cells.theta[:3], [float(v) for v in _fields(1)["Theta.particles"][:3]],
                       rtol=1e-5, atol=0)


CORRUPT = {"alpha.particles": ["nan", "inf", "-0.1", "1.5", "0.7"],
           "Theta.particles": ["nan", "-inf", "-1e-3", "-2"],
           "alphaPhi.particles": ["nan", "inf", "-inf"]}


CASE_DAMAGE = [(field, bad) for field in sorted(CORRUPT)
               for bad in CORRUPT[field] + ["short list", "truncated"]]


@pytest.mark.parametrize("field,damage", CASE_DAMAGE, ids=[f"{f}:{d}" for f, d in CASE_DAMAGE])
@settings(max_examples=2, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzzed_case_fields_are_one_line_exit_2(tutorial_mesh, tmp_path_factory, capsys,
                                                field, damage, data):
    """Random cells (faces) of one field of the case set to a non-finite, negative or
    out-of-range value (every such value of every field in turn), the list cut short by some
    entries, or the file truncated: exit 2, one line naming the field's file."""
    root = tmp_path_factory.mktemp("case-fuzz")
    case = root / "bed"
    shutil.copytree(tutorial_mesh, case)
    fields = _fields(_n_internal_faces(case))
    values = fields[field]
    if damage == "short list":
        del values[-data.draw(st.integers(1, 50)):]
    elif damage != "truncated":
        where = data.draw(st.lists(st.integers(0, len(values) - 1), min_size=1, max_size=4,
                                   unique=True))
        for i in where:
            values[i] = damage
    _write_time(case, fields)
    if damage == "truncated":
        path = case / TIME / field
        text = path.read_bytes()
        path.write_bytes(text[: int(len(text) * data.draw(st.sampled_from([0.05, 0.5, 0.95])))])
    _refused_in_one_line(capsys, _scene(root, str(case)), root / "out", field)


# ---------------------------------------------------------------------------- snapshot flux
def _snapshot_copy(root: Path) -> Path:
    snap = of.default_snapshot_path()
    shutil.copyfile(snap, root / "snap.vtu")
    shutil.copyfile(of.default_flux_path(), root / "snap_flux.npz")
    return root / "snap.vtu"


def _snapshot_scene(root: Path) -> Path:
    text = tiny_couple_text("snap.vtu")
    path = root / "s.toml"
    path.write_text(text + "\n[transport]\ncourant = 0.5\n")
    return path


def test_the_unmodified_snapshot_flux_is_read(tmp_path):
    _snapshot_copy(tmp_path)
    dom = load_domain(load_scene(_snapshot_scene(tmp_path)), need_flux=True)
    assert dom.flux.n_cells == dom.cells.n_cells == 900


FLUX_DAMAGE = ["nan flux", "inf boundary flux", "owner out of range", "negative neighbour",
               "boundary cell out of range", "other mesh", "flux cut short",
               "missing array", "truncated"]


@settings(max_examples=18, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(damage=st.sampled_from(FLUX_DAMAGE), data=st.data())
def test_fuzzed_snapshot_flux_is_one_line_exit_2(tmp_path_factory, capsys, damage, data):
    """The snapshot's face-flux file with random faces made non-finite, a face naming a cell
    the mesh does not have, the flux of another mesh, arrays of unequal length, an array
    missing, or the file truncated: exit 2, one line."""
    root = tmp_path_factory.mktemp("flux-fuzz")
    _snapshot_copy(root)
    path = root / "snap_flux.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    n_faces, n_bnd = len(arrays["flux"]), len(arrays["boundary_face_flux"])
    face = data.draw(st.integers(0, n_faces - 1))
    bface = data.draw(st.integers(0, n_bnd - 1))
    if damage == "nan flux":
        arrays["flux"] = arrays["flux"].copy()
        arrays["flux"][face] = np.nan
    elif damage == "inf boundary flux":
        arrays["boundary_face_flux"] = arrays["boundary_face_flux"].copy()
        arrays["boundary_face_flux"][bface] = data.draw(st.sampled_from([np.inf, -np.inf]))
    elif damage == "owner out of range":
        arrays["owner"] = arrays["owner"].copy()
        arrays["owner"][face] = 900 + data.draw(st.integers(0, 100))
    elif damage == "negative neighbour":
        arrays["neighbour"] = arrays["neighbour"].copy()
        arrays["neighbour"][face] = -data.draw(st.integers(1, 5))
    elif damage == "boundary cell out of range":
        arrays["boundary_face_cell"] = arrays["boundary_face_cell"].copy()
        arrays["boundary_face_cell"][bface] = data.draw(st.sampled_from([-1, 900, 10**6]))
    elif damage == "other mesh":
        arrays["n_cells"] = np.int64(900 + data.draw(st.sampled_from([-100, -1, 1, 100])))
    elif damage == "flux cut short":
        arrays["flux"] = arrays["flux"][: n_faces - data.draw(st.integers(1, 20))]
    elif damage == "missing array":
        del arrays[data.draw(st.sampled_from(["owner", "neighbour", "flux",
                                              "boundary_face_cell"]))]
    np.savez(path, **arrays)
    if damage == "truncated":
        raw = path.read_bytes()
        path.write_bytes(raw[: int(len(raw) * data.draw(st.sampled_from([0.1, 0.5, 0.99])))])
    _refused_in_one_line(capsys, _snapshot_scene(root), root / "out", "flux")
