"""Faults at the output directory: nothing lost, never a mix, one line and the right exit code.

An output is never an input of the same run nor another verb's directory; --overwrite removes
only paths inside the output, and refuses an edited file (size, time or content) before the
computation; a crash at any rename of the final move leaves the old output or the new one; the
leftovers of killed runs are cleaned by the next run; two runs into one --out: one wins, the
other is refused; disk full, a read-only place and a vanished directory give one line with
the earlier output intact; SIGINT and SIGTERM end quietly and say what was kept.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pbe_cfd.io import output
from pbe_cfd.cli import main
from test_data_safety import (TINY_RUN, box, fake_openfoam, refused,  # noqa: F401 (fixtures)
                              tiny_couple_text, tree)


def siblings(target: Path) -> list[str]:
    """The hidden names pbe-cfd may leave beside ``target`` (partial, old, lock)."""
    return sorted(p.name for p in target.parent.iterdir() if p.name.startswith(f".{target.name}."))


def content(root: Path) -> dict:
    """relative path -> bytes of every file below ``root``."""
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file()}


ROOT = Path(__file__).resolve().parents[2]


def cli(argv, **kw):
    """Start ``pbe-cfd ARGV`` (the console entry point, signal handlers included) with this
    checkout's code."""
    code = "import sys; from pbe_cfd.cli import run; run()"
    env = dict(kw.pop("env", os.environ))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env, **kw)


# ---------------------------------------------------------------------------- D1: kinds, inputs
def test_couple_never_replaces_a_case_run_directory_nor_the_case_it_reads(
        box, fake_openfoam, capsys):
    assert main(["case", "run", "--dir", "bed"]) == 0
    capsys.readouterr()
    (box / "s.toml").write_text(tiny_couple_text(str(box / "bed")))
    before = tree(box)
    # the case the scene reads
    refused(["couple", "s.toml", "--out", "bed", "--overwrite"], capsys,
            "is the OpenFOAM case", "input")
    refused(["couple", "s.toml", "--out", "bed/pbe", "--overwrite"], capsys, "lies inside")
    # a case run directory, even when the scene reads another case
    refused(["couple", "tiny-couple.toml", "--out", "bed", "--overwrite"], capsys,
            "`pbe-cfd case run`", "not of `pbe-cfd couple`")
    refused(["run", "tiny.toml", "--out", "bed", "--overwrite"], capsys, "`pbe-cfd case run`")
    assert tree(box) == before


@pytest.mark.slow
def test_case_run_never_replaces_a_run_output_and_no_output_holds_its_scene(
        box, fake_openfoam, capsys):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    before = tree(box)
    refused(["case", "run", "--dir", "r", "--overwrite"], capsys, "`pbe-cfd run`",
            "not of `pbe-cfd case run`")
    (box / "r" / "again.toml").write_text(TINY_RUN)
    refused(["run", "r/again.toml", "--out", "r", "--overwrite"], capsys, "holds the scene",
            "input")
    (box / "r" / "again.toml").unlink()
    assert tree(box) == before


def test_a_snapshot_and_its_flux_are_inputs(tmp_path, monkeypatch, capsys):
    from pbe_cfd.io import openfoam as of
    monkeypatch.chdir(tmp_path)
    snap = tmp_path / "snap"
    snap.mkdir()
    for src in (of.default_snapshot_path(), of.default_flux_path()):
        (snap / src.name).write_bytes(src.read_bytes())
    (tmp_path / "s.toml").write_text(tiny_couple_text(str(snap / of.default_snapshot_path().name)))
    before = tree(tmp_path)
    refused(["couple", "s.toml", "--out", "snap"], capsys, "holds the snapshot")
    refused(["couple", "s.toml", "--out", str(snap / of.default_snapshot_path().name)], capsys,
            "is the snapshot")
    assert tree(tmp_path) == before


# ---------------------------------------------------------------------------- D4, U4
def _earlier_output(target: Path) -> None:
    with output.atomic_directory(target, kind="run") as d:
        (d / "a.txt").write_text("old a\n")
        (d / "b.txt").write_text("old b\n")
        (d / "sub").mkdir()
        (d / "sub" / "c.txt").write_text("old c\n")


@pytest.mark.parametrize("entry", ["../victim.txt", "sub/../../victim.txt", "ABSOLUTE",
                                   "esc/victim.txt"])
