"""``pbe-cfd plan``: what a scene will compute, and what it leaves out, without running it."""
from __future__ import annotations

from . import model
from .methods.registry import method_of
from .physics.efficiency import EFFICIENCY_BY_NAME
from .physics.kernels import KERNEL_BY_NAME


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
        lines.append(f"  binder injection: {inj.rate:g} droplets/(m3 s) of "
                     f"{inj.droplet_diameter * 1e6:g} um into {where}")
    if scene.transport is None:
        if dom.type == "openfoam":
            left_out.append("transport between cells (no [transport] table)")
    else:
        lines.append(f"  transport: upwind by the granular face flux, Courant <= "
                     f"{scene.transport.courant:g}")
    lines.append(f"  method: {method_of(scene).plan_line(scene)}")
    if not scene.bivariate:
        left_out.append("binder coordinate (dry start, no injection)")
    lines.append(f"  cell fields needed: {', '.join(sorted(fields)) or 'none'}")
    t_gel = model.product_gel_time(scene)
    if t_gel is not None:
        lines.append(f"  product kernel gel time: {t_gel:.4g} s")
    if dom.type == "openfoam" and scene.transport is not None:
        try:
            from .transport import transport_plan_lines
            lines.extend(transport_plan_lines(scene))
        except Exception as exc:  # plan must still print what it can
            lines.append(f"  transport plan unavailable: {exc}")
    lines.append("  left out: " + ("; ".join(left_out) if left_out else "nothing"))
    return "\n".join(lines)
