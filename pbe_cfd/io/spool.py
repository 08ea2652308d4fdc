"""Per-output-time results streamed to disk as they are made, read back one output time at a
time: the states of the active cells and the cell fields of a coupled run (1e6 cells x 13
output times would otherwise be held in memory for the whole run).

A ``Spool`` is a list-like sequence (append, len, index, negative index, iteration) whose
items live in a private temporary directory (the system's, or ``directory``), one ``.npy``
file per array, written uncompressed (memory-mapped back on reading, so a read costs only the
pages touched). The directory is the program's own: it is removed by ``close()``, and when the
spool is garbage-collected or the interpreter exits. Nothing in it is an output of the run.

Items are one array, a dict of name -> array (the cell fields of one output time), or any
other object, pickled (the bed's size-distribution mixture of one output time); array units
are those of the values put in (scaled moments per m3 of bed, SI fields).
"""
from __future__ import annotations

import pickle
import shutil
import tempfile
import weakref
from pathlib import Path

import numpy as np

#: Prefix of a spool's temporary directory.
SPOOL_PREFIX = "pbe-spool-"
#: Marks an item stored as a pickle (any object that is neither an array nor a dict).
_PICKLED = "pickled"


class Spool:
    """A sequence of arrays or dicts of arrays kept on disk (see the module docstring).
    ``mmap``: read items back memory-mapped (read-only) instead of into memory."""

    def __init__(self, directory=None, mmap: bool = False):
        self.path = Path(tempfile.mkdtemp(prefix=SPOOL_PREFIX, dir=directory))
        self._items: list = []        # per item: None (one array) or the tuple of its names
        self._mmap = "r" if mmap else None
        self._bytes = 0
        self._finalizer = weakref.finalize(self, shutil.rmtree, str(self.path), True)

    # -- writing ------------------------------------------------------------------------
    def append(self, item) -> None:
        """Write ``item`` (an array, a dict name -> array, or another object) as output time
        len(self)."""
        k = len(self._items)
        if isinstance(item, dict):
            names = tuple(item)
            for j, name in enumerate(names):
                self._write(f"{k}_{j}.npy", item[name])
            self._items.append(names)
        elif isinstance(item, np.ndarray):
            self._write(f"{k}.npy", item)
            self._items.append(None)
        else:
            path = self.path / f"{k}.pkl"
            with open(path, "wb") as fh:
                pickle.dump(item, fh, protocol=pickle.HIGHEST_PROTOCOL)
            self._bytes += path.stat().st_size
            self._items.append(_PICKLED)

    def _write(self, name, value):
        arr = np.ascontiguousarray(value)
        np.save(self.path / name, arr, allow_pickle=False)
        self._bytes += arr.nbytes

    # -- reading ------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[j] for j in range(*k.indices(len(self)))]
        n = len(self._items)
        j = int(k) + n if int(k) < 0 else int(k)
        if not 0 <= j < n:
            raise IndexError(f"spool index {k} out of range ({n} output times)")
        names = self._items[j]
        if names is _PICKLED:
            with open(self.path / f"{j}.pkl", "rb") as fh:
                return pickle.load(fh)
        if names is None:
            return self._read(f"{j}.npy")
        return {name: self._read(f"{j}_{i}.npy") for i, name in enumerate(names)}

    def _read(self, name):
        return np.load(self.path / name, mmap_mode=self._mmap, allow_pickle=False)

    def __iter__(self):
        for j in range(len(self)):
            yield self[j]

    @property
    def nbytes(self) -> int:
        """Bytes written to the spool [bytes]."""
        return self._bytes

    def close(self) -> None:
        """Remove the spool's directory (its items can no longer be read)."""
        self._finalizer()
