"""The cNMC reference's registry entry: its scene keys, plan line and its ensemble run (it is
not integrated per cell; ``methods.registry`` lists it)."""
import dataclasses

from ..entry import NOT_INTEGRATED, MethodEntry, no_aux, no_diagnostics, no_hint
from .options import CnmcOptions


def _keys(t, defaults):
    return {"particles": t.number("particles", defaults.particles, integer=True, low=2,
                                  high=10_000_000),
            "replicas": t.number("replicas", defaults.replicas, integer=True, low=1,
                                 high=100_000),
            "seed": t.number("seed", defaults.seed, integer=True, low=0)}


def _plan(scene):
    m = scene.method.options
    return (f"constant-number Monte Carlo, {m.particles} particles x {m.replicas} replicas, "
            f"seed {m.seed}")


def _ensemble(plan, arrays, cell, times, progress=None):
    from .ensemble import simulate_ensemble
    m = plan.options
    initial = dataclasses.asdict(plan.initial)     # the keys simulate_ensemble reads
    return simulate_ensemble(arrays.params, arrays.config, cell, initial, times,
                             m.particles, m.replicas, m.seed, progress=progress,
                             segments=plan.spray or None)


def _population(state, aux, arrays):
    raise TypeError("the cNMC carries particles, not a moment state")


def _accuracy_knobs(quick):
    """The accuracy study's ensembles: particles x replicas (seed 11)."""
    sizes = ((1000, 2), (3000, 2)) if quick else ((1000, 4), (10000, 4), (100000, 4))
    return tuple((f"{n:.0e}".replace("e+0", "e") + f" x {r}",
                  {"particles": n, "replicas": r, "seed": 11}) for n, r in sizes)


ENTRY = MethodEntry(
    name="cnmc", code=NOT_INTEGRATED, scene_keys=_keys, options=CnmcOptions, order_key=None,
    order_label="cNMC particles", state_names=lambda s: [], aux=no_aux,
    tabulates_theta=False, population=_population, failure_hint=no_hint,
    diagnostics=no_diagnostics, plan_line=_plan, ensemble=_ensemble,
    distribution_text="mass histogram of each replica's particle list (50 classes per decade "
                      "of d), the replicas' mean and 95% band; d10/d50/d90 exact per replica",
    accuracy_knobs=_accuracy_knobs, dries=True, evaporates_droplets=True)
