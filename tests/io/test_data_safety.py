"""Lose nothing: no verb replaces or deletes a file it did not write.

For every verb that writes (run, couple, compare, render, bench, case run, couple --run-case,
--foam-fields, the Dask chunk store): a user file beside the output and inside it survives;
the current directory and its ancestors are refused; a directory pbe-cfd did not write is
refused; an earlier output is replaced only with --overwrite, and then only its own files.
Every refusal is exit code 2 before any work, and leaves the tree byte for byte as it was.
"""
from __future__ import annotations

import hashlib
import json
import os
import stat
import textwrap
from pathlib import Path

import meshio
import numpy as np
import pytest

from pbe_cfd.io import output
from pbe_cfd.cli import main
from pbe_cfd.scene.scene import resolve_scene_path

TINY_RUN = textwrap.dedent("""
    [scene]
    name = "tiny"
    end_time = 2.0
    output_interval = 1.0
    [domain]
    type = "well-mixed"
    solids_fraction = 0.3
    [material]
    density = 1000.0
    [initial]
    distribution = "monodisperse"
    number_density = 1e10
    mean_mass = 1e-9
    [aggregation]
    kernel = "constant"
    rate = 1e-11
    [method]
    name = "qmom"
    nodes = 2
""")


def tiny_couple_text(case: str | None = None) -> str:
    """The bundled fluid-bed scene shortened to 2 s (outputs at 0, 1, 2 s)."""
    text = resolve_scene_path("fluid-bed").read_text()
    text = text.replace("end_time = 60.0", "end_time = 2.0").replace(
        "output_interval = 5.0", "output_interval = 1.0")
    if case is not None:
        text = text.replace('case = "bundled:fluid_bed_small"', f'case = "{case}"')
    return text


def tree(root: Path, exclude=()) -> dict:
    """path -> (size, mtime_ns, sha256) of every file below root (not below ``exclude``)."""
    out = {}
    for p in sorted(root.rglob("*")):
        if any(p == e or e in p.parents for e in exclude) or not p.is_file():
            continue
        st = p.stat()
        out[p.relative_to(root).as_posix()] = (st.st_size, st.st_mtime_ns,
                                               hashlib.sha256(p.read_bytes()).hexdigest())
    return out


@pytest.fixture
def box(tmp_path, monkeypatch):
    """A working directory holding the user's files: notes.txt, data/keep.csv, the scenes."""
    work = tmp_path / "work"
    (work / "data").mkdir(parents=True)
    (work / "notes.txt").write_text("my notes\n")
    (work / "data" / "keep.csv").write_text("a,b\n1,2\n")
    (work / "tiny.toml").write_text(TINY_RUN)
    (work / "tiny-couple.toml").write_text(tiny_couple_text())
    monkeypatch.chdir(work)
    return work


def put_user_files(directory: Path) -> dict:
    """Two user files in ``directory``; returns their tree entries."""
    (directory / "mine.txt").write_text("mine\n")
    (directory / "sub").mkdir(exist_ok=True)
    (directory / "sub" / "keep.dat").write_bytes(b"\x00\x01")
    return {k: v for k, v in tree(directory).items() if k in ("mine.txt", "sub/keep.dat")}


def refused(argv, capsys, *phrases):
    capsys.readouterr()           # drop what earlier calls printed (a cold cache's compile notice)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("pbe-cfd: error: ") and len(err.strip().splitlines()) == 1, err
    for phrase in phrases:
        assert phrase in err, err
    return err


# ---------------------------------------------------------------------------- refusals
REFUSED_TARGETS = [
    (["run", "tiny.toml", "--out"], "current directory"),
    (["couple", "tiny-couple.toml", "--out"], "current directory"),
    (["bench", "cnmc", "--quick", "--out"], "current directory"),
    (["case", "run", "--dir"], "current directory"),
]


@pytest.mark.parametrize("argv,phrase", REFUSED_TARGETS, ids=lambda a: " ".join(a)[:20])
@pytest.mark.parametrize("target", [".", "..", "../.."])
def test_current_directory_and_ancestors_are_refused(box, capsys, argv, phrase, target):
    before = tree(box.parent)
    refused(argv + [target], capsys, phrase)
    assert tree(box.parent) == before


@pytest.mark.parametrize("argv", [a for a, _ in REFUSED_TARGETS], ids=lambda a: a[0])
def test_a_directory_pbe_cfd_did_not_write_is_refused(box, capsys, argv):
    before = tree(box)
    refused(argv + ["data"], capsys, "not written by pbe-cfd", "nothing was changed")
    assert tree(box) == before
    # even with --overwrite
    refused(argv + ["data", "--overwrite"], capsys, "not written by pbe-cfd")
    assert tree(box) == before


