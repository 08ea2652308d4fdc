"""What accuracy costs in time: ``pbe-cfd bench accuracy | throughput | cnmc | laguerre | couple``.

accuracy (``accuracy_study``)
    Each method over its accuracy knob -- QMOM nodes 1-4; Laguerre ROM order 2-4 on a coarse
    and a fine grid, moment-consistent and plain; cNMC particles 1e3-1e5 with replicas -- run on
    one well-mixed scene. Relative errors of M00, M20, M11, M02, d43 and the mean binder fraction
    M01/M10 at chosen times against a reference: the analytic solution where the scene has one
    (``analytic_reference``: constant kernel, droplets as ordinary particles), otherwise a cNMC
    ensemble far larger than any tested one, whose own 95% band is reported beside it. Wall time
    is the median of repeated runs; the first call (numba compilation or cache load, Laguerre
    tensor build) is reported apart. Writes accuracy.csv, accuracy.md, pareto.png, accuracy.json.

throughput (``throughput_study``)
    Cell-RHS evaluations per second and cell-steps per second of the shared integrator against
    the number of cells and numba threads, for QMOM N = 2, 3, 4 and the Laguerre ROM m = 2, 3, 4
    (Theta-interpolated tensor) with the ktgf kernel and the geometric and physical efficiency;
    the kernel-only rate (QMOM: the pair-rate evaluations its RHS needs; Laguerre: the bare
    quadratic-form contraction) as the ceiling and each method's share of it; and a plain
    NumPy/SciPy QMOM (``NumpyQMOM``: Wheeler and ``numpy.linalg.eigh`` per call, Python loops)
    integrated per cell by ``scipy.integrate.solve_ivp``, giving the speed-up as a ratio.
    Writes throughput.csv, throughput.md, throughput.png, machine.json.

cnmc, laguerre, couple
    Seed-scenario cNMC speed per replica (trials and accepted events per second); Laguerre
    tensor build time per order and grid and its RHS rate; cell-steps per second of
    ``run_coupled`` on the bundled small bed and on its cells replicated to ~3600 cells.

Every study accepts ``quick`` (a tiny configuration for tests: well under a minute once numba's
cache is warm). Numbers are measured, never asserted.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numba as nb
import numpy as np

from . import integrate, model
from .methods.dispatch import WORK_SIZE, method_rhs
from .methods.qmom import invert as _qmom_invert
from .physics.kernels import kernel_cell_factor as _cell_factor
from .physics import parameters as P
from .physics.properties import N_PROPS, particle_properties
from .physics.rates import pair_rate

#: quantities compared by the accuracy study (columns of RunResult)
QUANTITIES = ("M00", "M20", "M11", "M02", "d43_m", "binder_fraction")
#: chosen comparison times as fractions of the scene's end time (snapped to output times)
TIME_FRACTIONS = (0.1, 0.5, 1.0)
DEFAULT_ACCURACY_SCENE = "study-seed"
DEFAULT_THROUGHPUT_SCENE = "study-ktgf"


# ============================================================================ machine, timing
def machine_info() -> dict:
    """The machine the numbers were measured on (cores, CPU, load, versions)."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    import scipy
    return {"cpu": cpu, "logical_cores": os.cpu_count(),
            "numba_threads": nb.config.NUMBA_NUM_THREADS,
            "load_average_1_5_15min": [round(x, 2) for x in load],
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": nb.__version__,
            "platform": platform.platform()}


def _machine_line(info) -> str:
    la = info["load_average_1_5_15min"]
    return (f"{info['cpu'] or 'unknown CPU'}, {info['logical_cores']} logical cores, numba "
            f"{info['numba']} with {info['numba_threads']} threads; load average "
            f"{la[0]:.1f} / {la[1]:.1f} / {la[2]:.1f} (1 / 5 / 15 min) when the study started")


def _git_describe() -> str:
    try:
        import subprocess
        root = Path(__file__).resolve().parent.parent
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=5)
        return out.stdout.strip()
    except Exception:  # noqa: BLE001 - informative only
        return ""


def _say(quiet, text):
    if not quiet:
        print(text, file=sys.stderr, flush=True)


# ============================================================================ analytic reference
def analytic_applicable(scene) -> bool:
    """True if the scene's moments have the closed form of ``analytic_reference``: a
    well-mixed constant kernel without efficiency factors, droplets (if any) ordinary particles."""
    agg = scene.aggregation
    return (scene.domain.type == "well-mixed" and agg is not None and agg.kernel == "constant"
            and not agg.efficiency and not scene.separate_droplets)


def analytic_moments(scene, times) -> dict:
    """Closed-form moments [SI] of the two-component constant kernel with injection.

    With k0 the kernel [m3/s], R the injection [droplets/(m3 s)] of droplets of mass p_d (pure
    binder, ordinary particles), A = M10(0), C = M01(0), B = R p_d, the moment equations
    (DESIGN section 3, the constant kernel's gains 2 p p', p b' + p' b, 2 b b')
        dM00/dt = R - k0 M00^2 / 2,            dM10/dt = dM01/dt = B,
        dM20/dt = k0 M10^2 + R p_d^2,  dM11/dt = k0 M10 M01 + R p_d^2,  dM02/dt = k0 M01^2 + R p_d^2
    close and integrate to
        M00 = N_inf (N0 + N_inf tanh(s t)) / (N_inf + N0 tanh(s t)),  N_inf = sqrt(2 R / k0),
              s = k0 N_inf / 2   (R = 0: M00 = 2 N0 / (2 + k0 N0 t)),
        M10 = A + B t,  M01 = C + B t,
        M20 = M20(0) + R p_d^2 t + k0 (A^2 t + A B t^2 + B^2 t^3 / 3),
        M11 = M11(0) + R p_d^2 t + k0 (A C t + (A + C) B t^2 / 2 + B^2 t^3 / 3),
        M02 = M02(0) + R p_d^2 t + k0 (C^2 t + C B t^2 + B^2 t^3 / 3),
    and the mean binder fraction M01 / M10. Initial moments include free droplets.
    """
    if not analytic_applicable(scene):
        raise ValueError(f"{scene.source}: no closed form (needs a well-mixed constant kernel "
                         "without efficiency and without droplet_factor)")
    t = np.asarray(times, dtype=float)
    k0 = scene.aggregation.rate
    inj = scene.binder_injection
    rate = inj.rate if inj is not None else 0.0
    pd = (model.droplet_mass(inj.droplet_diameter, scene.material.binder_density)
          if inj is not None else 0.0)
    nd0 = scene.initial.droplet_number_density

    def m0(i, j):
        return model.size_moment(scene, i, j) + nd0 * pd ** (i + j)

    n0 = m0(0, 0)
    a_, c_ = m0(1, 0), m0(0, 1)
    b_ = rate * pd
    if rate > 0.0:
        n_inf = math.sqrt(2.0 * rate / k0)
        th = np.tanh(0.5 * k0 * n_inf * t)
        m00 = n_inf * (n0 + n_inf * th) / (n_inf + n0 * th)
    else:
        m00 = 2.0 * n0 / (2.0 + k0 * n0 * t)
    src2 = rate * pd * pd * t
    out = {
        "time_s": t,
        "M00": m00,
        "M10": a_ + b_ * t,
        "M01": c_ + b_ * t,
        "M20": m0(2, 0) + src2 + k0 * (a_ * a_ * t + a_ * b_ * t ** 2 + b_ * b_ * t ** 3 / 3.0),
        "M11": m0(1, 1) + src2 + k0 * (a_ * c_ * t + 0.5 * (a_ + c_) * b_ * t ** 2
                                       + b_ * b_ * t ** 3 / 3.0),
        "M02": m0(0, 2) + src2 + k0 * (c_ * c_ * t + c_ * b_ * t ** 2 + b_ * b_ * t ** 3 / 3.0),
    }
    out["binder_fraction"] = np.where(out["M10"] > 0, out["M01"] / out["M10"], 0.0)
    return out


def _lattice_unit(scene):
    """(unit mass u [kg], granule index q, droplet index r) with p0 = q u and p_d = r u (r = 0
    without droplets), or None if the masses do not share a small lattice."""
    if scene.initial.distribution != "monodisperse":
        return None
    p0 = scene.initial.mean_mass
    inj = scene.binder_injection
    if inj is None:
        return (p0, 1, 0) if scene.initial.droplet_number_density == 0 else None
    pd = model.droplet_mass(inj.droplet_diameter, scene.material.binder_density)
    for r in range(1, 7):
        q = p0 * r / pd
        if round(q) >= 1 and abs(q - round(q)) < 1e-9 * q:
            return pd / r, int(round(q)), r
    return None


