"""``pbe-cfd bench peer``: pbe-cfd's methods side by side with OpenFOAM's own population
balance (reactingTwoPhaseEulerFoam, ``populationBalanceTwoPhaseSystem``, the class method) on
closed well-mixed boxes, against closed forms or a fine reference (``peer_reference``).

Problems (volumes x in m3; the dispersed phase at alpha = 0.1 starts monodisperse at x = 1 m3,
n0 = 0.1 1/m3):
  aggregation   constant beta = 10 m3/s (beta n0 = 1 1/s), t = 2 s; closed form.
  breakage      S = 1 1/s (``powerLaw`` power 0), uniform binary daughters, t = 1 s; closed
                form.
  mixed         beta = 10 m3/s and S = x (``powerLaw`` power 1, x in m3), t = 2 s; M0 closed
                form, M2 from the extrapolated fine fixed-pivot reference.

Definitions matched (the conversion used for pbe-cfd, density rho = 1000 kg/m3, p = rho x):
  * ``constant`` coalescence: the 1/2 n n convention (pairs i = j carry 1/2) as pbe-cfd's
    ``constant`` kernel: k0 = C [m3/s] unchanged.
  * ``powerLaw``: S = x^power with x in m3 and no rate coefficient; pbe-cfd ``power`` with
    s0 = 1 1/s, a = power, p_ref = rho x 1 m3 (power 0: pbe-cfd ``constant``, s0 = 1 1/s).
  * ``uniformBinary``: daughters below the smallest group are dropped (2 (1 - x0 / xk)
    daughters per break instead of 2) and a break of the smallest group returns (x1 - x0) / x0
    of it; pbe-cfd ``uniform`` (b = 2 / p') has no lower end. The class grids reach 2^-16 m3
    (breakage) and 2^-10 m3 (mixed, where S = x makes small granules break slowly).
  * pairs whose volume exceeds the largest group do not coalesce in the class method; its
    grids reach 2^8 m3 (aggregation) and 2^6 m3 (mixed).
  * time: the class method steps with implicit death and explicit birth (first order in dt,
    fixed dt); pbe-cfd integrates adaptively at rtol 1e-8. The dt part is measured by a run at
    twice the step.
  * the class moments: n_i = alpha f_i / x_i from the written fields, M_k = sum n_i x_i^k.
"""
from __future__ import annotations

import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from ..methods.cnmc import ENTRY as CNMC
from ..methods.qmom import ENTRY as QMOM
from .common import _git_describe, _say, machine_info
from .peer_case import (ClassCase, PeerUnavailable, openfoam_missing, read_class_moments,
                        run_case)
from .peer_reference import (constant_aggregation_moments, constant_breakage_moments,
                             extrapolated_reference, geometric_grid,
                             linear_breakage_aggregation_m0)
from .peer_report import write_peer

ALPHA = 0.1
X_START = 1.0          # m3
N_START = ALPHA / X_START
RHO = 1000.0           # kg/m3, pbe-cfd's particle density (p = rho x)
AGG_RATE = 10.0        # m3/s
REF_SPAN = (2.0 ** -24, 2.0 ** 8)

#: name: (title, aggregation rate, breakup power, end time, class dt, class span, closed form)
PROBLEMS = {
    "aggregation": ("constant aggregation", AGG_RATE, None, 2.0, 2e-3, (1.0, 2.0 ** 8)),
    "breakage": ("constant breakage, uniform daughters", 0.0, 0.0, 1.0, 1e-3,
                 (2.0 ** -16, 1.0)),
    "mixed": ("constant aggregation + S = x breakage", AGG_RATE, 1.0, 2.0, 2e-3,
              (2.0 ** -10, 2.0 ** 6)),
}
#: class-method resolutions: groups per doubling of volume
CLASS_RESOLUTIONS = (1, 2, 3)
QMOM_NODES = (2, 3, 4)


