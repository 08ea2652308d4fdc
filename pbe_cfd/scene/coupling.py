"""The ``[coupling]`` table of a scene: two-way coupling of the population balance and the flow
(``pbe_cfd.runs.coupling``). Absent, the CFD fields are computed once and drive the whole
granulation (one-way coupling).

Keys (SI):
  interval        s of process time between CFD re-runs
  d32_change      relative change of the bed's d32 since the last CFD run that triggers one
                  (at least one of interval, d32_change)
  flow_time       s of flow each CFD re-run computes, from the previous segment's flow state
  average_from    s after a re-run's start where its fieldAverage window begins
                  (default flow_time / 3: the flow's start-up after the diameter changed)
  first_flow_time s of flow of the first CFD run when the scene's case is the bundled snapshot
                  (the template then runs from its packed bed; default flow_time)
  first_average_from  s where that first run's fieldAverage window begins (default
                  average_from)
  mesh            "small" or "full": the template's mesh for that first run
  warn_fraction   warn of defluidisation when the granules' minimum fluidisation velocity
                  reaches this fraction of the inlet's superficial velocity (default 0.8)
  inlet_velocity  m/s, the superficial velocity that warning compares with (default: the
                  case's gas inlet patch)
  check_interval  s of process time between the checks of d32_change and of the warning's
                  threshold (default: the output interval); a segment that ends between two
                  output times writes its boundary as an output time too
A segment also ends where the granules' U_mf first reaches warn_fraction of the inlet's
velocity, so the CFD re-runs (and the warning is given) as the bed nears defluidisation.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Coupling:
    """``[coupling]``: the segment schedule [s of process time, or a relative d32 change],
    the flow time [s] and averaging start [s] of each CFD re-run, the first run's flow time
    [s] and mesh, and the defluidisation warning (fraction [-], inlet velocity [m/s])."""
    flow_time: float                      # s of flow per CFD re-run, from the previous state
    interval: float | None = None         # s of process time between CFD re-runs
    d32_change: float | None = None       # relative change of the bed's d32 that re-runs the CFD
    average_from: float | None = None     # s after a re-run's start where its average begins
    first_flow_time: float | None = None  # s of flow of the template's first run (bundled case)
    first_average_from: float | None = None   # s where that first run's average begins
    mesh: str = "small"                   # the template's mesh for that first run
    warn_fraction: float = 0.8            # defluidisation warning at U_mf >= this x U_inlet
    inlet_velocity: float | None = None   # m/s compared with U_mf (default: the case's inlet)
    check_interval: float | None = None   # s between segment-end checks (default: outputs)

    @property
    def window_start(self) -> float:
        """s after a re-run's start where its averaging window begins."""
        return self.average_from if self.average_from is not None else self.flow_time / 3.0

    @property
    def first_flow(self) -> float:
        """s of flow of the first CFD run (from the template's packed bed)."""
        return self.first_flow_time if self.first_flow_time is not None else self.flow_time

    @property
    def first_window_start(self) -> float:
        """s where the first run's averaging window begins."""
        return (self.first_average_from if self.first_average_from is not None
                else self.window_start)


def parse_coupling(table, domain, error) -> Coupling:
    """Validate the ``[coupling]`` table (``table``: the scene module's key reader) of a scene
    whose domain is ``domain``; errors are raised as ``error(file, key, message)``."""
    c = Coupling(
        flow_time=table.number("flow_time", positive=True, unit="s"),
        interval=table.number("interval", None, positive=True, unit="s"),
        d32_change=table.number("d32_change", None, positive=True),
        average_from=table.number("average_from", None, non_negative=True, unit="s"),
        first_flow_time=table.number("first_flow_time", None, positive=True, unit="s"),
        first_average_from=table.number("first_average_from", None, non_negative=True,
                                        unit="s"),
        mesh=table.choice("mesh", ("small", "full"), "small"),
        warn_fraction=table.number("warn_fraction", 0.8, positive=True, high=1.0),
        inlet_velocity=table.number("inlet_velocity", None, positive=True, unit="m/s"),
        check_interval=table.number("check_interval", None, positive=True, unit="s"))
    table.finish()

    def fail(key, text):
        raise error(table.path, key, text)
    if c.interval is None and c.d32_change is None:
        fail("coupling", "expected interval (s of process time) or d32_change (a relative "
              "change of the bed's d32), or both: when to re-run the CFD")
    if not c.window_start < c.flow_time:
        fail("coupling.average_from", f"expected below flow_time = {c.flow_time:g} s, got "
              f"{c.window_start:g} s")
    if not c.first_window_start < c.first_flow:
        fail("coupling.first_flow_time", f"expected above the first run's average_from = "
             f"{c.first_window_start:g} s, got {c.first_flow:g} s")
    if domain.type != "openfoam":
        fail("coupling", "two-way coupling re-runs an OpenFOAM case: expected domain.type = "
              "\"openfoam\"")
    if domain.case is not None and domain.case.endswith(".vtu"):
        fail("domain.case", "two-way coupling continues the flow of an OpenFOAM case: "
              "expected a case directory or bundled:fluid_bed_small, got a snapshot .vtu")
    return c
