"""A lock file left by a run killed with SIGKILL (it still names the dead run's pid, but the
kernel dropped its flock): the next run into the same --out takes it over, says so in one
line naming the pid, and finishes (a lock a live run holds is refused:
test_output_faults.test_a_second_run_into_the_same_out_is_refused_while_the_first_writes)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

from pbe_cfd.io import output, output_guard
from pbe_cfd.cli import main
from test_data_safety import box  # noqa: F401 (fixture)
from test_output_faults import siblings

CLAIM_AND_WAIT = textwrap.dedent("""
    import sys, time
    from pbe_cfd.io import output
    output.prepare_directory(sys.argv[1], kind="run")
    print("claimed", flush=True)
    time.sleep(60)
""")


def _killed_holder(target) -> int:
    """Start a run that claims ``target``, kill it with SIGKILL once it holds the lock;
    returns its pid."""
    proc = subprocess.Popen([sys.executable, "-c", CLAIM_AND_WAIT, str(target)],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "claimed"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    return proc.pid


def _notes(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.strip().splitlines() if ln]


def test_a_lock_left_by_kill_9_is_reported_in_one_line_and_taken_over(box, capsys):
    target = box / "r"
    pid = _killed_holder(target)
    lock = output_guard.lock_path(target)
    assert lock.read_text().strip() == str(pid)          # the dead run's pid is still there
    capsys.readouterr()
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    err = _notes(capsys)
    stale = [ln for ln in err if "lock" in ln]
    assert len(stale) == 1, err
    assert stale[0].startswith("pbe-cfd: took over the lock .r.pbe-cfd-lock") and \
        f"pid {pid} no longer runs" in stale[0], stale
    assert output.read_manifest(target)["kind"] == "run"
    assert siblings(target) == []                          # the lock is gone with the run
    capsys.readouterr()
    assert main(["run", "tiny.toml", "--out", "r", "--overwrite"]) == 0
    assert not any("lock" in ln for ln in _notes(capsys))  # a clean lock: nothing to say


def test_a_stale_pid_of_another_live_process_is_not_taken_for_a_holder(box, capsys):
    """The pid in a stale lock may have been reused by an unrelated process (here this
    test's parent): the lock is free, so it is taken over, and the note says the pid is now
    another process's."""
    target = box / "r"
    output_guard.lock_path(target).write_text(f"{os.getppid()}\n")
    capsys.readouterr()
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    stale = [ln for ln in _notes(capsys) if "lock" in ln]
    assert len(stale) == 1 and f"pid {os.getppid()} is now another process" in stale[0], stale
    assert siblings(target) == []



KILLED_WHILE_WRITING = textwrap.dedent("""
    import os, sys
    from pbe_cfd.io import output
    with output.atomic_directory(sys.argv[1], overwrite=True, kind="run") as d:
        (d / "a.txt").write_text("half")
        print(os.getpid(), flush=True)
        os.kill(os.getpid(), 9)
""")


def test_a_run_killed_while_writing_leaves_a_lock_and_a_partial_said_in_one_line(box, capsys):
    target = box / "r"
    killed = subprocess.run([sys.executable, "-c", KILLED_WHILE_WRITING, str(target)],
                            capture_output=True, text=True)
    assert killed.returncode == -signal.SIGKILL
    pid = int(killed.stdout.strip())
    assert any(".partial-" in n for n in siblings(target))
    assert output_guard.lock_path(target).read_text().strip() == str(pid)
    capsys.readouterr()
    assert main(["run", "tiny.toml", "--out", "r"]) == 0
    said = [ln for ln in _notes(capsys) if "interrupted run" in ln or "lock" in ln]
    assert len(said) == 1, said
    assert "removed .r.partial-" in said[0] and f"pid {pid} no longer runs" in said[0], said
    assert siblings(target) == []