def reference(problem) -> dict:
    """Reference M0, M1, M2 [m3^k/m3] of a problem and how each was obtained."""
    _, rate, power, t_end, _, _ = PROBLEMS[problem]
    if problem == "aggregation":
        ref = constant_aggregation_moments(N_START, X_START, rate, t_end)
        return dict(ref, text="closed form (docs/physics.md section 10)")
    if problem == "breakage":
        ref = constant_breakage_moments(N_START, X_START, 1.0, t_end)
        return dict(ref, text="closed form (docs/physics.md section 8)")
    fine = extrapolated_reference(REF_SPAN[0], 2.0 ** 6, X_START, N_START, t_end, rate,
                                     power)
    m0 = linear_breakage_aggregation_m0(N_START, X_START, rate, t_end)
    return {"M0": m0, "M1": N_START * X_START, "M2": fine["M2"],
            "text": (f"M0 closed form (Riccati); M2 fixed pivot on {fine['pivots']} pivots "
                     f"over 2^-24..2^6 m3, Richardson-extrapolated (it moved M2 by "
                     f"{fine['spread_M2']:.1e}; its M0 is {abs(fine['M0'] / m0 - 1):.1e} "
                     "off the closed form)")}


def reference_checks() -> dict:
    """The fine fixed-pivot reference on the two closed-form problems: its relative M0 and M2
    errors (how far the reference of the mixed problem can be trusted)."""
    out = {}
    for problem in ("aggregation", "breakage"):
        _, rate, power, t_end, _, _ = PROBLEMS[problem]
        fine = extrapolated_reference(REF_SPAN[0], REF_SPAN[1] if power is None else 1.0,
                                         X_START, N_START, t_end, rate, power)
        exact = reference(problem)
        out[problem] = {k: abs(fine[k] / exact[k] - 1.0) for k in ("M0", "M2")}
    return out


# ============================================================================ class method
def class_case(problem, per_doubling, dt=None, end_time=None, cells=1) -> ClassCase:
    """The OpenFOAM case of a problem at ``per_doubling`` groups per doubling of volume."""
    _, rate, power, t_end, step, (low, high) = PROBLEMS[problem]
    x = geometric_grid(low, high, per_doubling)
    f = np.where(np.abs(np.log(x / X_START)) < 1e-9, 1.0, 0.0)
    return ClassCase(volumes=tuple(float(v) for v in x), fractions=tuple(float(v) for v in f),
                        alpha=ALPHA, coalescence_rate=rate, breakup_power=power,
                        dt=step if dt is None else dt,
                        end_time=t_end if end_time is None else end_time, cells=cells)


def _cpu_seconds(log_path) -> float:
    """The solver's last ``ExecutionTime`` [s] (its CPU time) from its log."""
    cpu = float("nan")
    for line in Path(log_path).read_text(errors="replace").splitlines():
        if line.startswith("ExecutionTime"):
            cpu = float(line.split("=")[1].split()[0])
    return cpu


def run_class(case, work_dir, name) -> dict:
    """Run one class case in ``work_dir``/name; its moments, wall and CPU times."""
    info = run_case(case, Path(work_dir) / name)
    mom = read_class_moments(case, info["case_dir"])
    return {"M0": float(mom["M0"][0]), "M1": float(mom["M1"][0]), "M2": float(mom["M2"][0]),
            "sum_f": float(mom["sum_f"][0]), "wall_s": info["solver_s"],
            "cpu_s": _cpu_seconds(Path(info["case_dir"]) / "log.solver"),
            "steps": info["steps"], "groups": len(case.volumes), "cells": case.cells}


