"""Draw a set of independent figures on two cores.

Drawing a matplotlib figure is Python-bound (about 0.1 s for a field section, 0.5 s for the
bed-moments panels), so the default `pbe-cfd couple` spends most of its wall time drawing.
``run_tasks`` draws a share of the figures in one forked child process while the parent draws
the rest: the child inherits the imported modules and the data already read, so it starts in
milliseconds. The child only draws (no numba, no OpenMP), which keeps the fork safe after the
solver's threads have run. Without fork, with one core, with few tasks, or with
``PBE_CFD_DRAW_PROCESSES=1``, everything is drawn here in order. A task the child could not
draw is drawn again here, so a failure in the child never loses a picture silently.
"""
from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable, Sequence

#: A task: (function, positional args, keyword args, relative cost).
Task = tuple[Callable[..., Any], tuple, dict, float]


def _run_all(tasks: Sequence[Task]) -> list:
    return [fn(*args, **kwargs) for fn, args, kwargs, _ in tasks]


def _use_child(tasks: Sequence[Task]) -> bool:
    if os.environ.get("PBE_CFD_DRAW_PROCESSES", "").strip() == "1":
        return False
    if len(os.sched_getaffinity(0)) < 2 or len(tasks) < 3:
        return False
    return "fork" in mp.get_all_start_methods()


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
    if not _use_child(tasks):
        return _run_all(tasks)
    here, child = split_by_cost(tasks)
    results: list = [None] * len(tasks)
    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("fork")) as pool:
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
