"""``pbe-cfd plan``: what a scene will compute, and what it leaves out, without running it.

For a coupled scene it also reads the CFD case: the cells, the active and spray cells and the
criterion that removed the others, the fields found (time-averaged or instantaneous), the
averaging window and the CFD time. Read-only: it opens a snapshot or a case whose converted
fields already exist, and writes nothing anywhere."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from . import model
from ..methods.registry import method_of
from ..scene import spray
from ..physics.breakage import DAUGHTERS_BY_NAME, SELECTION_BY_NAME
from ..physics.efficiency import EFFICIENCY_BY_NAME
from ..physics.kernels import KERNEL_BY_NAME


def describe_plan(scene) -> str:
    """Human-readable plan of a scene: coordinates, kernel, efficiencies, sources, method,
    fields needed, and the effects left out."""
    lines = [f"scene {scene.name!r} from {scene.source}",
             f"  time: 0 .. {scene.end_time:g} s, output every {scene.output_interval:g} s"]
    dom = scene.domain
    if dom.type == "well-mixed":
        lines.append("  domain: well-mixed (one cell)")
    else:
        lines.append(f"  domain: OpenFOAM case {dom.case} at time {dom.time}; cells with "
                     f"alpha >= {dom.alpha_min:g} solved, the rest left empty")
        lines.extend(case_lines(scene))
    coords = "p (granule mass) and b (binder mass)" if scene.bivariate else "p (granule mass) only"
    lines.append(f"  coordinates: {coords}")
    left_out = []
    agg = scene.aggregation
    fields = set()
    if agg is None:
        left_out.append("aggregation (no [aggregation] table)")
    else:
        kernel = KERNEL_BY_NAME[agg.kernel]
        lines.append(f"  aggregation: kernel {agg.kernel}, k0 = {agg.rate:g} {kernel.unit}")
        fields.update(kernel.cell_fields)
        if agg.efficiency:
            lines.append(f"  efficiency: {' x '.join(agg.efficiency)}")
            if any(EFFICIENCY_BY_NAME[f].uses_collision_velocity for f in agg.efficiency):
                if dom.type == "openfoam" or dom.collision_velocity is None:
                    lines.append("    collision velocity u0 = 4 sqrt(Theta/pi) from the "
                                 "granular temperature")
                    fields.add("granular_temperature")
                else:
                    lines.append(f"    collision velocity u0 = {dom.collision_velocity:g} m/s")
        else:
            lines.append("  efficiency: none (psi = 1)")
        if scene.separate_droplets:
            lines.append(f"  droplets: a population of their own, captured at "
                         f"{agg.droplet_factor:g} x the kernel; no droplet-droplet aggregation")
    inj = scene.binder_injection
    if inj is None:
        left_out.append("binder injection (no [binder_injection] table)")
    else:
        where = "spray-zone cells" if inj.zone is not None else "every cell"
        flow = " of solution over the spray zone" if inj.rate_unit == spray.MASS_FLOW else ""
        lines.append(f"  binder injection: {inj.rate:g} {inj.rate_unit}{flow}, droplets of "
                     f"{inj.droplet_diameter * 1e6:g} um into {where}")
        lines.extend(_spray_lines(scene, inj))
    brk = scene.breakage
    if brk is None:
        left_out.append("breakage (no [breakage] table)")
    else:
        lines.extend(_breakage_lines(scene, brk))
        fields.update(SELECTION_BY_NAME[brk.selection].cell_fields)
    if scene.drying is None:
        left_out.append("drying (no [drying] table)")
    else:
        lines.extend(_drying_lines(scene.drying))
        if scene.separate_droplets:
            lines.append("    free droplets evaporate: their liquid L_d carried beside their "
                         "number, each droplet at the class's mean liquid (d^2 law of the "
                         "liquid sphere, then the skeleton's periods)")
        lines.extend(air_lines(scene))
    if scene.transport is None:
        if dom.type == "openfoam":
            left_out.append("transport between cells (no [transport] table)")
    else:
        lines.append(f"  transport: upwind by the granular face flux, Courant <= "
                     f"{scene.transport.courant:g}")
    lines.append(f"  method: {method_of(scene).plan_line(scene)}")
    from ..distribution.tables import distribution_text
    lines.append(f"  size distribution (d10/d50/d90, psd.csv): {distribution_text(scene)}")
    if scene.output is not None and dom.type == "openfoam" and unconverted_reason(scene):
        lines.append(f"  per-cell size distribution (cell_psd.csv, png/cell_psd.png): "
                     f"{len(scene.output.cell_psd)} cells, resolved when the case is read")
    if not scene.bivariate:
        left_out.append("binder coordinate (dry start, no injection)")
    lines.append(f"  cell fields needed: {', '.join(sorted(fields)) or 'none'}")
    t_gel = model.product_gel_time(scene)
    if t_gel is not None:
        lines.append(f"  product kernel gel time: {t_gel:.4g} s")
    if dom.type == "openfoam" and scene.transport is not None:
        try:
            from ..transport.operator import transport_plan_lines
            lines.extend(transport_plan_lines(scene))
        except Exception as exc:  # plan must still print what it can
            lines.append(f"  transport plan unavailable: {exc}")
    if getattr(scene, "coupling", None) is not None:
        from .coupling_plan import plan_lines
        lines.extend(plan_lines(scene))
    lines.append("  left out: " + ("; ".join(left_out) if left_out else "nothing"))
    return "\n".join(lines)


def _breakage_lines(scene, brk):
    """The plan's breakage lines: selection, daughters, the gate, who does not break."""
    sel = SELECTION_BY_NAME[brk.selection]
    lines = [f"  breakage: selection {brk.selection}, {sel.formula}, s0 = {brk.rate:g} 1/s"]
    refs = []
    if "exponent" in sel.keys:
        refs.append(f"a = {brk.exponent:g}")
    if "reference_mass" in sel.keys:
        p_ref = brk.reference_mass if brk.reference_mass is not None else scene.initial.mean_mass
        refs.append(f"p_ref = {p_ref:g} kg" + (" (the initial mean granule mass)"
                                              if brk.reference_mass is None else ""))
    if refs:
        lines.append("    " + ", ".join(refs))
    if brk.reference_granular_temperature is not None:
        lines.append(f"    Theta_ref = {brk.reference_granular_temperature:g} m2/s2")
        if brk.yield_strength is not None:
            lines.append(f"    only where St_def = rho_g u0^2 / (2 Y) > "
                         f"{brk.critical_deformation_number:g} (Y = {brk.yield_strength:g} Pa, "
                         "u0 = 4 sqrt(Theta/pi); Tardos, Khan and Mort 1997)")
    lines.append(f"    daughters: {DAUGHTERS_BY_NAME[brk.daughters].formula}, binder in "
                 "proportion to mass" + ("; free droplets never break"
                                         if scene.separate_droplets else ""))
    return lines



