"""CLI fuzz: argument lists drawn from the real verbs and options, with good and bad values,
run in a sandbox of user files and earlier outputs.

Every command must end with exit code 0, 1 or 2, never an uncaught exception (a traceback),
and must not touch any file outside what it may write: the --out target of run/couple/compare,
the png/ directory (and manifest) of a rendered run. User files inside earlier outputs always
survive. Small scenes (2 s of granulation), a bounded number of examples, a per-example
deadline; commands that would start an OpenFOAM run, a Dask cluster or a benchmark are drawn
only with arguments that are refused before any work (bench's default --out, bench-out/, is
a user directory here), and couple always gets a scene (its default runs 60 s).
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import os
import shutil
import tempfile
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pbe_cfd.cli import main

from test_data_safety import TINY_RUN, tiny_couple_text

BAD_SCENE = TINY_RUN.replace("nodes = 2", "nodes = 2\nnode_count = 3")
USER_FILES = ("notes.txt", "data/keep.csv", "bench-out/mine.txt", "r_prev/mine.txt", "c_prev/mine.txt",
              "c_prev/png/mine.png", "fluid-bed-case/mine.txt", "user.png")

SCENES = ["tiny.toml", "bad.toml", "nosuch.toml", "notes.txt", "data", "constant-kernel"]
COUPLED = ["tiny-couple.toml", "bad.toml", "nosuch.toml", "tiny.toml", "notes.txt"]
OUTS = ["new1", "sub/new2", ".", "..", "data", "notes.txt", "notes.txt/x", "r_prev", "c_prev",
        "user.png"]
RUNS = ["r_prev", "c_prev", "data", "nosuch", "notes.txt", "data/keep.csv", "tiny.toml"]
FIGURES = ["cmp.png", "cmp.svg", "cmp.txt", "user.png", ".", "data", "sub/cmp.png", "notes.txt"]
FIELDS = ["d43_m", "M00", "alpha", "binder_fraction", "nosuchfield", ""]
TIMES = ["7", "0", "1", "2", "-1", "nan", "inf", "x", "1e300"]
JUNK = ["--bogus", "-x", "", "--out", "--times"]


def _opt(flag, values):
    return st.sampled_from(values).map(lambda v: [flag, v])


def _flag(flag):
    return st.just([flag])


def _options(*parts):
    """A random subset of option token groups, in random order."""
    return st.lists(st.one_of(*parts), max_size=4).map(lambda groups: sum(groups, []))


#: Usually no junk token, sometimes one (so that most examples reach the command itself).
_JUNK = st.sampled_from([[]] * 6 + [[j] for j in JUNK])


def _argv(verb, positional, options):
    return st.tuples(positional, options, _JUNK).map(lambda t: [*verb, *t[0], *t[1], *t[2]])


def _one(values, extra=()):
    """One positional, rarely none or two."""
    return st.sampled_from([[v] for v in values] * 3 + [[]] + [list(e) for e in extra])


ARGV = st.one_of(
    _argv(["run"], _one(SCENES, [("tiny.toml", "bad.toml")]),
          _options(_opt("--out", OUTS), _flag("--overwrite"))),
    _argv(["couple"], st.sampled_from([[c] for c in COUPLED]),
          _options(_opt("--out", OUTS), _flag("--overwrite"), _flag("--foam-fields"),
                   _flag("--run-case"), _opt("--threads", ["1", "0", "-1", "x"]),
                   _opt("--mesh", ["small", "bogus"]), _opt("--workers", ["0", "x"]),
                   _opt("--chunks", ["0", "3x"]), _opt("--resume", ["nosuch", "data"]))),
    _argv(["compare"], st.lists(st.sampled_from(RUNS[:2] * 3 + RUNS), min_size=1,
                                max_size=3),
          _options(_opt("--out", FIGURES), _flag("--overwrite"))),
    _argv(["render"], _one(["c_prev"] * 4 + RUNS + ["."]),
          _options(_opt("--fields", FIELDS), _opt("--times", TIMES), _flag("--overwrite"),
                   _flag("--times"), _flag("--fields"),
                   st.lists(st.sampled_from(TIMES), min_size=2, max_size=3).map(
                       lambda ts: ["--times", *ts]))),
    _argv(["case"], _one(["run", "run", "walk"]),
          _options(_opt("--dir", ["data", ".", "..", "notes.txt", "fluid-bed-case"]),
                   _opt("--mesh", ["small", "full", "bogus"]))),
    _argv(["bench"], _one(["cnmc", "accuracy", "bogus"]),
          _options(_opt("--out", [".", "..", "data", "b_prev", "notes.txt"]),
                   _flag("--quick"))),
    _argv(["plan"], _one(SCENES + COUPLED), st.just([])),
    _argv(["scenes"], st.just([]), st.just([])),
    st.lists(st.sampled_from(["run", "--out", "x", "render", "-h", "nosuch"]), max_size=3),
)


def _tree(root: Path) -> dict:
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file():
            st_ = p.stat()
            out[p.relative_to(root).as_posix()] = (st_.st_size, st_.st_mtime_ns,
                                                   hashlib.sha256(p.read_bytes()).hexdigest())
    return out


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """The sandbox every example starts from: user files, a run and a coupled output, an
    earlier bench output, a user's fluid-bed-case, and the scenes."""
    root = tmp_path_factory.mktemp("fuzz-base")
    (root / "data").mkdir()
    (root / "notes.txt").write_text("my notes\n")
    (root / "data" / "keep.csv").write_text("a,b\n1,2\n")
    (root / "tiny.toml").write_text(TINY_RUN)
    (root / "tiny-couple.toml").write_text(tiny_couple_text())
    (root / "bad.toml").write_text(BAD_SCENE)
    (root / "user.png").write_bytes(b"\x89PNG the user's picture")
    (root / "bench-out").mkdir()              # bench's default --out: a user directory
    (root / "bench-out" / "mine.txt").write_text("mine\n")
    (root / "fluid-bed-case").mkdir()
    (root / "fluid-bed-case" / "mine.txt").write_text("mine\n")
    cwd = os.getcwd()
    os.chdir(root)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["run", "tiny.toml", "--out", "r_prev"]) == 0
            assert main(["couple", "tiny-couple.toml", "--out", "c_prev"]) == 0
    finally:
        os.chdir(cwd)
    from pbe_cfd.io import output
    with output.atomic_directory(root / "b_prev") as d:
        (d / "cnmc.csv").write_text("x\n")
        (d / "accuracy.csv").write_text("x\n")
    (root / "r_prev" / "mine.txt").write_text("mine\n")
    (root / "c_prev" / "mine.txt").write_text("mine\n")
    (root / "c_prev" / "png" / "mine.png").write_bytes(b"mine")
    return root


