"""A case nobody in this project wrote: OpenFOAM's tutorial twoPhaseEulerFoam/RAS/fluidisedBed
(package openfoam-examples), run briefly once per module, then read as a user meets it
(ascii, binary, compressed, decomposed without reconstructPar, renamed phase, 3-D). The user's
case is only read; only the requested pbe.* fields are written into it."""
from __future__ import annotations

import gzip
import hashlib
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pbe_cfd.io import openfoam as of

TUTORIAL = Path("/usr/share/doc/openfoam-examples/examples/multiphase/twoPhaseEulerFoam/"
                "RAS/fluidisedBed")
if not TUTORIAL.is_dir():
    TUTORIAL = Path("/usr/share/openfoam/tutorials/multiphase/twoPhaseEulerFoam/RAS/"
                    "fluidisedBed")
pytestmark = [pytest.mark.openfoam,
              pytest.mark.skipif(shutil.which("twoPhaseEulerFoam") is None
                                 or not TUTORIAL.is_dir(),
                                 reason="needs OpenFOAM and openfoam-examples")]
END = "0.02"      # s of flow: 100 steps of the tutorial's 2e-4 s, written every 0.01 s


def _env():
    return dict(os.environ, WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR",
                                                          "/usr/share/openfoam"))


def _tool(case: Path, *args):
    r = subprocess.run(list(args), cwd=case, env=_env(), capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]


def _unpack(src: Path, dest: Path):
    """Copy the tutorial; Debian ships its large files gzipped (alpha.*.gz)."""
    shutil.copytree(src, dest)
    for gz in dest.rglob("*.gz"):
        gz.with_suffix("").write_bytes(gzip.decompress(gz.read_bytes()))
        gz.unlink()


def _shorten(case: Path):
    """endTime END, writes every 0.01 s, its fieldAverage from 0.01 s with Theta and the
    solids face flux added (the transport step needs alphaPhi)."""
    cd = case / "system" / "controlDict"
    text = cd.read_text()
    text = re.sub(r"^endTime\s+[^;]*;", f"endTime {END};", text, flags=re.M)
    text = re.sub(r"^writeInterval\s+[^;]*;", "writeInterval 0.01;", text, flags=re.M)
    avg = "            {\n                 mean on;\n                 prime2Mean off;\n" \
          "                 base time;\n            }\n"
    text = text.replace("            p\n", f"            Theta.particles\n{avg}"
                        f"            alphaPhi.particles\n{avg}            p\n", 1)
    text = text.replace("writeControl    writeTime;",
                        "writeControl    writeTime;\n        timeStart 0.01;", 1)
    cd.write_text(text)


DEPTH_CELLS = (10, 60, 3)   # the 3-D copy: 1800 cells, 0.15 x 1 x 0.02 m as the tutorial


def _three_d(case: Path):
    """The tutorial extruded in depth: DEPTH_CELLS cells, its front and back planes walls
    (joined to the patch ``walls``; the fields' entries for the removed empty patch are
    ignored), alpha from the tutorial's own setFieldsDict on the new mesh."""
    bm = case / "system" / "blockMeshDict"
    text = bm.read_text().replace("(30 200 1)", "({} {} {})".format(*DEPTH_CELLS))
    text, n = re.subn(r"\)\s*empty frontAndBackPlanes\s*\(\s*(\(0 3 2 1\))\s*(\(4 5 6 7\))",
                      r"    \1\n        \2", text)
    assert n == 1, "the tutorial's blockMeshDict changed"
    bm.write_text(text)
    for orig in (case / "0").glob("alpha.*.orig"):
        shutil.copyfile(orig, orig.with_suffix(""))      # the 2-D setFields result replaced
    _tool(case, "blockMesh")
    _tool(case, "setFields")
    _tool(case, "twoPhaseEulerFoam")


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory):
    """The run tutorial (ascii) and its variants, each a separate copy."""
    root = tmp_path_factory.mktemp("tutorial")
    plain = root / "plain"
    _unpack(TUTORIAL, plain)
    _shorten(plain)
    _tool(plain, "blockMesh")
    _tool(plain, "twoPhaseEulerFoam")
    cases = {"plain": plain}
    for kind, fmt, comp in (("binary", "binary", "off"), ("compressed", "ascii", "on")):
        c = root / kind
        shutil.copytree(plain, c)
        cd = c / "system" / "controlDict"
        text = re.sub(r"^writeFormat\s+[^;]*;", f"writeFormat {fmt};", cd.read_text(),
                      flags=re.M)
        cd.write_text(re.sub(r"^writeCompression\s+[^;]*;", f"writeCompression {comp};", text,
                             flags=re.M))
        _tool(c, "foamFormatConvert", "-constant", "-time", END)
        cases[kind] = c
    dec = root / "decomposed"
    shutil.copytree(plain, dec)
    (dec / "system" / "decomposeParDict").write_text(
        "FoamFile { version 2.0; format ascii; class dictionary; object decomposeParDict; }\n"
        "numberOfSubdomains 2;\nmethod simple;\n"
        "simpleCoeffs { n (2 1 1); delta 0.001; }\n")
    _tool(dec, "decomposePar", "-time", END)
    shutil.rmtree(dec / END)               # a parallel run's result: only processor*/END
    cases["decomposed"] = dec
    deep = root / "3d"
    _unpack(TUTORIAL, deep)
    _shorten(deep)
    _three_d(deep)
    cases["3d"] = deep
    return cases