# ============================================================================ pbe-cfd
def pbe_scene(problem):
    """The pbe-cfd well-mixed scene of a problem (p = rho x, the conversions of the module
    doc), method QMOM N = 3."""
    from ..scene.scene import scene_from_dict
    title, rate, power, t_end, _, _ = PROBLEMS[problem]
    data = {"scene": {"name": f"peer-{problem}", "end_time": t_end, "output_interval": t_end},
            "domain": {"type": "well-mixed"}, "material": {"density": RHO},
            "initial": {"distribution": "monodisperse", "number_density": N_START,
                        "mean_mass": RHO * X_START},
            "method": {"name": QMOM.name, QMOM.order_key: 3}}
    if rate > 0:
        data["aggregation"] = {"kernel": "constant", "rate": rate}
    if power == 0.0:
        data["breakage"] = {"selection": "constant", "rate": 1.0, "daughters": "uniform"}
    elif power is not None:
        data["breakage"] = {"selection": "power", "rate": 1.0, "exponent": power,
                            "reference_mass": RHO * 1.0, "daughters": "uniform"}
    return scene_from_dict(data, path=f"<bench peer {title}>")


def run_pbe(scene, changes, repeats) -> dict:
    """One pbe-cfd method through the well-mixed run path: volume moments at the end, the
    median wall and process time of ``repeats`` runs after a first (compiling) one."""
    from ..runs.simulate import run_well_mixed
    sc = scene.with_method(**changes)
    t0 = time.perf_counter()
    res = run_well_mixed(sc)
    first = time.perf_counter() - t0
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_well_mixed(sc)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    cols = res.columns
    out = {f"M{k}": float(cols[f"M{k}0"][-1]) / RHO ** k for k in (0, 1, 2)}
    # the moment methods' accepted steps; the cNMC has events, not steps (no cell-step cost)
    steps = res.stats.get("accepted_steps")
    out.update(wall_s=statistics.median(walls), cpu_s=statistics.median(cpus),
               first_call_s=first, steps=None if steps is None else int(steps), cells=1)
    return out


def pbe_variants(quick):
    """(method label, knob label, Method changes) of the pbe-cfd runs."""
    out = [(QMOM.name, f"N={n}", {"name": QMOM.name, QMOM.order_key: n}) for n in QMOM_NODES]
    if not quick:
        out.append((CNMC.name, "1e4 x 4", {"name": CNMC.name, "particles": 10000,
                                            "replicas": 4, "seed": 5}))
    return out


# ============================================================================ the study
def _errors(row, ref):
    for k in ("M0", "M1", "M2"):
        row[f"err_{k}"] = row[k] / ref[k] - 1.0
    steps = row.get("steps")
    row["per_cell_step_s"] = (row["wall_s"] / (steps * row.get("cells", 1)) if steps
                              else float("nan"))
    return row


def equal_accuracy(rows, problem, target=0.01) -> dict:
    """Groups the class method needs for |M2 error| = target, from a power-law fit
    |err| ~ G^-p over its runs, its wall and CPU time there from fits ~ G^q, and their ratios
    to QMOM N = 3's on the same problem."""
    cls = [r for r in rows if r["problem"] == problem and r["method"] == "class"
           and r.get("dt_check") is None and r.get("cells", 1) == 1]
    qm = [r for r in rows if r["problem"] == problem and r["knob"] == "N=3"]
    if len(cls) < 2 or not qm:
        return {}
    g = np.log([r["groups"] for r in cls])
    e = np.log([abs(r["err_M2"]) for r in cls])
    pe = np.polyfit(g, e, 1)
    groups = math.exp((math.log(target) - pe[1]) / pe[0]) if pe[0] < 0 else float("nan")
    out = {"target": target, "error_order": -pe[0], "groups": groups,
           "qmom3_err_M2": qm[0]["err_M2"]}
    for kind in ("wall_s", "cpu_s"):
        fit = np.polyfit(g, np.log([r[kind] for r in cls]), 1)
        cost = (math.exp(np.polyval(fit, math.log(groups))) if math.isfinite(groups)
                else float("nan"))
        out.update({f"class_{kind}": cost, f"qmom3_{kind}": qm[0][kind],
                    f"ratio_{kind}": cost / qm[0][kind]})
    return out