def smoluchowski_d43(scene, times, rtol=1e-10):
    """d43 [m] (and the lattice's M00 [1/m3], as a check) of the constant-kernel scene from the
    discrete Smoluchowski equation on the mass lattice n u (granules at n = q, droplets
    entering at n = r; ``_lattice_unit``):
        dc_n/dt = k0/2 sum_{i+j=n} c_i c_j - k0 c_n sum_i c_i + R delta_(n, r),
    truncated at L = 60 x the largest mean size (+64) cells, integrated by DOP853 at rtol 1e-10.
    The mass beyond the lattice is reported (``lost_mass_share``). Returns None if the masses do
    not share a small lattice (then the study has no d43 reference)."""
    from scipy.integrate import solve_ivp

    lat = _lattice_unit(scene)
    if lat is None:
        return None
    unit, q, r = lat
    times = np.asarray(times, dtype=float)
    ana = analytic_moments(scene, times)
    mean_max = float(np.max(ana["M10"] / ana["M00"])) / unit
    size = int(60 * mean_max) + 64
    k0 = scene.aggregation.rate
    inj = scene.binder_injection
    rate = inj.rate if inj is not None else 0.0
    scale = max(float(ana["M00"].max()), 1.0)
    c0 = np.zeros(size + 1)              # index n = 1..size (index 0 unused)
    c0[q] += scene.initial.number_density / scale
    if r > 0:
        c0[r] += scene.initial.droplet_number_density / scale
    kk = k0 * scale

    def rhs(_t, c):
        conv = np.convolve(c, c)[:size + 1]
        dc = 0.5 * kk * conv - kk * c * c.sum()
        if r > 0:
            dc[r] += rate / scale
        return dc

    sol = solve_ivp(rhs, (0.0, float(times[-1])), c0, method="DOP853", t_eval=times,
                    rtol=rtol, atol=1e-14 * c0.max())
    if not sol.success:
        return None
    n = np.arange(size + 1)
    d = np.cbrt(6.0 * n * unit / (math.pi * scene.material.density))
    c = sol.y
    d43 = (d ** 4) @ c / np.maximum((d ** 3) @ c, 1e-300)
    mass = (n * unit) @ c * scale
    lost = float(np.max(np.abs(mass - ana["M10"]) / ana["M10"]))
    return {"time_s": times, "d43_m": d43, "M00": c.sum(axis=0) * scale,
            "lost_mass_share": lost, "lattice_cells": size, "unit_kg": unit}


def analytic_reference(scene, times) -> dict:
    """Reference columns at ``times``: closed-form moments and binder fraction, d43 from the
    discrete Smoluchowski solution where the masses share a lattice. ``info`` says how each
    was obtained and how well the lattice reproduces the closed-form M00."""
    ref = analytic_moments(scene, times)
    info = {"kind": "analytic",
            "text": "closed-form moments of the constant kernel with injection "
                    "(bench.analytic_moments)"}
    lat = smoluchowski_d43(scene, times)
    if lat is not None:
        ref["d43_m"] = lat["d43_m"]
        check = float(np.max(np.abs(lat["M00"] - ref["M00"]) / ref["M00"]))
        info["text"] += (f"; d43 from the discrete Smoluchowski equation on {lat['lattice_cells']}"
                         f" lattice masses (its M00 within {check:.1e} of the closed form, mass "
                         f"beyond the lattice {lat['lost_mass_share']:.1e})")
        info["d43_lattice_m00_check"] = check
    else:
        info["text"] += "; no d43 reference (masses not on a common lattice)"
    return ref, info