def _case_dir(scene) -> Path:
    """The case directory named by ``[domain] case``, relative to the scene file."""
    path = Path(scene.domain.case)
    if not path.is_absolute() and scene.source:
        path = Path(scene.source).parent / path
    return path


def unconverted_reason(scene) -> str | None:
    """Why the scene's case cannot be opened without writing into it (a case with no mesh
    whose fields at the chosen time foamToVTK has not converted), or None where it can (a
    snapshot; a case with its mesh, whose fields are converted in pbe-cfd's own cache as a
    run does, never in the case; converted fields that exist)."""
    from ..io import openfoam as of
    from ..io.openfoam.fields import _vtk_internal_file
    from ..io.openfoam.readable import has_mesh
    from .domain import BUNDLED_PREFIX

    case = scene.domain.case
    if case.startswith(BUNDLED_PREFIX) or case.endswith(".vtu"):
        return None
    path = _case_dir(scene)
    if not path.is_dir():
        return None                      # load_domain names what is wrong
    if has_mesh(path):
        return None                      # converted in pbe-cfd's cache, not in the case
    try:
        t = of.pick_time(path, "latest" if scene.domain.time == "latest"
                         else float(scene.domain.time))
    except (of.OpenFOAMError, ValueError):
        return None
    if _vtk_internal_file(path, t) is None:
        return (f"its fields at t = {t:g} s are not converted yet; a run converts them with "
                "foamToVTK first, which plan does not do (it writes nothing)")
    return None


def _control_entry(text: str, key: str) -> str | None:
    m = re.search(rf"^\s*{key}\s+([^;\s]+)\s*;", text, flags=re.M)
    return m.group(1) if m else None


