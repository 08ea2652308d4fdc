"""Two-way coupling: the flow follows the granules (``[coupling]``, docs/physics.md section 14).

The granulation is cut into segments. Segment 0 runs on the scene's CFD fields (the user's
case at ``[domain] time``, or for the bundled snapshot the case template run from its packed
bed for ``first_flow_time``). A segment ends at the first output time where ``interval`` [s]
of process time has passed since it began, or where the bed's Sauter mean diameter d32 [m]
(of the granules, weighted by mass over the bed: seed 001 eq. 5.2.8, d32 = m3/m2) has moved
by ``d32_change`` relative to the diameter the segment's CFD used. The CFD is then re-run
from the previous segment's flow state with d = d32 for ``flow_time`` [s] of flow, averaged
over its last ``flow_time - average_from`` [s] (``io.openfoam.rerun``), and the next segment
integrates with the new time-averaged alpha, Theta and solids flux.

At a segment boundary the bed's population is carried over to the new solids field: the bed
total of every state component (per m3 of bed x cell volume, summed over the cells) is spread
over the new active cells in proportion to their alpha (granules fill the solids fraction, as
at the start). Every moment of the bed is conserved exactly; the spatial structure within the
bed is the new flow's (its circulation mixes the bed in seconds, segments last minutes).

What reads the scene: ``two_way_plan`` (the run's ``TwoWayPlan``, before the first CFD) and
each segment's pass ``segment_problem`` (its CFD fields and ``runs.problem.problem_of``, with
segment 0's scales for the later segments); the rest of the run reads the plan and the
segments' problems.

Every finished step is kept in the segment store (``runs.coupling_store``) so that a killed
run continues from its last finished step (``--resume``) with bitwise the same result.
"""
from __future__ import annotations

import dataclasses
import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import model
from .batch import CellBatch, SimulationError, check_physics
from ..io import openfoam as of
from .domain import Domain, case_path, load_domain
from .executor import SerialExecutor
from ..io.openfoam import rerun
from .problem import problem_of
from ..physics import parameters as P
from ..util.population import mean_diameters


@dataclass
class Segment:
    """One granulation segment and the CFD it ran on (SI): process times [s], the CFD case and
    its averaged time [s], the particle diameter the CFD used [m], the domain read from it,
    the output times [s] and the history of states (one (n_active, n_state) array per time),
    wall seconds of CFD and population balance."""
    index: int
    t_start: float
    t_end: float
    case: str
    cfd_time: float
    cfd_window: tuple
    diameter: float
    domain: Domain
    times: np.ndarray
    history: list
    idx: np.ndarray
    aux: object
    cfd_wall_s: float
    pbe_wall_s: float
    rows: np.ndarray = None
    active: np.ndarray = None
    spray: np.ndarray = None
    d32_end: float = float("nan")


@dataclass(frozen=True)
class TwoWayPlan:
    """What a two-way run reads of its scene besides the segments' problems (SI).

    name, source     the scene's name and file (titles, messages)
    coupling         the ``[coupling]`` table (``scene.coupling.Coupling``)
    end_time         the scene's end time [s]
    density          granule material density [kg/m3] (U_mf)
    phase            the CFD's particle phase (``[domain] phase``)
    diameter         diameter of a granule of the initial mean mass [m] (the template's CFD)
    user_case        the user's OpenFOAM case (None: the bundled template) and
    domain_time      its ``[domain] time`` (segment 0's fields)
    fluidisation     gas density [kg/m3], viscosity [Pa s], inlet velocity [m/s]
                     (``fluidisation_values``)
    """
    name: str
    source: str
    coupling: object
    end_time: float
    density: float
    phase: str
    diameter: float
    user_case: Path | None
    domain_time: object
    fluidisation: dict


def two_way_plan(scene) -> TwoWayPlan:
    """The ``TwoWayPlan`` of a validated scene with ``[coupling]`` (SceneError where its
    physics cannot run: ``batch.check_physics``, before any CFD runs)."""
    check_physics(scene)
    return TwoWayPlan(name=scene.name, source=scene.source, coupling=scene.coupling,
                      end_time=float(scene.end_time), density=float(scene.material.density),
                      phase=scene.domain.phase, diameter=initial_diameter(scene),
                      user_case=case_path(scene), domain_time=scene.domain.time,
                      fluidisation=fluidisation_values(scene))


