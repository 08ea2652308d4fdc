"""Resource limits of a run, checked when a scene is read (so ``plan`` refuses what a run
would): the number of output times, a method's table memory against the machine, and
tolerances that keep the error control. Each check returns the refusal text (what was asked,
the limit, what is expected) or None; ``scene`` names the file and key.
"""
from __future__ import annotations

import math
import os

#: most output times a scene may ask for: a well-mixed run keeps one state and writes one
#: moments.csv row (~30 numbers, ~0.5 kB) per output time, 1e5 times ~ 50 MB; a coupled run
#: writes one .vtu of every cell per output time (the bundled 800-cell bed: ~40 kB each) and
#: keeps every cell's state per time, 1e4 times ~ 0.4 GB of VTK for that small bed
MAX_OUTPUT_TIMES = {"well-mixed": 100_000, "openfoam": 10_000}
#: share of the machine's physical memory one method's tables may take (the run, its states,
#: the OpenFOAM fields and the other processes need the rest)
MEMORY_SHARE = 0.5
#: accepted [method] rtol [-]: above 0.1 the error control no longer resolves a rate; below
#: 1e-13 (~450 machine epsilons) the error estimate of a step, a difference of scaled moments
#: of order 1 over ~10 operations, is round-off
RTOL_RANGE = (1.0e-13, 0.1)


def scene_refusals(scene, entry) -> list:
    """[(key, refusal)] of a validated scene's resource limits: output times, the method's
    table memory (``entry``: its ``methods.registry`` entry), tolerances."""
    out = [("scene.output_interval", output_count_refusal(scene.end_time, scene.output_interval,
                                                          scene.domain.type)),
           (f"method.{(entry.table_keys or ('name',))[0]}",
            table_memory_refusal(scene.method.options, entry.table_bytes,
                                 entry.table_keys))]
    out += [(f"method.{key}", text)
            for key, text in tolerance_refusals(scene.method.rtol, scene.method.atol)]
    return [(key, text) for key, text in out if text]


def output_count(end_time: float, output_interval: float) -> int:
    """Number of output times [-] of a run: 0, every output_interval [s], and end_time [s]
    (``batch.output_times`` lists them), counted without listing them."""
    n = int(math.floor(end_time / output_interval + 1e-9))
    return n + 1 + (1 if end_time - n * output_interval > 1e-9 * end_time else 0)


def output_count_refusal(end_time: float, output_interval: float, domain_type: str):
    """Refusal of more than MAX_OUTPUT_TIMES[domain_type] output times (times in s)."""
    limit = MAX_OUTPUT_TIMES[domain_type]
    ratio = end_time / output_interval
    if ratio > limit or output_count(end_time, output_interval) > limit:
        return (f"end_time / output_interval = {ratio:.4g} output times, more than the limit "
                f"of {limit} for a {domain_type} domain: expected output_interval >= "
                f"{end_time / (limit - 1):.4g} s")
    return None


def machine_memory() -> int:
    """Physical memory of the machine [bytes] (0 where the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 0


def table_memory_refusal(options, table_bytes, keys):
    """Refusal of a method whose tables (``table_bytes(options)`` [bytes] of the scene's
    ``method.options``, set by the ``[method]`` ``keys``) need more than MEMORY_SHARE of the
    machine's memory."""
    need = table_bytes(options)
    total = machine_memory()
    if need and total and need > MEMORY_SHARE * total:
        asked = " x ".join(f"{k} = {getattr(options, k)}" for k in keys)
        return (f"{asked} needs {need / 2**30:.3g} GiB for the method's tables, more than "
                f"{MEMORY_SHARE:.0%} of this machine's {total / 2**30:.3g} GiB: expected a "
                f"smaller grid")
    return None


def tolerance_refusals(rtol: float, atol: float):
    """[(key, refusal)] of tolerances [-] on the scaled state that lose the error control."""
    out = []
    if not RTOL_RANGE[0] <= rtol <= RTOL_RANGE[1]:
        out.append(("rtol", f"expected >= {RTOL_RANGE[0]:g} (a step's error estimate is a "
                            f"difference of scaled moments of order 1; round-off below) and "
                            f"<= {RTOL_RANGE[1]:g}, got {rtol:g}"))
    if atol > rtol:
        out.append(("atol", f"expected at most rtol = {rtol:g}: the integrator's state is "
                            "scaled so that the initial moments are of order 1, and an absolute "
                            "tolerance above rtol switches off the error control of moments at "
                            f"that scale; got {atol:g}"))
    return out
