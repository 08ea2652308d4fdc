"""The gamma-EQMOM's registry entry: scene keys, state names, aux, population, plan line,
failure hint and diagnostics (the callables ``methods.registry.MethodEntry`` names).

Units as in ``methods.registry``: SI outside, scaled moments in the state.
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from . import inversion as I
from . import state as S


def scene_keys(t, defaults):
    """The ``[method]`` keys of EQMOM: ``nodes`` (kernels N, 1..5)."""
    return {"nodes": t.number("nodes", 2, integer=True, low=1, high=I.MAX_KERNELS)}


def state_names(scene):
    """State entry names of the scene's EQMOM."""
    return S.state_names(scene.method.nodes, scene.bivariate, scene.separate_droplets)


def aux(scene, arrays, theta_grid=None):
    """[secondary Gauss nodes per kernel] (``state.secondary_nodes``)."""
    return np.array([float(S.secondary_nodes(scene.method.nodes))])


def population(state, aux_, arrays):
    """(w [1/m3], p [kg], b [kg]) of the kernels' secondary particles."""
    x, w, b = S.particles_of(state, arrays.config, aux_)
    return w * arrays.number_scale, x * arrays.mass_scale, np.clip(b, 0.0, x) * arrays.mass_scale


def kernels_si(state, aux_, arrays):
    """(sigma [kg], centres [kg], number weights [1/m3], binder fractions [-], status) of one
    scaled state."""
    sigma, x, w, y, status = S.kernels_of(state, arrays.config, aux_)
    return (sigma * arrays.mass_scale, x * arrays.mass_scale, w * arrays.number_scale, y,
            status)


def plan_line(scene):
    """The method's line of ``pbe-cfd plan``."""
    m = scene.method
    return (f"gamma EQMOM with {m.nodes} kernels ({S.secondary_nodes(m.nodes)} secondary "
            f"Gauss nodes each, binder fraction per kernel); state "
            f"{', '.join(state_names(scene))}; rtol {m.rtol:g}")


def failure_hint(scene, arrays, state, aux_):
    """What the inversion made of a stopped cell's state."""
    sigma, x, w, y, status = S.kernels_of(state, arrays.config, aux_)
    return (f" (EQMOM inversion: {I.STATUS_TEXT[status]}, {len(x)} kernels, "
            f"sigma = {sigma * arrays.mass_scale:.3g} kg)")


def fallback_counts(states, aux_, arrays):
    """Counter status -> rows of the states whose inversion used that branch."""
    return Counter(S.kernels_of(s, arrays.config, aux_)[4] for s in np.atleast_2d(states))


def diagnostics(states, aux_, arrays):
    """({rows per inversion branch}, warnings): a warning names how many rows (times or
    cells) needed the closest-sigma fallback or could not be inverted."""
    counts = fallback_counts(states, aux_, arrays)
    stats = {f"eqmom_{I.STATUS_TEXT[k].split(' ')[0]}_rows": int(v) for k, v in counts.items()}
    notes = []
    for code in (I.CLOSEST, I.FAILED):
        if counts.get(code):
            notes.append(f"EQMOM: {counts[code]} of {sum(counts.values())} final states: "
                         f"{I.STATUS_TEXT[code]}")
    return stats, notes