def test_overwrite_never_removes_a_path_outside_the_output(tmp_path, monkeypatch, entry):
    monkeypatch.chdir(tmp_path)
    target = tmp_path / "o"
    _earlier_output(target)
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / "victim.txt"
    victim.write_text("the user's\n")
    if entry == "ABSOLUTE":
        entry = str(victim)
    elif entry.startswith("esc/"):
        (target / "esc").symlink_to(outside, target_is_directory=True)
    else:
        (tmp_path / "victim.txt").write_text("the user's\n")
        victim = tmp_path / "victim.txt"
    data = json.loads((target / output.MANIFEST).read_text())
    data["files"][entry] = output._stat_entry(victim)     # size, time and hash all match
    (target / output.MANIFEST).write_text(json.dumps(data))
    before = tree(tmp_path)
    for attempt in (lambda: output.atomic_directory(target, overwrite=True, kind="run"),
                    lambda: output.atomic_directory(target, overwrite=True, kind="run",
                                                    add=True)):
        with pytest.raises(output.OutputRefused, match="pbe-cfd removes only files inside"):
            with attempt() as d:
                (d / "a.txt").write_text("new a\n")
    with pytest.raises(output.OutputRefused, match="removes only files inside"):
        output.remove_written(target)
    assert victim.read_text() == "the user's\n"
    assert tree(tmp_path) == before


@pytest.mark.slow
@pytest.mark.parametrize("edit", ["same size and time", "same size, new time"])
def test_an_edited_file_is_refused_before_the_computation(box, capsys, monkeypatch, edit):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    path = box / "r" / "summary.json"
    st = path.stat()
    text = path.read_text()
    path.write_text(text.replace("tiny", "TINY"))            # a user edit of equal length
    if edit == "same size and time":
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_size == st.st_size
    before = tree(box)

    def computation(*a, **kw):
        raise AssertionError("the run started before the refusal")
    monkeypatch.setattr("pbe_cfd.runs.simulate.run_well_mixed", computation)
    refused(["run", "tiny.toml", "--out", "r", "--overwrite"], capsys, "summary.json",
            "changed since")
    assert tree(box) == before and siblings(box / "r") == []


# ---------------------------------------------------------------------------- D3: crash at step k
CRASH_SCRIPT = textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from pbe_cfd.io import output
    try:
        from pbe_cfd.io import output_guard
    except ImportError:                   # an output module without the exchange
        output_guard = None
    target, k, fallback = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3] == "fallback"
    calls = [0]
    def dying(fn):
        def wrapped(*a, **kw):
            calls[0] += 1
            if calls[0] == k:
                os._exit(77)              # as kill -9: no cleanup of any kind
            return fn(*a, **kw)
        return wrapped
    os.rename, os.replace = dying(os.rename), dying(os.replace)
    if output_guard is None:
        pass
    elif fallback:                        # a file system without an atomic exchange
        def exchange(a, b):
            raise OSError(22, "Invalid argument")
        output_guard._renameat2_exchange = exchange
    else:
        output_guard._renameat2_exchange = dying(output_guard._renameat2_exchange)
    with output.atomic_directory(target, overwrite=True, kind="run") as d:
        (d / "a.txt").write_text("new a\\n")
        (d / "d.txt").write_text("new d\\n")
    print(calls[0])
