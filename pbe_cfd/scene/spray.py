"""The spray schedule of ``[binder_injection]``: when droplets are sprayed, at which rate.

A schedule is a tuple of (t_start [s], rate [droplets/(m3 s)]) in increasing time; each rate
holds until the next start, nothing is sprayed before the first, and an empty schedule means
the table's ``rate`` all the time (docs/physics.md section 7). The per-cell integration runs each
segment with the cell rows' injection scaled by rate / peak rate (``runs.batch.CellBatch``).
"""
import math
from dataclasses import dataclass, replace

#: units of ``[binder_injection] rate`` and the schedule's rates (``rate_unit``): droplets per
#: m3 of spray-zone cell and s (the default), or the nozzle's mass flow of sprayed solution
#: [kg/s] over the whole spray zone (an OpenFOAM domain; ``per_volume`` converts it)
PER_VOLUME = "droplets/(m3 s)"
MASS_FLOW = "kg/s"
RATE_UNITS = (PER_VOLUME, MASS_FLOW)


@dataclass(frozen=True)
class Zone:
    """Spray zone of an OpenFOAM domain: cells with alpha in [alpha_low, alpha_high] [-] whose
    centre lies in the box [box_min, box_max] [m]."""
    alpha_low: float = 0.0
    alpha_high: float = 1.0
    box_min: tuple = (-math.inf, -math.inf, -math.inf)
    box_max: tuple = (math.inf, math.inf, math.inf)


@dataclass(frozen=True)
class BinderInjection:
    """Binder droplets: rate [droplets/(m3 s)] (a schedule's peak rate), droplet_diameter [m],
    zone (OpenFOAM only), solids_fraction [-] (dissolved binder solids per sprayed mass,
    docs/physics.md section 7), schedule ((t_start [s], rate), ...) (empty: ``rate`` always),
    rate_unit: "droplets/(m3 s)", or "kg/s" (OpenFOAM only) for rate and the schedule's
    rates as the nozzle's flow of solution, which each run spreads over the spray zone's
    cells of its case (docs/physics.md section 7)."""
    rate: float
    droplet_diameter: float
    zone: Zone | None = None
    solids_fraction: float = 0.0
    schedule: tuple = ()
    rate_unit: str = PER_VOLUME


def per_volume(injection, zone_volume, droplet_mass):
    """The ``BinderInjection`` in droplets/(m3 s): a MASS_FLOW table's rates [kg/s] divided by
    the droplet's mass [kg] and the spray zone's volume [m3] (its cells holding granules); a
    PER_VOLUME table unchanged. Raises ValueError for an empty zone."""
    if injection.rate_unit != MASS_FLOW:
        return injection
    if not zone_volume > 0.0:
        raise ValueError(f"a mass flow of {injection.rate:g} kg/s is sprayed over the spray "
                         "zone's cells, and the zone holds no cell with granules")
    f = 1.0 / (droplet_mass * zone_volume)
    return replace(injection, rate=injection.rate * f, rate_unit=PER_VOLUME,
                   schedule=tuple((t, r * f) for t, r in injection.schedule))


def parse_injection(path, data, domain, table, vector3, error):
    """The [binder_injection] table ``data`` of a scene (``domain``: its ``Domain``) as a
    ``BinderInjection``; ``table``, ``vector3``, ``error``: the scene reader's ``_Table``,
    ``_vector3`` and ``SceneError``."""
    t = table(path, "binder_injection", data)
    unit = t.choice("rate_unit", RATE_UNITS, PER_VOLUME)
    if unit == MASS_FLOW and domain.type != "openfoam":
        raise error(path, "binder_injection.rate_unit",
                    "a mass flow [kg/s] is sprayed over a spray zone's cells: expected "
                    f"domain.type = \"openfoam\", or rate_unit = \"{PER_VOLUME}\"")
    rate, schedule, solids = parse_spray(path, t, error, unit)
    diameter = t.number("droplet_diameter", positive=True, unit="m")
    zone = None
    if t.has("zone"):
        if domain.type != "openfoam":
            raise error(path, "binder_injection.zone",
                        "a spray zone needs cells: expected domain.type = \"openfoam\"")
        z = table(path, "binder_injection.zone", t.raw("zone"))
        zone = Zone(alpha_low=z.number("alpha_low", 0.0, non_negative=True, high=1.0),
                    alpha_high=z.number("alpha_high", 1.0, non_negative=True, high=1.0),
                    box_min=vector3(path, f"{z.name}.box_min", z.raw("box_min", [-1e30] * 3)),
                    box_max=vector3(path, f"{z.name}.box_max", z.raw("box_max", [1e30] * 3)))
        z.finish()
    t.finish()
    return BinderInjection(rate=rate, droplet_diameter=diameter, zone=zone,
                           solids_fraction=solids, schedule=schedule, rate_unit=unit)


