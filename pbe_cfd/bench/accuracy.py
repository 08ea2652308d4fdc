"""The accuracy study: each method over its accuracy knob against a reference (analytic, or a
far larger cNMC ensemble), with wall times (``pbe-cfd bench accuracy``)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from ..runs import model
from ..runs.batch import output_times
from ..physics import parameters as P
from ..methods.registry import METHOD_REGISTRY, METHODS
from ..scene.scene import SceneError, load_scene
from ..runs.simulate import run_well_mixed
from .analytic import analytic_applicable, analytic_reference
from .accuracy_report import write_accuracy
from .common import _git_describe, _say, machine_info

#: quantities compared by the accuracy study (columns of RunResult)
QUANTITIES = ("M00", "M20", "M11", "M02", "d43_m", "binder_fraction", "d50_m")
#: chosen comparison times as fractions of the scene's end time (snapped to output times)
TIME_FRACTIONS = (0.1, 0.5, 1.0)
DEFAULT_ACCURACY_SCENE = "study-seed"


# ============================================================================ cNMC reference
def _reference_cache_dir():
    base = os.environ.get("PBE_CFD_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "pbe_cfd"))
    return Path(base) / "bench"


def _cnmc_source_digest():
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for rel in ("methods/cnmc/ensemble.py", "physics/kernels.py", "physics/efficiency.py",
                "physics/rates.py", "physics/properties.py", "runs/model.py"):
        h.update((root / rel).read_bytes())
    return h.hexdigest()[:16]


def cnmc_reference(scene, particles, replicas, seed=97, use_cache=True, quiet=True):
    """cNMC ensemble reference of a scene (mean and 95% band per output time), cached on disk
    under $PBE_CFD_CACHE/bench (default ~/.cache/pbe_cfd/bench) by scene, size and source."""
    raw = {k: v for k, v in scene.raw.items() if k != "method"}
    key = hashlib.sha256(json.dumps({"scene": raw, "end": scene.end_time,
                                     "interval": scene.output_interval,
                                     "particles": int(particles), "replicas": int(replicas),
                                     "seed": int(seed), "src": _cnmc_source_digest()},
                                    sort_keys=True, default=str).encode()).hexdigest()[:24]
    path = _reference_cache_dir() / f"cnmc_ref_{key}.npz"
    if use_cache and path.exists():
        try:
            data = np.load(path)
            cols = {k: data[k] for k in data.files if k != "__wall"}
            return cols, float(data["__wall"]), True
        except (OSError, ValueError, KeyError):
            pass
    _say(quiet, f"  reference: cNMC {particles:g} particles x {replicas} replicas ...")
    start = time.perf_counter()
    res = run_well_mixed(scene.with_method(name=reference_method().name,
                                           particles=int(particles), replicas=int(replicas),
                                           seed=int(seed)))
    wall = time.perf_counter() - start
    cols = {k: np.asarray(v, dtype=float) for k, v in res.columns.items()}
    if use_cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
            np.savez(tmp, __wall=wall, **cols)
            os.replace(tmp, path)
        except OSError:
            pass
    return cols, wall, False


def reference_method():
    """The registry entry of the particle ensemble (the method run per replica, not per
    cell: ``MethodEntry.ensemble``) that gives the accuracy study's reference."""
    return next(e for e in METHOD_REGISTRY if e.ensemble is not None)


# ============================================================================ accuracy study
@dataclasses.dataclass
class Variant:
    """One method at one setting of its accuracy knob."""
    method: str          # the method's registered name
    label: str           # short knob label, e.g. "N=3", "m=3 fine consistent", "1e4 x 4"
    changes: dict        # Method fields for Scene.with_method

    @property
    def name(self):
        return f"{self.method} {self.label}"


def accuracy_variants(quick=False) -> list:
    """The knob settings the accuracy study runs: each registered method's
    ``accuracy_knobs`` (in registry order)."""
    return [Variant(e.name, label, dict(changes, name=e.name))
            for e in METHOD_REGISTRY if e.accuracy_knobs is not None
            for label, changes in e.accuracy_knobs(quick)]


def chosen_times(scene, fractions=TIME_FRACTIONS):
    """Output times nearest to the fractions of the end time (unique, > 0)."""
    grid = output_times(scene)
    idx = sorted({int(np.argmin(np.abs(grid - f * scene.end_time))) for f in fractions})
    return [i for i in idx if grid[i] > 0], grid


def _relative_errors(cols, ref, indices, quantities):
    """{quantity: [signed relative error at each index]} for the quantities both have."""
    errs = {}
    for q in quantities:
        if q not in cols or q not in ref:
            continue
        vals = []
        for i in indices:
            r = float(ref[q][i])
            v = float(cols[q][i])
            vals.append((v - r) / abs(r) if r != 0.0 and math.isfinite(r) else float("nan"))
        errs[q] = vals
    return errs


def run_variant(scene, variant, repeats=3, quiet=True):
    """Run one variant ``repeats`` + 1 times: (first-call wall [s], median wall [s] of the
    repeats, columns, stats). Raises what run_well_mixed raises."""
    sc = scene.with_method(**variant.changes)
    t0 = time.perf_counter()
    res = run_well_mixed(sc)
    first = time.perf_counter() - t0
    walls = []
    for _ in range(max(0, repeats)):
        t0 = time.perf_counter()
        res = run_well_mixed(sc)
        walls.append(time.perf_counter() - t0)
    median = statistics.median(walls) if walls else first
    return first, median, res.columns, res.stats