""")


def _wholly_new(target: Path, mine: bytes) -> bool:
    files = content(target)
    manifest = output.read_manifest(target)
    return (set(files) == {"a.txt", "d.txt", "mine.txt", output.MANIFEST}
            and files["a.txt"] == b"new a\n" and files["d.txt"] == b"new d\n"
            and files["mine.txt"] == mine and set(manifest["files"]) == {"a.txt", "d.txt"}
            and all(output._unchanged(target / r, e) for r, e in manifest["files"].items()))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exchange", "fallback"])
def test_a_crash_at_any_rename_of_the_final_move_leaves_old_or_new(tmp_path, capsys, mode):
    target = tmp_path / "o"
    outcomes = []
    for k in range(1, 10):
        if target.exists():
            shutil.rmtree(target)                # this test's own files
        for name in siblings(target):
            pytest.fail(f"leftover {name} before step {k}")
        _earlier_output(target)
        (target / "mine.txt").write_text("the user's file\n")
        old = content(target)
        proc = subprocess.run([sys.executable, "-c", CRASH_SCRIPT, str(target), str(k), mode],
                              capture_output=True, text=True)
        assert proc.returncode in (0, 77), proc.stderr
        if target.exists():
            state = "old" if content(target) == old else (
                "new" if _wholly_new(target, old["mine.txt"]) else "MIXED")
        else:        # between the two renames of the fallback: DIR.old-* holds it whole
            olds = [tmp_path / n for n in siblings(target) if ".old-" in n]
            state = "old, to restore" if len(olds) == 1 and content(olds[0]) == old else "LOST"
        outcomes.append(state)
        assert state in ("old", "new", "old, to restore"), (k, state, siblings(target))
        # the next --overwrite cleans up (one line each) and works
        capsys.readouterr()
        with output.atomic_directory(target, overwrite=True, kind="run") as d:
            (d / "a.txt").write_text("third\n")
        err = capsys.readouterr().err
        assert content(target) == {"a.txt": b"third\n", "mine.txt": old["mine.txt"],
                                   output.MANIFEST: (target / output.MANIFEST).read_bytes()}
        assert siblings(target) == [], siblings(target)
        if state == "old, to restore":
            assert "restored" in err
        if proc.returncode == 0:
            break
    # the steps: manifest, then one exchange (or two renames); completed on the last k
    assert outcomes[-1] == "new" and len(outcomes) == (3 if mode == "exchange" else 4), outcomes
    assert "old" in outcomes


def test_leftovers_of_a_killed_run_are_reported_and_cleaned(tmp_path, capsys):
    target = tmp_path / "o"
    _earlier_output(target)
    killed = textwrap.dedent("""
        import os, sys
        from pbe_cfd.io import output
        with output.atomic_directory(sys.argv[1], overwrite=True, kind="run") as d:
            (d / "a.txt").write_text("half")
            os._exit(9)
    """)
    first = subprocess.run([sys.executable, "-c", killed, str(target)], capture_output=True,
                           text=True)
    assert first.returncode == 9 and first.stderr == ""
    # a second killed run cleans the first one's leftover, and says so in one line
    second = subprocess.run([sys.executable, "-c", killed, str(target)], capture_output=True,
                            text=True)
    assert second.returncode == 9
    assert len(second.stderr.strip().splitlines()) == 1, second.stderr
    assert "left by an interrupted run" in second.stderr
    lookalike = tmp_path / ".o.partial-mine"               # not made by pbe-cfd: no marker
    lookalike.mkdir()
    (lookalike / "x").write_text("x")
    assert len([n for n in siblings(target) if ".partial-" in n]) == 2
    capsys.readouterr()
    with output.atomic_directory(target, overwrite=True, kind="run") as d:
        (d / "a.txt").write_text("new")
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "left by an interrupted run" in err[0], err
    assert siblings(target) == [".o.partial-mine"]
    assert (lookalike / "x").read_text() == "x"


# ---------------------------------------------------------------------------- T6: two runs
HOLD_SCRIPT = textwrap.dedent("""
    import sys, time
    from pbe_cfd.io import output
    output.prepare_directory(sys.argv[1], kind="run")
    print("claimed", flush=True)
    time.sleep(60)
