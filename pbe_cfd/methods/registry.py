"""The method registry: the list of methods, each one package's ``ENTRY`` (a ``MethodEntry``,
``methods.entry``).

Every part of the program that depends on the method asks its entry here, never compares the
method's name: the scene parses ``[method]`` with the entry's ``scene_keys`` into its
``options``; ``model.pack``
writes its ``code``, ``order`` and ``config_slots`` into ``config``, names the state entries
with ``state_names`` and checks ``work_size``; ``methods.dispatch`` builds the numba dispatch
(by code, literal and run-time) from ``rhs``/``realizable``/``project``/``conserved``; the runs
build its ``aux``, turn a state into SI columns through ``population`` (or ``columns``),
explain a stopped cell with ``failure_hint`` and report ``diagnostics``; ``pbe-cfd plan``
prints its ``plan_line``; the throughput study reads ``bench_orders``/``bench_scene``.

Adding a method ``foo`` (the contract):

1. a package ``methods/foo/`` with its numba functions of the signatures in ``MethodEntry``
   (``rhs(state, out, cell, aux, params, config, work)``, ``realizable``/``project(state, aux,
   params, config, work)``, ``conserved(config, params, pivots, coefs)``), plain functions of
   arrays and floats with ``cache=True``, using at most ``WORK_SIZE`` floats of ``work``;
2. in ``methods/foo/__init__.py`` (or a module it imports) ``ENTRY = MethodEntry(name="foo",
   code=<unused integer>, options=FooOptions, ...)``: its own ``[method]`` keys (a frozen
   dataclass ``FooOptions`` in ``methods/foo/options.py`` with their defaults, and
   ``scene_keys(t, defaults)`` reading them from the table with their limits; the scene
   holds them as ``scene.method.options``), state names, plan line, and its Python hooks
   (``population``, optional ``aux``, ...);
3. one line in ``METHOD_REGISTRY`` below (or ``register(ENTRY)`` at run time, as the test
   suite does for its toy method: the literal dispatch, and so the integrator, see it; the
   run-time dispatch ``method_rhs`` ... is built at import from the entries listed here).

Entries take the scene and the packed arrays (``model.Arrays``: params, config, number and mass
scales, droplet mass, state names) as arguments; the units are those of ``model``: SI outside,
scaled moments in the state.
"""
from __future__ import annotations

from . import cnmc, cqmom, eqmom, laguerre, qmom
from .entry import NOT_INTEGRATED, MethodEntry  # noqa: F401
from .laguerre import laguerre_state_names  # noqa: F401

#: the registered methods, in the order the scene lists them
METHOD_REGISTRY = [qmom.ENTRY, laguerre.ENTRY, cnmc.ENTRY, cqmom.ENTRY, eqmom.ENTRY]

#: name -> entry
METHODS = {}
#: the names a scene accepts, in registry order
METHOD_NAMES = ()
#: the methods the per-cell integrator runs (a coupled run needs one)
MOMENT_METHODS = ()


def _index():
    global METHOD_NAMES, MOMENT_METHODS
    codes = [m.code for m in METHOD_REGISTRY if m.integrated]
    if len(set(codes)) != len(codes) or len({m.name for m in METHOD_REGISTRY}) != len(
            METHOD_REGISTRY):
        raise ValueError("two methods share a name or a code")
    METHODS.clear()
    METHODS.update((m.name, m) for m in METHOD_REGISTRY)
    METHOD_NAMES = tuple(METHODS)
    MOMENT_METHODS = tuple(m.name for m in METHOD_REGISTRY if m.integrated)


def register(entry: MethodEntry) -> MethodEntry:
    """Add a method at run time (a test's toy method); a name or code already taken is an
    error. Returns the entry."""
    METHOD_REGISTRY.append(entry)
    try:
        _index()
    except ValueError:
        METHOD_REGISTRY.pop()
        _index()
        raise
    return entry


def unregister(name: str) -> None:
    """Remove a method registered at run time."""
    METHOD_REGISTRY[:] = [m for m in METHOD_REGISTRY if m.name != name]
    _index()


def entry_of_code(code: int) -> MethodEntry | None:
    """The integrated method with config[P.METHOD] = code, or None."""
    for m in METHOD_REGISTRY:
        if m.integrated and m.code == code:
            return m
    return None


def method_of(scene) -> MethodEntry:
    """The registry entry of the scene's method."""
    return METHODS[scene.method.name]


_index()
