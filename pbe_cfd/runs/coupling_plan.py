"""``plan`` lines of a two-way coupled scene: the segment schedule and the CFD cost estimate
(cells x flow time x segments)."""
from __future__ import annotations

import math

from .batch import output_times

#: cells of the template's meshes (openfoam_case/README.md)
TEMPLATE_CELLS = {"small": 900, "full": 3600}
#: CPU seconds per cell and per second of flow of twoPhaseEulerFoam on the bundled case at
#: its fixed deltaT 4e-4 s: 62 s for 1.5 s of flow on 900 cells (openfoam_case/README.md,
#: measured on this project's 2-core machine); an estimate for other cases and machines
CPU_PER_CELL_FLOW_SECOND = 62.0 / (900 * 1.5)


def schedule(scene) -> list[tuple[float, float]]:
    """(start, end) [s of process time] of the segments ``interval`` makes: each ends at the
    first output time at least ``interval`` after its start (one segment without one)."""
    c = scene.coupling
    times = output_times(scene)
    out, start = [], 0.0
    for t in times[1:]:
        if t >= times[-1] or (c.interval is not None and t - start >= c.interval * (1 - 1e-9)):
            out.append((start, float(t)))
            start = float(t)
    return out


def plan_lines(scene, n_cells: int | None = None) -> list[str]:
    """The plan's lines for ``[coupling]``: the schedule, the CFD runs and their cost."""
    c = scene.coupling
    segs = schedule(scene)
    bundled = scene.domain.case.startswith("bundled:")
    cells = n_cells or (TEMPLATE_CELLS[c.mesh] if bundled else None)
    shown = ", ".join(f"{a:g}-{b:g}" for a, b in segs[:8]) + (" ..." if len(segs) > 8 else "")
    lines = [f"  two-way coupling: {len(segs)} segments of process time [s]: {shown}"]
    where = ("output time" if c.check_interval is None
             else f"check (every {c.check_interval:g} s)")
    if c.d32_change is not None:
        lines.append(f"    a segment also ends at the first {where} where the bed's d32 "
                     f"moved {100 * c.d32_change:g}% from its CFD's diameter (more segments)")
    lines.append(f"    and at the first {where} where the granules' U_mf reaches "
                 f"{c.warn_fraction:g} x the inlet velocity (the defluidisation warning)")
    first = (f"the case template ({c.mesh} mesh) from its packed bed for {c.first_flow:g} s of "
             f"flow, averaged from {c.first_window_start:g} s" if bundled
             else f"the case {scene.domain.case} as it is, at time {scene.domain.time}")
    lines.append(f"    segment 0 runs on {first}")
    lines.append(f"    each later segment first re-runs twoPhaseEulerFoam in a copy pbe-cfd owns "
                 f"for {c.flow_time:g} s of flow from the previous state with d = bed d32, "
                 f"averaged over its last {c.flow_time - c.window_start:g} s")
    flow = (c.first_flow if bundled else 0.0) + c.flow_time * (len(segs) - 1)
    if cells is None:
        lines.append(f"    CFD cost: cells x {flow:g} s of flow ({len(segs) - 1} re-runs; "
                     "the case's cell count is read when it runs)")
    else:
        cpu = cells * flow * CPU_PER_CELL_FLOW_SECOND
        lines.append(f"    CFD cost: {cells} cells x {flow:g} s of flow = {cells * flow:.4g} "
                     f"cell-seconds, about {math.ceil(cpu):d} s of CPU (the bundled case's "
                     "62 s per 1.5 s on 900 cells)")
    return lines
