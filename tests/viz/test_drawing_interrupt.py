"""Ctrl-C while pictures are drawn: the terminal sends SIGINT to every process of the
foreground group, the drawing processes included; only the command's own process may react."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import sys, time
    from pbe_cfd.viz import figure_pool
    if sys.argv[1] == "started":
        assert figure_pool.start_processes()
    print("ready", flush=True)
    try:
        figure_pool.run_tasks([(time.sleep, (1.5,), {}, 1.0)] * 4)
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
    time.sleep(0.6)                   # the tasks are running in the drawing processes
    os.killpg(proc.pid, signal.SIGINT)              # what Ctrl-C in a terminal does
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in out, (out, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