# ============================================================================ cNMC reference
def _reference_cache_dir():
    base = os.environ.get("PBE_CFD_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "pbe_cfd"))
    return Path(base) / "bench"


def _cnmc_source_digest():
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for rel in ("methods/cnmc.py", "physics/kernels.py", "physics/efficiency.py",
                "physics/rates.py", "physics/properties.py", "model.py"):
        h.update((root / rel).read_bytes())
    return h.hexdigest()[:16]


def cnmc_reference(scene, particles, replicas, seed=97, use_cache=True, quiet=True):
    """cNMC ensemble reference of a scene (mean and 95% band per output time), cached on disk
    under $PBE_CFD_CACHE/bench (default ~/.cache/pbe_cfd/bench) by scene, size and source."""
    from .simulate import run_well_mixed

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
    res = run_well_mixed(scene.with_method(name="cnmc", particles=int(particles),
                                           replicas=int(replicas), seed=int(seed)))
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


# ============================================================================ accuracy study
@dataclasses.dataclass
class Variant:
    """One method at one setting of its accuracy knob."""
    method: str          # qmom | laguerre | cnmc
    label: str           # short knob label, e.g. "N=3", "m=3 fine consistent", "1e4 x 4"
    changes: dict        # Method fields for Scene.with_method

    @property
    def name(self):
        return f"{self.method} {self.label}"


def accuracy_variants(quick=False) -> list:
    """The knob settings the accuracy study runs (see module doc)."""
    out = []
    for n in ((1, 2, 3) if quick else (1, 2, 3, 4)):
        out.append(Variant("qmom", f"N={n}", {"name": "qmom", "nodes": n}))
    grids = {"coarse": 8, "fine": 12} if quick else {"coarse": 20, "fine": 40}
    orders = (2, 3) if quick else (2, 3, 4)
    for m in orders:
        for gname, g in grids.items():
            for consistent in (True, False):
                if quick and gname == "fine" and not consistent:
                    continue
                kind = "consistent" if consistent else "plain"
                out.append(Variant("laguerre", f"m={m} {gname} {kind}",
                                   {"name": "laguerre", "order": m, "consistent": consistent,
                                    "grid_mass": g, "grid_binder": g}))
    cn = ((1000, 2), (3000, 2)) if quick else ((1000, 4), (10000, 4), (100000, 4))
    for particles, replicas in cn:
        out.append(Variant("cnmc", f"{particles:.0e}".replace("e+0", "e") + f" x {replicas}",
                           {"name": "cnmc", "particles": particles, "replicas": replicas,
                            "seed": 11}))
    return out


def chosen_times(scene, fractions=TIME_FRACTIONS):
    """Output times nearest to the fractions of the end time (unique, > 0)."""
    from .simulate import output_times
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
    from .simulate import run_well_mixed
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


def laguerre_build_time(scene, variant):
    """Seconds to build the variant's Laguerre tensor from scratch (no disk cache)."""
    from .methods import laguerre_tensor as LT
    sc = scene.with_method(**variant.changes)
    arrays = model.pack(sc)
    weights, support = LT.scene_weights_support(sc)
    u0 = float(model.well_mixed_cell(sc)[0, P.COLLISION_VELOCITY])
    t0 = time.perf_counter()
    LT.build_aux(arrays.params, arrays.config, sc.method.order, weights=weights,
                 support=support, consistent=sc.method.consistent,
                 collision_velocity=u0 if u0 > 0 else None, use_cache=False)
    return time.perf_counter() - t0


def accuracy_study(scene_name=None, out_dir="bench-out", quick=False, repeats=None,
                   variants=None, reference=None, quiet=False) -> dict:
    """Run the accuracy study on a well-mixed scene (default: study-seed; quick: study-analytic)
    and write accuracy.csv, accuracy.md, pareto.png and accuracy.json into ``out_dir``.
    Returns the rows and the reference info.

    reference: None (automatic: analytic if available, else a cNMC ensemble of 1e6 particles x
    16 replicas, quick: 2e4 x 4) or (particles, replicas) to force a cNMC reference size.
    """
    from .scene import load_scene

    scene = load_scene(scene_name or (DEFAULT_ACCURACY_SCENE if not quick else "study-analytic"))
    if scene.domain.type != "well-mixed":
        from .scene import SceneError
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
        ref_info = {"kind": "cnmc", "particles": particles, "replicas": replicas,
                    "wall_s": wall, "cached": cached, "band": band,
                    "text": f"cNMC ensemble of {particles:g} particles x {replicas} replicas "
                            f"({particles * replicas:.2g} particle-replicas, "
                            f"{'cached' if cached else f'{wall:.0f} s'}); its 95% band "
                            "half-width per quantity is listed"}

    # ---- variants
    lag = [v for v in variants if v.method == "laguerre"]
    if lag:     # compile the tensor builder once, so that no build time includes it
        tiny = Variant("laguerre", "warm-up", dict(lag[0].changes, grid_mass=4, grid_binder=4))
        try:
            laguerre_build_time(scene, tiny)
        except Exception:  # noqa: BLE001 - the variant itself will report the problem
            pass
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
        if v.method == "laguerre":
            try:
                row["tensor_build_s"] = laguerre_build_time(scene, v)
            except Exception as exc:  # noqa: BLE001
                row["tensor_build_s"] = float("nan")
                row["tensor_build_error"] = str(exc)
        if v.method == "cnmc":
            row["own_band"] = {q: float(np.nanmax([abs(0.5 * (cols[q + "_hi"][i]
                                                              - cols[q + "_lo"][i])
                                                         / cols[q][i]) for i in idx]))
                               for q in QUANTITIES if q + "_lo" in cols}
        rows.append(row)
    result = {"scene": scene.name, "scene_source": scene.source,
              "times_s": [float(grid[i]) for i in idx], "reference": ref_info,
              "repeats": repeats, "quick": quick, "machine": machine,
              "commit": _git_describe(), "rows": rows}
    _write_accuracy(Path(out_dir), result)
    return result


# ---- accuracy outputs
def _fmt_err(e):
    if e is None or not math.isfinite(e):
        return "n/a"
    return f"{100 * e:.2g}%" if abs(e) >= 1e-4 else f"{e:.1e}"


def _accuracy_csv_rows(result):
    lines = []
    header = ["method", "knob", "status", "time_s"] + [f"err_{q}" for q in QUANTITIES] + [
        "max_abs_error", "wall_s_median", "first_call_s", "tensor_build_s", "steps",
        "rhs_calls", "cnmc_trials"]
    lines.append(header)
    for row in result["rows"]:
        times = result["times_s"] if row["status"] == "ok" else [float("nan")]
        for k, t in enumerate(times):
            rec = [row["method"], row["knob"], row["status"], t]
            for q in QUANTITIES:
                vals = row.get("errors", {}).get(q)
                rec.append(vals[k] if vals is not None else float("nan"))
            rec += [row.get("max_abs_error"), row.get("wall_s"), row.get("first_call_s"),
                    row.get("tensor_build_s", float("nan")), row.get("steps"),
                    row.get("rhs_calls"), row.get("trials")]
            lines.append(rec)
    return lines


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    return str(v)


def _write_csv(path, lines):
    import csv
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        for rec in lines:
            w.writerow([_csv_value(v) for v in rec])


def pareto_front(points):
    """Indices of the points (time, error) not dominated by another (lower time and error)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front = []
    best = float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def accuracy_markdown(result) -> str:
    """The accuracy table (max |relative error| over the chosen times) as Markdown."""
    ref = result["reference"]
    times = ", ".join(f"{t:g}" for t in result["times_s"])
    lines = [f"Scene `{result['scene']}`; errors are max |relative error| over t = {times} s "
             f"against the reference: {ref['text']}.", ""]
    names = {"M00": "M00", "M20": "M20", "M11": "M11", "M02": "M02", "d43_m": "d43",
             "binder_fraction": "binder fr."}
    head = "| method | knob | " + " | ".join(names[q] for q in QUANTITIES) + \
        " | max | wall [s] | first call [s] |"
    lines += [head, "|" + "---|" * (head.count("|") - 1)]
    pts = [(r["wall_s"], r["max_abs_error"]) for r in result["rows"] if r["status"] == "ok"
           and math.isfinite(r["max_abs_error"])]
    ok_rows = [r for r in result["rows"] if r["status"] == "ok"
               and math.isfinite(r["max_abs_error"])]
    front = {id(ok_rows[i]) for i in pareto_front(pts)}
    for r in result["rows"]:
        if r["status"] != "ok":
            lines.append(f"| {r['method']} | {r['knob']} | " + " | ".join("-" for _ in QUANTITIES)
                         + f" | {r['status'][:60]} | - | - |")
            continue
        cells = []
        for q in QUANTITIES:
            vals = r["errors"].get(q)
            cells.append(_fmt_err(max((abs(v) for v in vals if math.isfinite(v)), default=None))
                         if vals else "n/a")
        star = " *" if id(r) in front else ""
        extra = ""
        if "tensor_build_s" in r and math.isfinite(r["tensor_build_s"]):
            extra = f" (+{r['tensor_build_s']:.2g} tensor)"
        lines.append(f"| {r['method']} | {r['knob']}{star} | " + " | ".join(cells)
                     + f" | {_fmt_err(r['max_abs_error'])} | {r['wall_s']:.3g} | "
                     f"{r['first_call_s']:.3g}{extra} |")
    own = [(r["knob"], max((b for b in r.get("own_band", {}).values() if math.isfinite(b)),
                           default=float("nan")))
           for r in result["rows"] if r["status"] == "ok" and r["method"] == "cnmc"]
    if own:
        lines += ["", "cNMC variants' own 95% band half-width (max over quantities and times): "
                  + ", ".join(f"{k} {_fmt_err(b)}" for k, b in own) + "; their wall time is "
                  "the whole ensemble."]
    band = ref.get("band") or {}
    if ref["kind"] == "cnmc" and band:
        lines += ["", "Reference's own 95% band half-width (max over the chosen times): "
                  + ", ".join(f"{names[q]} {_fmt_err(b)}" for q, b in band.items()) + "."]
    lines += ["", "`*` on the Pareto front (no other variant is both faster and more accurate). "
              f"Wall time: median of {result['repeats']} runs; first call: the first run in the "
              "process (numba compilation or cache load; Laguerre: tensor build or disk-cache "
              "load), reported apart, with the uncached tensor build time in brackets. cNMC "
              "errors are those of one ensemble mean (one seed) and scatter by about its own "
              "band.", "", f"Machine: {_machine_line(result['machine'])}."]
    return "\n".join(lines) + "\n"


SIZE_QUANTITIES = ("M00", "M20", "d43_m")


def _row_error(row, quantities):
    """max |relative error| of a row over the given quantities and the chosen times."""
    vals = [abs(v) for q in quantities for v in row.get("errors", {}).get(q, [])
            if math.isfinite(v)]
    return max(vals) if vals else float("nan")


def plot_pareto(path, result):
    """Error against wall time, log-log, one marker per method and knob, the Pareto front
    drawn; left: all six quantities, right: the size distribution only (M00, M20, d43)."""
    from . import plotting  # noqa: F401 - selects the Agg backend
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    style = {"qmom": ("o", "C0"), "laguerre": ("s", "C1"), "cnmc": ("^", "C2")}
    for ax, quantities, what in ((axes[0], QUANTITIES,
                                  "M00, M20, M11, M02, d43, binder fraction"),
                                 (axes[1], SIZE_QUANTITIES, "M00, M20, d43")):
        rows = [(r, _row_error(r, quantities)) for r in result["rows"] if r["status"] == "ok"]
        rows = [(r, e) for r, e in rows if math.isfinite(e) and e > 0]
        seen = set()
        for r, e in rows:
            marker, colour = style.get(r["method"], ("x", "k"))
            filled = "plain" not in r["knob"]
            ax.plot(r["wall_s"], e, marker=marker, color=colour, ls="none", ms=8,
                    mfc=colour if filled else "none",
                    label=r["method"] if r["method"] not in seen else None)
            seen.add(r["method"])
            ax.annotate(r["knob"], (r["wall_s"], e), fontsize=7, xytext=(4, 3),
                        textcoords="offset points")
        pts = [(r["wall_s"], e) for r, e in rows]
        front = sorted(pareto_front(pts), key=lambda i: pts[i][0])
        if front:
            xs = [pts[i][0] for i in front]
            ys = [pts[i][1] for i in front]
            ax.step(xs + [max(p[0] for p in pts) * 1.5], ys + [ys[-1]], where="post",
                    color="k", lw=1, ls="--", label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per run [s] (median, compile excluded)")
        ax.set_ylabel(f"max |relative error| of {what}")
        ax.grid(True, which="both", alpha=0.3)
        if rows:
            ax.legend(fontsize=8)
    fig.suptitle(f"{result['scene']}: error vs cost (reference: "
                 f"{result['reference']['kind']}; unfilled: plain Laguerre projection)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _write_accuracy(out_dir, result):
    from . import output
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / "accuracy.csv", _accuracy_csv_rows(result))
        (d / "accuracy.md").write_text(accuracy_markdown(result))
        plot_pareto(d / "pareto.png", result)
        output.write_json(d / "accuracy.json", result)


# ============================================================================ throughput kernels
@nb.njit(cache=True, parallel=True)
def rhs_sweep(states, cells, aux, params, config, reps, out):
    """``reps`` RHS evaluations per cell (prange over cells), each on a different row of
    ``states`` (row (c + 7919 r) mod n) so that nothing is reused between calls."""
    n = states.shape[0]
    for c in nb.prange(n):
        work = np.empty(WORK_SIZE)
        for r in range(reps):
            s = (c + 7919 * r) % n
            method_rhs(states[s], out[c], cells[c], aux, params, config, work)


@nb.njit(cache=True, parallel=True)
def qmom_node_properties(states, cells, params, config, props, counts, factors):
    """Per cell: the quadrature's property rows (nodes, then the droplet in row n_max), the
    node count and the kernel's cell factor, as qmom_rhs computes them (setup of the
    kernel-only sweep)."""
    from_q = config[P.ORDER]
    for c in nb.prange(states.shape[0]):
        nodes = np.zeros(from_q)
        weights = np.zeros(from_q)
        binder = np.zeros(from_q)
        work = np.empty(WORK_SIZE)
        n = _qmom_invert(states[c], config, nodes, weights, binder, work)
        counts[c] = n
        num = 0.0
        den = 0.0
        for a in range(n):
            b = min(max(binder[a], 0.0), nodes[a])
            particle_properties(nodes[a] * params[P.MASS_SCALE], b * params[P.MASS_SCALE],
                                params, config, props[c], a)
            num += weights[a] * nodes[a] * props[c][a, 2]
            den += weights[a] * nodes[a]
        pd = params[P.DROPLET_MASS]
        particle_properties(pd, pd, params, config, props[c], from_q)
        factors[c] = _cell_factor(config[P.KERNEL], cells[c, P.ALPHA], cells[c, P.THETA],
                                  num / den if den > 0 else 0.0, params)


@nb.njit(cache=True, parallel=True)
def qmom_kernel_sweep(props, counts, cells, factors, params, config, reps, out):
    """Kernel-only ceiling of the QMOM RHS: per cell and repetition, the pair rates its RHS
    evaluates (N(N+1)/2 granule pairs and, with separate droplets, N droplet captures) through
    the registry's ``pair_rate`` on precomputed property rows -- nothing else."""
    n_max = config[P.ORDER]
    separate = config[P.SEPARATE_DROPLETS] == 1
    for c in nb.prange(props.shape[0]):
        pr = props[c]
        n = counts[c]
        u0 = cells[c, P.COLLISION_VELOCITY]
        acc = 0.0
        for r in range(reps):
            f = factors[c] * (1.0 + 1e-15 * r)
            for a in range(n):
                for b in range(a, n):
                    acc += pair_rate(pr, a, b, f, u0, params, config)
                if separate:
                    acc += pair_rate(pr, a, n_max, f, u0, params, config)
        out[c] = acc


