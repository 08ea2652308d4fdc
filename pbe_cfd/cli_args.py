"""Argument types and checks shared by the ``pbe-cfd`` subcommands (``cli``, ``cli_bench``):
positive whole numbers, the ``--overwrite`` flag, the ``--threads`` refusal, the one-line
error of an exit status."""
from __future__ import annotations

import argparse
import sys


def positive_int(text):
    """argparse type: a whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def add_overwrite(p, what="the files an earlier pbe-cfd run wrote there"):
    """The ``--overwrite`` flag of a subcommand that writes ``what``."""
    p.add_argument("--overwrite", action="store_true",
                   help=f"replace {what} (files pbe-cfd did not write are never replaced)")


def thread_limit() -> int:
    """Most numba threads a run may ask for: the cores numba starts its pool with
    (NUMBA_NUM_THREADS, by default the machine's cores)."""
    import numba
    return int(numba.config.NUMBA_NUM_THREADS)


def threads_refusal(threads) -> str | None:
    """The refusal of ``--threads`` values outside 1 .. the cores, or None."""
    values = threads if isinstance(threads, tuple) else (threads,)
    limit = thread_limit()
    for value in values:
        if value is not None and not 1 <= value <= limit:
            return (f"--threads: expected a whole number of threads from 1 to {limit} (the "
                    f"cores numba runs on), got {value}")
    return None


def fail(message, code=2):
    """Print ``pbe-cfd: error: message`` to stderr; returns the exit status ``code``."""
    print(f"pbe-cfd: error: {message}", file=sys.stderr)
    return code
