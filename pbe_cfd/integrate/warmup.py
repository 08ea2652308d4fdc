"""The integration kernel and the functions it calls, in stages that can compile in separate
processes.

numba compiles a function on one thread, callee before caller; a callee that another process
has compiled into the on-disk cache is loaded instead (with its code for linking), as long as
it is asked for with the same argument types. ``warm_stages`` lists the method's functions
with the argument types the kernel's call sites give them, the integrator's helpers and the
kernel itself, in stages: every function of a stage needs only functions of earlier stages or
of its own group, and each stage is split into groups of about equal compile time (measured:
docs/results/first-run.md). Groups of one stage compile in parallel (``runs.precompile``),
stage after stage; the caller then loads everything from the cache.

A type that no longer matches its call site costs time, never correctness: the caller then
compiles that function itself (``recompiled`` says which).
"""
from __future__ import annotations

from ..methods import registry
from ..physics import parameters as P
from . import exponential, rosenbrock, switches
from .cell import integrate_cells_kernel
from .codes import AUTO, EXPLICIT
from .kernel_types import call_types, kernel_signature, probe_args, signatures


def warm_stages(method: int, scheme: int, aux, params, config) -> list:
    """Stages of (function name, dispatcher, signature) groups for the kernel of method code
    ``method`` and scheme code ``scheme`` on the packed scene (aux, params, config): a list
    of stages, each a list of groups, each a list of (name, dispatcher, argument types).

    One stage of two groups: the method's functions (its right-hand side, realizability
    test, projection and invariants, which share the moment inversion); the integrator's
    helpers and the kernel itself (the integrator's functions that call the method are
    inlined into it, ``integrate`` module docstring). The kernel calls the method's functions
    through their addresses (``kernel_types``), so it compiles without them."""
    entry = registry.entry_of_code(method)
    t = call_types(aux, params, config)
    V, M, I, C, f, i = (t[k] for k in "VMICfi")
    sigs = signatures(aux, params, config)
    leaves = [("held_params", switches.held_params, (t["P"], C)),
              ("location_memory", switches.location_memory, ()),
              ("release", switches.release, (V,))]
    if scheme != EXPLICIT:
        leaves += [("spectral_radius", rosenbrock.spectral_radius, (M, V, V, i)),
                   ("lu_factor", rosenbrock.lu_factor, (M, I, i)),
                   ("lu_solve", rosenbrock.lu_solve, (M, I, V, i))]
    if scheme == AUTO:
        leaves += [("phi_functions", exponential.phi_functions, (f, V))]
    method = [(f"{entry.name} {name}", getattr(entry, name), getattr(sigs, name))
              for name in sigs._fields]
    kernel = [("integration kernel", integrate_cells_kernel,
               kernel_signature(scheme, probe_args(aux, params, config, 1), sigs))]
    return [[method, leaves + kernel]]


def compile_group(group) -> list:
    """Compile (or load from the cache) every (name, dispatcher, signature) of ``group``;
    returns the names numba compiled, here or as a callee of another (the others were in the
    cache)."""
    before = cache_misses([[group]])
    for _name, dispatcher, sig in group:
        dispatcher.compile(sig)
    return recompiled([[group]], before)   # with those compiled as callees of the group


def recompiled(stages, misses_before) -> list:
    """Names of the staged functions that numba compiled in this process since
    ``misses_before`` (``cache_misses(stages)`` taken before the kernel's compile): a
    function whose staged signature did not match its call site."""
    now = cache_misses(stages)
    return [name for name, count in now.items() if count > misses_before.get(name, 0)]


def cache_misses(stages) -> dict:
    """{name: numba's cache misses of its dispatcher in this process} over the stages."""
    return {name: sum(d.stats.cache_misses.values())
            for stage in stages for group in stage for name, d, _sig in group}
