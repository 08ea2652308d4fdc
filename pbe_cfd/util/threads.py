"""Thread pools kept for the life of the process, for numba kernels and special functions
that release the GIL; work split into shares run on them; the run's thread count.

A pool is made on first use for a given number of workers and purpose and then reused, so a
call costs a hand-over to running threads (about 0.1 ms), not a thread start. A process forked
after a pool ran inherits the pool without its threads: the pools are dropped in the child,
which makes its own.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor, wait

_POOLS: dict = {}
os.register_at_fork(after_in_child=_POOLS.clear)


def run_threads() -> int:
    """The run's thread count (numba's, set by ``--threads`` or ``numba.set_num_threads``;
    at least 1)."""
    import numba
    return max(1, int(numba.get_num_threads()))


def thread_pool(workers: int, purpose: str) -> ThreadPoolExecutor:
    """A pool of ``workers`` threads named after ``purpose``, kept for the process."""
    key = (int(workers), purpose)
    if key not in _POOLS:
        _POOLS[key] = ThreadPoolExecutor(max_workers=key[0],
                                         thread_name_prefix=f"pbe-cfd-{purpose}")
    return _POOLS[key]


def run_shares(call, shares, purpose: str) -> list:
    """``call(share)`` for every item of ``shares``: the first on the calling thread, the
    others on a pool of len(shares) - 1 threads (``thread_pool(..., purpose)``). Returns the
    results in the order of ``shares``, once every share has finished; an exception of any
    share is raised after all of them have (no share still runs when this returns)."""
    shares = list(shares)
    if len(shares) == 1:
        return [call(shares[0])]
    others = [thread_pool(len(shares) - 1, purpose).submit(call, s) for s in shares[1:]]
    try:
        first = call(shares[0])
    finally:
        wait(others)
    return [first] + [f.result() for f in others]