def test_a_file_as_output_directory_is_refused(box, capsys):
    before = tree(box)
    refused(["run", "tiny.toml", "--out", "notes.txt"], capsys, "not a directory")
    refused(["run", "tiny.toml", "--out", "notes.txt/run1"], capsys, "is a file")
    assert tree(box) == before


# ---------------------------------------------------------------------------- run
@pytest.mark.slow
def test_run_replaces_an_earlier_output_only_with_overwrite(box, capsys):
    outside = tree(box, exclude=[box / "r"])
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    manifest = output.read_manifest(box / "r")
    assert set(manifest["files"]) == {"moments.csv", "summary.json", "moments.png", "psd.csv",
                                      "psd.png", "columns.json"}
    user = put_user_files(box / "r")
    first = tree(box / "r")
    refused(["run", "tiny.toml", "--out", "r"], capsys, "earlier pbe-cfd output", "--overwrite")
    assert tree(box / "r") == first
    assert main(["run", "tiny.toml", "--out", "r", "--overwrite"]) == 0
    after = tree(box / "r")
    for rel in ("mine.txt", "sub/keep.dat"):
        assert after[rel] == user[rel]
    assert after["moments.csv"][1] != first["moments.csv"][1]    # replaced
    assert set(output.read_manifest(box / "r")["files"]) == {
        "moments.csv", "summary.json", "moments.png", "psd.csv", "psd.png", "columns.json"}
    assert tree(box, exclude=[box / "r"]) == outside    # nothing beside --out touched
    assert not [p for p in box.iterdir() if p.name.startswith(".r.")]


def test_a_changed_output_file_is_never_replaced(box, capsys):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    (box / "r" / "moments.csv").write_text("edited by hand\n")
    assert main(["run", "tiny.toml", "--out", "r", "--overwrite"]) == 2
    assert "changed since" in capsys.readouterr().err
    assert (box / "r" / "moments.csv").read_text() == "edited by hand\n"