@nb.njit(cache=True, parallel=True)
def laguerre_contraction_sweep(states, aux, reps, out):
    """Kernel-only ceiling of the Laguerre ROM: the bare quadratic form
    sum_{k<=l} Q[k, l, a] M_k M_l of one tensor slice (no interpolation, d43 or droplets)."""
    m = int(aux[1])
    K = m * m
    off = int(aux[7])
    n = states.shape[0]
    for c in nb.prange(n):
        for a in range(K):
            out[c, a] = 0.0
        for r in range(reps):
            st = states[(c + 7919 * r) % n]
            pos = off
            for k in range(K):
                mk = st[k]
                for l in range(k, K):
                    prod = mk * st[l]
                    for a in range(K):
                        out[c, a] += prod * aux[pos + a]
                    pos += K


# ============================================================================ throughput setup
def throughput_scene(method, order, scene_name=DEFAULT_THROUGHPUT_SCENE):
    """The throughput scene (ktgf, geometric + physical efficiency, separate droplets,
    injection) with the method and its order."""
    from .scene import load_scene
    scene = load_scene(scene_name)
    if method == "qmom":
        return scene.with_method(name="qmom", nodes=order)
    return scene.with_method(name="laguerre", order=order)


def synthetic_cells(n_cells, seed=0, theta_range=(1e-6, 2e-4), alpha_range=(0.05, 0.55),
                    injection=2.0e10, spray_share=0.2):
    """Cell rows like the bundled bed's active cells: alpha uniform, Theta log-uniform over the
    bed's range [m2/s2], u0 = 4 sqrt(Theta / pi), injection in a share of them."""
    rng = np.random.default_rng(seed)
    cells = np.zeros((n_cells, P.N_CELL))
    cells[:, P.ALPHA] = rng.uniform(*alpha_range, n_cells)
    cells[:, P.THETA] = np.exp(rng.uniform(math.log(theta_range[0]), math.log(theta_range[1]),
                                           n_cells))
    cells[:, P.COLLISION_VELOCITY] = 4.0 * np.sqrt(cells[:, P.THETA] / math.pi)
    cells[:, P.INJECTION] = np.where(rng.random(n_cells) < spray_share, injection, 0.0)
    return cells


def trajectory_states(scene, arrays, aux):
    """Scaled states of the well-mixed run of ``scene`` at its output times (t > 0)."""
    from .simulate import output_times
    times = output_times(scene)
    state = model.initial_moments(scene, arrays, arrays.state_names)
    work = state[None, :].copy()
    cells = model.well_mixed_cell(scene)
    steps = np.array([scene.output_interval * 1e-3])
    stats = np.zeros((1, integrate.N_STATS), dtype=np.int64)
    status = np.zeros(1, dtype=np.int64)
    reached = np.zeros(1)
    rows = []
    for k in range(1, len(times)):
        integrate.integrate_cells(work, cells, aux, arrays.params, arrays.config, times[k - 1],
                                  times[k], steps, scene.method.rtol, scene.method.atol,
                                  integrate.MAX_STEPS_PER_INTERVAL, stats, status, reached)
        if status[0] != integrate.OK:
            break
        rows.append(work[0].copy())
    return np.array(rows)