def averaging_window(scene, cells) -> str:
    """The fieldAverage window [s] the time-averaged fields cover, as text."""
    control = cells.source.get("control") or {}
    if "avgStart" in control:
        return f"{control['avgStart']:g} to {cells.time:g} s"
    system = _case_dir(scene) / "system"
    try:
        text = (system / "controlDict").read_text()
    except OSError:
        return "unknown (no system/controlDict to read it from)"
    included = re.search(r'^\s*#include(?:IfPresent)?\s+"([^"]+)"', text, flags=re.M)
    if included:                 # an included file (the template's controlDict.override) wins
        try:
            text = (system / included.group(1)).read_text() + "\n" + text
        except OSError:
            pass
    start = _control_entry(text, "timeStart")
    if start is not None and start.startswith("$"):
        start = _control_entry(text, start[1:])
    if start is None:
        first = _control_entry(text, "startTime") or "0"
        return (f"{first} to {cells.time:g} s (fieldAverage has no timeStart: the whole run, "
                "start-up included)")
    return f"{start} to {cells.time:g} s"


def _drying_lines(dry) -> list[str]:
    """The plan's lines on the [drying] table: the air, its wet bulb, the drying curve."""
    from ..physics.drying import gas_state
    rho, mu, diffusivity, t_wb, driving = gas_state(dry.air_temperature, dry.air_humidity,
                                                    dry.pressure)
    air = "inlet air" if dry.air_temperature_source == "cfd" else "air"
    return [f"  drying: {air} at {dry.air_temperature:g} K, humidity {dry.air_humidity:g} kg/kg, "
            f"{dry.pressure:g} Pa (wet bulb {t_wb:.2f} K, driving force {driving:.4g} kg/kg); "
            "Ranz-Marshall Sh at "
            + (f"slip {dry.slip_velocity:g} m/s" if dry.slip_velocity is not None
               else "each cell's slip velocity"),
            f"    constant rate above X_cr = {dry.critical_moisture:g}, falling rate to X_eq = "
            f"{dry.equilibrium_moisture:g} (kg liquid per kg dry solids)"]


def air_lines(scene) -> list[str]:
    """The plan's lines on the bed's air: which values are the scene's, the air balance, its
    flow and capacity, and how the bed's humidity is lagged (``runs.air``)."""
    from ..physics.drying import gas_state
    from .air import air_flow, case_inlet_velocity, domain_section
    dry = scene.drying
    out = _input_lines(scene)
    if dry.air_balance == "none":
        return out + ["    air balance: none (every granule sees the inlet air, as an isolated "
                      "granule would)"]
    area = velocity = None
    source = "air_mass_flow"
    if dry.air_mass_flow is None:
        if dry.bed_area is None:
            from .domain import load_domain
            area = domain_section(load_domain(scene).cells)
        if dry.superficial_velocity is None:
            velocity = case_inlet_velocity(scene)
        source = (f"superficial velocity {dry.superficial_velocity or velocity:g} m/s "
                  f"({'scene' if dry.superficial_velocity else 'the case gas inlet'}) x "
                  f"{dry.bed_area or area:g} m2 x the inlet's dry-air density")
    flow = air_flow(scene, area, velocity)
    if dry.air_temperature_source == "cfd":
        out = out + [f"    air balance: {dry.air_balance} gas; dry-air flow {flow:.4g} kg/s "
                     f"({source}); one bed humidity Y, each cell drying against "
                     "Y_s(T_wb) - Y at the wet bulb of its own gas temperature (a cell whose "
                     "Y_s(T_wb) is at or below Y does not dry: condensation is not modelled)"]
        return out + [f"    the bed's humidity: held {dry.air_interval:g} s at a time, from "
                      "each cell's evaporation over the interval before (first order in the "
                      "interval)"]
    driving = gas_state(dry.air_temperature, dry.air_humidity, dry.pressure)[4]
    return out + [f"    air balance: {dry.air_balance} gas; dry-air flow {flow:.4g} kg/s "
                  f"({source}); capacity G dY_in = {flow * driving:.4g} kg water/s",
                  f"    the bed's humidity: held {dry.air_interval:g} s at a time, from the "
                  "evaporation of the interval before (first order in the interval)"]


def _input_lines(scene) -> list[str]:
    """The plan's lines on where each per-cell drying input comes from (``runs.cell_gas``):
    the scene's value, or the CFD's fields with their range over the active cells."""
    from .cell_gas import from_cfd, source_lines
    if not from_cfd(scene):
        return source_lines(scene, None, None)
    reason = unconverted_reason(scene)
    if reason is not None:
        return [f"    per-cell drying inputs from the CFD not read: {reason}"]
    from .domain import load_domain
    cells = load_domain(scene).cells
    return source_lines(scene, cells, np.asarray(cells.alpha) >= scene.domain.alpha_min)