def test_overwrite_removes_only_unchanged_stale_files_it_wrote(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with output.atomic_directory("o") as d:
        for name in ("a.txt", "old/b.txt", "old/c.txt"):
            (d / name).parent.mkdir(exist_ok=True)
            (d / name).write_text(name)
    (tmp_path / "o" / "old" / "user.txt").write_text("user")
    with pytest.warns(UserWarning, match="kept .*c.txt: it changed"):
        with output.atomic_directory("o", overwrite=True) as d:
            (d / "a.txt").write_text("new a")
            # edited while the run computes (an edit before it is refused up front)
            (tmp_path / "o" / "old" / "c.txt").write_text("the user edited this")
    o = tmp_path / "o"
    assert (o / "a.txt").read_text() == "new a"
    assert not (o / "old" / "b.txt").exists()           # stale, unchanged, ours: removed
    assert (o / "old" / "c.txt").read_text() == "the user edited this"
    assert (o / "old" / "user.txt").read_text() == "user"
    assert set(output.read_manifest(o)["files"]) == {"a.txt"}


def test_failed_run_leaves_an_earlier_output_untouched(box):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    gel = TINY_RUN.replace('kernel = "constant"', 'kernel = "product"').replace(
        "rate = 1e-11", "rate = 1e9")
    (box / "gel.toml").write_text(gel)
    before = tree(box)
    assert main(["run", "gel.toml", "--out", "r", "--overwrite"]) == 2   # refused before
    assert tree(box) == before
    assert not [p for p in box.iterdir() if p.name.startswith(".r.partial")]


def test_outputs_honour_the_umask(box):
    old = os.umask(0o027)
    try:
        assert main(["run", "tiny.toml", "--out", "r"]) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((box / "r").stat().st_mode) == 0o750
    for p in (box / "r").iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o640, p


# ---------------------------------------------------------------------------- couple, render
@pytest.fixture
def coupled(box):
    assert main(["couple", "tiny-couple.toml", "--out", "c"]) == 0
    return box / "c"


@pytest.mark.slow
def test_couple_replaces_an_earlier_output_only_with_overwrite(box, coupled, capsys):
    user = put_user_files(coupled)
    png = put_user_files(coupled / "png")
    outside = tree(box, exclude=[coupled])
    refused(["couple", "tiny-couple.toml", "--out", "c"], capsys, "--overwrite")
    assert main(["couple", "tiny-couple.toml", "--out", "c", "--overwrite"]) == 0
    after = tree(coupled)
    for rel in ("mine.txt", "sub/keep.dat"):
        assert after[rel] == user[rel]
        assert after["png/" + rel] == png[rel]
    assert tree(box, exclude=[coupled]) == outside
    assert "vtk/pbe.pvd" in output.read_manifest(coupled)["files"]


@pytest.mark.slow
def test_render_adds_new_pictures_and_replaces_its_own_only_with_overwrite(coupled, capsys):
    user = put_user_files(coupled / "png")
    (coupled / "png" / "M01_t2s.png").write_bytes(b"the user's own picture")
    before = tree(coupled)
    # couple drew d43_m at 0 and 2 s: drawing them again needs --overwrite
    refused(["render", "c", "--fields", "d43_m"], capsys, "--overwrite")
    assert tree(coupled) == before
    # a new time is added without --overwrite
    assert main(["render", "c", "--fields", "M00", "--times", "1"]) == 0
    assert (coupled / "png" / "M00_t1s.png").is_file()
    assert "png/M00_t1s.png" in output.read_manifest(coupled)["files"]
    assert main(["render", "c", "--fields", "d43_m", "--overwrite"]) == 0
    # a picture pbe-cfd did not draw is never replaced
    refused(["render", "c", "--fields", "M01", "--times", "2", "--overwrite"], capsys,
            "M01_t2s.png", "not write")
    after = tree(coupled)
    assert after["png/M01_t2s.png"] == before["png/M01_t2s.png"]
    for rel in user:
        assert after["png/" + rel] == user[rel]


def test_render_of_a_series_pbe_cfd_did_not_write_goes_into_a_new_png_directory(
        coupled, box, capsys):
    foreign = box / "foreign"
    foreign.mkdir()
    for p in (coupled / "vtk").iterdir():
        (foreign / p.name).write_bytes(p.read_bytes())
    before = tree(foreign)
    assert main(["render", "foreign", "--fields", "M00"]) == 0
    after = tree(foreign)
    assert {k: v for k, v in after.items() if not k.startswith("png/")} == before
    assert "png/M00_t2s.png" in after
    (foreign / "png" / "mine.txt").write_text("mine")
    assert main(["render", "foreign", "--fields", "M00", "--overwrite"]) == 0
    assert (foreign / "png" / "mine.txt").read_text() == "mine"


@pytest.mark.slow
def test_compare_writes_a_marked_figure_and_never_replaces_a_users(box, coupled, capsys):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    (box / "user.png").write_bytes(b"\x89PNG not ours")
    before = tree(box)
    refused(["compare", "r", "c", "--out", "user.png"], capsys, "not written by pbe-cfd")
    refused(["compare", "r", "c", "--out", "user.png", "--overwrite"], capsys,
            "not written by pbe-cfd")
    refused(["compare", "r", "--out", "."], capsys, "is a directory")
    refused(["compare", "r", "--out", "data"], capsys, "is a directory")
    assert tree(box) == before
    assert main(["compare", "r", "c", "--out", "cmp.png"]) == 0
    assert output.file_is_marked(box / "cmp.png")
    refused(["compare", "r", "c", "--out", "cmp.png"], capsys, "--overwrite")
    assert main(["compare", "r", "c", "--out", "cmp.png", "--overwrite"]) == 0
    assert output.file_is_marked(box / "cmp_psd.png")       # the PSD overlay beside it
    assert tree(box, exclude=[box / "cmp.png", box / "cmp_psd.png"]) == before


# ---------------------------------------------------------------------------- bench
def test_bench_adds_its_files_and_replaces_them_only_with_overwrite(box, capsys):
    prev = box / "b"
    with output.atomic_directory(prev, kind="bench") as d:       # an earlier bench output
        (d / "cnmc.csv").write_text("x\n")
        (d / "laguerre.md").write_text("y\n")
    user = put_user_files(prev)
    refused(["bench", "cnmc", "--quick", "--out", "b"], capsys, "cnmc.csv", "--overwrite")
    with output.add_to_directory(prev, kind="bench") as d:   # another study's files are added
        (d / "couple.csv").write_text("z\n")
    after = tree(prev)
    for rel in user:
        assert after[rel] == user[rel]
    assert {"cnmc.csv", "laguerre.md", "couple.csv"} <= set(output.read_manifest(prev)["files"])
    (prev / "couple.md").write_text("the user's")
    with pytest.raises(output.OutputRefused, match="couple.md"):
        with output.add_to_directory(prev, kind="bench") as d:
            (d / "couple.md").write_text("z\n")
    assert (prev / "couple.md").read_text() == "the user's"


# ---------------------------------------------------------------------------- OpenFOAM cases
@pytest.fixture
def fake_openfoam(tmp_path, monkeypatch):
    """Stand-ins for the OpenFOAM tools and a case template whose Allrun writes a time
    directory, a log and a VTK file (the file names the real case writes), so that the case
    directory rules are checked without running OpenFOAM."""
    bin_dir = tmp_path / "fake-bin"
    bin_dir.mkdir()
    for tool in ("blockMesh", "setFields", "twoPhaseEulerFoam", "foamToVTK", "postProcess"):
        (bin_dir / tool).write_text("#!/bin/sh\nexit 0\n")
        (bin_dir / tool).chmod(0o755)
    project = tmp_path / "fake-foam"
    (project / "etc").mkdir(parents=True)
    (project / "etc" / "controlDict").write_text("// fake\n")
    template = tmp_path / "template"
    for d in ("0.orig", "constant", "system"):
        (template / d).mkdir(parents=True)
    (template / "0.orig" / "alpha.particles").write_text("alpha\n")
    (template / "system" / "controlDict").write_text("endTime 1.5;\n")
    (template / "Allrun").write_text(textwrap.dedent("""\
        #!/bin/bash
        cd "${0%/*}" || exit 1
        ./Allclean > /dev/null
        cp -r 0.orig 0
        echo "Allrun: running blockMesh"; echo mesh > log.blockMesh
        mkdir -p 1.5 VTK && echo a > 1.5/alpha.particlesMean && echo v > VTK/internal.vtu
        echo "Allrun: done"
        """))
    (template / "Allclean").write_text(textwrap.dedent("""\
        #!/bin/bash
        cd "${0%/*}" || exit 1
        rm -rf 0 [1-9]* 0.[0-9]* constant/polyMesh VTK postProcessing processor* log.*
        """))
    for script in ("Allrun", "Allclean"):
        (template / script).chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("WM_PROJECT_DIR", str(project))
    monkeypatch.setenv("PBE_CFD_CASE", str(template))
    return template


def test_case_run_keeps_user_files_and_replaces_its_own_case_only_with_overwrite(
        box, fake_openfoam, capsys):
    outside = tree(box, exclude=[box / "k"])
    assert main(["case", "run", "--dir", "k"]) == 0
    capsys.readouterr()
    files = output.read_manifest(box / "k")["files"]
    assert {"Allrun", "0/alpha.particles", "1.5/alpha.particlesMean", "log.blockMesh"} <= set(files)
    user = put_user_files(box / "k")
    refused(["case", "run", "--dir", "k"], capsys, "--overwrite")
    assert main(["case", "run", "--dir", "k", "--overwrite"]) == 0
    capsys.readouterr()
    after = tree(box / "k")
    for rel in user:
        assert after[rel] == user[rel]
    assert tree(box, exclude=[box / "k"]) == outside
    # a user file that Allclean would delete (log.*) is refused before anything runs
    (box / "k" / "log.mine").write_text("my log")
    before = tree(box / "k")
    refused(["case", "run", "--dir", "k", "--overwrite"], capsys, "log.mine", "Allclean")
    assert tree(box / "k") == before


def test_case_run_into_an_empty_directory_and_refusals(box, fake_openfoam, capsys):
    (box / "empty").mkdir()
    assert main(["case", "run", "--dir", "empty"]) == 0
    capsys.readouterr()
    refused(["case", "run", "--dir", "data"], capsys, "not written by pbe-cfd")
    refused(["case", "run", "--dir", "."], capsys, "current directory")


def test_run_case_refuses_a_users_fluid_bed_case(box, fake_openfoam, capsys):
    (box / "fluid-bed-case").mkdir()
    (box / "fluid-bed-case" / "mine.txt").write_text("mine")
    before = tree(box)
    refused(["couple", "tiny-couple.toml", "--run-case", "--out", "c"], capsys,
            "fluid-bed-case", "not written by pbe-cfd")
    assert tree(box) == before


def _fake_case(root: Path, time: float = 1.5) -> Path:
    """An OpenFOAM case with the bundled snapshot's mesh and fields: foamToVTK-style output
    and the polyMesh files write_foam_fields needs."""
    from pbe_cfd.io import openfoam as of
    cells = of.load_snapshot()
    case = root / "case"
    (case / f"{time:g}").mkdir(parents=True)
    (case / f"{time:g}" / "alpha.particlesMean").write_text("the CFD's own field\n")
    sub = case / "VTK" / "case_100"
    sub.mkdir(parents=True)
    mesh = meshio.Mesh(cells.mesh.points, [(b.type, b.data) for b in cells.mesh.cells],
                       cell_data={"alpha.particlesMean": [cells.alpha],
                                  "Theta.particlesMean": [cells.theta]})
    meshio.write(sub / "internal.vtu", mesh, file_format="vtu")
    (case / "VTK" / "case.vtm.series").write_text(json.dumps(
        {"file-series-version": "1.0", "files": [{"name": "case_100.vtm", "time": time}]}))
    pm = case / "constant" / "polyMesh"
    pm.mkdir(parents=True)
    n = cells.n_cells
    (pm / "owner").write_text(
        'FoamFile\n{\n    version 2.0;\n    format ascii;\n    class labelList;\n'
        f'    note "nPoints:0 nCells:{n} nFaces:0 nInternalFaces:0";\n    object owner;\n}}\n'
        f"{n}\n(\n" + "\n".join(str(i) for i in range(n)) + "\n)\n")
    (pm / "boundary").write_text(
        "FoamFile\n{\n    version 2.0;\n    format ascii;\n    class polyBoundaryMesh;\n"
        "    object boundary;\n}\n1\n(\n    walls\n    {\n        type wall;\n"
        "        nFaces 0;\n        startFace 0;\n    }\n)\n")
    return case


@pytest.mark.slow
def test_foam_fields_never_replace_a_field_pbe_cfd_did_not_write(box, capsys):
    refused(["couple", "tiny-couple.toml", "--foam-fields", "--out", "c"], capsys,
            "snapshot", "no OpenFOAM case time directory")
    assert not (box / "c").exists()
    case = _fake_case(box)
    (box / "s.toml").write_text(tiny_couple_text(str(case)))
    (case / "1.5" / "pbe.M00").write_text("the user's field")
    before = tree(case)
    refused(["couple", "s.toml", "--foam-fields", "--out", "c"], capsys, "pbe.M00",
            "not written by pbe-cfd")
    refused(["couple", "s.toml", "--foam-fields", "--out", "c", "--overwrite"], capsys,
            "pbe.M00")
    assert tree(case) == before and not (box / "c").exists()
    (case / "1.5" / "pbe.M00").unlink()
    capsys.readouterr()
    assert main(["couple", "s.toml", "--foam-fields", "--out", "c"]) == 0
    # the run says what it wrote into the user's case, and where
    assert f"pbe.* field files into the case: {case / '1.5'}" in capsys.readouterr().out
    written = case / "1.5" / "pbe.M00"
    assert output.file_is_marked(written)
    assert (case / "1.5" / "alpha.particlesMean").read_text() == "the CFD's own field\n"
    refused(["couple", "s.toml", "--foam-fields", "--out", "c2"], capsys, "--overwrite")
    assert main(["couple", "s.toml", "--foam-fields", "--out", "c2", "--overwrite"]) == 0
    assert output.file_is_marked(written)


# ---------------------------------------------------------------------------- chunk store
def test_chunk_store_removes_only_its_own_files(tmp_path):
    from pbe_cfd.runs.distributed import ChunkStore, ChunkStoreError

    user_dir = tmp_path / "run.chunks"
    user_dir.mkdir()
    (user_dir / "mine.txt").write_text("mine")
    with pytest.raises(ChunkStoreError, match="not a chunk store"):
        ChunkStore(user_dir).open("f", {}, resume=False)
    assert (user_dir / "mine.txt").read_text() == "mine"
    store_dir = tmp_path / "ok.chunks"
    store = ChunkStore(store_dir).open("f", {}, resume=False)
    store.save_chunk(0, {"x": np.zeros(3)})
    (store_dir / "mine.txt").write_text("mine")
    store = ChunkStore(store_dir).open("g", {}, resume=False)     # a fresh run
    assert not (store_dir / "chunk_00000.npz").exists()
    assert (store_dir / "mine.txt").read_text() == "mine"
    store.save_chunk(1, {"x": np.zeros(3)})
    store.remove()
    assert sorted(p.name for p in store_dir.iterdir()) == ["mine.txt"]
    (store_dir / "mine.txt").unlink()
    store = ChunkStore(store_dir).open("h", {}, resume=False)
    store.remove()
    assert not store_dir.exists()


def test_a_cluster_run_does_not_discard_an_earlier_runs_chunks(box, capsys):
    from pbe_cfd.runs.distributed import ChunkStore
    ChunkStore(box / "c.chunks").open("f", {}, resume=False).save_chunk(0, {"x": np.zeros(1)})
    before = tree(box)
    refused(["couple", "tiny-couple.toml", "--workers", "1", "--out", "c"], capsys,
            "--resume", "--overwrite")
    assert tree(box) == before
