"""Progress reporting of long runs: a tqdm bar on a terminal, silent otherwise.

A run reports progress by calling ``progress(fraction, text)`` (fraction of the run done [-],
a short status text); ``Progress`` is that callable for the command line.
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
from pathlib import Path

#: Said while numba compiles the kernels a run needs (a first run; later runs load them).
COMPILING = "compiling kernels (first run only)"
#: Said only when the compile takes longer than this [s]: a first-run compile takes minutes,
#: loading cached kernels well under a second (2-3 s on a heavily loaded machine).
NOTICE_AFTER_S = 3.0
#: How long a first compile takes where this machine has none on record: the qmom kernel with
#: the auto integrator (all three schemes) took 31-37 s of CPU on an idle 2-core machine of
#: this project, the other methods' 32-39 s; slower machines and load stretch that by up to
#: 2-3x (docs/results/first-run.md), and the wall time is longer while other work shares
#: the cores.
FIRST_COMPILE_HINT = "roughly 0.5-1.5 min of CPU time"


def _compile_record() -> Path:
    """The file of the compile times measured on this machine ({kernel: seconds}), in
    pbe-cfd's cache ($PBE_CFD_CACHE, else ~/.cache/pbe_cfd)."""
    base = os.environ.get("PBE_CFD_CACHE") or Path.home() / ".cache" / "pbe_cfd"
    return Path(base) / "compile_seconds.json"


def last_compile_s(kernel: str) -> float | None:
    """Seconds the last compile of ``kernel`` took on this machine, or None."""
    try:
        value = json.loads(_compile_record().read_text()).get(kernel)
    except (OSError, ValueError, AttributeError):
        return None
    return float(value) if isinstance(value, (int, float)) and value > 0 else None


def record_compile_s(kernel: str, seconds: float):
    """Keep the compile time of ``kernel`` [s of CPU] for the next notice (silently skipped where
    the cache directory cannot be written)."""
    path = _compile_record()
    try:
        known = json.loads(path.read_text()) if path.exists() else {}
        if not isinstance(known, dict):
            known = {}
        known[kernel] = round(float(seconds), 1)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}")
        tmp.write_text(json.dumps(known, indent=1, sort_keys=True))
        os.replace(tmp, path)
    except (OSError, ValueError):
        return


def compile_text(kernel: str) -> str:
    """The notice of a compile: what compiles and roughly how long it takes."""
    last = last_compile_s(kernel)
    how_long = (f"about {last:.0f} s of CPU time (the last compile on this machine)"
                if last is not None else FIRST_COMPILE_HINT)
    return f"{COMPILING}: {kernel}, {how_long}"


class Progress:
    """tqdm progress bar on a terminal; silent otherwise. ``Progress(label)(fraction, text)``
    moves the bar to ``fraction`` [-] (0..1) and shows ``text``; ``close()`` ends it."""

    def __init__(self, label):
        from tqdm import tqdm
        self.label = label
        self.bar = tqdm(total=1000, desc=label, unit="‰", disable=None, file=sys.stderr,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining} {postfix}")
        self.last = 0

    def __call__(self, fraction, text=""):
        if self.bar.disable:
            return
        pos = int(round(1000 * min(max(fraction, 0.0), 1.0)))
        if pos > self.last:
            self.bar.update(pos - self.last)
            self.last = pos
        if text:
            self.bar.set_postfix_str(text)

    def notice(self, text):
        """Say ``text`` now: in the bar on a terminal, as a line on stderr otherwise."""
        if self.bar.disable:
            print(f"{self.label}: {text}", file=sys.stderr, flush=True)
        else:
            self.bar.set_postfix_str(text)
            self.bar.refresh()

    def close(self):
        """End the bar (leaves the terminal line as it is)."""
        self.bar.close()


@contextlib.contextmanager
def notice_if_slow(progress, text=COMPILING, after_s=None):
    """Run the ``with`` body; if it takes longer than ``after_s`` [s] (default
    NOTICE_AFTER_S), tell ``progress``
    ``text`` while it runs (``progress.notice(text)``, or ``progress(0, text)`` for a plain
    callable, nothing for None): a compile says so, a cache load stays silent."""
    if progress is None:
        yield
        return
    say = getattr(progress, "notice", None) or (lambda t: progress(0.0, t))
    timer = threading.Timer(NOTICE_AFTER_S if after_s is None else after_s, say, args=(text,))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
