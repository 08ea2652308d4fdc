"""Size-distribution outputs: the d10/d50/d90/span columns, ``psd.csv`` and ``columns.json``.

``psd.csv`` (long format, one row per output time and diameter): ``time_s`` [s], ``d_m`` [m]
(log-spaced), ``Q3`` the mass (volume) fraction of the granules below d [-], ``q3_per_ln_d``
[-] the mean of dQ3/d(ln d) over the class [d e^(-h/2), d e^(h/2)] (h the grid's spacing in
ln d; the density per unit ln d, which integrates to 1 over ln d), and for bivariate scenes
``binder_fraction`` the granules' binder mass over granule mass in that class [-]. The cNMC
adds ``q3_lo``/``q3_hi``, the replicas' 95% band of q3, on its own lattice classes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernel_mixture, lognormal_mixture
from . import reconstruct as R
from ..methods.registry import method_of
from .quantiles import FRACTIONS, DistributionError, check_grid_covers, log_grid
from ..physics.injection import droplet_mass

#: the size columns added to moments.csv, bed_moments.csv and the VTK cell fields
SIZE_COLUMNS = ("d10_m", "d50_m", "d90_m", "span")
#: points of a reconstruction's psd.csv grid, and the mass fractions that bound it
PSD_POINTS = 40
GRID_FRACTIONS = (1.0e-4, 1.0 - 1.0e-4)
GRID_MARGIN = 1.25

#: the reconstructions of ``[method] size_distribution`` (docs/physics.md section 11.1)
SUPPORT, SEMI_INFINITE, EXPANSION = "support", "semi-infinite", "expansion"


def support_floor(scene) -> float:
    """The granules' smallest possible mass p_min [kg]: without breakage no granule is below
    the smallest initial granule's solids (a monodisperse start of mass p0 [kg]: p0, or
    (1 - binder fraction) p0 with drying; droplets counted as particles lower it to their mass
    p_d [kg], to 0 with drying); 0 with breakage or an initial distribution reaching 0."""
    init = scene.initial
    if scene.breakage is not None or init.distribution != "monodisperse":
        return 0.0
    drying = scene.drying is not None
    floor = init.mean_mass * ((1.0 - init.binder_fraction) if drying else 1.0)
    inj = scene.binder_injection
    if not scene.separate_droplets and (inj is not None or init.droplet_number_density > 0):
        p_d = (0.0 if inj is None else
               droplet_mass(inj.droplet_diameter, scene.material.binder_density))
        floor = 0.0 if drying else min(floor, p_d)
    return float(floor)


def size_distribution(scene) -> str:
    """The scene's reconstruction: ``[method] size_distribution``, or the method's first."""
    chosen = getattr(scene.method, "size_distribution", None)
    offered = method_of(scene).distributions
    return chosen if chosen is not None else (offered[0] if offered else "")


def _support_kernels(entry, order):
    """Gamma kernels of the support fit: None for the quadrature nodes (the row's distinct
    nodes less one), N for the EQMOM (its M00 .. M(2N)0), (m - 1) // 2 for the Laguerre ROM
    of order m (its carried M00 .. M(m-1)0; one kernel at least)."""
    return {"gamma": None, "kernel_mixture": order,
            "laguerre_density": max(1, (order - 1) // 2)}[entry.distribution]


@dataclass(frozen=True)
class DistributionPlan:
    """What the size-distribution outputs read of the scene, computed once
    (``distribution_plan``; SI).

    method          the method's registry entry (its reconstruction, its texts)
    method_name     the scene's ``[method] name`` (messages)
    choice          the reconstruction (``size_distribution``: "support", "semi-infinite",
                    "expansion"; "" none)
    floor           the support's smallest granule mass p_min [kg] (0: on [0, inf))
    kernels         gamma kernels of the support fit (``_support_kernels``; None: the
                    quadrature nodes' count, or no reconstruction)
    density         granule material density [kg/m3]
    bivariate       True if the granules carry binder
    text            the reconstruction in words (columns.json, ``plan``)
    """
    method: object
    method_name: str
    choice: str
    floor: float
    kernels: int | None
    density: float
    bivariate: bool
    text: str


def distribution_plan(scene) -> DistributionPlan:
    """The ``DistributionPlan`` of a validated scene."""
    entry = method_of(scene)
    kind, choice = entry.distribution, size_distribution(scene)
    floor = support_floor(scene) if choice == SUPPORT else 0.0
    kernels = _support_kernels(entry, entry.order(scene.method)) if kind is not None else None
    return DistributionPlan(method=entry, method_name=scene.method.name, choice=choice,
                            floor=floor, kernels=kernels, density=scene.material.density,
                            bivariate=scene.bivariate,
                            text=_text(entry, choice, floor, kernels, scene.bivariate))


def reconstruction_of(plan: DistributionPlan, arrays, states, aux, populations, labels=str):
    """The reconstruction of a moment method's scaled states (rows: times or cells);
    ``plan`` the run's ``DistributionPlan``, ``populations``: the rows' weighted particles
    from ``model.moment_outputs``."""
    kind, choice = plan.method.distribution, plan.choice
    rho, bivariate = plan.density, plan.bivariate
    if kind is None:
        raise DistributionError(f"method {plan.method_name!r}: no size-distribution "
                                "reconstruction")
    if choice == EXPANSION:
        return R.laguerre_table(states, aux, arrays, bivariate, labels)
    floor = plan.floor
    if kind == "kernel_mixture" and floor == 0.0:         # the EQMOM's own kernels
        own = lognormal_mixture if lognormal_mixture.is_lognormal(aux) else kernel_mixture
        return own.of_states(states, aux, arrays, rho, bivariate, labels)
    return kernel_mixture.of_nodes(populations, rho, bivariate, labels, floor=floor,
                                   kernels=plan.kernels,
                                   signed=kind == "laguerre_density")


def distribution_text(scene) -> str:
    """The scene's reconstruction in words (columns.json, ``plan``)."""
    return distribution_plan(scene).text


def _text(entry, choice, floor, n, bivariate) -> str:
    """The reconstruction in words: ``entry`` the method's registry entry, ``choice`` its
    ``size_distribution``, ``floor`` p_min [kg], ``n`` the support fit's kernels."""
    kind = entry.distribution
    if kind is None or choice in (EXPANSION, ""):
        return entry.distribution_text
    if kind == "kernel_mixture" and floor == 0.0:
        return entry.distribution_text
    n = n or 0
    if kind == "gamma":
        fitted = ("N - 1 gamma kernels of one width (one for N = 2) fitted to the carried "
                  "M00 .. M(2N-2)0")
    elif kind == "kernel_mixture":
        fitted = f"{n} gamma kernels of one width refitted to the carried M00 .. M{2 * n}0"
    else:
        fitted = (f"{n} gamma kernel{'s' * (n > 1)} of one width fitted to the carried "
                  f"M00 .. M{2 * n}0")
    where = (f"on [p_min, inf), p_min = {floor:.4g} kg the smallest granule possible (no "
             "breakage), moments of p - p_min" if floor > 0 else
             "on [0, inf)" + (" (no floor: breakage, or a start reaching 0)"
                              if choice == SUPPORT else ""))
    if kind == "laguerre_density":
        where += ("; a positive density by construction, where the ROM's own expansion "
                  "(size_distribution = \"expansion\") can dip below zero")
    binder = ("; binder fraction per size class interpolated in ln p between the nodes' "
              "binder values" if bivariate else "")
    return f"{fitted} {where} ([method] size_distribution = \"{choice}\"){binder}"


def size_columns(recon, labels=str) -> tuple[dict, list]:
    """({d10_m, d50_m, d90_m [m], span [-]} per row, notes): mass-based percentiles; 0 in a
    row without granules. A row whose percentile cannot be found is named in the notes and
    gets 0 (never a silent NaN)."""
    q = np.asarray(recon.quantiles(FRACTIONS), dtype=float)
    notes = list(recon.notes)
    bad = ~np.all(np.isfinite(q), axis=1)
    if np.any(bad):
        rows = np.flatnonzero(bad)
        notes.append(f"size distribution: no percentile found at {R._rows_text(rows, labels)} "
                     "(the cumulative does not reach the fraction); d10, d50, d90 set to 0 "
                     "there")
        q[bad] = 0.0
    d10, d50, d90 = q[:, 0], q[:, 1], q[:, 2]
    span = np.where(d50 > 0, (d90 - d10) / np.where(d50 > 0, d50, 1.0), 0.0)
    return {"d10_m": d10, "d50_m": d50, "d90_m": d90, "span": span}, notes


def auto_grid(recon, points: int = PSD_POINTS) -> np.ndarray:
    """Log-spaced diameters [m] from GRID_MARGIN below the smallest row's Q3 = 1e-4 to
    GRID_MARGIN above the largest row's Q3 = 1 - 1e-4; DistributionError without granules."""
    full = ~np.asarray(recon.empty)
    if not np.any(full):
        raise DistributionError("size distribution: no granules at any output time, no "
                                "diameter grid to draw it on")
    if hasattr(recon, "bounds"):           # a bed mixture: its rows' own range bounds it
        lo, hi = recon.bounds(GRID_FRACTIONS)
        q = np.column_stack([lo[:, 0], hi[:, 1]])
    else:
        q = np.asarray(recon.quantiles(GRID_FRACTIONS), dtype=float)[full]
    q = q[np.all(np.isfinite(q) & (q > 0), axis=1)]
    if q.size == 0:
        raise DistributionError("size distribution: no row has percentiles to bound a grid")
    return log_grid(float(q[:, 0].min()) / GRID_MARGIN, float(q[:, 1].max()) * GRID_MARGIN,
                    points)


#: the run's note where no output time holds granules (no size-distribution file)
NO_GRANULES = ("size distribution: no granules at any output time (nothing to reconstruct): "
               "no psd.csv, psd.png or cell_psd.csv written; d10, d50, d90 and span are 0")


def psd_if_granules(times, recon) -> tuple[dict | None, list]:
    """``psd_columns`` of ``recon`` on its own grid, or (None, [NO_GRANULES]) where no row
    holds granules (a scene whose population has not formed by its end: droplets sprayed
    with no granules to capture them)."""
    if not np.any(~np.asarray(recon.empty)):
        return None, [NO_GRANULES]
    return psd_columns(times, recon)


def psd_columns(times, recon, grid=None, band=None) -> tuple[dict, list]:
    """(psd.csv columns, notes) of a reconstruction with one row per output time ``times``
    [s] on ``grid`` [m] (default ``auto_grid``). ``band``: (q3_lo, q3_hi) per row and grid
    point (the cNMC's) or None."""
    grid = auto_grid(recon) if grid is None else np.asarray(grid, dtype=float)
    h = math.log(grid[1] / grid[0])
    lo, hi = grid * math.exp(-0.5 * h), grid * math.exp(0.5 * h)
    n = grid.size
    points = np.concatenate([grid, lo[:1], hi])    # the class edges: lo[1:] = hi[:-1]
    if hasattr(recon, "psd_rows"):   # a bed's mixtures: the rows' Q3 evaluated once for both
        at, binder = recon.psd_rows(points, lo, hi, np.arange(n, 2 * n + 1))
    else:
        at, binder = recon.cdf(points), recon.class_binder(lo, hi)
    big_q, edges = at[:, :n], at[:, n:]
    q3 = (edges[:, 1:] - edges[:, :-1]) / h
    cols = {"time_s": np.repeat(np.asarray(times, float), grid.size),
            "d_m": np.tile(grid, len(times)), "Q3": big_q.ravel(), "q3_per_ln_d": q3.ravel()}
    if binder is not None:
        cols["binder_fraction"] = binder.ravel()
    if band is not None:
        cols["q3_lo"], cols["q3_hi"] = (np.asarray(b, float).ravel() for b in band)
    notes = []
    full = ~np.asarray(recon.empty)
    if np.any(full):
        note = check_grid_covers(edges[full, 0], edges[full, -1], grid, "psd.csv")
        if note:
            notes.append(note)
    return cols, notes


def cnmc_psd_columns(times, result, bivariate) -> tuple[dict | None, list]:
    """(psd.csv columns, notes) of a cNMC ensemble on its own lattice classes (those holding
    mass at some time, one class of margin each side), with the replicas' band of q3; (None,
    [NO_GRANULES]) where no replica holds granules at any output time."""
    table = R.cnmc_table(result, bivariate)
    mean = np.asarray(result["psd_mass_fraction"], float)
    used = np.flatnonzero(mean.max(axis=0) > 0)
    if used.size == 0:
        return None, [NO_GRANULES]
    a, b = max(used[0] - 1, 0), min(used[-1] + 2, mean.shape[1])
    edges = table.log_edges
    grid = np.exp(0.5 * (edges[a:b] + edges[a + 1:b + 1]))
    h = edges[1] - edges[0]
    band = (np.asarray(result["psd_mass_fraction_lo"])[:, a:b] / h,
            np.asarray(result["psd_mass_fraction_hi"])[:, a:b] / h)
    return psd_columns(times, table, grid, band)


#: bed_moments.csv columns that are totals over the bed, not volume-weighted means
BED_TOTALS = {
    "bed_mass_kg": "the particles' mass in the bed, free droplets included: the sum over the "
                   "cells of M10 times the cell volume [kg]",
    "bed_binder_mass_kg": "the binder mass in the bed, free droplets included: the sum over the "
                          "cells of M01 times the cell volume [kg]"}


def column_labels(plan: DistributionPlan, state_names, columns, bed: bool = False) -> dict:
    """name -> what the column is: carried (a moment of the method's state), derived or
    reconstructed (how), for the columns.json sidecar; ``plan`` the run's
    ``DistributionPlan``."""
    entry = plan.method
    how = plan.text
    out = {}
    for name in columns:
        base = name[:-3] if name.endswith(("_lo", "_hi")) else name
        if name == "time_s":
            text = "time [s]"
        elif not entry.integrated:
            text = ("estimated from the particle lists: mean of the replicas"
                    + ("; _lo/_hi the 95% band of that mean" if base != name else ""))
        elif base in state_names:
            text = "carried: an entry of the method's state"
        elif base.startswith("M"):
            text = "reconstructed, not carried: " + entry.moments_text
        elif base in ("d32_m", "d43_m"):
            text = "derived from the method's population (nodes or reconstruction) [m]"
        elif base == "binder_fraction":
            text = "derived: M01 / M10 [-]"
        else:
            text = BED_TOTALS.get(base, "")
        if base in SIZE_COLUMNS:
            text = (f"reconstructed size distribution, mass-based "
                    f"{'span (d90 - d10)/d50 [-]' if base == 'span' else 'percentile [m]'}: "
                    + how)
        text = text or "derived"
        if bed and name != "time_s" and base not in BED_TOTALS:
            text = "bed (volume-weighted over the cells): " + text
        out[name] = text
    return out


def psd_file_labels(plan: DistributionPlan, columns) -> dict:
    """columns.json's entry for psd.csv ({"psd.csv": ``psd_labels``}), or {} where the run
    has no psd.csv (``columns`` None: no granules at any output time)."""
    return {} if columns is None else {"psd.csv": psd_labels(plan, columns)}


def psd_labels(plan: DistributionPlan, columns) -> dict:
    """name -> meaning of the psd.csv columns (``plan`` the run's ``DistributionPlan``)."""
    how = plan.text
    texts = {"time_s": "time [s]", "d_m": "diameter [m], log-spaced",
             "Q3": "reconstructed: mass fraction of the granules below d [-]; " + how,
             "q3_per_ln_d": "reconstructed: mean of dQ3/d(ln d) over the class [d e^(-h/2), "
                            "d e^(h/2)], h the grid spacing in ln d [-]",
             "binder_fraction": "reconstructed: binder mass / granule mass in the class [-]",
             "q3_lo": "lower end of the replicas' 95% band of q3 [-]",
             "q3_hi": "upper end of the replicas' 95% band of q3 [-]"}
    return {c: texts[c] for c in columns}
