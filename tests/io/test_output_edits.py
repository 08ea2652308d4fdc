"""A user's edit of an output file is an edit even when it keeps the file's size.

The manifest records each written file's size and modification time; an edit that replaces
bytes in place (a corrected number, a retyped character) keeps the size, so only the
modification time tells it apart. Every such file must then count as the user's: kept on
--overwrite, refused as a collision, never removed.
"""
import os

import pytest

from pbe_cfd.io import output


def _same_size_edit(path):
    """Replace the first byte of ``path`` in place (same size) and move its modification time
    one second on, as an editor saving a second later does."""
    data = bytearray(path.read_bytes())
    data[0] = ord("X") if data[0] != ord("X") else ord("Y")
    st = path.stat()
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    assert path.stat().st_size == st.st_size


def test_an_edit_that_keeps_the_size_is_still_an_edit(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with output.atomic_directory("o") as d:
        (d / "a.txt").write_text("written by pbe-cfd\n")
        (d / "b.txt").write_text("also ours\n")
    o = tmp_path / "o"
    _same_size_edit(o / "b.txt")
    edited = (o / "b.txt").read_bytes()
    # replace mode: an edit known before the run is refused before anything is written
    with pytest.raises(output.OutputRefused, match="b.txt changed since"):
        with output.atomic_directory("o", overwrite=True) as d:
            (d / "a.txt").write_text("new a\n")
    assert (o / "b.txt").read_bytes() == edited
    assert (o / "a.txt").read_text() == "written by pbe-cfd\n"
    # an edit made while the run computes: the stale file is kept, with a warning naming it
    with output.atomic_directory("p") as d:
        (d / "a.txt").write_text("written by pbe-cfd\n")
        (d / "b.txt").write_text("also ours\n")
    p = tmp_path / "p"
    with pytest.warns(UserWarning, match="kept .*b.txt: it changed"):
        with output.atomic_directory("p", overwrite=True) as d:
            _same_size_edit(p / "b.txt")
            (d / "a.txt").write_text("new a\n")
    assert (p / "b.txt").read_bytes()[:1] in (b"X", b"Y")
    assert set(output.read_manifest(p)["files"]) == {"a.txt"}
    # add mode: a same-size edit of a file the new output would replace is a collision
    _same_size_edit(o / "a.txt")
    with pytest.raises(output.OutputRefused, match="changed since"):
        output.prepare_directory(o, overwrite=True, names=["a.txt"])
    # removal: the edited file is no longer ours to remove
    assert output.remove_written(o) is False
    assert (o / "a.txt").exists() and (o / "b.txt").read_bytes() == edited
