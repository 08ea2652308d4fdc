"""Transport of the granule population between cells by the granular-phase face flux.

The scene's ``[transport]`` table turns this on for an OpenFOAM domain. Granules (and free
binder droplets) move with the solids: the carrier is the time-averaged solids volume flux
``alphaPhi.particlesMean`` F_f [m3/s] through each face, and the transported intensive quantity
is the state per unit solids volume, q_c = S_c / alpha_c (S_c: scaled moments per m3 of bed).

Design (all SI):

* **Domain of transport.** Only the active cells (alpha >= alpha_min, the cells that hold
  granules) exchange granules. The flux through faces between an active and an inactive cell,
  and through the outer boundary, is set to zero: the bed is closed, nothing leaves the active
  set, and nothing is lost into the lean freeboard.
* **Flux correction.** The averaged flux restricted to the active set is not divergence-free
  (the averaging window sees alpha drift, and the cut at the active-set boundary removes
  flux). It is replaced by the nearest divergence-free flux in the least-squares sense on each
  connected component: F' = F - D^T lambda with (D D^T) lambda = D F, D the cell-face
  incidence matrix (a graph-Laplacian solve, one cell pinned per component). The size of the
  change ||F' - F||_1 / ||F||_1 is reported.
* **Scheme.** First-order upwind, explicit: one substep of length dt maps
  q_c <- (1 - dt Out_c / W_c) q_c + dt / W_c sum_in |F'_f| q_upwind, with W_c = alpha_c V_c the
  solids volume and Out_c the outgoing flux. Because F' is divergence-free the weights sum to
  one, and under the CFL limit dt max(Out_c / W_c) <= courant <= 1 they are non-negative: every
  cell's new state is a convex combination of old states, so a realizable moment set stays
  realizable, a uniform q stays uniform, and the bed totals sum_c V_c S_c are conserved to
  round-off (the extensive update moves exactly what leaves one cell into the next). The update
  is one scipy.sparse matrix acting on all cells and all state entries at once.
* **Splitting.** Strang (default): transport dt_s/2, sources dt_s, transport dt_s/2, per split
  step dt_s (``split_step``), the closing half of a split step joined with the opening half of
  the next within an output interval (``Transport.plan``); or Lie (sources dt_s, then
  transport dt_s). Each transport part is sub-stepped to respect the CFL limit.
* **QMOM node-wise binder.** The size moments of a mixture stay realizable, but the node-wise
  binder solved from mixed M_k1 may fall outside [0, p_a]. Such cells are re-projected by the
  method's own projection, which keeps M00, M10, M01 and the droplets exactly (so number, mass
  and binder stay conserved) and moves only the higher moments; the count and the size of the
  change are reported. The check runs after each transport part (the states the source
  integrator receives); the substeps in between are linear and invert nothing.
* **Scales.** Substeps cost one sparse product over all cells; the source integration, not
  the transport, sets the cost of a coupled run (see ``Transport.report``).
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import scipy.sparse as sp
from numba import typeof
from numba.core import types

from ..integrate import faults
from ..integrate.kernel_types import (addresses_of, closure_check_address, layout_key,
                                      signatures)
from .solids_flux import (ActiveFlux, circulation_time, restrict_and_correct, upwind_generator,
                          vertical_axis)
from .substeps import apply_substeps

#: Coefficient of variation of a spray-zone tracer at which the bed counts as mixed [-].
MIX_COV = 0.05
#: Cap on the simulated time of the mixing-time estimate: circulation times [-], substeps [-].
MIX_CIRCULATION_CAP = 200.0
MIX_SUBSTEP_CAP = 200_000


# ---------------------------------------------------------------------------- the operator
@dataclass
class Transport:
    """The transport operator of one coupled run; built once by ``build_transport``.

    Public attributes: ``n`` active cells; ``dt_max`` the largest CFL-admissible substep [s];
    ``split_step`` [s]; ``splitting`` ("strang" or "lie"); ``warnings`` (list of str).
    """
    n: int
    alpha: np.ndarray            # (n,) solids fraction of the active cells [-]
    volume: np.ndarray           # (n,) cell volumes [m3]
    generator: sp.csr_matrix     # L [1/s] on states per m3 of bed
    out_rate: np.ndarray         # (n,) Out_c / W_c [1/s]
    courant: float
    dt_max: float
    split_step: float
    split_step_source: str
    splitting: str
    flux_stats: dict
    tracer_cells: np.ndarray     # (n,) bool, where the mixing-time tracer starts
    circulation_time: float      # solids volume / mean upward solids flux [s]
    repair: object = None        # callable(states) -> (cells repaired, max rel change) or None
    warnings: list = field(default_factory=list)
    _mats: dict = field(default_factory=dict, repr=False)
    _count: dict = field(default_factory=lambda: {
        "split_steps": 0, "transport_calls": 0, "substeps": 0, "timed_substeps": 0,
        "transport_s": 0.0,
        "source_s": 0.0, "repaired_cells": 0, "repair_max_rel_change": 0.0,
        "max_courant_used": 0.0}, repr=False)
    _mixing: dict | None = field(default=None, repr=False)

    # -- pieces -----------------------------------------------------------------------
    def step_matrix(self, dt: float) -> sp.csr_matrix:
        """The one-substep update B = I + dt L [-] for a substep dt [s] (cached)."""
        key = float(dt)
        mat = self._mats.get(key)
        if mat is None:
            mat = (sp.identity(self.n, format="csr") + key * self.generator).tocsr()
            if len(self._mats) > 8:
                self._mats.clear()
            self._mats[key] = mat
        return mat

    def substeps(self, duration: float) -> tuple[int, float]:
        """(number of substeps, substep [s]) that cover ``duration`` [s] under the CFL."""
        if duration <= 0.0 or not math.isfinite(self.dt_max):
            return (0 if duration <= 0.0 else 1), duration
        k = max(1, int(math.ceil(duration / self.dt_max * (1.0 - 1e-12))))
        return k, duration / k

    def compile(self, n_state: int) -> float:
        """Compile (or load from numba's disk cache) what the transport runs, on no cells:
        the mixture repair of the scene's method. Returns the wall time it took [s]."""
        t0 = _time.perf_counter()
        if self.repair is not None:
            self.repair(np.zeros((0, n_state)))
        return _time.perf_counter() - t0

    def transport(self, states: np.ndarray, duration: float) -> int:
        """Carry ``states`` (n, n_state), per m3 of bed, for ``duration`` [s] in place (no
        sources). Returns the number of substeps taken."""
        if duration <= 0.0 or self.n == 0:
            return 0
        t0 = _time.perf_counter()
        k, dt = self.substeps(duration)
        if math.isfinite(self.dt_max) and self.out_rate.size:
            c = dt * float(self.out_rate.max())
            self._count["max_courant_used"] = max(self._count["max_courant_used"], c)
            states[...] = apply_substeps(self.step_matrix(dt), states, k)
        if self.repair is not None:
            fixed, change = self.repair(states)
            self._count["repaired_cells"] += fixed
            self._count["repair_max_rel_change"] = max(self._count["repair_max_rel_change"],
                                                       change)
        if self._count["transport_calls"] == 0:
            # the first call loads or compiles the realizability kernels: kept apart
            self._count["first_call_s"] = _time.perf_counter() - t0
        else:
            self._count["timed_substeps"] += k
            self._count["transport_s"] += _time.perf_counter() - t0
        self._count["substeps"] += k
        self._count["transport_calls"] += 1
        return k

    def plan(self, t0: float, t1: float) -> list:
        """The parts of ``advance`` from t0 to t1 [s], in order: ("T", duration [s]) for a
        transport part and ("S", ta [s], tb [s]) for a source part. The one place of the
        split-step arithmetic (the distributed run follows the same list).

        Split steps h = (t1 - t0) / n, n = ceil((t1 - t0) / split_step). Strang: transport
        h/2, then per split step sources h followed by transport h (the closing half of
        one split step joined with the opening half of the next: the transport is linear
        and autonomous, so T(h/2) T(h/2) and T(h) are the same operator up to the CFL
        substep length), the last transport part h/2. Lie: sources h, then transport h.
        """
        span = t1 - t0
        if span <= 0.0:
            return []
        n_split = max(1, int(math.ceil(span / self.split_step * (1.0 - 1e-12))))
        h = span / n_split
        bounds = [(t0 + k * h, t1 if k == n_split - 1 else t0 + (k + 1) * h)
                  for k in range(n_split)]
        parts = []
        if self.splitting == "strang":
            parts.append(("T", 0.5 * (bounds[0][1] - bounds[0][0])))
            for k, (ta, tb) in enumerate(bounds):
                parts.append(("S", ta, tb))
                half = 0.5 * (tb - ta)
                if k + 1 < n_split:
                    nxt = bounds[k + 1]
                    half += 0.5 * (nxt[1] - nxt[0])
                parts.append(("T", half))
        else:
            for ta, tb in bounds:
                parts += [("S", ta, tb), ("T", tb - ta)]
        return parts

    def advance(self, states: np.ndarray, t0: float, t1: float, source_step) -> None:
        """Advance ``states`` (n, n_state; scaled moments per m3 of bed of the active cells)
        from t0 to t1 [s] in place by operator splitting of transport and sources, part by
        part as ``plan(t0, t1)`` lists them.

        ``source_step(states, ta, tb)`` integrates the per-cell sources from ta to tb [s] in
        place.
        """
        for part in self.plan(t0, t1):
            if part[0] == "T":
                self.transport(states, part[1])
            else:
                self._source(source_step, states, part[1], part[2])
                self._count["split_steps"] += 1

    def _source(self, source_step, states, ta, tb):
        t = _time.perf_counter()
        source_step(states, ta, tb)
        self._count["source_s"] += _time.perf_counter() - t

    # -- diagnostics ------------------------------------------------------------------
    def bed_totals(self, states: np.ndarray) -> np.ndarray:
        """Bed totals sum_c V_c S_c of each state entry (scaled units times m3)."""
        return self.volume @ states

    def mixing(self) -> dict:
        """Mixing of the bed by this transport alone (computed once, cached).

        A tracer released uniformly per unit solids in ``tracer_cells`` (the spray zone, or
        the top tenth of the bed) is carried until the solids-weighted coefficient of
        variation over the active cells falls to MIX_COV. Returns ``mixing_time_s`` (that
        time [s], or None if not reached within the cap), ``variance_efold_s`` (e-folding time
        of the tracer variance at the end [s]), ``circulation_time_s`` (solids volume / mean
        upward solids flux through horizontal sections [s]), ``turnover_time_s`` (solids
        volume / total face flux, the mean cell exchange time [s]) and the tracer's start
        fraction of the solids.
        """
        if self._mixing is not None:
            return self._mixing
        solids = self.alpha * self.volume
        w_tot = float(solids.sum())
        flux_tot = float((self.out_rate * solids).sum())
        turnover = w_tot / flux_tot if flux_tot > 0 else math.inf
        res = {"turnover_time_s": turnover, "circulation_time_s": self.circulation_time,
               "mixing_time_s": None, "variance_efold_s": None,
               "tracer_solids_fraction": float(solids[self.tracer_cells].sum() / w_tot)
               if w_tot > 0 else 0.0, "criterion": f"tracer CoV <= {MIX_COV:g}"}
        if self.n < 2 or not math.isfinite(turnover) or not self.tracer_cells.any():
            self._mixing = res
            return res
        circ = self.circulation_time if math.isfinite(self.circulation_time) else turnover
        k_sub, dt = self.substeps(self.dt_max * max(1, int(0.01 * circ / self.dt_max)))
        dt_chunk = k_sub * dt
        mat = self.step_matrix(dt)
        q = self.tracer_cells.astype(float)
        s = q * self.alpha                       # per m3 of bed

        def cov(s):
            qq = s / self.alpha
            mean = float(solids @ qq) / w_tot
            return math.sqrt(max(float(solids @ (qq - mean) ** 2) / w_tot, 0.0)) / mean

        t, c_prev, t_prev = 0.0, cov(s), 0.0
        c0 = c_prev
        t_cap = min(MIX_CIRCULATION_CAP * circ, MIX_SUBSTEP_CAP * dt)
        res["cap_s"] = t_cap
        while t < t_cap:
            for _ in range(k_sub):
                s = mat @ s
            t += dt_chunk
            c = cov(s)
            if c <= MIX_COV * 1.0 and res["mixing_time_s"] is None:
                # log-linear interpolation between the two samples
                if c_prev > MIX_COV and c > 0:
                    frac = math.log(c_prev / MIX_COV) / math.log(c_prev / c)
                    res["mixing_time_s"] = t_prev + frac * (t - t_prev)
                else:
                    res["mixing_time_s"] = t
                if c > 0 and c_prev > c:
                    res["variance_efold_s"] = 0.5 * (t - t_prev) / math.log(c_prev / c)
                break
            if c > 0 and c_prev > c:
                res["variance_efold_s"] = 0.5 * (t - t_prev) / math.log(c_prev / c)
            c_prev, t_prev = c, t
        res["tracer_cov_start"] = c0
        self._mixing = res
        return res

    def report(self) -> dict:
        """JSON-able account: CFL, substeps, split step, flux correction, mixing, timings
        (seconds of wall time and per cell-substep / per cell-split-step costs)."""
        c = self._count
        out = {
            "scheme": "first-order upwind on the solids flux, explicit; states per unit "
                      "solids volume; closed active set",
            "splitting": self.splitting, "split_step_s": self.split_step,
            "split_step_source": self.split_step_source,
            "courant_limit": self.courant, "dt_max_s": self.dt_max,
            "max_courant_used": c["max_courant_used"],
            "max_out_rate_per_s": float(self.out_rate.max()) if self.out_rate.size else 0.0,
            "active_cells": self.n, "flux": dict(self.flux_stats),
            "split_steps": c["split_steps"], "transport_calls": c["transport_calls"],
            "substeps": c["substeps"],
            "substeps_per_split_step": c["substeps"] / c["split_steps"] if c["split_steps"]
            else None,
            "qmom_binder_repairs": c["repaired_cells"],
            "qmom_binder_repair_max_rel_change": c["repair_max_rel_change"],
            "transport_wall_s": c["transport_s"], "source_wall_s": c["source_s"],
            "transport_first_call_s": c.get("first_call_s", 0.0),
            "timing_note": "transport timings exclude the first call (kernel loading)",
            "transport_s_per_cell_substep": c["transport_s"] / (c["timed_substeps"] * self.n)
            if c["timed_substeps"] and self.n else None,
            "source_s_per_cell_split_step": c["source_s"] / (c["split_steps"] * self.n)
            if c["split_steps"] and self.n else None,
        }
        out["mixing"] = self.mixing()
        return out


# ---------------------------------------------------------------------------- building
@dataclass(frozen=True)
class TransportSettings:
    """What the transport operator reads of the scene (``transport_settings``; SI).

    courant         the largest Courant number of a substep [-]
    split_step      the scene's split step [s] (None: ``DEFAULT_SPLIT_STEP``)
    splitting       "lie" or "strang"
    output_interval the scene's output interval [s] (the split step never exceeds it)
    repairs         True if the method may need its projection of mixed states
                    (``MethodEntry.repairs_mixture``)
    """
    courant: float
    split_step: float | None
    splitting: str
    output_interval: float
    repairs: bool


def transport_settings(scene) -> TransportSettings:
    """The ``TransportSettings`` of a validated scene with a ``[transport]`` table."""
    from ..methods.registry import method_of, method_plan
    t = scene.transport
    return TransportSettings(courant=t.courant, split_step=t.split_step,
                             splitting=t.splitting, output_interval=scene.output_interval,
                             repairs=bool(method_of(scene).repairs_mixture(method_plan(scene))))


def transport_of_scene(scene, domain, active: np.ndarray, rows: np.ndarray) -> Transport:
    """``build_transport`` of a scene outside a run (``pbe-cfd plan``, studies): its settings,
    and where the method repairs mixed states its arrays packed with the coupled scales of
    the active cells and its method data."""
    from ..physics import parameters as P
    settings = transport_settings(scene)
    arrays = aux = None
    if settings.repairs:
        from ..methods.registry import method_of
        from ..runs import model
        from ..runs.domain import coupled_scales
        idx = np.flatnonzero(np.asarray(active, dtype=bool))
        scaled = coupled_scales(scene, np.asarray(rows[idx, P.ALPHA], dtype=float))
        arrays = model.pack(scaled)
        aux = method_of(scene).aux(scaled, arrays, None)
    return build_transport(settings, domain, active, rows, arrays=arrays, aux=aux)


def build_transport(settings: TransportSettings, domain, active: np.ndarray,
                    rows: np.ndarray, arrays=None, aux=None) -> Transport:
    """The transport operator of a coupled run (built once).

    settings: the run's ``TransportSettings`` (courant [-], split_step [s], splitting);
    domain: couple.Domain whose ``flux`` is a FaceFlux [m3/s] and ``cells`` has
    cell_volume [m3] and cell_centre [m]; active: (n_cells,) bool over all mesh cells;
    rows: (n_cells, N_CELL) cell rows (ALPHA [-] is the solids fraction used, INJECTION
    [droplets/(m3 s)] marks the spray zone for the mixing-time tracer); arrays: the run's
    packed arrays (``model.pack`` of the coupled scales) and aux its method data, for the
    method's projection of mixed states (needed where ``settings.repairs``).
    """
    from ..physics import parameters as P

    if domain.flux is None:
        raise ValueError("build_transport: the domain has no face flux (load it with "
                         "need_flux=True)")
    active = np.asarray(active, dtype=bool)
    idx = np.flatnonzero(active)
    alpha = np.asarray(rows[idx, P.ALPHA], dtype=float)
    volume = np.asarray(domain.cells.cell_volume, dtype=float)[idx]
    if domain.flux.n_cells != active.size:
        raise ValueError(f"build_transport: flux mesh has {domain.flux.n_cells} cells, the "
                         f"domain {active.size}")
    if settings.repairs and (arrays is None or aux is None):
        raise ValueError("build_transport: the method repairs mixed states: expected the "
                         "run's packed arrays and aux (``transport_of_scene`` packs them)")
    warnings = []
    holds = alpha > 0.0
    if not holds.all():
        warnings.append(f"transport: {int((~holds).sum())} active cells have alpha = 0 and "
                        "are left out of the transport")
    mask = np.zeros(active.size, dtype=bool)
    mask[idx[holds]] = True
    af = restrict_and_correct(domain.flux, mask)
    # map the flux's cell set (active with alpha > 0) into the active ordering
    pos = np.searchsorted(idx, af.cells)
    af_active = ActiveFlux(cells=idx, owner=pos[af.owner], neighbour=pos[af.neighbour],
                           flux=af.flux, raw_flux=af.raw_flux, stats=af.stats)
    safe_alpha = np.where(holds, alpha, 1.0)
    gen, out_rate = upwind_generator(af_active, safe_alpha, volume)
    rmax = float(out_rate.max()) if out_rate.size else 0.0
    courant = float(settings.courant)
    dt_max = courant / rmax if rmax > 0 else math.inf
    split, split_src = _split_step(settings, dt_max)
    st = af.stats
    if st["correction_l1_rel"] > 0.2:
        warnings.append(f"transport: the divergence correction changed the solids flux by "
                        f"{100 * st['correction_l1_rel']:.0f}% (L1): the averaged flux is far "
                        "from steady on the active set, most often because the case's "
                        "averaging window includes the start-up (start its fieldAverage "
                        "later with timeStart)")
    centre = np.asarray(domain.cells.cell_centre, dtype=float)[idx]
    spray = np.asarray(rows[idx, P.INJECTION], dtype=float) > 0.0
    if spray.any():
        tracer = spray & holds
    else:
        axis = vertical_axis(centre)
        tracer = holds & (centre[:, axis] >= np.quantile(centre[:, axis], 0.9))
    circ = circulation_time(af_active, centre, alpha * volume)
    tr = Transport(n=idx.size, alpha=safe_alpha, volume=volume, generator=gen,
                   out_rate=out_rate, courant=courant, dt_max=dt_max, split_step=split,
                   split_step_source=split_src, splitting=settings.splitting, flux_stats=st,
                   tracer_cells=tracer, circulation_time=circ, warnings=warnings)
    tr.repair = _mixture_repair(settings, arrays, aux)
    return tr


def _split_step(settings, dt_max):
    """The split step [s] and where it came from (the scene, or the default)."""
    if settings.split_step is not None:
        return min(float(settings.split_step), settings.output_interval), "scene"
    return min(DEFAULT_SPLIT_STEP, settings.output_interval), "default"


#: Split step used when the scene does not set one [s] (see the module docstring; the
#: splitting-error study in tests/transport/test_transport.py and the issue note justify it).
DEFAULT_SPLIT_STEP = 0.25


def _mixture_repair(settings, arrays, aux):
    """A callable re-projecting the cells whose mixed state is not on the method's closure
    (``MethodEntry.on_closure``; QMOM: node-wise binder outside [0, p_a]), or None where the
    method's ``repairs_mixture`` says mixing keeps its states on it (``settings.repairs``)."""
    if not settings.repairs:
        return None
    params, config = arrays.params, arrays.config

    def repair(states):
        return cells_off_closure(states, aux, params, config, fix=True)

    return repair


@nb.njit(cache=True)
def _repair_cells(on_closure, project, states, aux, params, config, changed, work, fix):
    """Count the cells whose state is not on the method's closure and, if ``fix``,
    re-project them; ``changed[c]`` the largest relative change of an entry. on_closure,
    project: the method's closure test (``MethodEntry.closure_test``) and projection as
    first-class functions (``integrate.kernel_types``, the integration kernel's signatures):
    this kernel compiles once for every method, and only the scene's method's functions are
    compiled."""
    count = 0
    n_state = states.shape[1]
    before = np.empty(n_state)
    for c in range(states.shape[0]):
        if on_closure(states[c], aux, params, config, work):
            continue
        count += 1
        if not fix:
            continue
        before[:] = states[c]
        project(states[c], aux, params, config, work)
        worst = 0.0
        for k in range(n_state):
            scale = abs(before[k])
            if scale > 0.0:
                worst = max(worst, abs(states[c, k] - before[k]) / scale)
        changed[c] = worst
    return count


_REPAIR_KERNELS = {}


def _repair_kernel(method, args):
    """The compiled ``_repair_cells`` for the types of ``args`` and the entry points of the
    method's closure test and projection (compiled, or loaded from numba's disk cache, on
    first use; found by the arguments' layout afterwards)."""
    key = (int(method),) + tuple(layout_key(a) for a in args)
    found = _REPAIR_KERNELS.get(key)
    if found is None:
        sigs = signatures(*args[1:4])
        functions = (closure_check_address(method, sigs), addresses_of(method, sigs).project)
        sig = ((types.FunctionType(sigs.realizable), types.FunctionType(sigs.project))
               + tuple(typeof(a) for a in args))
        _repair_cells.compile(sig)
        found = (_repair_cells.overloads[sig].entry_point, functions)
        _REPAIR_KERNELS[key] = found
    return found


def cells_off_closure(states, aux, params, config, fix=False):
    """Number of rows of ``states`` (scaled moment states, one row per cell) that are not on
    the closure of the method config[METHOD] (``MethodEntry.closure_test``); with ``fix``
    they are re-projected in place by its projection.
    Returns (count, largest relative change of any entry of a re-projected cell)."""
    from ..methods.entry import WORK_SIZE
    from ..physics import parameters as P
    given = np.asarray(states)
    # the method's functions take C-contiguous rows: another layout is checked on a copy
    states = np.ascontiguousarray(given)
    changed = np.zeros(states.shape[0])
    args = (states, aux, params, config, changed, np.empty(WORK_SIZE), bool(fix))
    entry, functions = _repair_kernel(int(config[P.METHOD]), args)
    counted = []
    caught = faults.watched(lambda: counted.append(
        entry(*functions, *args)))
    if caught.count:
        raise faults.MethodRaised(
            f"the method's closure test or projection raised {caught.first} on "
            f"{states.shape[0]} transported cell state(s) ({caught.count} time(s))")
    n = counted[0]
    if fix and n and states is not given:
        given[...] = states
    return int(n), float(changed.max()) if changed.size else 0.0


# ---------------------------------------------------------------------------- plan
def transport_plan_lines(scene) -> list[str]:
    """Lines for ``pbe-cfd plan``: the flux used, its correction, the CFL substep [s], the
    split step [s] and the mixing time of the bed [s] (reads the domain and its flux)."""
    from ..runs.domain import build_cells, load_domain

    t = scene.transport
    domain = load_domain(scene, need_flux=True)
    rows, active, spray, _ = build_cells(scene, domain.cells)
    tr = transport_of_scene(scene, domain, active, rows)
    st = tr.flux_stats
    mix = tr.mixing()
    lines = [f"  transport flux: {st['field']} at t = {domain.flux.time:g} s, "
             f"{st['faces_inside']} faces inside the {tr.n} active cells, "
             f"total |flux| {st['flux_inside_m3_s']:.3g} m3/s",
             f"    closed active set: flux cut at its edge "
             f"{100 * st['cut_at_active_edge_rel']:.2g}%, at the outer boundary {100 * st['cut_at_boundary_rel']:.2g}% of the inside flux",
             f"    divergence-free correction: {100 * st['correction_l1_rel']:.3g}% of the flux "
             f"(L1), largest face change {100 * st['correction_max_rel']:.3g}% of the largest "
             f"face flux; residual divergence {st['divergence_after_rel']:.1e}"]
    k, dt = tr.substeps(0.5 * tr.split_step if t.splitting == "strang" else tr.split_step)
    rmax = float(tr.out_rate.max()) if tr.out_rate.size else 0.0
    if rmax > 0:
        lines.append(f"  transport CFL: Courant <= {tr.courant:g} gives substeps <= "
                     f"{tr.dt_max:.4g} s (fastest cell exchanges its solids in "
                     f"{1.0 / rmax:.4g} s)")
    else:
        lines.append("  transport CFL: no flux inside the active set, nothing moves")
    lines.append(f"  transport split step: {tr.split_step:g} s ({t.splitting}, "
                 f"{tr.split_step_source}); {k} substep(s) of {dt:.4g} s per transport part")
    if mix["mixing_time_s"] is not None:
        lines.append(f"  bed mixing time: {mix['mixing_time_s']:.3g} s (spray-zone tracer "
                     f"CoV to {MIX_COV:g}; variance e-folds in {mix['variance_efold_s']:.3g} s)"
                     f"; circulation time (solids volume / upward flux) "
                     f"{mix['circulation_time_s']:.3g} s")
    elif "cap_s" not in mix:
        lines.append("  bed mixing time: none (no solids flux inside the active set)")
    else:
        lines.append(f"  bed mixing time: above {mix['cap_s']:.3g} s (spray-zone "
                     f"tracer CoV not down to {MIX_COV:g}); circulation time "
                     f"{mix['circulation_time_s']:.3g} s")
    return lines
