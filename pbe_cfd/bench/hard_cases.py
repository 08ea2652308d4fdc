"""The hard-case variants (``pbe-cfd bench hard-cases``): does the hard cell finish by default,
for every method, over Theta, the gap to packing and the Stokes switch, and how far is it from
a tight-tolerance run of the same variant.

The cell (docs/results/hard-cases.md): a well-mixed ktgf cell (``study-ktgf``: eke kernel with
the geometric and physical efficiency, friction cap alpha_min_friction = 0.5, packing
alpha_max = 0.62) at alpha = alpha_max - gap, granular temperature Theta [m2/s2], k0 = 1e-3,
binder droplets injected at 1e4 x the seed rate (``SEED_RATE``), the viscous Stokes criterion
sharp (width 0, the default) or smooth of the width ``SMOOTH_WIDTH`` (0.005, wider than the
fallback width of ``runs.batch``). Each method runs with the [method] table of its bundled scene
(``METHODS``).

A variant at the default rtol 1e-8 is compared with the same variant at ``REFERENCE_RTOL``
(atol scaled alike): the largest relative difference over the output times of M00, M20 and d43.
Under the sharp switch the reference may itself stall while a pair slides along St = St* and
continue smoothed; the row then says from when (``ref smoothed from``), and the difference is
partly the smoothing's. The cNMC has no tolerance: its row states the 95% band of its
replicas (half-width relative to the mean, largest over the outputs of M00, M20) and its
difference from the QMOM N = 3 reference of the same variant, in units of that half-width.
"""
from __future__ import annotations

import dataclasses
import math
import re
import time
from pathlib import Path

import numpy as np

from ..methods.eqmom import ENTRY as EQMOM
from ..physics.injection import droplet_mass
from ..runs.batch import SimulationError
from ..runs.simulate import run_well_mixed
from ..scene.scene import SceneError, load_scene
from .common import _git_describe, _machine_line, _say, _write_simple, machine_info

SEED_RATE = 1.485e8          # droplets/(m3 s): the seed scene's injection
INJECTION_FACTOR = 1e4       # the hard case's injection / the seed rate
K0 = 1e-3                    # the hard case's aggregation rate constant
THETAS = (1e-6, 1e-2, 2.0, 10.0)          # m2/s2
PACKING_GAPS = (1e-5, 1e-3)               # alpha_max - alpha [-]
FRICTION_CAP = 0.5           # study-ktgf's alpha_min_friction: g0 is evaluated at min(alpha, it)
#: (alpha_max - alpha [-], alpha_min_friction or None): under the cap both gaps are one cell for
#: the rates (tests/bench/test_bench_hard_cases.py), so it runs at the smaller
CELLS = ((PACKING_GAPS[0], FRICTION_CAP),) + tuple((g, None) for g in PACKING_GAPS)
SMOOTH_WIDTH = 0.005        # relative width of the grid's smooth switch [-] (ours: the column of
#                             docs/results/hard-cases.md; the fallback's is STOKES_FALLBACK_WIDTH)
WIDTHS = (0.0, SMOOTH_WIDTH)
DEFAULT_RTOL = 1e-8
REFERENCE_RTOL = 1e-10
END_TIME = 0.2               # s (the study); outputs every END_TIME / 10
QUICK_END_TIME = 0.02        # s (quick)
CNMC_PARTICLES, CNMC_REPLICAS = 500, 8

#: (label, bundled scene whose [method] table is used, changes to that table)
METHODS = (("QMOM N = 2", "study-ktgf", {"nodes": 2}),
           ("QMOM N = 3", "study-ktgf", {}),
           ("CQMOM 2 x 2", "seed-wurster-cqmom", {}),
           ("CQMOM 3 x 3", "seed-wurster-cqmom", {"nodes": 3, "binder_nodes": 3}),
           ("EQMOM N = 3", "study-ktgf", {"name": EQMOM.name}),
           ("Laguerre m = 3", "seed-wurster-laguerre", {}),
           # the ROM whose weight and support follow the wet class (its range: the granules'
           # mass grows up to ~1e5-fold next to packing, docs/results/hard-cases.md)
           ("Laguerre m = 3 following", "seed-wurster-laguerre",
            {"following_support": True, "following_growth": 1e6}),
           ("cNMC", "seed-wurster-cnmc", {"particles": CNMC_PARTICLES,
                                          "replicas": CNMC_REPLICAS}))
METHOD_LABELS = tuple(m[0] for m in METHODS)
QUANTITIES = ("M00", "M20", "d43_m")


def injection_rate() -> float:
    """The hard case's droplet injection [1/(m3 s)]."""
    return INJECTION_FACTOR * SEED_RATE