def cell_states(trajectory, n_cells, seed=1):
    """One state per cell: a random row of the trajectory with the number density scaled by a
    random factor in [0.3, 1] (all moments scale alike: still realizable)."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(trajectory), n_cells)
    factor = rng.uniform(0.3, 1.0, n_cells)
    return np.ascontiguousarray(trajectory[pick] * factor[:, None])


@dataclasses.dataclass
class ThroughputCase:
    """Everything one method needs for the throughput measurements."""
    method: str
    order: int
    scene: object
    arrays: object
    aux: np.ndarray
    trajectory: np.ndarray
    aux_build_s: float = 0.0

    @property
    def label(self):
        return f"{'QMOM N' if self.method == 'qmom' else 'Laguerre m'} = {self.order}"


def throughput_case(method, order, theta_range=(1e-6, 2e-4), slices=24,
                    scene_name=DEFAULT_THROUGHPUT_SCENE):
    """Build the scene, packed arrays, aux (Laguerre: tensor tabulated on a Theta grid of
    ``slices`` log-spaced values, as ``run_coupled`` does) and a trajectory of states."""
    from .methods import laguerre_tensor as LT
    scene = throughput_scene(method, order, scene_name)
    arrays = model.pack(scene)
    build = 0.0
    if method == "laguerre":
        # trajectory with the well-mixed (fixed u0) tensor, measurements with the Theta grid
        aux_fixed = LT.aux_for_scene(scene, arrays)
        traj = trajectory_states(scene, arrays, aux_fixed)
        t0 = time.perf_counter()
        aux = LT.aux_for_scene(dataclasses.replace(
            scene, domain=dataclasses.replace(scene.domain, collision_velocity=None)), arrays,
            theta_grid=np.geomspace(theta_range[0], theta_range[1], slices))
        build = time.perf_counter() - t0
    else:
        aux = np.zeros(1)
        traj = trajectory_states(scene, arrays, aux)
    return ThroughputCase(method, order, scene, arrays, aux, traj, build)


def _time_call(fn, repeats):
    """(best, median) wall seconds of ``repeats`` calls of fn()."""
    walls = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
    return min(walls), statistics.median(walls)


def measure_rhs_rate(case, n_cells, threads, target_evals=200_000, repeats=3, seed=0):
    """Cell-RHS evaluations per second (best and median of ``repeats``) on n_cells cells."""
    nb.set_num_threads(threads)
    cells = synthetic_cells(n_cells, seed=seed)
    states = cell_states(case.trajectory, n_cells, seed=seed + 1)
    out = np.zeros_like(states)
    params, config = case.arrays.params, case.arrays.config
    reps = max(1, int(round(target_evals / n_cells)))
    rhs_sweep(states, cells, case.aux, params, config, 1, out)          # compile / warm
    best, median = _time_call(lambda: rhs_sweep(states, cells, case.aux, params, config, reps,
                                                out), repeats)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError(f"{case.label}: non-finite RHS in the throughput sweep")
    evals = reps * n_cells
    return evals / best, evals / median


def measure_ceiling(case, n_cells, threads, target_evals=400_000, repeats=3, seed=0):
    """Kernel-only rate (cells per second, best and median): see qmom_kernel_sweep and
    laguerre_contraction_sweep."""
    nb.set_num_threads(threads)
    cells = synthetic_cells(n_cells, seed=seed)
    states = cell_states(case.trajectory, n_cells, seed=seed + 1)
    params, config = case.arrays.params, case.arrays.config
    reps = max(1, int(round(target_evals / n_cells)))
    if case.method == "qmom":
        n_max = int(config[P.ORDER])
        props = np.zeros((n_cells, n_max + 1, N_PROPS))
        counts = np.zeros(n_cells, dtype=np.int64)
        factors = np.zeros(n_cells)
        qmom_node_properties(states, cells, params, config, props, counts, factors)
        out = np.zeros(n_cells)
        qmom_kernel_sweep(props, counts, cells, factors, params, config, 1, out)
        best, median = _time_call(lambda: qmom_kernel_sweep(props, counts, cells, factors,
                                                            params, config, reps, out), repeats)
    else:
        out = np.zeros_like(states)
        laguerre_contraction_sweep(states, case.aux, 1, out)
        best, median = _time_call(lambda: laguerre_contraction_sweep(states, case.aux, reps,
                                                                     out), repeats)
    evals = reps * n_cells
    return evals / best, evals / median


def measure_steps(case, n_cells, threads, interval=1.0, seed=0, rtol=None, atol=None):
    """Cell-steps per second of ``integrate_cells`` on n_cells cells over one interval [s]
    after a warm-up interval (which also fills each cell's step memory). Returns a dict with
    accepted steps, RHS calls, wall time and the count of cells that did not finish."""
    nb.set_num_threads(threads)
    cells = synthetic_cells(n_cells, seed=seed)
    states = cell_states(case.trajectory, n_cells, seed=seed + 1)
    params, config = case.arrays.params, case.arrays.config
    rtol = case.scene.method.rtol if rtol is None else rtol
    atol = case.scene.method.atol if atol is None else atol
    steps = np.full(n_cells, interval * 1e-3)
    status = np.zeros(n_cells, dtype=np.int64)
    reached = np.zeros(n_cells)

    def run(t0, t1, stats):
        integrate.integrate_cells(states, cells, case.aux, params, config, t0, t1, steps, rtol,
                                  atol, integrate.MAX_STEPS_PER_INTERVAL, stats, status,
                                  reached)

    warm = np.zeros((n_cells, integrate.N_STATS), dtype=np.int64)
    run(0.0, interval, warm)
    stats = np.zeros((n_cells, integrate.N_STATS), dtype=np.int64)
    t0 = time.perf_counter()
    run(interval, 2 * interval, stats)
    wall = time.perf_counter() - t0
    tot = stats.sum(axis=0)
    accepted = int(tot[integrate.ACCEPTED])
    return {"cell_steps_per_s": accepted / wall if wall > 0 else float("nan"),
            "accepted": accepted, "rhs_calls": int(tot[integrate.RHS_CALLS]),
            "rejected": int(tot[integrate.REJECTED_ERROR] + tot[integrate.REJECTED_REALIZABILITY]),
            "wall_s": wall, "failed_cells": int(np.count_nonzero(status != integrate.OK)),
            "rhs_per_s_in_steps": int(tot[integrate.RHS_CALLS]) / wall if wall > 0 else 0.0}


# ============================================================================ NumPy/SciPy baseline
class NumpyQMOM:
    """The QMOM right-hand side as a user would write it without this package: NumPy Wheeler
    recurrence, ``numpy.linalg.eigh`` of the Jacobi matrix, binder per node by
    ``numpy.linalg.solve`` of the weighted Vandermonde system (clipped to [0, p]), the kernel
    and efficiency formulas of DESIGN section 3 as plain Python functions, Python loops over
    pairs and moments. Same state layout and scaling as ``methods.qmom`` (scaled moments), so
    ``scipy.integrate.solve_ivp(baseline.rhs, ...)`` integrates exactly what the package does
    (without its realizability control)."""

    def __init__(self, params, config):
        self.p = [float(x) for x in params]
        self.n = int(config[P.ORDER])
        self.kernel = int(config[P.KERNEL])
        self.geometric = int(config[P.USE_GEOMETRIC]) == 1
        self.physical = int(config[P.USE_PHYSICAL]) == 1
        self.saturation = int(config[P.USE_SATURATION]) == 1
        self.separate = int(config[P.SEPARATE_DROPLETS]) == 1
        self.bivariate = int(config[P.BIVARIATE]) == 1
        self.n_state = int(config[P.N_STATE])

    # -- quadrature
    def quadrature(self, m):
        n = self.n
        m0 = m[0]
        if not m0 > 0:
            return np.zeros(0), np.zeros(0)
        mean = m[1] / m0
        mu = np.array([m[k] / (m0 * mean ** k) for k in range(2 * n)])
        sigma = np.zeros((n + 1, 2 * n + 1))
        sigma[1, :2 * n] = mu
        a = np.zeros(n)
        b = np.zeros(n)
        a[0] = mu[1] / mu[0]
        n_eff = 1
        for k in range(1, n):
            for l in range(k, 2 * n - k):
                sigma[k + 1, l] = (sigma[k, l + 1] - a[k - 1] * sigma[k, l]
                                   - b[k - 1] * sigma[k - 1, l])
            if not sigma[k + 1, k] > 1e-11 * abs(sigma[k, k + 1]):
                break
            a[k] = sigma[k + 1, k + 1] / sigma[k + 1, k] - sigma[k, k] / sigma[k, k - 1]
            b[k] = sigma[k + 1, k] / sigma[k, k - 1]
            n_eff = k + 1
        off = np.sqrt(b[1:n_eff])
        jacobi = np.diag(a[:n_eff]) + np.diag(off, 1) + np.diag(off, -1)
        vals, vecs = np.linalg.eigh(jacobi)
        return vals * mean, vecs[0, :] ** 2 * m0

    def binder(self, m, x, w):
        n = len(x)
        if not self.bivariate or n == 0:
            return np.zeros(n)
        rhs = np.asarray(m[2 * self.n:2 * self.n + n])
        vander = np.vander(x, n, increasing=True).T * w
        try:
            b = np.linalg.solve(vander, rhs)
        except np.linalg.LinAlgError:
            b = np.full(n, rhs[0] / max(np.sum(w * x), 1e-300)) * x
        return np.clip(b, 0.0, x)

    # -- physics of DESIGN section 3, one pair at a time
    def props(self, pm, bm):
        p = self.p
        d = (6.0 * pm / (math.pi * p[P.DENSITY])) ** (1.0 / 3.0)
        y = bm / pm if pm > 0 else 0.0
        x = pm / (p[P.REFERENCE_VOLUME] * p[P.DENSITY]) if p[P.REFERENCE_VOLUME] > 0 else 0.0
        eta = 1.0 / (1.0 + math.exp(-p[P.GEO_SLOPE] * (y - p[P.GEO_CENTRE])))
        layer = math.exp(p[P.PHI_SLOPE] * (y - p[P.PHI_CENTRE]) / 3.0)
        return pm, bm, d, x, eta, layer

    def cell_factor(self, alpha, theta, d43):
        p = self.p
        if self.kernel != 4:
            return p[P.RATE]
        cap = p[P.ALPHA_MIN_FRICTION]
        if cap > 0 and alpha > cap:
            alpha = cap
        g0 = 1.0 if alpha <= 0 else 1.0 / (1.0 - (alpha / p[P.ALPHA_MAX]) ** (1.0 / 3.0))
        return p[P.RATE] * g0 * math.sqrt(max(theta, 0.0)) * d43 ** 1.5

    def rate(self, r1, r2, factor, u0):
        p = self.p
        p1, b1, d1, x1, eta1, l1 = r1
        p2, b2, d2, x2, eta2, l2 = r2
        k = self.kernel
        if k == 0:
            beta = factor
        elif k == 1:
            beta = factor * (p1 + p2)
        elif k == 2:
            beta = factor * p1 * p2
        elif k == 3:
            beta = factor * (x1 ** (1 / 3) + x2 ** (1 / 3)) ** 2 * math.sqrt(1 / x1 + 1 / x2)
        else:
            beta = factor * (d1 + d2) ** 2 * math.sqrt(1 / d1 ** 3 + 1 / d2 ** 3)
        psi = 1.0
        if self.geometric:
            psi *= 1.0 - (1.0 - eta1) * (1.0 - eta2)
        if self.physical:
            st = (4 * p[P.DENSITY] * u0 * d1 * d2 * (d1 + d2) ** 2
                  / (9 * p[P.BINDER_VISCOSITY] * (d1 ** 3 + d2 ** 3)))
            ratio = p[P.GYRATION_RADIUS] * (l1 + l2) / p[P.ASPERITY]
            st_crit = 2.0 * math.log(ratio) if ratio > 1.0 else 0.0
            w = p[P.STOKES_WIDTH]
            if w <= 0 or st_crit <= 0:
                psi *= 1.0 if st <= st_crit else 0.0
            else:
                psi *= 0.5 * (1.0 - math.tanh((st - st_crit) / (w * st_crit)))
        if self.saturation:
            binder = b1 + b2
            solid = p1 + p2 - binder
            if solid > 0:
                eps = p[P.POROSITY]
                s = binder / solid * p[P.DENSITY] * (1 - eps) / (p[P.BINDER_DENSITY] * eps)
                psi *= min(1.0, s / p[P.SATURATION_MAX])
        return beta * psi

    def rhs(self, _t, y, cell):
        """d(state)/dt (scaled moments per s) of one cell (alpha, Theta, u0, injection)."""
        p = self.p
        n_max = self.n
        out = np.zeros(self.n_state)
        x, w = self.quadrature(y)
        b = self.binder(y, x, w)
        ns, ms = p[P.NUMBER_SCALE], p[P.MASS_SCALE]
        rows = [self.props(x[a] * ms, b[a] * ms) for a in range(len(x))]
        d43 = 0.0
        if self.kernel == 4 and len(x):
            d = np.array([r[2] for r in rows])
            d43 = float(np.sum(w * d ** 4) / np.sum(w * d ** 3))
        factor = self.cell_factor(cell[P.ALPHA], cell[P.THETA], d43)
        u0 = cell[P.COLLISION_VELOCITY]
        for a in range(len(x)):
            for c in range(a, len(x)):
                pair = w[a] * w[c] * ns * self.rate(rows[a], rows[c], factor, u0)
                if a == c:
                    pair *= 0.5
                s = x[a] + x[c]
                out[0] -= pair
                for k in range(2, 2 * n_max):
                    out[k] += pair * (s ** k - x[a] ** k - x[c] ** k)
                if self.bivariate:
                    for k in range(1, n_max):
                        out[2 * n_max + k] += pair * (b[a] * (s ** k - x[a] ** k)
                                                      + b[c] * (s ** k - x[c] ** k))
        inj = cell[P.INJECTION] / ns
        pd = p[P.DROPLET_MASS]
        xd = pd / ms
        if self.separate:
            nd = y[-1]
            if nd > 0:
                drop = self.props(pd, pd)
                for a in range(len(x)):
                    flux = nd * w[a] * ns * p[P.DROPLET_FACTOR] * self.rate(rows[a], drop,
                                                                            factor, u0)
                    s = x[a] + xd
                    for k in range(1, 2 * n_max):
                        out[k] += flux * (s ** k - x[a] ** k)
                    if self.bivariate:
                        for k in range(n_max):
                            out[2 * n_max + k] += flux * (s ** k * (b[a] + xd) - x[a] ** k * b[a])
                    out[-1] -= flux
            out[-1] += inj
        elif inj:
            for k in range(2 * n_max):
                out[k] += inj * xd ** k
                if self.bivariate and k < n_max:
                    out[2 * n_max + k] += inj * xd ** (k + 1)
        return out


def measure_baseline(case, n_cells=4, interval=1.0, rhs_samples=200, seed=0, rtol=None,
                     atol=None):
    """Rates of the plain NumPy/SciPy path (one core, Python): RHS evaluations per second on
    ``rhs_samples`` cell states, and solve_ivp (RK23, the same tolerances and interval as
    ``measure_steps``, after the same warm-up interval) on ``n_cells`` cells, extrapolated per
    cell."""
    from scipy.integrate import solve_ivp
    base = NumpyQMOM(case.arrays.params, case.arrays.config)
    cells = synthetic_cells(max(n_cells, rhs_samples), seed=seed)
    states = cell_states(case.trajectory, max(n_cells, rhs_samples), seed=seed + 1)
    t0 = time.perf_counter()
    for i in range(rhs_samples):
        base.rhs(0.0, states[i], cells[i])
    rhs_rate = rhs_samples / (time.perf_counter() - t0)
    rtol = case.scene.method.rtol if rtol is None else rtol
    atol = case.scene.method.atol if atol is None else atol
    nfev = 0
    steps = 0
    wall = 0.0
    for i in range(n_cells):
        y0 = states[i].copy()
        warm = solve_ivp(base.rhs, (0.0, interval), y0, method="RK23", rtol=rtol, atol=atol,
                         args=(cells[i],))
        t0 = time.perf_counter()
        sol = solve_ivp(base.rhs, (interval, 2 * interval), warm.y[:, -1], method="RK23",
                        rtol=rtol, atol=atol, args=(cells[i],))
        wall += time.perf_counter() - t0
        nfev += sol.nfev
        steps += len(sol.t) - 1
    return {"rhs_per_s": rhs_rate, "cell_steps_per_s": steps / wall if wall > 0 else 0.0,
            "rhs_per_s_in_solve_ivp": nfev / wall if wall > 0 else 0.0, "cells": n_cells,
            "steps": steps, "nfev": nfev, "wall_s": wall}


# ============================================================================ throughput study
def throughput_study(out_dir="bench-out", quick=False, cells=None, threads=None, methods=None,
                     interval=None, quiet=False, scene_name=DEFAULT_THROUGHPUT_SCENE) -> dict:
    """Run the throughput study and write throughput.csv, throughput.md, throughput.png and
    machine.json into ``out_dir``. Returns the rows (see module doc)."""
    cells = cells or ((100, 1000) if quick else (100, 1000, 10_000, 100_000))
    max_threads = nb.config.NUMBA_NUM_THREADS
    threads = threads or tuple(t for t in (1, 2) if t <= max_threads)
    methods = methods or ((("qmom", 2), ("qmom", 3), ("laguerre", 2), ("laguerre", 3)) if quick
                          else (("qmom", 2), ("qmom", 3), ("qmom", 4), ("laguerre", 2),
                                ("laguerre", 3), ("laguerre", 4)))
    interval = interval or (0.05 if quick else 0.1)
    repeats = 1 if quick else 3
    target = 20_000 if quick else 300_000
    machine = machine_info()
    _say(quiet, f"throughput study: {len(methods)} methods x {len(cells)} cell counts x "
         f"threads {threads}")
    rows = []
    baseline = None
    cases = {}
    for method, order in methods:
        t0 = time.perf_counter()
        case = throughput_case(method, order, scene_name=scene_name)
        cases[(method, order)] = case
        setup = time.perf_counter() - t0
        _say(quiet, f"  {case.label}: setup {setup:.1f} s")
        for th in threads:
            ceiling = measure_ceiling(case, max(cells), th, target_evals=2 * target,
                                      repeats=repeats)
            for n in cells:
                rhs_best, rhs_median = measure_rhs_rate(case, n, th, target_evals=target,
                                                        repeats=repeats)
                steps = measure_steps(case, n, th, interval=interval)
                rows.append({"method": method, "order": order, "label": case.label,
                             "cells": n, "threads": th, "rhs_per_s": rhs_best,
                             "rhs_per_s_median": rhs_median,
                             "cell_steps_per_s": steps["cell_steps_per_s"],
                             "rhs_per_step": steps["rhs_calls"] / max(steps["accepted"], 1),
                             "rejected_share": steps["rejected"] / max(steps["accepted"]
                                                                      + steps["rejected"], 1),
                             "failed_cells": steps["failed_cells"],
                             "ceiling_per_s": ceiling[0],
                             "share_of_ceiling": rhs_best / ceiling[0],
                             "aux_build_s": case.aux_build_s})
                _say(quiet, f"    {n:>6d} cells, {th} thr: {rhs_best:.3g} RHS/s, "
                     f"{steps['cell_steps_per_s']:.3g} cell-steps/s "
                     f"(ceiling {ceiling[0]:.3g}/s)")
    # plain NumPy/SciPy baseline (QMOM N = 3 if measured, else the first QMOM)
    qm = [k for k in cases if k[0] == "qmom"]
    if qm:
        key = ("qmom", 3) if ("qmom", 3) in cases else qm[0]
        _say(quiet, f"  NumPy/SciPy baseline, QMOM N = {key[1]} ...")
        baseline = measure_baseline(cases[key], n_cells=1 if quick else 4, interval=interval,
                                    rhs_samples=30 if quick else 300)
        baseline["order"] = key[1]
    result = {"machine": machine, "commit": _git_describe(), "quick": quick,
              "interval_s": interval, "repeats": repeats, "rows": rows, "baseline": baseline,
              "scene": scene_name}
    _write_throughput(Path(out_dir), result)
    return result


def _speedups(result):
    """Speed-ups of the numba path over the NumPy/SciPy baseline (largest cell count)."""
    base = result.get("baseline")
    if not base:
        return []
    order = base["order"]
    rows = [r for r in result["rows"] if r["method"] == "qmom" and r["order"] == order]
    if not rows:
        return []
    n = max(r["cells"] for r in rows)
    out = []
    for r in rows:
        if r["cells"] != n:
            continue
        out.append({"threads": r["threads"], "cells": n,
                    "rhs": r["rhs_per_s"] / base["rhs_per_s"],
                    "steps": r["cell_steps_per_s"] / max(base["cell_steps_per_s"], 1e-300)})
    return out


def throughput_markdown(result) -> str:
    """Throughput tables (RHS/s, cell-steps/s per method, cells, threads) as Markdown."""
    rows = result["rows"]
    cells = sorted({r["cells"] for r in rows})
    threads = sorted({r["threads"] for r in rows})
    labels = []
    for r in rows:
        if r["label"] not in labels:
            labels.append(r["label"])

    def cell(label, n, th, key):
        for r in rows:
            if r["label"] == label and r["cells"] == n and r["threads"] == th:
                return r[key]
        return float("nan")

    out = [f"Scene `{result['scene']}` (ktgf kernel, geometric and physical efficiency, "
           "droplets as their own population, injection in 20% of the cells); cells with "
           "alpha 0.05-0.55 and Theta 1e-6-2e-4 m2/s2 (log-uniform, the bundled bed's range); "
           "states from the well-mixed run, number density scaled per cell.", ""]
    for key, title in (("rhs_per_s", "Cell-RHS evaluations per second"),
                       ("cell_steps_per_s", "Cell-steps per second (accepted RK3(2) steps, "
                                            "realizability checks and re-projection included)")):
        out += [f"**{title}**", ""]
        head = "| method | " + " | ".join(f"{n:g} cells, {th} thr" for n in cells
                                          for th in threads) + " |"
        out += [head, "|" + "---|" * (head.count("|") - 1)]
        for label in labels:
            out.append(f"| {label} | " + " | ".join(f"{cell(label, n, th, key):.3g}"
                                                    for n in cells for th in threads) + " |")
        out.append("")
    n = max(cells)
    out += [f"**Kernel-only ceiling and share** ({n:g} cells): QMOM -- the registry pair rates "
            "its RHS needs (N(N+1)/2 granule pairs + N droplet captures) on precomputed "
            "property rows; Laguerre -- the bare quadratic form of one tensor slice.", ""]
    head = "| method | " + " | ".join(f"ceiling {th} thr [1/s] | share {th} thr"
                                      for th in threads) + " | RHS calls per step |"
    out += [head, "|" + "---|" * (head.count("|") - 1)]
    for label in labels:
        parts = []
        for th in threads:
            parts.append(f"{cell(label, n, th, 'ceiling_per_s'):.3g}")
            parts.append(f"{100 * cell(label, n, th, 'share_of_ceiling'):.0f}%")
        out.append(f"| {label} | " + " | ".join(parts)
                   + f" | {cell(label, n, threads[0], 'rhs_per_step'):.2f} |")
    base = result.get("baseline")
    if base:
        out += ["", f"**Plain NumPy/SciPy QMOM N = {base['order']}** (bench.NumpyQMOM: "
                "numpy Wheeler + eigh per call, Python loops; one core): "
                f"{base['rhs_per_s']:.3g} RHS/s; solve_ivp RK23 per cell: "
                f"{base['cell_steps_per_s']:.3g} cell-steps/s "
                f"({base['rhs_per_s_in_solve_ivp']:.3g} RHS/s inside solve_ivp, measured on "
                f"{base['cells']} cells and extrapolated per cell).", ""]
        sp = _speedups(result)
        if sp:
            out += ["| speed-up over NumPy/SciPy | " + " | ".join(
                f"{s['threads']} thr" for s in sp) + " |",
                "|---|" + "---|" * len(sp),
                "| RHS evaluations | " + " | ".join(f"{s['rhs']:.0f}x" for s in sp) + " |",
                "| cell-steps | " + " | ".join(f"{s['steps']:.0f}x" for s in sp) + " |"]
    out += ["", f"RHS rates: best of {result['repeats']} sweeps; cell-steps: one interval of "
            f"{result['interval_s']:g} s after a warm-up interval. Machine: "
            f"{_machine_line(result['machine'])}."]
    return "\n".join(out) + "\n"


def plot_throughput(path, result):
    from . import plotting  # noqa: F401 - selects the Agg backend
    import matplotlib.pyplot as plt

    rows = result["rows"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    labels = []
    for r in rows:
        if r["label"] not in labels:
            labels.append(r["label"])
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, title in ((axes[0], "rhs_per_s", "cell-RHS evaluations / s"),
                           (axes[1], "cell_steps_per_s", "cell-steps / s")):
        for i, label in enumerate(labels):
            for th, ls in ((1, "--"), (2, "-")):
                sel = sorted((r["cells"], r[key]) for r in rows
                             if r["label"] == label and r["threads"] == th)
                if not sel:
                    continue
                ax.plot([s[0] for s in sel], [s[1] for s in sel], ls, marker="o",
                        color=colours[i % len(colours)], label=f"{label}, {th} thr")
        base = result.get("baseline")
        if base:
            v = base["rhs_per_s"] if key == "rhs_per_s" else base["cell_steps_per_s"]
            ax.axhline(v, color="k", lw=1, ls=":",
                       label=f"NumPy/SciPy QMOM N = {base['order']} (1 core)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cells")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2, loc="center left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _write_throughput(out_dir, result):
    from . import output
    lines = [["method", "order", "cells", "threads", "rhs_per_s", "rhs_per_s_median",
              "cell_steps_per_s", "rhs_per_step", "rejected_share", "failed_cells",
              "ceiling_per_s", "share_of_ceiling", "aux_build_s"]]
    for r in result["rows"]:
        lines.append([r[k] for k in lines[0]])
    base = result.get("baseline")
    if base:
        lines.append(["numpy-scipy-qmom", base["order"], base["cells"], 1, base["rhs_per_s"],
                      base["rhs_per_s"], base["cell_steps_per_s"],
                      base["nfev"] / max(base["steps"], 1), "", "", "", "", ""])
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / "throughput.csv", lines)
        (d / "throughput.md").write_text(throughput_markdown(result))
        plot_throughput(d / "throughput.png", result)
        output.write_json(d / "throughput.json", result)
        output.write_json(d / "machine.json", result["machine"])


# ======================================================================= cnmc, laguerre, couple
def cnmc_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Seed-scenario cNMC speed per replica: wall time, trials and accepted events per second
    (``methods.cnmc.seed_scenario_benchmark``, one core)."""
    from .methods import cnmc
    sizes = (1000, 3000) if quick else (1000, 10_000, 100_000)
    end = 60.0 if quick else 600.0
    rows = []
    for n in sizes:
        _say(quiet, f"  cNMC seed scenario, {n} particles ...")
        res = cnmc.seed_scenario_benchmark(particles=n, replicas=1, seed=0, end_time=end,
                                           output_interval=end / 10, verbose=False)
        r = res["result"]
        rows.append({"particles": n, "end_time_s": end, "wall_s": res["wall_s_per_replica"],
                     "trials_per_s": float(res["trials_per_s"]),
                     "accepted_per_s": float(res["accepted_per_s"]),
                     "trials": int(r["trials"]), "accepted": int(r["accepted"])})
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows}
    lines = ["| particles | simulated [s] | wall per replica [s] | trials/s | accepted/s | "
             "acceptance |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['particles']:g} | {r['end_time_s']:g} | {r['wall_s']:.3g} | "
                     f"{r['trials_per_s']:.3g} | {r['accepted_per_s']:.3g} | "
                     f"{r['accepted'] / max(r['trials'], 1):.2f} |")
    lines += ["", "Seed 000 scenario (eke, geometric + physical efficiency, droplets as their own "
              "population, injection), one replica per size, one core. Machine: "
              f"{_machine_line(result['machine'])}."]
    _write_simple(Path(out_dir), "cnmc", rows, "\n".join(lines) + "\n", result)
    return result