@dataclass
class TwoWayRun:
    """What ``run_two_way`` returns: the segments, the packed arrays of the run (segment 0's
    scales), warnings, compile seconds, the gas and inlet values of the defluidisation check
    (SI), the run's plan and the output plan (``runs.problem.OutputPlan``)."""
    segments: list
    arrays: object
    warnings: list = field(default_factory=list)
    compile_time_s: float = 0.0
    fluidisation: dict = field(default_factory=dict)
    plan: TwoWayPlan | None = None
    outputs: object = None


def initial_diameter(scene) -> float:
    """Diameter [m] of a granule of the scene's initial mean mass."""
    return (6.0 * scene.initial.mean_mass / (math.pi * scene.material.density)) ** (1 / 3)


def granule_d32(plan, arrays, aux, states, volumes) -> float:
    """Sauter mean diameter d32 [m] of the bed's granules (free droplets excluded): every
    cell's quadrature weighted by its volume [m3] (``states`` per m3 of bed); ``plan`` the
    run's ``methods.entry.MethodPlan``."""
    populations = []
    model.moment_outputs(plan, arrays, states, aux, populations=populations)
    ws = [np.asarray(w) * volumes[c] for c, (w, _, _) in enumerate(populations)]
    ps = [np.asarray(p) for _, p, _ in populations]
    d32, _ = mean_diameters(np.concatenate(ws), np.concatenate(ps), plan.density)
    return float(d32)


def carry_over(states, volumes, alpha_new, volumes_new) -> np.ndarray:
    """The bed's population on a new solids field: the bed totals of ``states`` (per m3 of
    bed, cells of ``volumes`` [m3]) spread over the new cells in proportion to alpha [-]
    (``volumes_new`` [m3]); every bed total is conserved."""
    total = np.sum(states * volumes[:, None], axis=0)
    share = alpha_new / float(np.sum(alpha_new * volumes_new))
    return share[:, None] * total[None, :]


def segment_domain(scene, case, time, need_flux: bool, first: bool) -> Domain:
    """The CFD fields of a segment's case at ``time`` (a written time name or "latest"). Later
    segments' cases hold the population balance's diameter, not the scene's initial one, so
    the material comparison is the first segment's only."""
    dom = dataclasses.replace(scene.domain, case=str(case), time=time,
                              accept_material_mismatch=(scene.domain.accept_material_mismatch
                                                        or not first))
    domain = load_domain(dataclasses.replace(scene, domain=dom), need_flux=need_flux)
    if not first:
        domain.warnings = [w for w in domain.warnings if "particle diameter" not in w]
    return domain


def segment_problem(scene, case, time, k: int, scales=None):
    """The pass of segment k: the CFD fields of its ``case`` at ``time`` (``segment_domain``)
    and the scene packed on them (``runs.problem.problem_of``; ``scales``: segment 0's number
    scales [1/m3] for the later segments, so that all integrate in the same scaled units).
    Returns (domain, problem)."""
    domain = segment_domain(scene, case, time, scene.transport is not None, first=k == 0)
    try:
        problem = problem_of(scene, domain, scales=scales)
    except SimulationError as exc:
        raise SimulationError(f"two-way segment {k}: {exc}") from None
    return domain, problem


def _first_cfd(plan, store, log) -> dict:
    """Segment 0's CFD: the user's case as it is, or the template run from its packed bed."""
    c = plan.coupling
    user = plan.user_case
    if user is not None:
        t = of.pick_time(user, plan.domain_time, phase=plan.phase)
        from ..io.openfoam.material import case_material
        d = case_material(user, plan.phase)["diameter"][0] or plan.diameter
        return {"case": str(user), "time_name": of.time_name(user, t), "diameter": d,
                "cfd_wall_s": 0.0, "window": None}
    target = store.case_dir(0)
    d = plan.diameter
    t0 = _time.perf_counter()
    try:
        rerun.start_case(target, plan.phase, d, c.first_flow, c.first_window_start,
                         mesh=c.mesh, log=log)
    except of.OpenFOAMError as exc:
        raise _segment_error(0, 0.0, 0.0, exc) from None
    return {"case": target.name, "time_name": rerun.latest_time_name(target), "diameter": d,
            "cfd_wall_s": _time.perf_counter() - t0,
            "window": [c.first_window_start, c.first_flow]}