def variant_scene(label, theta, gap, width, rtol=DEFAULT_RTOL, end=END_TIME,
                  cap=FRICTION_CAP):
    """The hard cell (module doc) with the method ``label`` of ``METHODS``, Theta [m2/s2],
    alpha = alpha_max - gap [-], Stokes switch width [-], rtol [-] (atol 1e-14 rtol / 1e-8
    [moment units]), to ``end`` [s] with ten outputs; ``cap``: alpha_min_friction [-] (None:
    g0 at alpha itself, ~ 3 alpha_max / gap)."""
    _, source, changes = next(m for m in METHODS if m[0] == label)
    s = load_scene("study-ktgf")
    method = load_scene(source).method
    if changes:
        method = method.replaced(**changes)
    method = dataclasses.replace(method, rtol=rtol, atol=1e-14 * rtol / 1e-8)
    alpha = s.domain.alpha_max - gap
    return dataclasses.replace(
        s, end_time=end, output_interval=end / 10,
        domain=dataclasses.replace(s.domain, solids_fraction=alpha, granular_temperature=theta,
                                   alpha_min_friction=cap),
        aggregation=dataclasses.replace(s.aggregation, rate=K0),
        binder_injection=dataclasses.replace(s.binder_injection, rate=injection_rate()),
        material=dataclasses.replace(s.material, stokes_switch_width=width),
        method=method)


_SMOOTHED_AT = re.compile(r"sharp viscous Stokes criterion .* at t = ([0-9.eE+-]+) s")


def smoothed_from(warnings):
    """The time [s] from which the run continued with the smooth fallback switch, or None."""
    for w in warnings:
        m = _SMOOTHED_AT.search(w)
        if m:
            return float(m.group(1))
    return None


def run(scene):
    """One run of ``scene``: (RunResult or None, the stop message or None, wall [s])."""
    start = time.perf_counter()
    try:
        res = run_well_mixed(scene)
    except (SimulationError, SceneError, FloatingPointError) as exc:
        return None, " ".join(str(exc).split()), time.perf_counter() - start
    return res, None, time.perf_counter() - start


def checks(scene, res) -> dict:
    """What a finished run must satisfy: finite moments; realizable output sets (M00 M20 >=
    M10^2 and 0 <= M01 <= M10, 1e-12 round-off); M10 growing at exactly the injected droplet
    mass rate (its largest relative deviation [-])."""
    c = res.columns
    finite = all(bool(np.all(np.isfinite(c[k]))) for k in ("M00", "M10", "M01", "M20", "d43_m"))
    realizable = bool(np.all(c["M20"] * c["M00"] >= c["M10"] ** 2 * (1 - 1e-12))
                      and np.all((c["M01"] >= 0) & (c["M01"] <= c["M10"] * (1 + 1e-12))))
    mat = scene.binder_injection
    rate = mat.rate * droplet_mass(mat.droplet_diameter, scene.material.binder_density)
    mass = float(np.max(np.abs(c["M10"] - (c["M10"][0] + rate * c["time_s"])) / c["M10"]))
    return {"finite": finite, "realizable": realizable, "M10_rel_err": mass}


def largest_difference(got, ref) -> float:
    """Largest relative difference [-] of M00, M20, d43 over the output times."""
    return max(float(np.max(np.abs(got[k] - ref[k]) / np.abs(ref[k]))) for k in QUANTITIES)


def band_half_width(res) -> float:
    """The cNMC's 95% band of its replicas: largest half-width relative to the mean [-] over
    the output times of M00 and M20."""
    c = res.columns
    return max(float(np.max(0.5 * (c[k + "_hi"] - c[k + "_lo"]) / np.abs(c[k])))
               for k in ("M00", "M20") if k + "_hi" in c)


def run_variant(label, theta, gap, cap, width, end=END_TIME, reference=True,
                qmom_reference=None):
    """One row of the study: the variant at the default rtol and (``reference``) at
    REFERENCE_RTOL; for the cNMC, its band and the difference from ``qmom_reference`` (the
    columns of QMOM N = 3 at REFERENCE_RTOL). Returns (row, the default run's columns or
    None, the reference's columns or None)."""
    row = {"method": label, "theta": theta, "gap": gap, "cap": cap, "width": width,
           "end_s": end}
    scene = variant_scene(label, theta, gap, width, end=end, cap=cap)
    res, stop, wall = run(scene)
    row.update(finished=res is not None, stop=stop, wall_s=round(wall, 3))
    if res is None:
        return row, None, None
    row.update(checks(scene, res))
    row.update(smoothed_from=smoothed_from(res.warnings),
               accepted_steps=int(res.stats.get("accepted_steps", 0)),
               switch_steps=int(res.stats.get("stokes_switch_steps", 0)),
               M00=float(res.columns["M00"][-1]), M20=float(res.columns["M20"][-1]),
               d43_m=float(res.columns["d43_m"][-1]))
    ref_cols = None
    if label == "cNMC":
        half = band_half_width(res)
        row["band"] = half
        if qmom_reference is not None:
            row["diff_qmom3_ref"] = largest_difference(res.columns, qmom_reference)
        return row, res.columns, None
    if reference:
        ref, ref_stop, ref_wall = run(variant_scene(label, theta, gap, width, REFERENCE_RTOL,
                                                    end, cap))
        row.update(ref_finished=ref is not None, ref_stop=ref_stop,
                   ref_wall_s=round(ref_wall, 3))
        if ref is not None:
            ref_cols = ref.columns
            row["ref_smoothed_from"] = smoothed_from(ref.warnings)
            row["diff_ref"] = largest_difference(res.columns, ref.columns)
    return row, res.columns, ref_cols