def peer_study(out_dir="bench-out", quick=False, repeats=None, quiet=False) -> dict:
    """Run the peer comparison and write peer.csv, peer.md, peer.png and peer.json into
    ``out_dir``. Raises peer_case.PeerUnavailable when OpenFOAM is not installed."""
    why = openfoam_missing()
    if why:
        raise PeerUnavailable(why)
    repeats = (1 if quick else 3) if repeats is None else repeats
    resolutions = (1, 2) if quick else CLASS_RESOLUTIONS
    problems = ("aggregation",) if quick else tuple(PROBLEMS)
    machine = machine_info()
    rows, refs = [], {}
    with tempfile.TemporaryDirectory(prefix="pbe-cfd-peer-") as work:
        for problem in problems:
            ref = refs[problem] = reference(problem)
            scale = 0.25 if quick else 1.0
            t_end = PROBLEMS[problem][3] * scale
            if quick:
                ref.update({k: v for k, v in constant_aggregation_moments(
                    N_START, X_START, AGG_RATE, t_end).items()})
            for q in resolutions:
                case = class_case(problem, q, end_time=t_end)
                _say(quiet, f"  {problem}: class method, {len(case.volumes)} groups ...")
                row = run_class(case, work, f"{problem}-q{q}")
                rows.append(_errors(dict(row, problem=problem, method="class",
                                         knob=f"{row['groups']} groups"), ref))
            if not quick:
                q = resolutions[-1]
                case = class_case(problem, q, dt=2.0 * PROBLEMS[problem][4])
                _say(quiet, f"  {problem}: class method, {len(case.volumes)} groups, 2 dt ...")
                row = run_class(case, work, f"{problem}-q{q}-2dt")
                rows.append(_errors(dict(row, problem=problem, method="class", dt_check=True,
                                         knob=f"{row['groups']} groups, 2 dt"), ref))
            scene = pbe_scene(problem)
            if quick:
                import dataclasses
                scene = dataclasses.replace(scene, end_time=t_end, output_interval=t_end)
            for method, knob, changes in pbe_variants(quick):
                _say(quiet, f"  {problem}: {method} {knob} ...")
                row = run_pbe(scene, changes, repeats)
                rows.append(_errors(dict(row, problem=problem, method=method, knob=knob), ref))
        cost = _cells_cost(work, quick, quiet)
    checks = {} if quick else reference_checks()
    ratios = {p: equal_accuracy(rows, p) for p in problems}
    result = {"rows": rows, "references": {p: r["text"] for p, r in refs.items()},
              "titles": {p: PROBLEMS[p][0] for p in problems},
              "reference_checks": checks, "equal_accuracy": ratios, "cells_cost": cost,
              "machine": machine, "commit": _git_describe(), "quick": quick,
              "repeats": repeats}
    write_peer(Path(out_dir), result)
    return result


def _cells_cost(work, quick, quiet) -> dict:
    """Marginal cost per cell-step of the class method: the aggregation problem at 2 groups per
    doubling on a box of 1 and of N cells for a short time."""
    cells = 8 if quick else 64
    t_end = 0.1 if quick else 0.5
    walls = {}
    for n in (1, cells):
        case = class_case("aggregation", 2, end_time=t_end, cells=n)
        _say(quiet, f"  cost per cell: class method on {n} cells ...")
        walls[n] = run_class(case, work, f"cells-{n}")
    steps = walls[1]["steps"]
    marginal = (walls[cells]["wall_s"] - walls[1]["wall_s"]) / ((cells - 1) * steps)
    return {"cells": cells, "steps": steps, "groups": walls[1]["groups"],
            "wall_1_s": walls[1]["wall_s"], f"wall_{cells}_s": walls[cells]["wall_s"],
            "marginal_per_cell_step_s": marginal}