def laguerre_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Laguerre tensor build time per order and grid (one u0 slice, and a Theta grid of
    slices as the coupling builds it) and the RHS rate with the Theta-interpolated tensor."""
    from .methods import laguerre_tensor as LT
    orders = (2, 3) if quick else (2, 3, 4)
    grids = (8, 12) if quick else (20, 40)
    slices = 4 if quick else 24
    n_cells = 1000 if quick else 10_000
    rows = []
    for m in orders:
        case = throughput_case("laguerre", m)
        sc, arrays = case.scene, case.arrays
        for g in grids:
            weights, support = LT.scene_weights_support(sc)
            support = dict(support, n_p=g, n_b=g)
            u0 = float(model.well_mixed_cell(sc)[0, P.COLLISION_VELOCITY])
            t0 = time.perf_counter()
            LT.build_aux(arrays.params, arrays.config, m, weights=weights, support=support,
                         consistent=True, collision_velocity=u0, use_cache=False)
            one = time.perf_counter() - t0
            t0 = time.perf_counter()
            aux = LT.build_aux(arrays.params, arrays.config, m, weights=weights, support=support,
                               consistent=True, theta_grid=np.geomspace(1e-6, 2e-4, slices),
                               use_cache=False)
            many = time.perf_counter() - t0
            c = dataclasses.replace(case, aux=aux)
            rates = {th: measure_rhs_rate(c, n_cells, th, target_evals=50_000 if quick
                                          else 300_000, repeats=1 if quick else 3)[0]
                     for th in (1, 2) if th <= nb.config.NUMBA_NUM_THREADS}
            rows.append({"order": m, "grid": g, "nodes": int(aux[LT.AUX_N_NODES]),
                         "build_one_slice_s": one, "slices": slices,
                         "build_theta_grid_s": many,
                         **{f"rhs_per_s_{th}thr": v for th, v in rates.items()}})
            _say(quiet, f"  Laguerre m={m} grid {g}: build {one:.2f} s / {many:.2f} s "
                 f"({slices} slices), RHS {rates}")
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows}
    ths = [th for th in (1, 2) if th <= nb.config.NUMBA_NUM_THREADS]
    lines = ["| m | grid | nodes on support | build, 1 slice [s] | build, Theta grid [s] | "
             + " | ".join(f"RHS/s {th} thr" for th in ths) + " |",
             "|---|---|---|---|---|" + "---|" * len(ths)]
    for r in rows:
        lines.append(f"| {r['order']} | {r['grid']} x {r['grid']} | {r['nodes']} | "
                     f"{r['build_one_slice_s']:.3g} | {r['build_theta_grid_s']:.3g} "
                     f"({r['slices']} slices) | "
                     + " | ".join(f"{r[f'rhs_per_s_{th}thr']:.3g}" for th in ths) + " |")
    lines += ["", f"ktgf + geometric + physical scene; RHS on {n_cells} cells with the "
              "Theta-interpolated tensor. Machine: " + _machine_line(result["machine"]) + "."]
    _write_simple(Path(out_dir), "laguerre", rows, "\n".join(lines) + "\n", result)
    return result


def replicated_domain(domain, copies):
    """The domain's cells repeated ``copies`` times (a larger mesh with the same fields)."""
    from .couple import Domain
    cells = domain.cells
    n = len(cells.alpha) * copies
    big = dataclasses.replace(
        cells, alpha=np.tile(cells.alpha, copies), theta=np.tile(cells.theta, copies),
        cell_volume=np.tile(cells.cell_volume, copies),
        cell_centre=np.tile(cells.cell_centre, (copies, 1)),
        vtk_cell_id=np.arange(n, dtype=np.int64))
    return Domain(cells=big, flux=None, description=f"{domain.description} x {copies}")


