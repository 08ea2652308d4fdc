"""The run state of the per-cell integration, shared by every run.

A ``CellBatch`` holds what ``integrate.integrate_cells`` works on -- the packed parameters and
switches, the method's auxiliary data, one row of local fields and one scaled state per cell,
and the per-cell work arrays (step memory [s], counters, status, time reached [s]) -- and
advances them: ``advance(t0, t1)``, ``raise_if_failed()``, ``stats()``. The well-mixed run is
a batch of one cell, the coupled run one of all active cells, a cluster task one of a chunk's
cells, a benchmark one of synthetic cells.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from .. import integrate
from . import model
from ..methods.registry import method_plan
from ..physics import parameters as P
from ..scene import spray
from ..scene.scene import SceneError
from ..util.progress import compile_text, notice_if_slow, record_compile_s

#: relative width w of the smooth viscous Stokes switch, 0.5 (1 - tanh((St - St*)/(w St*))),
#: a cell continues with when its step controller stalls under the sharp step. Ours: the
#: widest that stays on the sharp solution of the hard cell at Theta 10 m2/s2 (M00 -0.35% at
#: 6 s; w = 0.005 leaves it at 1 s for an aggregation runaway the cNMC does not show:
#: docs/results/hard-cases.md, "The smooth switch's width at Theta 10")
STOKES_FALLBACK_WIDTH = 0.001


class SimulationError(RuntimeError):
    """The run could not reach its end time; the message says which cell, when and why."""


def output_times(scene) -> np.ndarray:
    """Output times [s]: 0, every output_interval, and end_time."""
    n = int(math.floor(scene.end_time / scene.output_interval + 1e-9))
    times = [k * scene.output_interval for k in range(n + 1)]
    if scene.end_time - times[-1] > 1e-9 * scene.end_time:
        times.append(scene.end_time)
    return np.array(times)


def check_physics(scene):
    """Refuse runs whose answer would be meaningless: product-kernel gelation, and a
    well-mixed cell whose granules (number_density [1/m3] x mean_mass [kg] / density
    [kg/m3]) would fill more than alpha_max of its volume (SceneError, exit 2)."""
    if scene.domain.type == "well-mixed":
        implied = (scene.initial.number_density * scene.initial.mean_mass
                   / scene.material.density)
        if not implied <= scene.domain.alpha_max:
            raise SceneError(scene.source, "initial.number_density",
                             f"{scene.initial.number_density:.4g} granules of "
                             f"{scene.initial.mean_mass:.4g} kg per m3 fill a solids volume "
                             f"fraction of {implied:.4g} (number_density x mean_mass / "
                             f"density), above alpha_max = {scene.domain.alpha_max:g}; "
                             "expected a lower number_density")
    t_gel = model.product_gel_time(scene)
    if t_gel is not None and scene.end_time >= t_gel:
        raise SceneError(
            scene.source, "scene.end_time",
            f"the product kernel gels at t_gel = 1/(k0 M20(0)) = {t_gel:.6g} s (k0 = "
            f"{scene.aggregation.rate:g} m3/(kg2 s), M20(0) = {model.size_moment(scene, 2):.6g} "
            f"kg2/m3) and its moments diverge there: expected end_time below t_gel, got "
            f"{scene.end_time:g} s")


@dataclass
class CellBatch:
    """Cells integrated together by ``integrate.integrate_cells`` (arrays modified in place).

    params, config  packed arrays (``physics.parameters``)
    aux             method data (``methods.registry``)
    rows            (n, N_CELL) local fields per cell (SI)
    states          (n, n_state) scaled states
    rtol, atol      tolerances of the step control on the scaled state [-]
    steps           (n,) step memory [s]; stats (n, N_STATS) counters; status (n,) codes;
    reached         (n,) time each cell got to [s]
    For messages: ``source`` (the scene's file), ``plan`` (the method's
    ``methods.entry.MethodPlan``: its name, hints and output check), ``cell_ids`` the global
    number of each row (None: a well-mixed run, one cell), ``arrays`` the packed arrays.
    """
    params: np.ndarray
    config: np.ndarray
    aux: np.ndarray
    rows: np.ndarray
    states: np.ndarray
    rtol: float
    atol: float
    steps: np.ndarray
    max_steps: int = integrate.MAX_STEPS_PER_INTERVAL
    stats_counts: np.ndarray = None
    status: np.ndarray = None
    reached: np.ndarray = None
    source: str = ""
    plan: object = None
    arrays: object = None
    cell_ids: np.ndarray | None = None
    hints: bool = True
    compiled_now: bool = False     # set by compile(): the kernel or the method compiled
    smoothed: np.ndarray = None    # (n,) True: the cell runs with the smooth Stokes switch
    notes: list = field(default_factory=list)   # what the batch did that a run reports
    #: spray schedule [(t0 [s], t1 [s], rate / peak rate [-])] (``spray.factors``): each
    #: segment runs with the rows' injection scaled by its factor; empty: the rows as given
    schedule: list = field(default_factory=list)
    #: the bed's air balance (``runs.air.BedAir``): None, the scene's air at every cell
    air: object = None
    #: the method's output-time watcher (``MethodEntry.output_watch``) and its line in notes
    watch: object = None
    watch_note: int = -1

    def __post_init__(self):
        n = self.states.shape[0]
        if self.stats_counts is None:
            self.stats_counts = np.zeros((n, integrate.N_STATS), dtype=np.int64)
        if self.status is None:
            self.status = np.zeros(n, dtype=np.int64)
        if self.reached is None:
            self.reached = np.zeros(n)
        if self.smoothed is None:
            self.smoothed = np.zeros(n, dtype=bool)

    @classmethod
    def for_scene(cls, scene, arrays, aux, rows, states, cell_ids=None) -> "CellBatch":
        """A batch of the scene's method and tolerances; the first step of every cell is
        1e-3 of the output interval [s]."""
        n = states.shape[0]
        inj = scene.binder_injection
        return cls(params=arrays.params, config=arrays.config, aux=aux, rows=rows,
                   states=states, rtol=scene.method.rtol, atol=scene.method.atol,
                   steps=np.full(n, scene.output_interval * 1e-3), source=scene.source,
                   plan=method_plan(scene), arrays=arrays, cell_ids=cell_ids,
                   schedule=spray.factors(inj, scene.end_time) if inj is not None else [])

    @classmethod
    def for_problem(cls, problem) -> "CellBatch":
        """A batch of a packed problem's cells (``runs.problem.Problem``: its arrays, aux,
        rows, tolerances, first step and spray schedule; a copy of its initial states)."""
        n = problem.states.shape[0]
        return cls(params=problem.arrays.params, config=problem.arrays.config,
                   aux=problem.aux, rows=problem.rows,
                   states=np.array(problem.states, dtype=np.float64, copy=True),
                   rtol=problem.rtol, atol=problem.atol, steps=np.full(n, problem.first_step),
                   source=problem.source, plan=problem.outputs.method_plan,
                   arrays=problem.arrays, cell_ids=problem.cell_ids,
                   schedule=list(problem.schedule))

    @property
    def n_cells(self) -> int:
        """Number of cells [-]."""
        return self.states.shape[0]

    # -- integration ---------------------------------------------------------------------
    def compile(self) -> float:
        """Compile the integration kernel this batch runs (or load it from numba's disk
        cache), by a call on one cell whose status tells the kernel to skip it: the same
        argument types as ``advance``, nothing integrated. Returns the wall time it took [s]
        (seconds on a first run, milliseconds once cached); ``compiled_now`` then says whether
        numba compiled it (True) or found it in its cache (False)."""
        method = int(self.config[P.METHOD])
        misses = integrate.compile_misses(method)
        start = _time.perf_counter()
        one = slice(0, 1)
        integrate.integrate_cells(self.states[one].copy(), self.rows[one].copy(), self.aux,
                                  self.params, self.config, 0.0, 0.0, self.steps[one].copy(),
                                  self.rtol, self.atol, self.max_steps,
                                  np.zeros_like(self.stats_counts[one]),
                                  np.full(1, integrate.UNREALIZABLE_START, dtype=np.int64),
                                  np.zeros_like(self.reached[one]))
        seconds = _time.perf_counter() - start
        self.compiled_now = integrate.compile_misses(method) > misses
        return seconds

    def kernel_name(self) -> str:
        """The compiled kernel this batch runs, as a run names it: method and integrator."""
        scheme = {code: name for name, code in integrate.SCHEMES.items()}.get(
            int(self.config[P.INTEGRATOR]), "?")
        method = self.plan.method.name if self.plan is not None else \
            f"method {int(self.config[P.METHOD])}"
        return f"the {method} kernel with the {scheme} integrator"

    def compile_announced(self, progress, extra=None) -> float:
        """``compile`` (and ``extra()``, more kernels of the run, if given), telling
        ``progress`` what compiles and roughly how long it takes when it is slow (a first
        run); a compile's CPU time is kept for the next notice (numba compiles on one
        thread: on an idle core the wall time, and unlike it not stretched by other load).
        Returns the wall time [s]."""
        name = self.kernel_name()
        cpu = _time.process_time()
        with notice_if_slow(progress, compile_text(name)):
            seconds = self.compile()
            if extra is not None:
                seconds += extra()
        if self.compiled_now:
            record_compile_s(name, _time.process_time() - cpu)
        return seconds

    def advance(self, t0: float, t1: float, states: np.ndarray | None = None):
        """Integrate every cell still running from t0 to t1 [s] in place (``states``: the
        batch's own by default, or an array of the same shape). Cells that stop keep their
        status; see ``raise_if_failed``.

        A cell whose step controller stalls on the jump of the sharp viscous Stokes criterion
        (a pair held on St = St*, where the rates switch on and off with every step) continues
        from the time it reached with the smooth switch of relative width
        ``STOKES_FALLBACK_WIDTH``, and keeps it to the end of the run (``notes`` says which
        cell, from when). With a spray schedule, [t0, t1] is cut at the schedule's switching
        times and each piece runs with the rows' injection times its segment's factor."""
        states = self.states if states is None else states
        if not self.schedule:
            self._advance(states, t0, t1)
            return
        rows = self.rows
        try:
            for s0, s1, factor in self.schedule:
                a, b = max(s0, t0), min(s1, t1)
                if b > a:
                    self.rows = rows.copy()
                    self.rows[:, P.INJECTION] *= factor
                    self._advance(states, a, b)
        finally:
            self.rows = rows

    def _advance(self, states, t0, t1):
        """``advance`` over [t0, t1] [s] with the batch's rows as they are (with an air
        balance in its pieces, each at the bed's driving force: ``runs.air``)."""
        if self.air is None:
            self._advance_cells(states, t0, t1)
        else:
            self.air.advance(self, states, t0, t1, self._advance_cells)

    def probe(self, states, t0, t1):
        """Integrate ``states`` (a copy of the batch's) from t0 to t1 [s] with copies of the
        step memory and counters: the batch is left as it was."""
        integrate.integrate_cells(states, self.rows, self.aux, self.params, self.config, t0,
                                  t1, self.steps.copy(), self.rtol, self.atol, self.max_steps,
                                  np.zeros_like(self.stats_counts), self.status.copy(),
                                  self.reached.copy())

    def _advance_cells(self, states, t0, t1):
        """The cells' integration over [t0, t1] [s] (sharp, then smooth Stokes switch)."""
        smoothed = self.smoothed.copy()
        sharp = integrate.sharp_stokes_switch(self.params, self.config)
        self._integrate(states, ~smoothed, self.params, t0, t1)
        if smoothed.any():
            self._integrate(states, smoothed, self.smooth_params(), t0, t1)
        if sharp:
            self._continue_smoothly(states, t0, t1)

    def _integrate(self, states, mask, params, t0, t1):
        """integrate_cells on the cells of ``mask`` only (the others are skipped: their
        status is set to a code the kernel skips and restored afterwards)."""
        if not mask.any():
            return
        if mask.all():
            integrate.integrate_cells(states, self.rows, self.aux, params, self.config, t0, t1,
                                      self.steps, self.rtol, self.atol, self.max_steps,
                                      self.stats_counts, self.status, self.reached)
            return
        saved = self.status.copy()
        self.status[~mask & (saved == integrate.OK)] = integrate.UNREALIZABLE_START
        integrate.integrate_cells(states, self.rows, self.aux, params, self.config, t0, t1,
                                  self.steps, self.rtol, self.atol, self.max_steps,
                                  self.stats_counts, self.status, self.reached)
        self.status[~mask] = saved[~mask]

    def smooth_params(self) -> np.ndarray:
        """The batch's params with the smooth Stokes switch of ``STOKES_FALLBACK_WIDTH``."""
        params = np.array(self.params, dtype=np.float64, copy=True)
        params[P.STOKES_WIDTH] = STOKES_FALLBACK_WIDTH
        return params

    def _continue_smoothly(self, states, t0, t1):
        """Cells whose step controller stalled under the sharp Stokes step in this call (step
        floor or step budget; the step is the one discontinuity of the rates): each continues
        alone from the time it reached to t1."""
        params = self.smooth_params()
        stalled = ((self.status == integrate.STEP_BELOW_FLOOR)
                   | (self.status == integrate.TOO_MANY_STEPS))
        for c in np.flatnonzero(~self.smoothed & stalled):
            t_jump = float(self.reached[c])
            self.smoothed[c] = True
            self.status[c] = integrate.OK
            self.steps[c] = 1e-6 * (t1 - t0)
            one = slice(c, c + 1)
            integrate.integrate_cells(states[one], self.rows[one], self.aux, params,
                                      self.config, t_jump, t1, self.steps[one], self.rtol,
                                      self.atol, self.max_steps, self.stats_counts[one],
                                      self.status[one], self.reached[one])
            cell = c if self.cell_ids is None else int(self.cell_ids[c])
            self.notes.append(
                f"cell {cell}: the sharp viscous Stokes criterion held a pair on the critical "
                f"Stokes number at t = {t_jump:.6g} s (the rates switch with every step); "
                f"continued from there with the smooth switch of relative width "
                f"{STOKES_FALLBACK_WIDTH:g} (material.stokes_switch_width; "
                "docs/results/hard-cases.md)")

    def step(self, t0: float, t1: float, states: np.ndarray | None = None):
        """``advance`` then ``raise_if_failed``: the source step of a run."""
        self.advance(t0, t1, states)
        self.raise_if_failed(states)

    def source_step(self, states: np.ndarray, t0: float, t1: float):
        """``step`` with the signature of ``Transport.advance``'s source step."""
        self.step(t0, t1, states)

    def failed(self) -> np.ndarray:
        """Positions of the cells that stopped."""
        return np.flatnonzero(self.status != integrate.OK)

    def raise_if_failed(self, states: np.ndarray | None = None, failed=None):
        """Raise SimulationError naming the first stopped cell (of ``failed``, default all
        stopped cells), the time it reached and why, with the method's hint."""
        bad = self.failed() if failed is None else np.asarray(failed)
        if bad.size == 0:
            return
        c = int(bad[0])
        states = self.states if states is None else states
        source = self.source
        params = self.smooth_params() if self.smoothed[c] else self.params
        text = integrate.failure_reason(int(self.status[c]), self.stats_counts[c], params,
                                        self.config)
        if self.cell_ids is None:
            message = (f"{source}: cell {c} stopped at t = {self.reached[c]:.6g} s: {text} "
                       f"(floor {self.params[P.STEP_FLOOR]:.3g} s)")
        else:
            message = (f"{source}: cell {int(self.cell_ids[c])} (alpha "
                       f"{self.rows[c, P.ALPHA]:.4g}, Theta {self.rows[c, P.THETA]:.3g} m2/s2) "
                       f"stopped at t = {self.reached[c]:.6g} s: {text}; {bad.size} cell(s) "
                       "affected")
        if self.hints and self.plan is not None:
            message += self.plan.method.failure_hint(self.plan, self.arrays, states[c],
                                                     self.aux)
        raise SimulationError(message)

    def check_output(self, t: float, states: np.ndarray | None = None):
        """Raise SimulationError naming the first cell whose state at the output time ``t``
        [s] is no answer (the method's ``output_check``: e.g. the Laguerre ROM's carried
        moments outside the realizable set), its local fields and why."""
        check = self.plan.method.output_check if self.plan is not None else None
        if check is None:
            return
        states = self.states if states is None else states
        found = check(states, self.aux, self.arrays)
        if found is None:
            self._watch(t, states)
            return
        c, text = found
        source = self.source
        if self.cell_ids is None:
            where = f"{source}: at t = {t:.6g} s"
        else:
            where = (f"{source}: cell {int(self.cell_ids[c])} (alpha {self.rows[c, P.ALPHA]:.4g}, "
                     f"Theta {self.rows[c, P.THETA]:.3g} m2/s2) at t = {t:.6g} s")
        raise SimulationError(f"{where}: {text}")

    def _watch(self, t: float, states: np.ndarray):
        """The method's ``output_watch`` at output time t [s]: one line in ``notes``."""
        make = self.plan.method.output_watch
        if make is None:
            return
        self.watch = self.watch or make()
        if self.watch.update(t, states, self.rows, self.aux, self.arrays, self.cell_ids):
            self.watch_note = len(self.notes) if self.watch_note < 0 else self.watch_note
            self.notes[self.watch_note:self.watch_note + 1] = [self.watch.text()]

    # -- accounting ----------------------------------------------------------------------
    def stats(self) -> dict:
        """Counters summed over the cells (``integrate.stats_summary``): accepted steps, steps
        rejected by the error control and by realizability, right-hand-side calls, implicit
        steps, Jacobians and scheme switches; the output watch's entries if it found any."""
        out = integrate.stats_summary(self.stats_counts)
        return out | (self.watch.stats() if self.watch_note >= 0 else {})

    def shared(self) -> dict:
        """What every chunk of this batch shares (aux, params, config, tolerances, step
        budget): the arguments of ``CellBatch.of_chunk``."""
        return {"aux": np.asarray(self.aux), "params": np.asarray(self.params),
                "config": np.asarray(self.config), "rtol": float(self.rtol),
                "atol": float(self.atol), "max_steps": int(self.max_steps),
                "schedule": list(self.schedule)}

    @classmethod
    def of_chunk(cls, shared: dict, rows, states, steps) -> "CellBatch":
        """A batch of some cells (copies of ``states`` and ``steps``) with the ``shared``
        data of the whole run (``shared()``); no messages context."""
        return cls(params=shared["params"], config=shared["config"], aux=shared["aux"],
                   rows=np.ascontiguousarray(rows),
                   states=np.array(states, dtype=np.float64, order="C", copy=True),
                   rtol=shared["rtol"], atol=shared["atol"],
                   steps=np.array(steps, dtype=np.float64, copy=True),
                   max_steps=shared["max_steps"], hints=False,
                   schedule=list(shared.get("schedule", ())))
