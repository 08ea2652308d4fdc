"""The method registry: the list of methods, each one package's ``ENTRY`` (a ``MethodEntry``,
``methods.entry``).

Every part of the program that depends on the method asks its entry here, never compares the
method's name: the scene parses ``[method]`` with the entry's ``scene_keys`` into its
``options``; ``model.pack``
writes its ``code``, ``order`` and ``config_slots`` into ``config``, names the state entries
with ``state_names`` and checks ``work_size``; the integration kernel takes its
``rhs``/``realizable``/``project``/``conserved`` as first-class functions
(``integrate.kernel_types``), and ``methods.dispatch`` builds the run-time numba dispatch
by code from them; the runs
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
3. its package name in ``PACKAGES`` below (or ``register(ENTRY)`` at run time, as the test
   suite does for its toy method: the integrator sees it; the
   run-time dispatch ``method_rhs`` ... is built on its first use from the methods listed
   then).

A method's package is imported when its entry is first asked for (``METHODS[name]``,
``method_of``): a scene imports (and so defines the numba functions of) its own method only.
``METHOD_NAMES`` needs no import; ``METHOD_REGISTRY``, ``MOMENT_METHODS`` and a code no loaded
entry owns (``entry_of_code``) import every package.

Entries take the scene and the packed arrays (``model.Arrays``: params, config, number and mass
scales, droplet mass, state names) as arguments; the units are those of ``model``: SI outside,
scaled moments in the state.
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence

from .entry import NOT_INTEGRATED, MethodEntry, MethodPlan  # noqa: F401

#: the method packages ``methods/<name>/`` (each one's ``ENTRY`` is named ``<name>``), in the
#: order the scene lists them
PACKAGES = ("qmom", "laguerre", "cnmc", "cqmom", "eqmom")

_NAMES: list[str] = list(PACKAGES)          # the registered names, in order
_ENTRIES: dict[str, MethodEntry] = {}       # name -> entry, of the names loaded so far


def _clash(entry: MethodEntry) -> str | None:
    """Why ``entry`` cannot join the loaded entries (a name or a code taken), or None."""
    for other in _ENTRIES.values():
        if other.name == entry.name and other is not entry:
            return f"two methods share the name {entry.name!r}"
        if entry.integrated and other.integrated and other.code == entry.code \
                and other is not entry:
            return f"methods {other.name!r} and {entry.name!r} share the code {entry.code}"
    return None


def _load(name: str) -> MethodEntry:
    """The entry of a registered name, importing its package on first use; KeyError for a
    name not registered."""
    entry = _ENTRIES.get(name)
    if entry is not None:
        return entry
    if name not in _NAMES or name not in PACKAGES:
        raise KeyError(name)
    entry = importlib.import_module(f"{__package__}.{name}").ENTRY
    if entry.name != name:
        raise ValueError(f"methods/{name}/ declares the method {entry.name!r}")
    clash = _clash(entry)
    if clash:
        raise ValueError(clash)
    _ENTRIES[name] = entry
    return entry


def _all() -> tuple:
    return tuple(_load(n) for n in _NAMES)


class _View(Sequence):
    """A read-only sequence computed on use (``of()``), so that naming it imports nothing."""

    def __init__(self, of):
        self._of = of

    def __getitem__(self, i):
        return self._of()[i]

    def __len__(self):
        return len(self._of())

    def __eq__(self, other):
        return isinstance(other, (Sequence, _View)) and tuple(self) == tuple(other)

    __hash__ = None

    def __repr__(self):
        return repr(self._of())


class _Methods(Mapping):
    """name -> entry of every registered method; an entry is loaded when asked for."""

    def __getitem__(self, name):
        return _load(name)

    def __iter__(self):
        return iter(tuple(_NAMES))

    def __len__(self):
        return len(_NAMES)

    def __contains__(self, name):
        return name in _NAMES


#: the registered methods' entries, in the order the scene lists them (iterating imports every
#: method package)
METHOD_REGISTRY = _View(_all)
#: name -> entry
METHODS = _Methods()
#: the methods the per-cell integrator runs (a coupled run needs one); using it imports every
#: method package
MOMENT_METHODS = _View(lambda: tuple(m.name for m in _all() if m.integrated))


def __getattr__(attr):
    if attr == "METHOD_NAMES":          # the names a scene accepts, in order (no import)
        return tuple(_NAMES)
    if attr == "laguerre_state_names":
        from .laguerre import laguerre_state_names
        return laguerre_state_names
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


def register(entry: MethodEntry) -> MethodEntry:
    """Add a method at run time (a test's toy method); a name or code already taken is an
    error. Returns the entry."""
    if entry.name in _NAMES:
        raise ValueError(f"two methods share the name {entry.name!r}")
    _all()                              # every code is known before a new one joins
    clash = _clash(entry)
    if clash:
        raise ValueError(clash)
    _NAMES.append(entry.name)
    _ENTRIES[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a method registered at run time."""
    if name in _NAMES:
        _NAMES.remove(name)
    _ENTRIES.pop(name, None)


def entry_of_code(code: int) -> MethodEntry | None:
    """The integrated method with config[P.METHOD] = code, or None (the loaded entries are
    asked first; only a code none of them owns imports the other packages)."""
    loaded = tuple(_ENTRIES[n] for n in _NAMES if n in _ENTRIES)
    for entries in (lambda: loaded, _all):      # _all imports: only if no loaded entry owns it
        for m in entries():
            if m.integrated and m.code == code:
                return m
    return None


def method_of(scene) -> MethodEntry:
    """The registry entry of the scene's method."""
    return _load(scene.method.name)


def method_plan(scene) -> MethodPlan:
    """What the method's hooks after the one pass read of a validated scene (``MethodPlan``;
    density in kg/m3)."""
    return MethodPlan(method=method_of(scene), options=scene.method.options,
                      bivariate=scene.bivariate, separate_droplets=scene.separate_droplets,
                      density=scene.material.density, initial=scene.initial)