def failure_status(exc) -> str:
    """The whole reason a variant failed, on one line (a table cell)."""
    return "failed: " + " ".join(str(exc).split())


def couple_study(out_dir="bench-out", quick=False, quiet=False) -> dict:
    """Cell-steps per second of ``run_coupled`` on the bundled small bed (900 cells) and on its
    cells replicated 4 times (3600 cells, standing in for the full mesh, whose snapshot is not
    bundled), threads 1 and 2."""
    from .couple import load_domain, run_coupled
    from .scene import load_scene
    base = load_scene("fluid-bed")
    end, interval = (2.0, 1.0) if quick else (10.0, 5.0)
    base = dataclasses.replace(base, end_time=end, output_interval=interval)
    small = load_domain(base)
    domains = [("small (900 cells)", small)]
    if not quick:
        domains.append(("small x 4 (3600 cells)", replicated_domain(small, 4)))
    methods = [("QMOM N = 2", {"name": "qmom", "nodes": 2}, 0.0)]
    if not quick:
        # the Laguerre ROM stalls on the scene's dry start without droplets (its binder
        # moments M11, M02 get negative rates at t = 0): also run it with droplets at t = 0
        drops = 0.045 * base.material.density / base.initial.mean_mass   # per m3 of solids
        methods += [("QMOM N = 3", {"name": "qmom", "nodes": 3}, 0.0),
                    ("Laguerre m = 3", {"name": "laguerre", "order": 3}, 0.0),
                    ("Laguerre m = 3, 4.5 droplets per 100 granules at t = 0",
                     {"name": "laguerre", "order": 3}, drops)]
    rows = []
    for mlabel, changes, drops in methods:
        scene = base.with_method(**changes)
        if drops:
            scene = dataclasses.replace(scene, initial=dataclasses.replace(
                scene.initial, droplet_number_density=drops))
        for dlabel, dom in domains:
            try:
                run_coupled(dataclasses.replace(scene, end_time=interval), dom, threads=1)
            except Exception as exc:  # noqa: BLE001 - a failing method is a result
                rows.append({"method": mlabel, "domain": dlabel, "threads": 0,
                             "active_cells": 0, "wall_s": float("nan"), "accepted_steps": 0,
                             "cell_steps_per_s": float("nan"), "rhs_calls": 0,
                             "status": failure_status(exc)})
                _say(quiet, f"  couple {mlabel} {dlabel}: failed: {exc}")
                continue
            for th in (1, 2):
                if th > nb.config.NUMBA_NUM_THREADS:
                    continue
                t0 = time.perf_counter()
                res = run_coupled(scene, dom, threads=th)
                wall = time.perf_counter() - t0
                st = res.stats
                rows.append({"method": mlabel, "domain": dlabel, "threads": th,
                             "active_cells": st["active_cells"], "wall_s": wall,
                             "accepted_steps": st["accepted_steps"],
                             "cell_steps_per_s": st["accepted_steps"] / wall,
                             "rhs_calls": st["rhs_calls"], "status": "ok"})
                _say(quiet, f"  couple {mlabel} {dlabel} {th} thr: {wall:.2f} s, "
                     f"{st['accepted_steps'] / wall:.3g} cell-steps/s")
    result = {"machine": machine_info(), "commit": _git_describe(), "rows": rows,
              "end_time_s": end}
    lines = ["| method | domain | active cells | threads | wall [s] | cell-steps/s | "
             "RHS calls/s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['method']} | {r['domain']} | - | - | - | "
                         f"{r['status'].replace('|', '/')} | - |")
            continue
        lines.append(f"| {r['method']} | {r['domain']} | {r['active_cells']} | {r['threads']} | "
                     f"{r['wall_s']:.3g} | {r['cell_steps_per_s']:.3g} | "
                     f"{r['rhs_calls'] / r['wall_s']:.3g} |")
    lines += ["", f"fluid-bed scene to t = {end:g} s (whole run_coupled: set-up, solve, output "
              "fields). Machine: " + _machine_line(result["machine"]) + "."]
    _write_simple(Path(out_dir), "couple", rows, "\n".join(lines) + "\n", result)
    return result