def _allowed(argv, sandbox: Path) -> list[Path]:
    """Paths a command may write below (resolved): its --out, or a render's png/ + manifest."""
    from pbe_cfd.cli import build_parser
    try:
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            args = build_parser().parse_args(argv)
    except SystemExit:
        return []
    out = []
    if args.command in ("run", "couple", "compare") and getattr(args, "out", None):
        target = Path(args.out) if not getattr(args, "resume", None) else Path(args.resume)
        out.append((sandbox / target).resolve())
        if args.command == "compare" and target.name:    # the PSD overlay beside the figure
            out.append((sandbox / target.with_name(f"{target.stem}_psd{target.suffix}")).resolve())
    if args.command == "render" and args.dir:
        d = (sandbox / args.dir).resolve()
        out += [d / "png", d / "pbe-cfd-manifest.json"]
    return out


@pytest.mark.slow
@settings(max_examples=80, deadline=timedelta(seconds=90), derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.too_slow])
@given(argv=ARGV)
def test_cli_never_crashes_and_touches_nothing_outside_its_output(base, argv):
    with tempfile.TemporaryDirectory() as tmp:
        sandbox = Path(tmp) / "box" / "work"
        shutil.copytree(base, sandbox, symlinks=True)          # copy2: mtimes kept
        before = _tree(sandbox.parent.parent)
        err, cwd = io.StringIO(), os.getcwd()
        os.chdir(sandbox)
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    code = main(argv)
                except SystemExit as exc:                   # argparse: usage errors, -h
                    code = exc.code
        finally:
            os.chdir(cwd)
        assert code in (0, 1, 2), (argv, code, err.getvalue())
        assert "Traceback" not in err.getvalue(), (argv, err.getvalue())
        after = _tree(sandbox.parent.parent)
        allowed = _allowed(argv, sandbox)
        root = sandbox.parent.parent
        for rel in set(before) | set(after):
            if before.get(rel) == after.get(rel):
                continue
            path = (root / rel).resolve()
            assert any(path == a or a in path.parents for a in allowed), (argv, rel, code)
        for rel in USER_FILES:
            key = f"box/work/{rel}"
            assert after.get(key) == before[key], (argv, rel)
        leftovers = [p for p in sandbox.rglob(".*partial*")]
        assert not leftovers, (argv, leftovers)