""")


@pytest.mark.slow
def test_a_second_run_into_the_same_out_is_refused_while_the_first_writes(box, capsys):
    holder = subprocess.Popen([sys.executable, "-c", HOLD_SCRIPT, str(box / "r")],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "claimed"
        refused(["run", "tiny.toml", "--out", "r"], capsys, "another pbe-cfd run",
                f"pid {holder.pid}")
        assert not (box / "r").exists()
    finally:
        holder.kill()
        holder.wait()
    # the kernel dropped the lock with the process (as after kill -9): the next run proceeds
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    assert siblings(box / "r") == []


@pytest.mark.slow
def test_two_concurrent_runs_into_one_new_out_one_wins(box):
    procs = [cli(["run", "tiny.toml", "--out", "r"], cwd=box) for _ in range(2)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    err = next(text for code, text in results if code == 2)
    assert "Traceback" not in err and "Errno" not in err
    assert err.strip().splitlines()[-1].startswith("pbe-cfd: error: ")
    assert set(output.read_manifest(box / "r")["files"]) == {
        "moments.csv", "summary.json", "moments.png", "psd.csv", "psd.png", "columns.json"}
    assert siblings(box / "r") == []


# ---------------------------------------------------------------------------- T1, T2: OS errors
def _one_line(capsys, code, argv, *phrases):
    capsys.readouterr()
    assert main(argv) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pbe-cfd: error: "), err
    for phrase in phrases:
        assert phrase in err[0], err
    return err[0]


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["disk full", "vanished directory"])
def test_an_os_error_while_writing_keeps_the_earlier_output(box, capsys, monkeypatch, fault):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    before = tree(box)
    real = output.write_json

    def failing(path, data):
        if fault == "vanished directory":
            import shutil
            shutil.rmtree(Path(path).parent)
            return real(path, data)
        with open(path, "w") as fh:          # half a file, then the disk is full
            fh.write("{")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    monkeypatch.setattr(output, "write_json", failing)
    phrase = "No space left" if fault == "disk full" else "No such file"
    _one_line(capsys, 1, ["run", "tiny.toml", "--out", "r", "--overwrite"], phrase,
              "earlier output there is intact")
    assert tree(box) == before and siblings(box / "r") == []
    _one_line(capsys, 1, ["run", "tiny.toml", "--out", "new"], phrase, "nothing was left")
    assert not (box / "new").exists() and siblings(box / "new") == []


@pytest.fixture
def small_tmpfs(tmp_path):
    """A tmpfs mounted at tmp_path/mnt (root only; skipped where mounting is not allowed)."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()

    def mount(size_bytes):
        if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_bytes}", "tmpfs",
                           str(mnt)], capture_output=True).returncode != 0:
            pytest.skip("cannot mount a tmpfs here")
        return mnt
    yield mount
    subprocess.run(["umount", str(mnt)], capture_output=True)


