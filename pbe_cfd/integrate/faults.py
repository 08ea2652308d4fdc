"""Exceptions raised by the method's functions inside the integration kernel.

The kernel calls the method's functions through their C entry points (``kernel_types``). An
exception raised in one (a float division by zero, say) cannot cross that boundary: numba's
entry point hands it to ``sys.unraisablehook``, which prints it, and returns, and the kernel
goes on with whatever the function had written so far (a partial right-hand side). Left
alone, that is a silent wrong answer.

``watched(call, *args)`` runs ``call`` with the hook's reports of the calling thread caught
(the kernel's shares each run on a thread of their own, so reports are told apart by
thread): what was raised, and how often, comes back as a ``Faults``. The hook is installed
once per process and hands every report of a thread not watched to the hook it replaced.
``integrate_cells`` stops the cells the exceptions came from (``METHOD_RAISED``); other
kernels that call the method raise ``MethodRaised``.
"""
from __future__ import annotations

import sys
import threading
from dataclasses import dataclass

_LOCAL = threading.local()
_LOCK = threading.Lock()
_PREVIOUS: list = []     # the hook replaced, once installed
_LAST: list = [""]       # the text of the latest exception caught in this process


class MethodRaised(RuntimeError):
    """The method's functions raised inside a kernel where no cell could be stopped for it
    (the message names the exception)."""


@dataclass
class Faults:
    """Exceptions caught while a call ran: their count and the first one's text."""
    count: int = 0
    first: str = ""

    def add(self, text: str, count: int = 1):
        """``count`` more exceptions, the first of them described by ``text``."""
        if self.count == 0:
            self.first = text
        self.count += count


def describe(unraisable) -> str:
    """One line naming an exception handed to ``sys.unraisablehook``: its type and message."""
    kind = getattr(unraisable.exc_type, "__name__", str(unraisable.exc_type))
    value = unraisable.exc_value
    message = str(value) if value is not None else ""
    return f"{kind}: {message}" if message else kind


def _hook(unraisable):
    record = getattr(_LOCAL, "record", None)
    if record is None:
        _PREVIOUS[0](unraisable)
        return
    text = describe(unraisable)
    record.add(text)
    _LAST[0] = text


def _install():
    with _LOCK:
        if not _PREVIOUS:
            _PREVIOUS.append(sys.unraisablehook)
            sys.unraisablehook = _hook


def watched(call, *args) -> Faults:
    """Run ``call(*args)`` on this thread with the exceptions that the kernel's entry points
    hand to ``sys.unraisablehook`` on this thread caught, not printed; returns them."""
    _install()
    outer = getattr(_LOCAL, "record", None)
    record = Faults()
    _LOCAL.record = record
    try:
        call(*args)
    finally:
        _LOCAL.record = outer
    if outer is not None and record.count:
        outer.add(record.first, record.count)
    return record


def last_text() -> str:
    """The type and message of the latest exception caught in this process ("" if none)."""
    return _LAST[0]
