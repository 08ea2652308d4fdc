"""Progress reporting of long runs: a tqdm bar on a terminal, silent otherwise.

A run reports progress by calling ``progress(fraction, text)`` (fraction of the run done [-],
a short status text); ``Progress`` is that callable for the command line.
"""
from __future__ import annotations

import sys


class Progress:
    """tqdm progress bar on a terminal; silent otherwise. ``Progress(label)(fraction, text)``
    moves the bar to ``fraction`` [-] (0..1) and shows ``text``; ``close()`` ends it."""

    def __init__(self, label):
        from tqdm import tqdm
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

    def close(self):
        """End the bar (leaves the terminal line as it is)."""
        self.bar.close()