def _tree(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("kind", ["binary", "compressed", "decomposed"])
def test_variants_read_equal_to_the_plain_case_cell_by_cell(tutorial, kind):
    """The same time read from a binary, compressed or decomposed (not reconstructed) copy
    equals the ascii case cell by cell: OpenFOAM writes 6 significant digits in ascii, so
    the ascii-derived variants agree to that (rel 1e-5); volumes come from the same mesh."""
    ref = of.read_cell_fields(tutorial["plain"], "latest")
    before = _tree(tutorial[kind])
    got = of.read_cell_fields(tutorial[kind], "latest")
    assert _tree(tutorial[kind]) == before            # the user's case only read
    assert got.time == ref.time == float(END)
    assert got.source["decomposed"] == (kind == "decomposed")
    np.testing.assert_allclose(got.alpha, ref.alpha, rtol=1e-5, atol=0)
    np.testing.assert_allclose(got.theta, ref.theta, rtol=1e-5, atol=0)
    np.testing.assert_allclose(got.cell_volume, ref.cell_volume, rtol=1e-9, atol=0)
    fr = of.read_face_flux(tutorial["plain"], "latest")
    fg = of.read_face_flux(tutorial[kind], "latest")
    np.testing.assert_allclose(fg.flux, fr.flux, rtol=1e-5, atol=1e-12 * np.abs(fr.flux).max())
    assert _tree(tutorial[kind]) == before


def test_an_edited_field_is_read_anew(tutorial, tmp_path):
    """The readable copy is keyed by its inputs: after the user scales alpha.particlesMean
    in the case, the next read returns the new values (not the first read's)."""
    case = tmp_path / "case"
    shutil.copytree(tutorial["plain"], case)
    first = of.read_cell_fields(case, END)
    field = case / END / "alpha.particlesMean"
    text = field.read_text()
    head, rest = text.split("internalField", 1)
    m = re.search(r"\(\n(.*?)\n\)", rest, flags=re.S)
    values = np.array([float(v) for v in m.group(1).split()])
    edited = rest[:m.start(1)] + "\n".join(f"{0.5 * v:.6g}" for v in values) + rest[m.end(1):]
    field.write_text(head + "internalField" + edited)
    second = of.read_cell_fields(case, END)
    np.testing.assert_allclose(second.alpha, 0.5 * first.alpha, rtol=1e-5, atol=1e-12)


def _renamed(src: Path, dest: Path, phase: str) -> Path:
    """A copy whose solids phase is called ``phase``: file names and entries renamed."""
    shutil.copytree(src, dest)
    for p in sorted(dest.rglob("*"), key=lambda p: -len(p.parts)):
        if p.is_file() and "polyMesh" not in p.parts:
            p.write_text(p.read_text().replace("particles", phase))
        if "particles" in p.name:
            p.rename(p.with_name(p.name.replace("particles", phase)))
    return dest


def _scene(path: Path, case: str, extra: str = "", transport: bool = False):
    """The bundled fluid-bed scene over ``case``, 2 s of granulation; the tutorial's material
    (300 um, 2500 kg/m3) differs from the scene's, accepted knowingly."""
    from pbe_cfd.scene.scene import resolve_scene_path
    text = resolve_scene_path("fluid-bed").read_text()
    text = text.replace("end_time = 60.0", "end_time = 2.0").replace(
        "output_interval = 5.0", "output_interval = 1.0")
    text = text.replace('case = "bundled:fluid_bed_small"',
                        f'case = "{case}"\naccept_material_mismatch = true\n{extra}')
    if transport:
        text += "\n[transport]\ncourant = 0.5\n"
    path.write_text(text)
    return path


def _only_pbe_fields_differ(before: dict, after: dict, time: str):
    changed = {k for k in set(before) | set(after) if before.get(k) != after.get(k)}
    for rel in changed:
        parts = rel.split("/")
        assert parts[-1].startswith("pbe.") and parts[-2] == time and rel not in before, rel


def _foam_values(case: Path, name: str, decomposed: bool) -> np.ndarray:
    """The cell values of a field pbe-cfd wrote (ascii nonuniform List) in the case's cell
    order; for a decomposed case gathered from the processors through their
    cellProcAddressing (processor cell -> case cell)."""
    def numbers(path: Path, dtype):
        m = re.search(r"\d+\s*\((.*?)\)\s*;?\s*(boundaryField|//|$)", path.read_text(),
                      flags=re.S)
        return np.array(m.group(1).split(), dtype=dtype)
    if not decomposed:
        return numbers(case / END / name, float)
    parts = [(numbers(case / f"processor{i}" / "constant" / "polyMesh" / "cellProcAddressing",
                      int), numbers(case / f"processor{i}" / END / name, float))
             for i in range(2)]
    out = np.full(sum(len(a) for a, _ in parts), np.nan)
    for addressing, values in parts:
        out[addressing] = values
    return out


def _final_vtk(out: Path, field: str) -> np.ndarray:
    from pbe_cfd.io.vtk import read_series
    t, mesh = read_series(out / "vtk" / "pbe.pvd")[-1]
    return np.asarray(mesh.cell_data[field][0], dtype=float)


N_CELLS = {"3d": DEPTH_CELLS[0] * DEPTH_CELLS[1] * DEPTH_CELLS[2]}   # else the tutorial's 30 x 200


@pytest.mark.parametrize("kind", ["plain", "binary", "compressed", "decomposed", "renamed", "3d"])
def test_couple_writes_only_the_requested_fields_into_the_users_case(tutorial, tmp_path, kind,
                                                                     monkeypatch, capsys):
    """`couple` and `couple --foam-fields`, each with and without [transport], run from another
    directory, over the user's case with a log.foamToVTK and a VTK/ of the user's own: each
    reads every cell of the case's mesh; every file of the case is as it was, but the pbe.*
    fields of the time read (per processor when decomposed), and those hold the run's final
    moments (the transport run's replacing the first with --overwrite)."""
    import json

    from pbe_cfd.cli import main
    case = tmp_path / "cases" / "bed"
    extra = ""
    if kind == "renamed":
        _renamed(tutorial["plain"], case, "solids")
        extra = 'phase = "solids"'
    else:
        shutil.copytree(tutorial[kind], case, symlinks=True)   # as it is, links included
    (case / "log.foamToVTK").write_text("the user's own log\n")
    (case / "VTK").mkdir()
    (case / "VTK" / "mine.vtu").write_text("the user's own VTK\n")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    still = _scene(scenes / "s.toml", "../cases/bed", extra)
    moving = _scene(scenes / "t.toml", "../cases/bed", extra, transport=True)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    before = _tree(case)
    for out, scene in (("o1", still), ("o2", moving)):
        assert main(["couple", str(scene), "--out", out]) == 0
        assert _tree(case) == before, out
        summary = json.loads((work / out / "summary.json").read_text())
        assert any("accept_material_mismatch" in w for w in summary["warnings"])
        assert summary["stats"]["cells"] == N_CELLS.get(kind, 30 * 200)
    decomposed = kind == "decomposed"
    assert main(["couple", str(still), "--foam-fields", "--out", "o3"]) == 0
    first = _tree(case)
    _only_pbe_fields_differ(before, first, END)
    # 10 significant digits written against float32 VTK values (2**-24 relative): rtol 1e-6
    np.testing.assert_allclose(_foam_values(case, "pbe.M00", decomposed),
                               _final_vtk(work / "o3", "M00"), rtol=1e-6, atol=0)
    assert main(["couple", str(moving), "--foam-fields", "--overwrite", "--out", "o4"]) == 0
    after = _tree(case)
    _only_pbe_fields_differ(before, after, END)
    assert set(after) == set(first)
    np.testing.assert_allclose(_foam_values(case, "pbe.M00", decomposed),
                               _final_vtk(work / "o4", "M00"), rtol=1e-6, atol=0)
    where = [case / f"processor{i}" for i in range(2)] if decomposed else [case]
    for d in where:
        assert (d / END / "pbe.M00").is_file()
    assert not (case / END).exists() or not decomposed
    assert sorted(p.name for p in work.iterdir()) == ["o1", "o2", "o3", "o4"]
    if kind == "3d":
        _section_drawn_from_the_run(work / "o1")


def _section_drawn_from_the_run(out: Path):
    """`render --section z=0` over the 3-D run: the plane cuts the middle layer of cells (the
    tutorial's depth is -0.01 to 0.01 m in 3 layers), its polygons carry those cells' values
    from the run's last VTK file, and the picture is drawn."""
    from pbe_cfd.viz.section import read_section
    from pbe_cfd.io.vtk import read_pvd, read_series
    from pbe_cfd.cli import main
    t, mesh = read_series(out / "vtk" / "pbe.pvd")[-1]
    polys, data, axes, note = read_section(read_pvd(out / "vtk" / "pbe.pvd")[-1][1], ("z", 0.0))
    nx, ny, nz = DEPTH_CELLS
    assert axes == ("x", "y") and len(polys) == nx * ny
    pts = np.asarray(mesh.points)
    centre_z = np.array([pts[c].mean(axis=0)[2] for c in mesh.cells[0].data])
    layer = np.abs(centre_z) < 0.01 / nz                 # the middle of three layers
    assert layer.sum() == nx * ny
    np.testing.assert_allclose(np.sort(data["d43_m"]),
                               np.sort(np.asarray(mesh.cell_data["d43_m"][0])[layer]),
                               rtol=1e-6, atol=0)       # float32 values, read twice
    png = out / "png" / "d43_m_t2s.png"
    stamp = png.stat().st_mtime_ns
    assert main(["render", str(out), "--section", "z=0", "--fields", "d43_m", "--times", "2",
                 "--overwrite"]) == 0
    assert png.stat().st_mtime_ns != stamp


def test_a_material_mismatch_is_refused_in_one_line(tutorial, tmp_path, capsys):
    """Without the accepting key, the scene's 100.4 um / 1021 kg/m3 against the tutorial's
    300 um / 2500 kg/m3 is an exit-2 error naming both values and both files."""
    from pbe_cfd.cli import main
    s = _scene(tmp_path / "s.toml", str(tutorial["plain"]))
    s.write_text(s.read_text().replace("accept_material_mismatch = true", ""))
    assert main(["couple", str(s), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert "1021" in err[0] and "2500" in err[0] and "thermophysicalProperties" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_failing_openfoam_tool_is_one_line_and_leaves_no_copy(tutorial, tmp_path):
    """A case whose mesh points file is truncated: the conversion fails in one line naming the
    tool, nothing is written into the case, and no partial copy is left in the cache."""
    from pbe_cfd.io.openfoam.readable import SOURCE_FILE, cache_root
    case = tmp_path / "case"
    shutil.copytree(tutorial["plain"], case)
    points = case / "constant" / "polyMesh" / "points"
    points.write_bytes(points.read_bytes()[:2000])
    before = _tree(case)
    copies = {p.name for p in cache_root().iterdir()}
    with pytest.raises(of.OpenFOAMError) as err:
        of.read_cell_fields(case, END)
    text = str(err.value)
    assert "\n" not in text and "failed on t = 0.02 s" in text
    assert _tree(case) == before
    new = {p.name for p in cache_root().iterdir()} - copies - {"failed"}
    assert not any((cache_root() / n / SOURCE_FILE).exists() for n in new) and not new
