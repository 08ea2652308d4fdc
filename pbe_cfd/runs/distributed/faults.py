"""Deterministic fault injection for tests of the cluster path (``PBE_CFD_FAULT``)."""
from __future__ import annotations

import math
import os

#: Environment variable for deterministic fault injection: "raise:3,5" makes chunks 3 and 5
#: raise in their task, "exit:3" makes the worker running chunk 3 exit (a lost worker);
#: an optional "@T" ("raise:1@5") fires only for source steps starting at t >= T s.
FAULT_ENV = "PBE_CFD_FAULT"


# ---------------------------------------------------------------------------- faults
def parse_fault(text: str | None) -> dict | None:
    """Parse ``PBE_CFD_FAULT`` ("raise:3,5", "exit:2", "raise:1@5"): {"mode", "chunks",
    "after" [s]} or None."""
    if not text:
        return None
    mode, _, rest = text.partition(":")
    after = -math.inf
    if "@" in rest:
        rest, _, at = rest.partition("@")
        after = float(at)
    if mode not in ("raise", "exit"):
        raise ValueError(f"{FAULT_ENV}: mode must be 'raise' or 'exit', got {mode!r}")
    chunks = sorted({int(s) for s in rest.split(",") if s.strip()})
    return {"mode": mode, "chunks": chunks, "after": after}


def _maybe_fail(fault, chunk: int, t: float):
    if not fault or chunk not in fault["chunks"] or t < fault.get("after", -math.inf):
        return
    if fault["mode"] == "exit":
        os._exit(70)        # the worker process dies: a lost worker, as a crash would be
    raise RuntimeError(f"injected fault in chunk {chunk} ({FAULT_ENV})")