def _write_simple(out_dir, name, rows, markdown, result):
    from . import output
    keys = list(rows[0]) if rows else []
    lines = [keys] + [[r.get(k) for k in keys] for r in rows]
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / f"{name}.csv", lines)
        (d / f"{name}.md").write_text(markdown)
        output.write_json(d / f"{name}.json", result)


# ============================================================================ CLI
#: The files each study writes into --out (several studies may share one directory).
STUDY_FILES = {
    "accuracy": ["accuracy.csv", "accuracy.md", "pareto.png", "accuracy.json"],
    "throughput": ["throughput.csv", "throughput.md", "throughput.png", "throughput.json",
                   "machine.json"],
    **{name: [f"{name}.csv", f"{name}.md", f"{name}.json"]
       for name in ("cnmc", "laguerre", "couple")},
}


def bench_command(args) -> int:
    """``pbe-cfd bench STUDY [SCENE] --out DIR [--quick]``."""
    from . import output
    out = Path(args.out)
    quick = bool(getattr(args, "quick", False))
    study = args.study
    output.prepare_directory(out, getattr(args, "overwrite", False), names=STUDY_FILES[study])
    start = time.perf_counter()
    if study == "accuracy":
        res = accuracy_study(args.scene, out, quick=quick)
        files = "accuracy.csv, accuracy.md, pareto.png"
        print(accuracy_markdown(res))
    elif study == "throughput":
        res = throughput_study(out, quick=quick,
                               scene_name=args.scene or DEFAULT_THROUGHPUT_SCENE)
        files = "throughput.csv, throughput.md, throughput.png, machine.json"
        print(throughput_markdown(res))
    elif study == "cnmc":
        cnmc_study(out, quick=quick)
        files = "cnmc.csv, cnmc.md"
        print((out / "cnmc.md").read_text())
    elif study == "laguerre":
        laguerre_study(out, quick=quick)
        files = "laguerre.csv, laguerre.md"
        print((out / "laguerre.md").read_text())
    else:
        couple_study(out, quick=quick)
        files = "couple.csv, couple.md"
        print((out / "couple.md").read_text())
    print(f"bench {study}: {time.perf_counter() - start:.1f} s; wrote {out}/{{{files}}}")
    return 0