def _next_cfd(plan, store, k, prev_case, prev_time, d, t_process, log) -> dict:
    """Segment k's CFD: the previous case continued with diameter d [m]."""
    c = plan.coupling
    target = store.case_dir(k)
    t0 = _time.perf_counter()
    start = float(prev_time)
    try:
        rerun.continue_case(prev_case, prev_time, target, plan.phase, d, c.flow_time,
                            c.window_start, log=log)
    except of.OpenFOAMError as exc:
        raise _segment_error(k, t_process, start, exc) from None
    return {"case": target.name, "time_name": rerun.latest_time_name(target), "diameter": d,
            "cfd_wall_s": _time.perf_counter() - t0,
            "window": [start + c.window_start, start + c.flow_time]}


def _segment_error(k, t_process, t_cfd, exc) -> SimulationError:
    where = f" (log {exc.log_path})" if getattr(exc, "log_path", None) else ""
    first = str(exc).splitlines()[0]
    return SimulationError(f"two-way segment {k} (process time {t_process:g} s, CFD from "
                           f"t = {t_cfd:g} s) failed: {first}{where}")


def fluidisation_values(scene) -> dict:
    """Gas density [kg/m3], viscosity [Pa s] and inlet superficial velocity [m/s] of the
    scene's case (the template for the bundled snapshot); ``[coupling] inlet_velocity``
    replaces the case's."""
    case = case_path(scene) or of.default_case_dir()
    values = rerun.fluidisation_inputs(case, scene.domain.phase)
    if scene.coupling.inlet_velocity is not None:
        values["inlet_velocity"] = scene.coupling.inlet_velocity
    return values


def _ends_here(c, t_start, t, d32, d_cfd, t_end, nears_umf=False) -> bool:
    """True when a segment begun at t_start [s] ends at check time t [s]; ``nears_umf``: the
    granules' U_mf has just reached the warning's fraction of the inlet velocity."""
    if t >= t_end - 1e-9 * t_end or nears_umf:
        return True
    if c.interval is not None and t - t_start >= c.interval * (1 - 1e-9):
        return True
    return (c.d32_change is not None
            and abs(d32 / d_cfd - 1.0) >= c.d32_change * (1 - 1e-9))


def check_times(t0: float, t1: float, step: float | None) -> list:
    """The check times [s] in (t0, t1]: equal pieces of at most ``step`` [s], ending at t1."""
    if step is None or step >= (t1 - t0) * (1 - 1e-12):
        return [t1]
    n = int(math.ceil((t1 - t0) / step * (1 - 1e-12)))
    return [t0 + (t1 - t0) * k / n for k in range(1, n)] + [t1]


def _nears_umf(plan, fluid, d_cfd, d32) -> bool:
    """True when granules of d32 [m] reach U_mf >= warn_fraction x U_inlet and the CFD's
    diameter d_cfd [m] did not (``plan``: the run's ``TwoWayPlan``)."""
    from .coupling_output import umf_of
    u_in = fluid.get("inlet_velocity")
    if u_in is None:
        return False
    limit = plan.coupling.warn_fraction * u_in
    return bool(umf_of(plan, fluid, d32) >= limit > umf_of(plan, fluid, d_cfd))