@pytest.mark.slow
def test_a_full_disk_keeps_the_earlier_output(box, capsys, small_tmpfs):
    assert main(["run", "tiny.toml", "--out", "probe"]) == 0
    pages = sum(-(-p.stat().st_size // 4096) for p in (box / "probe").iterdir())
    # room for one output and a half: the earlier one fits, a second copy beside it does not
    mnt = small_tmpfs((pages * 3 // 2 + 1) * 4096)
    assert main(["run", "tiny.toml", "--out", str(mnt / "r")]) == 0
    before = tree(mnt)
    _one_line(capsys, 1, ["run", "tiny.toml", "--out", str(mnt / "r"), "--overwrite"],
              "No space left on device", "intact")
    assert tree(mnt) == before and siblings(mnt / "r") == []


def test_a_read_only_place_is_refused_before_the_computation(box, capsys, small_tmpfs):
    mnt = small_tmpfs(1 << 20)
    assert main(["run", "tiny.toml", "--out", str(mnt / "r")]) == 0
    subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
    before = tree(mnt)
    _one_line(capsys, 2, ["run", "tiny.toml", "--out", str(mnt / "r"), "--overwrite"],
              "Read-only file system", "nothing was changed")
    _one_line(capsys, 2, ["run", "tiny.toml", "--out", str(mnt / "new")],
              "Read-only file system")
    assert tree(mnt) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores permissions (the read-only mount "
                    "above holds the promise there)")
def test_a_directory_without_write_permission_is_refused_before_the_computation(box, capsys):
    (box / "locked").mkdir()
    (box / "locked").chmod(0o555)
    try:
        _one_line(capsys, 2, ["run", "tiny.toml", "--out", "locked/r"], "Permission denied")
    finally:
        (box / "locked").chmod(0o755)
    assert list((box / "locked").iterdir()) == []


# ---------------------------------------------------------------------------- U5: signals
SLOW_RUN = textwrap.dedent("""
    import sys, time
    import pbe_cfd.io.output as output
    import pbe_cfd.runs.simulate as sim
    def slow(*a, **kw):                   # a long computation
        print("busy", file=sys.stderr, flush=True)
        time.sleep(60)
    def slow_json(path, data):            # a long write: half a file in the partial directory
        open(path, "w").write("{")
        print("busy", file=sys.stderr, flush=True)
        time.sleep(60)
    if sys.argv.pop(1) == "computing":
        sim.run_well_mixed = slow
    else:
        output.write_json = slow_json
    from pbe_cfd.cli import run
    run()
""")


@pytest.mark.parametrize("phase", ["computing", "writing"])
@pytest.mark.parametrize("sig,code,name", [(signal.SIGINT, 130, "Ctrl-C"),
                                           (signal.SIGTERM, 143, "SIGTERM")])
@pytest.mark.slow
def test_a_signal_mid_run_ends_quietly_and_says_what_was_kept(box, sig, code, name, phase):
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    before = tree(box)
    for out, kept in (("r", "not changed (the earlier output there is kept)"),
                      ("new", "not written")):
        proc = subprocess.Popen([sys.executable, "-c", SLOW_RUN, phase, "run", "tiny.toml",
                                 "--out", out, "--overwrite"], cwd=box, stderr=subprocess.PIPE,
                                text=True)
        assert proc.stderr.readline().strip() == "busy"
        proc.send_signal(sig)
        err = proc.stderr.read()
        assert proc.wait(timeout=60) == code
        assert err.strip().splitlines() == [f"pbe-cfd: error: interrupted ({name}); "
                                            f"{box / out} {kept}"], err
        assert tree(box) == before and siblings(box / out) == []


def test_ctrl_c_during_case_run_removes_the_half_run_case_and_its_solver(
        box, fake_openfoam, tmp_path, capsys):
    assert main(["case", "run", "--dir", "k"]) == 0           # an earlier case, and a user file
    (box / "k" / "mine.txt").write_text("mine\n")
    allrun = fake_openfoam / "Allrun"
    allrun.write_text(allrun.read_text().replace(
        'echo "Allrun: done"', 'echo "Allrun: running twoPhaseEulerFoam"\n'
        'sleep 60 & echo $! > "$PBE_TEST_PIDFILE"; wait\necho "Allrun: done"'))
    pidfile = tmp_path / "solver.pid"
    proc = cli(["case", "run", "--dir", "k", "--overwrite"], cwd=box,
               env={**os.environ, "PBE_TEST_PIDFILE": str(pidfile)})
    while "running twoPhaseEulerFoam" not in proc.stderr.readline():
        assert proc.poll() is None
    while not pidfile.is_file() or not pidfile.read_text().strip():
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 130
    last = err.strip().splitlines()[-1]
    assert last.startswith("pbe-cfd: error: interrupted (Ctrl-C); --dir ") and \
        "removed the" in last and "your files there are kept" in last, err
    assert "Traceback" not in err
    assert sorted(p.name for p in (box / "k").iterdir()) == ["mine.txt"]
    assert siblings(box / "k") == []
    solver = int(pidfile.read_text())
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:                                   # gone, or a zombie nobody reaped yet
            if Path(f"/proc/{solver}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                break
        except (FileNotFoundError, ProcessLookupError):
            break
        time.sleep(0.1)
    else:
        pytest.fail("the solver of the interrupted case still runs")


def test_kill_9_of_case_run_leaves_no_solver_running(box, fake_openfoam, tmp_path):
    """SIGKILL of ``pbe-cfd case run`` cannot be caught; the bundled Allrun and the tool it runs
    must die with it (parent-death signals), not write on into the case."""
    from importlib import resources
    template = tmp_path / "bundled"
    shutil.copytree(resources.files("pbe_cfd") / "data" / "openfoam_case", template)
    pidfile = tmp_path / "solver.pid"
    solver = Path(os.environ["PATH"].split(os.pathsep)[0]) / "twoPhaseEulerFoam"
    solver.write_text('#!/bin/sh\necho $$ > "$PBE_TEST_PIDFILE"\nexec sleep 60\n')
    proc = cli(["case", "run", "--dir", "k"], cwd=box,
               env={**os.environ, "PBE_CFD_CASE": str(template),
                    "PBE_TEST_PIDFILE": str(pidfile)})
    deadline = time.monotonic() + 60
    while not pidfile.is_file() or not pidfile.read_text().strip():
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    pid = int(pidfile.read_text())
    proc.kill()
    proc.wait(timeout=30)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:                                   # gone, or a zombie nobody reaped yet
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                break
        except (FileNotFoundError, ProcessLookupError):
            break
        time.sleep(0.1)
    else:
        os.kill(pid, signal.SIGKILL)
        pytest.fail("the solver of the killed case run still runs")