def _spray_lines(scene, inj) -> list[str]:
    """The plan's lines on the sprayed binder's solids and the spray schedule."""
    out = []
    if inj.solids_fraction > 0.0:
        out.append(f"    binder solution: solids fraction {inj.solids_fraction:g}; the liquid "
                   f"{1.0 - inj.solids_fraction:g} p_d wets (b), the solids join the granule")
    if inj.schedule:
        parts = [f"{t0:g}-{t1:g} s: {rate:g}"
                 for t0, t1, rate in spray.segments(inj, scene.end_time)]
        out.append(f"    spray schedule ({inj.rate_unit}): {'; '.join(parts)}")
    return out


def _spray_flow_line(scene, cells) -> str:
    """The peak flow the spray zone of ``cells`` receives, in both units."""
    from ..physics.injection import droplet_mass
    from .domain import spray_zone_volume
    inj = scene.binder_injection
    volume = spray_zone_volume(scene, cells)
    mass = droplet_mass(inj.droplet_diameter, scene.material.binder_density)
    try:
        per = spray.per_volume(inj, volume, mass)
    except ValueError as exc:
        return f"    sprayed: nothing: {exc}"
    return (f"    sprayed at the peak: {per.rate * mass * volume:.4g} kg/s of solution = "
            f"{per.rate:.4g} droplets/(m3 s) over the {volume:.4g} m3 of spray-zone cells "
            "holding granules")


def spray_lines(scene, cells, active: np.ndarray) -> list[str]:
    """The spray zone among the active cells and what removed the other active cells."""
    inj = scene.binder_injection
    if inj is None:
        return []
    if inj.zone is None:
        return [f"  spray zone: every active cell ({int(active.sum())})",
                _spray_flow_line(scene, cells)]
    z = inj.zone
    centre = np.asarray(cells.cell_centre)
    alpha = np.asarray(cells.alpha)
    inside = np.all((centre >= np.array(z.box_min)) & (centre <= np.array(z.box_max)), axis=1)
    window = (alpha >= z.alpha_low) & (alpha <= z.alpha_high)
    spray = active & inside & window
    return [f"  spray zone: {int(spray.sum())} of the {int(active.sum())} active cells; "
            f"removed {int((active & ~inside).sum())} outside the box, "
            f"{int((active & inside & (alpha > z.alpha_high)).sum())} above alpha_high = "
            f"{z.alpha_high:g}, {int((active & inside & (alpha < z.alpha_low)).sum())} below "
            f"alpha_low = {z.alpha_low:g}", _spray_flow_line(scene, cells)]


def case_lines(scene) -> list[str]:
    """The plan's lines about the CFD case of an OpenFOAM-domain scene (one read of it)."""
    from .domain import load_domain

    reason = unconverted_reason(scene)
    if reason is not None:
        return [f"  case not opened: {reason}"]
    domain = load_domain(scene)
    cells = domain.cells
    alpha = np.asarray(cells.alpha)
    active = alpha >= scene.domain.alpha_min
    kind = ("time-averaged" if cells.averaged
            else "instantaneous (no fieldAverage output at this time)")
    src = cells.source
    return [f"  case read: {domain.description}; CFD time {cells.time:g} s",
            f"  fields: {src.get('alpha_field')} and {src.get('theta_field')}, {kind}",
            f"  averaging window: {averaging_window(scene, cells)}" if cells.averaged
            else "  averaging window: none (instantaneous fields)",
            f"  cells: {cells.n_cells}; active {int(active.sum())} (alpha >= alpha_min = "
            f"{scene.domain.alpha_min:g}; {int((~active).sum())} below it hold no granules)",
            *spray_lines(scene, cells, active), *cell_psd_lines(scene, cells, active)]


def cell_psd_lines(scene, cells, active) -> list[str]:
    """The cells of ``[output] cell_psd`` (SceneError, as the run, for a bad selection)."""
    if scene.output is None:
        return []
    from .couple import select_psd_cells
    from .problem import output_plan
    sel = select_psd_cells(output_plan(scene), cells, active)
    alpha = np.asarray(cells.alpha, dtype=float)[sel.cells]
    cells_text = "; ".join(f"{sel.label(j)}, alpha {alpha[j]:.3g}"
                           for j in range(len(sel.cells)))
    return [f"  per-cell size distribution (cell_psd.csv, png/cell_psd.png): {cells_text}"]
