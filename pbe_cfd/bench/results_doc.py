"""A study's block in its results document: ``pbe-cfd bench STUDY --results-doc FILE``.

The study's Markdown report (``STUDY.md`` of its output directory) goes between two marker
lines of FILE (docs/results/STUDY.md in the repository), with the command and the time it was
run. Every line outside the markers stays as it was: a document without the markers gets the
block appended, a missing document is created. A document whose markers are broken (one
without the other, twice, or in the wrong order) is refused before the study runs, naming the
file and the marker. The new document is written beside the old and moved over it in one
rename, so a crash leaves the old one or the new one.
"""
from __future__ import annotations

import datetime
import os
import tempfile
from pathlib import Path


class ResultsDocError(ValueError):
    """A results document whose study block cannot be located: names the file and marker."""


def markers(study: str) -> tuple[str, str]:
    """The begin and end lines of ``study``'s block."""
    return (f"<!-- pbe-cfd bench {study}: begin (written by the command; edits between these "
            "lines are replaced) -->", f"<!-- pbe-cfd bench {study}: end -->")


def _block_span(lines: list[str], study: str, path) -> tuple[int, int] | None:
    """(begin, end) line indices of the block, None if the document has no block."""
    begin, end = markers(study)
    starts = [i for i, line in enumerate(lines) if line.strip() == begin]
    stops = [i for i, line in enumerate(lines) if line.strip() == end]
    if not starts and not stops:
        return None
    if len(starts) != 1 or len(stops) != 1 or stops[0] < starts[0]:
        order = ", the end first" if starts and stops and stops[0] < starts[0] else ""
        raise ResultsDocError(
            f"{path}: expected one line {begin!r} and after it one line {end!r} (found "
            f"{len(starts)} and {len(stops)}{order}); fix the markers or remove both")
    return starts[0], stops[0]


def check(path, study: str) -> None:
    """Refuse (``ResultsDocError``) a document whose block of ``study`` cannot be located, or a
    place it cannot be written; a missing document is fine."""
    path = Path(path)
    if path.is_dir():
        raise ResultsDocError(f"{path}: is a directory; expected a Markdown file")
    if path.exists():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise ResultsDocError(f"{path}: cannot be read as text ({exc})") from None
        _block_span(text.splitlines(), study, path)
    parent = path.resolve().parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise ResultsDocError(f"{path}: its directory {parent} does not exist or cannot be written")


def block(study: str, report: str, command: str, when: datetime.datetime | None = None) -> list:
    """The lines of ``study``'s block: markers, the command and its UTC time, the report."""
    when = when or datetime.datetime.now(datetime.timezone.utc)
    begin, end = markers(study)
    return [begin, "",
            f"Latest `{command}`, {when.strftime('%Y-%m-%d %H:%M')} UTC:", "",
            *report.rstrip("\n").splitlines(), "", end]


def refresh(path, study: str, report: str, command: str, when=None) -> str:
    """Write ``report`` into the block of ``study`` in the document ``path``. Returns what was
    done: "created", "appended" or "replaced"."""
    path = Path(path)
    check(path, study)
    new_block = block(study, report, command, when)
    if not path.exists():
        lines = [f"# pbe-cfd bench {study}", "", *new_block]
        action = "created"
    else:
        text = path.read_text()
        lines = text.splitlines()
        span = _block_span(lines, study, path)
        if span is None:
            lines = lines + ([""] if lines and lines[-1].strip() else []) + new_block
            action = "appended"
        else:
            lines = lines[:span[0]] + new_block + lines[span[1] + 1:]
            action = "replaced"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial",
                               dir=path.resolve().parent)
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        if path.exists():
            os.chmod(tmp, path.stat().st_mode & 0o7777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return action


def command_line(args) -> str:
    """The ``pbe-cfd bench`` command of parsed arguments, as a user would type it (without
    ``--overwrite`` and ``--results-doc``)."""
    words = ["pbe-cfd", "bench", args.study] + ([args.scene] if args.scene else [])
    if args.quick:
        words.append("--quick")
    if args.methods:
        words += ["--methods", ",".join(
            f"{name}:{'x'.join(map(str, order)) if isinstance(order, tuple) else order}"
            for name, order in args.methods)]
    for flag, values in (("--cells", args.cells), ("--threads", args.threads)):
        if values:
            words += [flag, ",".join(str(v) for v in values)]
    return " ".join(words + ["--out", str(args.out)])
