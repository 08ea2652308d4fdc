"""Outputs of a two-way coupled run (``runs.coupling``): the per-segment table, the
defluidisation check, and the coupled outputs across segments.

Per segment (``segments.csv``, ``segments.png``, summary.json ``coupling``): process and CFD
times [s], the particle diameter the CFD used [m], the bed expansion (solids-volume-weighted
mean alpha [-] and the height holding 99% of the solids volume [m]), the spread of Theta
(10/50/90% of the solids volume [m2/s2]), the spray zone (cells, volume [m3]), the bed's d32,
d43 and mass at the segment's end, Wen & Yu's U_mf [m/s] against the inlet velocity [m/s], and
the wall seconds of CFD and population balance. The VTK series, bed_moments.csv and psd.csv
run across the segments (at each boundary the time of the segment before); every VTK file
holds the process time (its time value) and ``cfd_time_s`` (the CFD time of its fields).
"""
from __future__ import annotations

import numpy as np

from .couple import CoupledResult, _bed_distribution, _cell_psd, _outputs, select_psd_cells
from ..physics.fluidisation import minimum_fluidisation_velocity

#: fraction of the solids volume below the bed height [-] (ours: a bed surface that ignores
#: the few particles thrown into the freeboard)
BED_HEIGHT_FRACTION = 0.99


def _weighted_quantiles(values, weights, qs):
    order = np.argsort(values)
    v, w = values[order], weights[order]
    c = np.cumsum(w) / np.sum(w)
    return [float(v[min(np.searchsorted(c, q), v.size - 1)]) for q in qs]


def gravity_axis(domain) -> int:
    """The vertical axis of the mesh (0, 1, 2): the one the cell centres span furthest
    (the bundled bed is 0.6 m high, 0.15 m wide)."""
    centre = np.asarray(domain.cells.cell_centre, dtype=float)
    return int(np.argmax(np.ptp(centre, axis=0)))


def bed_state(domain, active, spray) -> dict:
    """Bed expansion, Theta spread and spray zone of one segment's CFD fields (SI)."""
    cells = domain.cells
    alpha = np.asarray(cells.alpha, dtype=float)
    theta = np.asarray(cells.theta, dtype=float)
    vol = np.asarray(cells.cell_volume, dtype=float)
    solids = alpha * vol
    z = np.asarray(cells.cell_centre, dtype=float)[:, gravity_axis(domain)]
    (height,) = _weighted_quantiles(z - z.min(), solids, [BED_HEIGHT_FRACTION])
    a = active
    t10, t50, t90 = _weighted_quantiles(theta[a], solids[a], [0.1, 0.5, 0.9])
    return {"mean_alpha": float(np.sum(alpha[a] * vol[a]) / np.sum(vol[a])),
            "bed_height_m": height + 0.5 * float(np.median(np.cbrt(vol))),
            "theta_p10_m2_s2": t10, "theta_p50_m2_s2": t50, "theta_p90_m2_s2": t90,
            "theta_mean_m2_s2": float(np.sum(theta[a] * solids[a]) / np.sum(solids[a])),
            "active_cells": int(np.count_nonzero(a)), "spray_cells": int(np.count_nonzero(spray)),
            "spray_volume_m3": float(np.sum(vol[spray]))}


def umf_of(plan, fluid: dict, d: float) -> float:
    """Wen & Yu's U_mf [m/s] of granules of diameter d [m] and the density [kg/m3] of
    ``plan`` (the run's ``coupling.TwoWayPlan``) in the case's gas (nan when the case does
    not give the gas's density and viscosity)."""
    if fluid.get("gas_density") is None or fluid.get("gas_viscosity") is None:
        return float("nan")
    return minimum_fluidisation_velocity(d, plan.density, fluid["gas_density"],
                                         fluid["gas_viscosity"])


def defluidisation_warning(plan, fluid, d, t) -> str | None:
    """The warning when granules of d32 = d [m] at process time t [s] have a minimum
    fluidisation velocity at or above ``warn_fraction`` of the inlet's (None otherwise);
    ``plan``: the run's ``coupling.TwoWayPlan``."""
    u_in = fluid.get("inlet_velocity")
    umf = umf_of(plan, fluid, d)
    frac = plan.coupling.warn_fraction
    if u_in is None or not np.isfinite(umf) or umf < frac * u_in:
        return None
    state = ("the bed is defluidised: U_mf exceeds it" if umf >= u_in else
             "the bed stops bubbling when U_mf reaches it")
    return (f"defluidisation: at t = {t:g} s the granules' d32 = {d * 1e6:.4g} um has a "
            f"minimum fluidisation velocity U_mf = {umf:.4g} m/s (Wen & Yu 1966), "
            f"{100 * umf / u_in:.0f}% of the inlet's superficial velocity {u_in:.4g} m/s "
            f"([coupling] warn_fraction = {frac:g}); {state}")


def segment_rows(run) -> dict:
    """The columns of segments.csv (one row per segment, SI) of a ``coupling.TwoWayRun``."""
    cols = {}
    fluid = run.fluidisation
    for seg in run.segments:
        row = {"segment": seg.index, "process_start_s": seg.t_start,
               "process_end_s": seg.t_end, "cfd_time_s": seg.cfd_time,
               "cfd_window_start_s": seg.cfd_window[0] if seg.cfd_window else np.nan,
               "diameter_m": seg.diameter, "d32_end_m": seg.d32_end,
               **bed_state(seg.domain, seg.active, seg.spray),
               "u_mf_m_s": umf_of(run.plan, fluid, seg.diameter),
               "inlet_velocity_m_s": fluid.get("inlet_velocity") or np.nan,
               "cfd_wall_s": seg.cfd_wall_s, "pbe_wall_s": seg.pbe_wall_s}
        for key, value in row.items():
            cols.setdefault(key, []).append(value)
    return {k: np.asarray(v, dtype=float) for k, v in cols.items()}


