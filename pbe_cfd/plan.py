"""``pbe-cfd plan``: what a scene will compute, and what it leaves out, without running it."""
from __future__ import annotations

from . import model
from .physics.kernels import KERNEL_USES_CELL, KERNELS
from .scene import Scene


def describe_plan(scene: Scene) -> str:
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
        lines.append(f"  aggregation: kernel {agg.kernel}, k0 = {agg.rate:g} "
                     f"{KERNELS[agg.kernel][2]}")
        fields.update(KERNEL_USES_CELL.get(agg.kernel, ()))
        if agg.efficiency:
            lines.append(f"  efficiency: {' x '.join(agg.efficiency)}")
            if "physical" in agg.efficiency:
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
    m = scene.method
    if m.name == "qmom":
        arrays = model.pack(scene)
        lines.append(f"  method: QMOM with {m.nodes} nodes; state {', '.join(arrays.state_names)}"
                     f"; rtol {m.rtol:g}")
    elif m.name == "laguerre":
        arrays = model.pack(scene)
        lines.append(f"  method: Laguerre ROM of order {m.order} "
                     f"({'moment-consistent' if m.consistent else 'plain projection'}), "
                     f"support p <= {m.support_mass:g} kg, b <= {m.support_binder:g} kg, grid "
                     f"{m.grid_mass} x {m.grid_binder}; {len(arrays.state_names)} states")
    else:
        lines.append(f"  method: constant-number Monte Carlo, {m.particles} particles x "
                     f"{m.replicas} replicas, seed {m.seed}")
    if not scene.bivariate:
        left_out.append("binder coordinate (dry start, no injection)")
    lines.append(f"  cell fields needed: {', '.join(sorted(fields)) or 'none'}")
    t_gel = model.product_gel_time(scene)
    if t_gel is not None:
        lines.append(f"  product kernel gel time: {t_gel:.4g} s")
    if dom.type == "openfoam" and scene.transport is not None:
        try:
            from .couple import transport_plan_lines
            lines.extend(transport_plan_lines(scene))
        except Exception as exc:  # plan must still print what it can
            lines.append(f"  transport plan unavailable: {exc}")
    lines.append("  left out: " + ("; ".join(left_out) if left_out else "nothing"))
    return "\n".join(lines)