def variants(quick=False):
    """The (label, Theta, gap, cap, width) of the study: every method x THETAS x CELLS x
    WIDTHS; quick: every method at Theta 2 m2/s2 under the cap, both switches."""
    if quick:
        return [(m, 2.0) + CELLS[0] + (w,) for m in METHOD_LABELS for w in WIDTHS]
    return [(m, th) + cell + (w,) for m in METHOD_LABELS for th in THETAS for cell in CELLS
            for w in WIDTHS]


def _fmt(x, spec=".2g"):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def _outcome(r):
    if not r["finished"]:
        return "**stops**: " + (r["stop"] or "")[:200]
    bad = [k for k in ("finite", "realizable") if not r.get(k)]
    text = "yes" if not bad else "yes, not " + " / ".join(bad)
    if r.get("smoothed_from") is not None:
        text += f" (smoothed from {r['smoothed_from']:.4g} s)"
    return text


def _against(r):
    if "band" in r:
        d = r.get("diff_qmom3_ref")
        return (f"band +-{_fmt(r['band'])}; QMOM N = 3 ref. {_fmt(d)}"
                + (f" ({d / r['band']:.1f} half-widths)" if d is not None and r["band"] > 0
                   else ""))
    if "ref_finished" not in r:
        return "-"
    if not r["ref_finished"]:
        return "ref. stops: " + (r["ref_stop"] or "")[:120]
    text = _fmt(r.get("diff_ref"))
    if r.get("ref_smoothed_from") is not None:
        text += f" (ref. smoothed from {r['ref_smoothed_from']:.4g} s)"
    return text


def markdown(rows, end, info) -> str:
    """The study's table: one line per variant."""
    lines = ["| method | Theta [m2/s2] | alpha_max - alpha (friction cap) | switch | finished "
             "| accepted steps (across a switch) | M00 [1/m3] | d43 [mm] | M10 exact to | "
             "difference from rtol 1e-10 (M00, M20, d43) | wall [s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        switch = "sharp" if r["width"] == 0.0 else f"smooth {r['width']:g}"
        steps = (f"{r['accepted_steps']} ({r['switch_steps']})" if r["finished"] else "-")
        lines.append(
            f"| {r['method']} | {r['theta']:g} | {r['gap']:g} ({r['cap'] or 'none'}) | "
            f"{switch} | {_outcome(r)} | "
            f"{steps} | {_fmt(r.get('M00'), '.6g')} | "
            f"{_fmt(r.get('d43_m') and r['d43_m'] * 1e3, '.4g')} | "
            f"{_fmt(r.get('M10_rel_err'))} | {_against(r)} | {r['wall_s']:.3g} |")
    lines += ["", f"End time {end:g} s, ten outputs; rtol 1e-8 against rtol "
              f"{REFERENCE_RTOL:g}; cNMC {CNMC_PARTICLES} particles x {CNMC_REPLICAS} "
              "replicas. Machine: " + _machine_line(info) + " (wall times include waiting "
              "for the CPU; not a benchmark)."]
    return "\n".join(lines) + "\n"


def study_rows(quick=False, quiet=False, end=None, only=None):
    """Run ``variants(quick)`` (``only``: labels to keep) to ``end`` [s] (END_TIME, quick:
    QUICK_END_TIME); one progress line per variant. Returns the rows."""
    end = end or (QUICK_END_TIME if quick else END_TIME)
    todo = [v for v in variants(quick) if only is None or v[0] in only]
    qmom_refs = {}
    rows = []
    for i, (label, theta, gap, cap, width) in enumerate(todo):
        key = (theta, gap, cap, width)
        if label == "cNMC" and key not in qmom_refs:
            _, _, qmom_refs[key] = run_variant("QMOM N = 3", *key, end)
        row, _, ref = run_variant(label, *key, end, qmom_reference=qmom_refs.get(key))
        if label == "QMOM N = 3":
            qmom_refs[key] = ref
        rows.append(row)
        _say(quiet, f"hard-cases {i + 1}/{len(todo)}: {label}, Theta {theta:g}, gap {gap:g}, "
                    f"cap {cap}, width {width:g}: {_outcome(row)[:80]}; {_against(row)[:60]}")
    return rows


def hard_cases_study(out_dir, quick=False, quiet=False) -> dict:
    """Run ``study_rows`` and write hard-cases.csv/.md/.json into ``out_dir``."""
    info = machine_info()
    end = QUICK_END_TIME if quick else END_TIME
    rows = study_rows(quick=quick, quiet=quiet, end=end)
    result = {"machine": info, "commit": _git_describe(), "rows": rows, "quick": quick,
              "end_time_s": end}
    _write_simple(Path(out_dir), "hard-cases", rows, markdown(rows, end, info), result)
    return result