def parse_spray(path, t, error, unit=PER_VOLUME):
    """(peak rate [``unit``], schedule, solids_fraction [-]) of the [binder_injection] table
    reader ``t`` (``scene._Table``); ``error(path, key, text)`` is raised on bad input."""
    solids = t.number("solids_fraction", 0.0, non_negative=True)
    if not solids < 1.0:
        raise error(path, "binder_injection.solids_fraction",
                    f"expected a mass fraction in [0, 1) (dissolved solids per sprayed mass), "
                    f"got {solids}")
    return _schedule(path, t, error, unit) + (solids,)


def _schedule(path, t, error, unit=PER_VOLUME):
    """(peak rate [``unit``], schedule): ``rate`` with optional ``start``/``stop`` [s], or
    ``schedule = [[t, rate], ...]``."""
    if not t.has("schedule"):
        rate = t.number("rate", non_negative=True, unit=unit)
        start = t.number("start", None, non_negative=True, unit="s")
        stop = t.number("stop", None, positive=True, unit="s")
        if start is None and stop is None:
            return rate, ()
        start = start or 0.0
        if stop is not None and not stop > start:
            raise error(path, "binder_injection.stop",
                        f"expected a time after start ({start:g} s), got {stop:g}")
        return rate, ((start, rate),) + (((stop, 0.0),) if stop is not None else ())
    for key in ("rate", "start", "stop"):
        if t.has(key):
            raise error(path, f"binder_injection.{key}",
                        "give either rate (with optional start and stop) or schedule, not both")
    raw = t.raw("schedule")
    key = "binder_injection.schedule"
    if not isinstance(raw, list) or not raw:
        raise error(path, key, f"expected a list of [time (s), rate ({unit})] "
                               f"pairs, got {raw!r}")
    out = []
    for k, seg in enumerate(raw):
        if (not isinstance(seg, list) or len(seg) != 2
                or any(isinstance(v, bool) or not isinstance(v, (int, float))
                       or not math.isfinite(v) for v in seg)):
            raise error(path, key, f"entry {k}: expected [time (s), rate "
                                   f"({unit})], got {seg!r}")
        start, rate = float(seg[0]), float(seg[1])
        if start < 0.0 or rate < 0.0:
            raise error(path, key, f"entry {k}: expected a non-negative time and rate, "
                                   f"got {seg!r}")
        if out and not start > out[-1][0]:
            raise error(path, key, f"entry {k}: out of order: expected a time after "
                                   f"{out[-1][0]:g} s, got {start:g}")
        out.append((start, rate))
    return max(r for _, r in out), tuple(out)


def spray_refusals(scene, entry):
    """[(key, refusal)] of a scene's spray against its method (``entry``: its
    ``MethodEntry``): binder solids in droplets of their own need a method whose droplets may
    carry them."""
    inj = scene.binder_injection
    if inj is None:
        return []
    if inj.solids_fraction > 0.0 and scene.separate_droplets and not entry.solute_droplets:
        return [("binder_injection.solids_fraction",
                 f"the {entry.name} method's free droplets hold pure liquid: expected 0 with "
                 f"[aggregation] droplet_factor, or another method")]
    return []


def segments(injection, end_time):
    """[(t0 [s], t1 [s], rate [droplets/(m3 s)])] of a ``BinderInjection`` covering
    [0, end_time [s]] in order."""
    schedule = injection.schedule
    if not schedule:
        return [(0.0, float(end_time), injection.rate)]
    out = [(0.0, min(schedule[0][0], float(end_time)), 0.0)] if schedule[0][0] > 0.0 else []
    for k, (start, rate) in enumerate(schedule):
        stop = schedule[k + 1][0] if k + 1 < len(schedule) else math.inf
        if start < end_time:
            out.append((start, min(stop, float(end_time)), rate))
    return out


def injected(injection, t):
    """Droplets injected per m3 by a ``BinderInjection`` from 0 to t [s] [1/m3]."""
    if not injection.schedule:
        return injection.rate * t
    return sum(rate * (min(t1, t) - t0) for t0, t1, rate in segments(injection, t) if t > t0)


def factors(injection, end_time):
    """[(t0 [s], t1 [s], rate / peak rate [-])] of the schedule from 0 on, the last segment
    open-ended (t1 = inf) past end_time [s]; empty without a schedule (the cell rows' rate
    holds throughout)."""
    if not injection.schedule:
        return []
    peak = injection.rate
    out = [(t0, t1, (rate / peak) if peak > 0.0 else 0.0)
           for t0, t1, rate in segments(injection, end_time)]
    out[-1] = (out[-1][0], math.inf, out[-1][2])
    return out
