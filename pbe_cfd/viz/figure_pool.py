"""Draw a set of independent figures on two cores.

Drawing a matplotlib figure is Python-bound (about 0.1 s for a field section, 0.5 s for the
bed-moments panels), so the default `pbe-cfd couple` spends most of its wall time drawing.
``run_tasks`` draws a share of the figures in one forked child process while the parent draws
the rest: the child inherits the imported modules and the data already read, so it starts in
milliseconds. The child only draws (no numba, no OpenMP), which keeps the fork safe after the
solver's threads have run. Without fork, with one core, with few tasks, or with
``PBE_CFD_DRAW_PROCESSES=1``, everything is drawn here in order. A task the child could not
draw is drawn again here, so a failure in the child never loses a picture silently.

A command that knows early that it will draw (``pbe-cfd couple``) calls ``start_processes``
first: two drawing processes are forked before the solver starts any thread and import
matplotlib and meshio while the run computes; ``run_tasks`` then hands every task to them.
The drawing processes ignore Ctrl-C (SIGINT): the command's own process stops and ends them,
so an interrupted run prints no traceback of theirs.
"""
from __future__ import annotations

import atexit
import multiprocessing as mp
import os
import signal
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Sequence

#: A task: (function, positional args, keyword args, relative cost).
Task = tuple[Callable[..., Any], tuple, dict, float]


def _run_all(tasks: Sequence[Task]) -> list:
    return [fn(*args, **kwargs) for fn, args, kwargs, _ in tasks]


def _two_processes_allowed() -> bool:
    if os.environ.get("PBE_CFD_DRAW_PROCESSES", "").strip() == "1":
        return False
    return len(os.sched_getaffinity(0)) >= 2 and "fork" in mp.get_all_start_methods()


def _use_child(tasks: Sequence[Task]) -> bool:
    return len(tasks) >= 3 and _two_processes_allowed()


_POOL: ProcessPoolExecutor | None = None


def _ignore_interrupt():
    """In a drawing process: Ctrl-C is for the command's own process, which ends this one."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _preload():
    _ignore_interrupt()
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401
    import meshio  # noqa: F401


def start_processes() -> bool:
    """Fork two drawing processes now (before any solver thread exists) that import the
    drawing libraries in the background; False where drawing stays in this process."""
    global _POOL
    if _POOL is not None or not _two_processes_allowed():
        return _POOL is not None
    _POOL = ProcessPoolExecutor(max_workers=2, mp_context=mp.get_context("fork"),
                                initializer=_preload)
    _POOL.submit(int)                    # forks both processes now
    atexit.register(stop_processes)
    return True


def drawing_elsewhere() -> bool:
    """True once ``start_processes`` has forked the drawing processes."""
    return _POOL is not None


def stop_processes() -> None:
    """Let the drawing processes end (nothing to do if none were started)."""
    global _POOL
    if _POOL is not None:
        pool, _POOL = _POOL, None
        pool.shutdown(wait=True, cancel_futures=True)


def _submit(pool, tasks: Sequence[Task]) -> dict:
    """Hand every task to the started processes, costliest first; index -> future of those
    they took."""
    order = sorted(range(len(tasks)), key=lambda k: -tasks[k][3])
    futures = {}
    for i in order:
        try:
            futures[i] = pool.submit(_run_all, [tasks[i]])
        except BrokenProcessPool:
            break
    return futures


def _collect(tasks: Sequence[Task], futures: dict) -> list:
    """The results of submitted tasks; a task the processes could not take or finish because
    one died is drawn here (and the broken pool is let go)."""
    results: list = [None] * len(tasks)
    broken = len(futures) < len(tasks)
    for i in range(len(tasks)):
        try:
            if i not in futures:
                raise BrokenProcessPool("not submitted")
            results[i] = futures[i].result()[0]
        except BrokenProcessPool:        # a drawing process died: draw the task here
            broken = True
            results[i] = _run_all([tasks[i]])[0]
    if broken:
        stop_processes()
    return results


def _run_in_pool(pool, tasks: Sequence[Task]) -> list:
    """Every task by the started processes (``_submit``, ``_collect``)."""
    return _collect(tasks, _submit(pool, tasks))


def start_tasks(tasks: Sequence[Task]):
    """Hand tasks to the started drawing processes now, to draw while this process goes on;
    ``finish_tasks`` returns their results. Without started processes nothing is drawn
    before ``finish_tasks``, which then runs them as ``run_tasks`` does."""
    tasks = list(tasks)
    return tasks, (_submit(_POOL, tasks) if _POOL is not None else None)


def finish_tasks(started) -> list:
    """The results, in the order given, of the tasks ``start_tasks`` handed out."""
    tasks, futures = started
    if futures is None:
        return run_tasks(tasks)
    return _collect(tasks, futures)


def split_by_cost(tasks: Sequence[Task]) -> tuple[list[int], list[int]]:
    """Indices of the tasks for here and for the child: the costliest first, each to the side
    with less work so far (the parent also forks and collects, so it starts one unit behind)."""
    here, child = [], []
    load_here, load_child = 1.0, 0.0
    for i in sorted(range(len(tasks)), key=lambda k: -tasks[k][3]):
        if load_child < load_here:
            child.append(i)
            load_child += tasks[i][3]
        else:
            here.append(i)
            load_here += tasks[i][3]
    return sorted(here), sorted(child)


def run_tasks(tasks: Sequence[Task]) -> list:
    """Run every task and return their results in the order given. Functions and arguments
    must be picklable (module-level functions; arrays, paths, dicts)."""
    tasks = list(tasks)
    if _POOL is not None:
        return _run_in_pool(_POOL, tasks)
    if not _use_child(tasks):
        return _run_all(tasks)
    here, child = split_by_cost(tasks)
    results: list = [None] * len(tasks)
    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("fork"),
                             initializer=_ignore_interrupt) as pool:
        future = pool.submit(_run_all, [tasks[i] for i in child])
        for i, value in zip(here, _run_all([tasks[i] for i in here])):
            results[i] = value
        try:
            drawn = future.result()
        except Exception:  # noqa: BLE001 - the child died or failed: draw its share here
            drawn = _run_all([tasks[i] for i in child])
    for i, value in zip(child, drawn):
        results[i] = value
    return results
