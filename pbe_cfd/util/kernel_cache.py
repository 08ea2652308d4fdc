"""Where numba keeps pbe-cfd's compiled kernels, so that a cache built once stays valid for
the same sources wherever they sit (a checkout, an installed package, a copy).

numba's own locators name a module's cache directory by a hash of the module's absolute
directory, so a kernel compiled from a checkout is not found by the installed package (nor by
a copy of the checkout), although the sources are the same. ``PackageCacheLocator`` names it
by the module's place inside the package instead (``pbe_cfd/methods/qmom``), under a root
keyed by a hash of the package's compiled sources (``source_hash``: numba keys an entry only
by its own module's source, so a caller would otherwise keep stale inlined code of a callee
from another module). An entry is still checked against its module's source (a content hash,
``get_source_stamp``), numba's version, the Python version and the CPU (numba's index key), so
a cache copied to another kind of machine recompiles instead of loading.

The root is ``$NUMBA_CACHE_DIR/pbe_cfd-<hash>`` when the user sets NUMBA_CACHE_DIR, else
``$XDG_CACHE_HOME/pbe_cfd/numba/<hash>`` (default ``~/.cache/pbe_cfd/numba/<hash>``).
``pbe-cfd compile`` fills it ahead of the first run.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: The package directory (the one holding pbe_cfd/__init__.py) this module belongs to.
PACKAGE_ROOT = Path(__file__).resolve().parent.parent
#: Hex digits of the source hash that name the cache root.
HASH_DIGITS = 16


def compiled_sources(root: Path, compiled: tuple) -> list[Path]:
    """The .py files under package directory ``root`` that can change compiled code: those
    matching ``compiled`` (paths relative to the package, a trailing "/" for a folder)."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if any(rel == c or (c.endswith("/") and rel.startswith(c)) for c in compiled):
            out.append(path)
    return out


def source_hash(root: Path, compiled: tuple) -> str:
    """Hash of the compiled sources of the package at ``root`` (their paths relative to the
    package and their bytes): equal for equal sources wherever the package sits."""
    digest = hashlib.sha1()
    for path in compiled_sources(root, compiled):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:HASH_DIGITS]


def cache_root(digest: str) -> Path:
    """The directory of the compiled kernels of sources with hash ``digest``."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return Path(user) / f"pbe_cfd-{digest}"
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "pbe_cfd" / "numba" / digest


def _module_key(py_file: str) -> tuple[str, str] | None:
    """(directory name, place in the package) of a source file inside PACKAGE_ROOT, else None."""
    try:
        folder = Path(py_file).resolve().parent
        rel = folder.relative_to(PACKAGE_ROOT)
    except (OSError, ValueError):
        return None
    place = "/".join(("pbe_cfd", *rel.parts))
    return folder.name, place


def _locator_class():
    """numba's locator interface subclassed for the package's modules (None where this numba
    has no such interface: numba's own locators then apply)."""
    try:
        from numba.core import caching
        base, mixin = caching._CacheLocator, caching._SourceFileBackedLocatorMixin
    except (ImportError, AttributeError):
        return None

    class PackageCacheLocator(mixin, base):
        """A module of the package, cached under ``root`` by its place in the package."""
        root: str | None = None

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            name, place = _module_key(py_file)
            self._cache_path = os.path.join(
                self.root, f"{name}_{hashlib.sha1(place.encode()).hexdigest()}")

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            """The module's content hash (not its modification time: an installed copy of
            the same source is the same source)."""
            with open(self._py_file, "rb") as fh:
                return hashlib.sha256(fh.read()).hexdigest()

        @classmethod
        def from_function(cls, py_func, py_file):
            if cls.root is None or _module_key(py_file) is None:
                return None
            return super().from_function(py_func, py_file)

    return PackageCacheLocator


def install(digest: str) -> Path | None:
    """Make numba cache the package's kernels under ``cache_root(digest)`` (first among
    numba's locators; other code keeps numba's own). Returns the root, or None where it
    cannot be created or this numba has no locator interface (numba's defaults then apply)."""
    root = cache_root(digest)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    locator = _locator_class()
    if locator is None:
        return None
    from numba.core import caching
    locator.root = str(root)
    classes = caching.CacheImpl._locator_classes
    classes[:] = [c for c in classes if c.__name__ != locator.__name__]
    classes.insert(0, locator)
    return root