def defluidisation_warnings(run) -> list:
    """One warning per segment of a ``coupling.TwoWayRun`` whose CFD diameter, or the final
    d32, nears U_mf = U_inlet."""
    out = []
    for seg in run.segments:
        w = defluidisation_warning(run.plan, run.fluidisation, seg.diameter, seg.t_start)
        if w:
            out.append(w)
    last = run.segments[-1]
    w = defluidisation_warning(run.plan, run.fluidisation, last.d32_end, last.t_end)
    if w and w not in out:
        out.append(w)
    return out


def combined_result(run, wall_s: float) -> CoupledResult:
    """The coupled outputs across the segments of a ``coupling.TwoWayRun`` (what they read of
    the scene: its ``outputs``): cell fields and bed columns at every output time (a
    boundary's time once, from the segment that ended there), psd and labels."""
    from ..io.spool import Spool
    times, fields, mixtures, bed, cell_ids = [], Spool(), Spool(), {}, []
    plan = run.outputs
    warnings = list(run.warnings)
    first = run.segments[0]
    selection = select_psd_cells(plan, first.domain.cells, first.active)
    for seg in run.segments:
        cf, b, mx = _outputs(plan, run.arrays, seg.aux, seg.domain.cells, seg.active,
                             seg.spray, seg.idx, seg.times, seg.history, warnings)
        skip = 1 if seg.index > 0 else 0
        for f in cf[skip:]:          # one output time in memory at a time
            f["cfd_time_s"] = np.full(seg.domain.cells.n_cells, seg.cfd_time)
            f["segment"] = np.full(seg.domain.cells.n_cells, float(seg.index))
            fields.append(f)
        cf.close()
        times.extend(seg.times[skip:])
        for k in range(skip, len(mx)):  # likewise
            mixtures.append(mx[k])
        mx.close()
        cell_ids.extend([seg.idx] * (len(mx) - skip))
        for name, values in b.items():
            bed.setdefault(name, []).extend(np.asarray(values)[skip:])
    times = np.asarray(times)
    bed = {k: np.asarray(v, dtype=float) for k, v in bed.items()}
    warnings.extend(defluidisation_warnings(run))
    psd, labels = _bed_distribution(plan, run.arrays, times, bed, mixtures, fields, warnings)
    cell_psd = _cell_psd(plan, selection, times, mixtures, cell_ids, psd, labels, warnings)
    mixtures.close()
    stats = {"cells": int(run.segments[0].domain.cells.n_cells), "segments": len(run.segments),
             "active_cells": int(run.segments[-1].idx.size),
             "cfd_wall_s": float(sum(s.cfd_wall_s for s in run.segments)),
             "pbe_wall_s": float(sum(s.pbe_wall_s for s in run.segments))}
    return CoupledResult(times=times, cell_fields=fields, bed_columns=bed, stats=stats,
                         wall_time_s=wall_s, warnings=warnings,
                         compile_time_s=run.compile_time_s, psd=psd, labels=labels,
                         plan=plan, cell_psd=cell_psd)


def plot_segments(path, cols, title: str, metadata=None):
    """segments.png: per segment (steps over process time) the CFD's particle diameter and the
    bed's d32 at the end [um], the bed expansion, the spread of Theta, U_mf against the inlet."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t0, t1 = cols["process_start_s"], cols["process_end_s"]
    edges = np.append(t0, t1[-1])

    def steps(ax, values, **kw):
        ax.stairs(values, edges, **kw)

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
    ax = axes[0, 0]
    steps(ax, cols["diameter_m"] * 1e6, label="CFD particle diameter")
    ax.plot(t1, cols["d32_end_m"] * 1e6, "o", label="bed d32 at segment end")
    ax.set_ylabel("diameter [um]")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    steps(ax, cols["mean_alpha"], label="mean alpha (active cells)")
    ax.set_ylabel("mean alpha [-]")
    ax2 = ax.twinx()
    steps(ax2, cols["bed_height_m"], color="C1", label="bed height (99% of solids)")
    ax2.set_ylabel("bed height [m]", color="C1")
    ax.legend(fontsize=8, loc="lower left")
    ax = axes[1, 0]
    for q, ls in (("p10", ":"), ("p50", "-"), ("p90", "--")):
        steps(ax, cols[f"theta_{q}_m2_s2"], linestyle=ls, label=f"Theta {q} (solids volume)")
    ax.set_yscale("log")
    ax.set_ylabel("Theta [m2/s2]")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    steps(ax, cols["u_mf_m_s"], label="U_mf of the CFD diameter (Wen & Yu)")
    steps(ax, cols["inlet_velocity_m_s"], linestyle="--", label="inlet superficial velocity")
    ax.set_ylabel("velocity [m/s]")
    ax.legend(fontsize=8)
    for a in axes.flat:
        a.set_xlabel("process time [s]")
    fig.suptitle(title)
    fig.savefig(path, dpi=110, metadata=metadata)
    plt.close(fig)