def table_build_time(scene, variant):
    """Seconds to build the variant's tables from scratch (no disk cache), or None for a
    method without tables (``MethodEntry.table_build``)."""
    build = METHODS[variant.method].table_build
    if build is None:
        return None
    return build(scene.with_method(**variant.changes), model.pack, model.well_mixed_cell)


def accuracy_study(scene_name=None, out_dir="bench-out", quick=False, repeats=None,
                   variants=None, reference=None, quiet=False) -> dict:
    """Run the accuracy study on a well-mixed scene (default: study-seed; quick: study-analytic)
    and write accuracy.csv, accuracy.md, pareto.png and accuracy.json into ``out_dir``.
    Returns the rows and the reference info.

    reference: None (automatic: analytic if available, else a cNMC ensemble of 1e6 particles x
    16 replicas, quick: 2e4 x 4) or (particles, replicas) to force a cNMC reference size.
    """
    scene = load_scene(scene_name or (DEFAULT_ACCURACY_SCENE if not quick else "study-analytic"))
    if scene.domain.type != "well-mixed":
        raise SceneError(scene.source, "domain.type",
                         "the accuracy study runs well-mixed scenes: expected \"well-mixed\"")
    repeats = (1 if quick else 3) if repeats is None else repeats
    variants = variants if variants is not None else accuracy_variants(quick)
    idx, grid = chosen_times(scene)
    machine = machine_info()
    _say(quiet, f"accuracy study on {scene.name}: {len(variants)} variants, times "
         f"{', '.join(f'{grid[i]:g}' for i in idx)} s")

    # ---- reference
    if reference is None and analytic_applicable(scene):
        ref, ref_info = analytic_reference(scene, grid)
        ref_info["band"] = {q: 0.0 for q in QUANTITIES}
        if "d50_lattice_step" in ref_info:      # the lattice's step at the chosen times
            ref_info["band"]["d50_m"] = max(ref_info["d50_lattice_step"][i] for i in idx)
    else:
        particles, replicas = reference if reference is not None else (
            (20000, 4) if quick else (1_000_000, 16))
        cols, wall, cached = cnmc_reference(scene, particles, replicas, quiet=quiet)
        ref = cols
        band = {}
        for q in QUANTITIES:
            if q + "_lo" in cols:
                half = 0.5 * (cols[q + "_hi"] - cols[q + "_lo"])
                rel = [abs(half[i] / cols[q][i]) if cols[q][i] != 0 else float("nan")
                       for i in idx]
                band[q] = float(np.nanmax(rel)) if rel else float("nan")
        ref_info = {"kind": reference_method().name, "particles": particles, "replicas": replicas,
                    "wall_s": wall, "cached": cached, "band": band,
                    "text": f"cNMC ensemble of {particles:g} particles x {replicas} replicas "
                            f"({particles * replicas:.2g} particle-replicas, "
                            f"{'cached' if cached else f'{wall:.0f} s'}); its 95% band "
                            "half-width per quantity is listed"}

    # ---- variants
    rows = []
    for v in variants:
        _say(quiet, f"  {v.name} ...")
        row = {"method": v.method, "knob": v.label, "settings": dict(v.changes)}
        try:
            first, median, cols, stats = run_variant(scene, v, repeats=repeats)
        except Exception as exc:  # noqa: BLE001 - a failing variant is a result, not a crash
            row.update(status=f"failed: {type(exc).__name__}: {exc}".splitlines()[0][:300],
                       wall_s=float("nan"), first_call_s=float("nan"), errors={},
                       max_abs_error=float("nan"))
            rows.append(row)
            continue
        errs = _relative_errors(cols, ref, idx, QUANTITIES)
        finite = [abs(e) for vals in errs.values() for e in vals if math.isfinite(e)]
        row.update(status="ok", wall_s=median, first_call_s=first,
                   first_call_extra_s=max(first - median, 0.0), errors=errs,
                   max_abs_error=max(finite) if finite else float("nan"),
                   steps=stats.get("accepted_steps"), rhs_calls=stats.get("rhs_calls"),
                   trials=stats.get("trials"))
        try:
            build = table_build_time(scene, v)
        except Exception as exc:  # noqa: BLE001 - reported in the row
            build = float("nan")
            row["tensor_build_error"] = str(exc)
        if build is not None:
            row["tensor_build_s"] = build
        if METHODS[v.method].ensemble is not None:
            row["own_band"] = {q: float(np.nanmax([abs(0.5 * (cols[q + "_hi"][i]
                                                              - cols[q + "_lo"][i])
                                                         / cols[q][i]) for i in idx]))
                               for q in QUANTITIES if q + "_lo" in cols}
        rows.append(row)
    result = {"scene": scene.name, "scene_source": scene.source,
              "times_s": [float(grid[i]) for i in idx], "reference": ref_info,
              "repeats": repeats, "quick": quick, "machine": machine,
              "commit": _git_describe(), "rows": rows}
    write_accuracy(Path(out_dir), result)
    return result


# ---- accuracy outputs
