"""The gamma-EQMOM's registry entry (``ENTRY``; ``methods.registry`` lists it): scene keys,
state names, aux, population, plan line, failure hint, diagnostics and its numba functions.

Units as in ``methods.entry``: SI outside, scaled moments in the state.
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from ...physics import parameters as P
from ..entry import MethodEntry
import pbe_cfd.methods.quadrature.gamma_inversion as I
import pbe_cfd.methods.eqmom.state as S
from .options import KERNELS, EqmomOptions
from .sources import (eqmom_conserved, eqmom_on_closure, eqmom_project, eqmom_realizable,
                      eqmom_rhs)

#: config[P.METHOD] of the EQMOM
CODE = 3


def scene_keys(t, defaults):
    """The ``[method]`` keys of EQMOM: ``nodes`` (kernels N, 1..5) and ``kernel`` (their
    family: "gamma" or "lognormal")."""
    return {"nodes": t.number("nodes", defaults.nodes, integer=True, low=1, high=I.MAX_KERNELS),
            "kernel": t.choice("kernel", KERNELS, defaults.kernel)}


def state_names(scene):
    """State entry names of the scene's EQMOM."""
    return S.state_names(scene.method.options.nodes, scene.bivariate, scene.separate_droplets,
                         getattr(scene, "drying", None) is not None)


def aux(scene, arrays, theta_grid=None):
    """[secondary nodes per kernel, kernel family, (lognormal) Gauss-Hermite points and
    weights] (``state.aux_array``)."""
    return S.aux_array(scene.method.options.nodes, scene.method.options.kernel)


def population(state, aux_, arrays):
    """(w [1/m3], p [kg], b [kg]) of the kernels' secondary particles."""
    x, w, b = S.particles_of(state, arrays.config, aux_)
    return w * arrays.number_scale, x * arrays.mass_scale, np.clip(b, 0.0, x) * arrays.mass_scale


def kernels_si(state, aux_, arrays):
    """(sigma [kg] (gamma) or [-] (lognormal: of ln p), centres [kg] (lognormal: medians),
    number weights [1/m3], binder fractions [-], status) of one scaled state."""
    sigma, x, w, y, status = S.kernels_of(state, arrays.config, aux_)
    lognormal = S.kernel_family(np.asarray(aux_, float)) == I.LOGNORMAL
    return (sigma if lognormal else sigma * arrays.mass_scale, x * arrays.mass_scale,
            w * arrays.number_scale, y, status)


def plan_line(scene):
    """The method's line of ``pbe-cfd plan``."""
    n, kernel = scene.method.options.nodes, scene.method.options.kernel
    rule = "Gauss-Hermite" if kernel == "lognormal" else "Gauss"
    return (f"{kernel} EQMOM with {n} kernels ({S.secondary_nodes(n, kernel)} secondary "
            f"{rule} nodes each, binder fraction per kernel); state "
            f"{', '.join(state_names(scene))}; rtol {scene.method.rtol:g}")


def failure_hint(plan, arrays, state, aux_):
    """What the inversion made of a stopped cell's state."""
    sigma, x, w, y, status = kernels_si(state, aux_, arrays)
    unit = "" if S.kernel_family(np.asarray(aux_, float)) == I.LOGNORMAL else " kg"
    return (f" (EQMOM inversion: {I.STATUS_TEXT[status]}, {len(x)} kernels, "
            f"sigma = {sigma:.3g}{unit})")


def fallback_counts(states, aux_, arrays):
    """Counter status -> rows of the states whose inversion used that branch."""
    return Counter(S.kernels_of(s, arrays.config, aux_)[4] for s in np.atleast_2d(states))


def diagnostics(states, aux_, arrays):
    """({rows per inversion branch}, warnings): a warning names how many rows (times or
    cells) needed the fewer-kernel or the closest-sigma fallback or could not be inverted."""
    counts = fallback_counts(states, aux_, arrays)
    stats = {f"eqmom_{I.STATUS_TEXT[k].split(' ')[0]}_rows": int(v) for k, v in counts.items()}
    notes = []
    for code in (I.FEWER, I.CLOSEST, I.FAILED):
        if counts.get(code):
            notes.append(f"EQMOM: {counts[code]} of {sum(counts.values())} final states: "
                         f"{I.STATUS_TEXT[code]}")
    return stats, notes


ENTRY = MethodEntry(
    name="eqmom", code=CODE, scene_keys=scene_keys, options=EqmomOptions, order_key="nodes", order_label="EQMOM N",
    state_names=state_names, aux=aux, tabulates_theta=False, population=population,
    failure_hint=failure_hint, diagnostics=diagnostics, plan_line=plan_line,
    repairs_mixture=lambda plan: True,
    # its droplet sources take the droplet as pure binder liquid (b = p_d): the scene refuses
    # a solids fraction with droplets of their own for it
    solute_droplets=False, dries=True, evaporates_droplets=True,
    rhs=eqmom_rhs, realizable=eqmom_realizable, project=eqmom_project,
    on_closure=eqmom_on_closure,
    conserved=eqmom_conserved,
    work_size=lambda config: S.work_size(int(config[P.ORDER]), int(config[P.N_STATE])),
    bench_orders=int, bench_scene=lambda scene, order: scene.with_method(nodes=order),
    bench_quick=("3",), bench_full=("2", "3"),
    distribution="kernel_mixture",
    distributions=("support", "semi-infinite"),
    distribution_text="the EQMOM's own density: N gamma (kernel = \"lognormal\": lognormal) "
                      "kernels in granule mass fitted to the "
                      "carried M00 .. M(2N)0; binder fraction per size class from the kernels' "
                      "binder fractions",
    moments_text="from the EQMOM kernels' secondary Gauss nodes (binder fraction per kernel)",
    accuracy_knobs=lambda quick: tuple((f"N={n}", {"nodes": n})
                                       for n in ((2, 3) if quick else (2, 3, 4))))
