"""Ctrl-C while pictures are drawn: the terminal sends SIGINT to every process of the
foreground group, the drawing processes included, busy or idle; only the command's own process
may react."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import signal, sys, time
    # as started from a terminal: Ctrl-C raises KeyboardInterrupt (a test runner's worker may
    # hand its children SIGINT ignored, which Python then keeps)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from pbe_cfd.viz import figure_pool
    if sys.argv[1] == "started":
        assert figure_pool.start_processes()
    # (function, args, kwargs, cost): the costliest-first order hands the short task to a
    # drawing process, which is then idle, waiting for work, when Ctrl-C comes; the long
    # ones keep the other process (or this one) busy
    short, long = (time.sleep, (0.1,), {}, 2.0), (time.sleep, (3.0,), {}, 1.0)
    tasks = [short, long] if sys.argv[1] == "started" else [short, long, long]
    print("ready", flush=True)
    try:
        figure_pool.run_tasks(tasks)
    except KeyboardInterrupt:
        figure_pool.stop_processes()
        print("interrupted", flush=True)
        sys.exit(130)
    print("finished", flush=True)
""")


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: drawn in one process")
@pytest.mark.parametrize("mode", ["started", "forked per call"])
def test_ctrl_c_prints_no_traceback_of_the_drawing_processes(mode, tmp_path):
    env = {**os.environ, "PBE_CFD_DRAW_PROCESSES": ""}
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT, mode], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    assert proc.stdout.readline().strip() == "ready"
    import time
    time.sleep(0.6)          # a drawing process is idle, the long task(s) still run
    os.killpg(proc.pid, signal.SIGINT)              # what Ctrl-C in a terminal does
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in out, (out, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
