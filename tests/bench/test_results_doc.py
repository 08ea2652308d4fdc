"""``pbe-cfd bench STUDY --results-doc FILE``: the study's report goes between its two marker
lines of FILE, and every other byte of the document stays as it was; broken markers are
refused before the study runs."""
import datetime

import pytest

from pbe_cfd import cli
from pbe_cfd.bench import results_doc as rd

WHEN = datetime.datetime(2026, 12, 1, 21, 30, tzinfo=datetime.timezone.utc)
PROSE_BEFORE = "# Integrators\n\nProse a person wrote, with a table:\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
PROSE_AFTER = "\n## Discussion\n\nMore prose, kept as written.\n"


def test_a_missing_document_is_created_with_the_block(tmp_path):
    doc = tmp_path / "integrators.md"
    assert rd.refresh(doc, "integrators", "| x |\n|---|\n| 3 |\n", "pbe-cfd bench integrators",
                      when=WHEN) == "created"
    lines = doc.read_text().splitlines()
    begin, end = rd.markers("integrators")
    assert lines[0] == "# pbe-cfd bench integrators"
    assert lines.index(begin) < lines.index("| 3 |") < lines.index(end)
    assert "Latest `pbe-cfd bench integrators`, 2026-12-01 21:30 UTC:" in lines


def test_only_the_block_is_replaced_and_the_prose_around_it_is_kept(tmp_path):
    doc = tmp_path / "integrators.md"
    begin, end = rd.markers("integrators")
    doc.write_text(PROSE_BEFORE + f"{begin}\n\nold report\n\n{end}\n" + PROSE_AFTER)
    assert rd.refresh(doc, "integrators", "new report\n", "pbe-cfd bench integrators",
                      when=WHEN) == "replaced"
    text = doc.read_text()
    assert text.startswith(PROSE_BEFORE) and text.endswith(PROSE_AFTER)
    assert "old report" not in text and text.count("new report") == 1
    once = text
    rd.refresh(doc, "integrators", "new report\n", "pbe-cfd bench integrators", when=WHEN)
    assert doc.read_text() == once                      # the same report: the same document


def test_a_document_without_the_block_gets_it_appended(tmp_path):
    doc = tmp_path / "accuracy.md"
    doc.write_text(PROSE_BEFORE)
    assert rd.refresh(doc, "accuracy", "report\n", "pbe-cfd bench accuracy", when=WHEN) == "appended"
    text = doc.read_text()
    assert text.startswith(PROSE_BEFORE)
    assert text.rstrip().endswith(rd.markers("accuracy")[1])
    # another study's block in the same file is prose to this one
    rd.refresh(doc, "throughput", "speed\n", "pbe-cfd bench throughput", when=WHEN)
    assert "report" in doc.read_text() and "speed" in doc.read_text()


@pytest.mark.parametrize("broken", ["begin only", "end only", "twice", "end first"])
def test_broken_markers_are_refused_and_the_document_is_unchanged(tmp_path, broken):
    begin, end = rd.markers("cnmc")
    body = {"begin only": f"{begin}\n", "end only": f"{end}\n",
            "twice": f"{begin}\n{end}\n{begin}\n{end}\n", "end first": f"{end}\n{begin}\n"}[broken]
    doc = tmp_path / "cnmc.md"
    doc.write_text(PROSE_BEFORE + body)
    before = doc.read_bytes()
    with pytest.raises(rd.ResultsDocError, match=r"cnmc\.md: expected one line"):
        rd.refresh(doc, "cnmc", "report\n", "pbe-cfd bench cnmc")
    assert doc.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cnmc.md"]     # no partial file


def test_the_cli_refuses_broken_markers_before_the_study_runs(tmp_path, capsys):
    begin, _ = rd.markers("cnmc")
    doc = tmp_path / "cnmc-doc.md"
    doc.write_text(PROSE_BEFORE + begin + "\n")
    code = cli.main(["bench", "cnmc", "--quick", "--out", str(tmp_path / "out"),
                     "--results-doc", str(doc)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "cnmc-doc.md" in err[0]
    assert not (tmp_path / "out").exists()                 # refused before anything was written


def test_the_cli_writes_the_studys_report_into_the_document(tmp_path):
    doc = tmp_path / "cnmc.md"
    doc.write_text(PROSE_BEFORE)
    out = tmp_path / "out"
    assert cli.main(["bench", "cnmc", "--quick", "--out", str(out), "--results-doc", str(doc)]) == 0
    text = doc.read_text()
    assert text.startswith(PROSE_BEFORE)
    report = (out / "cnmc.md").read_text().rstrip("\n")
    begin, end = rd.markers("cnmc")
    block = text[text.index(begin):text.index(end)]
    assert report in block and "`pbe-cfd bench cnmc --quick" in block