def run_two_way(scene, store, progress=None, log=None, warn=None) -> TwoWayRun:
    """Run the segments of a two-way coupled scene (module docstring), continuing the finished
    steps the ``store`` holds. ``progress(fraction, text)`` after each output time, ``log``
    receives the CFD's progress lines, ``warn`` the defluidisation warning of a segment's end
    (``coupling_output.defluidisation_warning``) before the next CFD runs. The scene is read
    by ``two_way_plan`` and each segment's ``segment_problem`` only."""
    plan = two_way_plan(scene)
    cfd = store.cfd(0)
    if cfd is None:
        cfd = _first_cfd(plan, store, log)
        store.save_cfd(0, cfd)
    run = TwoWayRun(segments=[], arrays=None, fluidisation=plan.fluidisation, plan=plan)
    states = volumes = scales = None
    k, t_start = 0, 0.0
    while True:
        case = Path(cfd["case"]) if Path(cfd["case"]).is_absolute() else store.case_dir(k)
        domain, problem = segment_problem(scene, case, cfd["time_name"], k, scales)
        run.warnings.extend(w for w in domain.warnings if w not in run.warnings)
        if k == 0:               # [output] cell_psd checked on the first CFD fields
            from .couple import select_psd_cells
            select_psd_cells(problem.outputs, domain.cells, problem.active)
            run.arrays, run.outputs, scales = problem.arrays, problem.outputs, problem.scales
        idx = problem.cell_ids
        vol = np.asarray(domain.cells.cell_volume, dtype=float)[idx]
        seg = Segment(k, t_start, t_start, str(case), float(domain.cells.time),
                      tuple(cfd["window"] or ()), float(cfd["diameter"]), domain, None, None,
                      idx, problem.aux, float(cfd["cfd_wall_s"]), 0.0, problem.mesh_rows,
                      problem.active, problem.spray)
        done = store.granulation(k)
        if done is not None:
            seg.times, seg.history = done["times"], list(done["history"])
            seg.pbe_wall_s, seg.t_end, seg.d32_end = (done["pbe_wall_s"], done["t_end"],
                                                      done["d32_end"])
        else:
            first = (problem.states if states is None
                     else carry_over(states, volumes, problem.rows[:, P.ALPHA], vol))
            run.compile_time_s += _granulate(plan, problem, seg, first, progress)
            store.save_granulation(k, {"t_end": seg.t_end, "d32_end": seg.d32_end,
                                       "pbe_wall_s": seg.pbe_wall_s},
                                   seg.times, seg.history, idx)
        run.segments.append(seg)
        states, volumes = np.asarray(seg.history[-1]), vol
        if seg.t_end >= plan.end_time * (1 - 1e-12):
            return run
        if warn is not None:
            from .coupling_output import defluidisation_warning
            text = defluidisation_warning(plan, run.fluidisation, seg.d32_end, seg.t_end)
            if text:
                warn(text)
        k, t_start, prev = k + 1, seg.t_end, cfd
        cfd = store.cfd(k)
        if cfd is None:
            cfd = _next_cfd(plan, store, k, case, prev["time_name"], seg.d32_end, t_start, log)
            store.save_cfd(k, cfd)


def _granulate(plan, problem, seg, states, progress) -> float:
    """Integrate segment ``seg`` (its ``problem``, from ``states``) from its start over the
    output times until it ends (``_ends_here``, checked every ``check_interval``); fills its
    times, history, end time, d32 and wall seconds. ``plan``: the run's ``TwoWayPlan`` (the
    case's gas values for U_mf). Returns the compile seconds."""
    batch = CellBatch.for_problem(dataclasses.replace(problem, states=states))
    compile_s = batch.compile()
    t0 = _time.perf_counter()
    arrays, aux = problem.arrays, problem.aux
    transport = None
    if problem.transport is not None:
        from ..transport.operator import build_transport
        transport = build_transport(problem.transport, seg.domain, seg.active, seg.rows,
                                    arrays=arrays, aux=aux)
    executor = SerialExecutor()
    vol = np.asarray(seg.domain.cells.cell_volume, dtype=float)[seg.idx]
    out_t, history = [seg.t_start], [batch.states.copy()]
    later = [t for t in problem.times if t > seg.t_start * (1 + 1e-12) + 1e-12]
    c, end_time, fluid = plan.coupling, plan.end_time, plan.fluidisation
    ended = False
    for t in later:
        last = out_t[-1]
        for tc in check_times(last, float(t), c.check_interval):
            executor.run(batch, np.array([last, tc]), transport)
            last = tc
            d32 = granule_d32(batch.plan, arrays, aux, batch.states, vol)
            ended = _ends_here(c, seg.t_start, tc, d32, seg.diameter, end_time,
                               _nears_umf(plan, fluid, seg.diameter, d32))
            if ended or tc == t:
                out_t.append(float(tc))
                history.append(batch.states.copy())
                break
        if progress is not None:
            progress(out_t[-1] / end_time, f"segment {seg.index}: t = {out_t[-1]:.4g} "
                     f"s, d32 = {d32 * 1e6:.1f} um")
        if ended:
            seg.d32_end = d32
            break
    seg.times, seg.history, seg.t_end = np.array(out_t), history, out_t[-1]
    seg.pbe_wall_s = _time.perf_counter() - t0
    return compile_s
