"""A user's own OpenFOAM case: every path of a scene is read relative to the scene file, for
reading and writing alike, whatever the working directory."""
from __future__ import annotations

import os

from test_data_safety import _fake_case, tiny_couple_text, tree

from pbe_cfd.io import output
from pbe_cfd.cli import main


def test_relative_case_is_read_and_written_next_to_the_scene(tmp_path, monkeypatch, capsys):
    """The scene in project/ names case = "bed"; a decoy case sits at the same relative path
    from the working directory. Reading and --foam-fields both use project/bed; the decoy is
    left byte for byte as it was."""
    project, work = tmp_path / "project", tmp_path / "work"
    project.mkdir()
    work.mkdir()
    _fake_case(project).rename(project / "bed")
    _fake_case(work).rename(work / "bed")                # the decoy
    (project / "s.toml").write_text(tiny_couple_text("bed"))
    decoy = tree(work / "bed")
    monkeypatch.chdir(work)
    assert main(["couple", str(project / "s.toml"), "--foam-fields", "--out", "out"]) == 0
    assert output.file_is_marked(project / "bed" / "1.5" / "pbe.M00")
    assert tree(work / "bed") == decoy
    # from a third directory the same scene reads and writes the same case
    third = tmp_path / "third"
    third.mkdir()
    monkeypatch.chdir(third)
    assert main(["couple", os.path.relpath(project / "s.toml"), "--foam-fields", "--out",
                 "out", "--overwrite"]) == 0
    assert tree(work / "bed") == decoy
    assert sorted(p.name for p in third.iterdir()) == ["out"]     # nothing but the output


def test_time_as_a_string_is_a_written_time(tmp_path, monkeypatch):
    """``time = "1.5"`` (OpenFOAM's directory name) reads that time like ``time = 1.5``."""
    from pbe_cfd.runs.domain import load_domain
    from pbe_cfd.scene.scene import load_scene
    _fake_case(tmp_path)
    for value in ('"1.5"', "1.5"):
        text = tiny_couple_text("case").replace('time = "latest"', f"time = {value}")
        if f"time = {value}" not in text:
            text = text.replace('case = "case"', f'case = "case"\ntime = {value}')
        (tmp_path / "s.toml").write_text(text)
        monkeypatch.chdir(tmp_path.parent)
        dom = load_domain(load_scene(tmp_path / "s.toml"))
        assert dom.cells.time == 1.5
