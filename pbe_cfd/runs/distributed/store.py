"""The chunk store ``DIR.chunks/`` of a cluster run: finished chunks and output-time
checkpoints written atomically, with a fingerprint of the problem, for ``--resume``."""
from __future__ import annotations

import hashlib
import json
import os
import threading
from pathlib import Path

import numpy as np

from ...io.output import remove_matching
from ...scene.scene import SceneError

#: Name of the chunk store next to an output directory DIR: DIR.chunks/.
STORE_SUFFIX = ".chunks"
MANIFEST = "manifest.json"
#: The files a chunk store writes (nothing else in DIR.chunks/ is ever removed).
STORE_FILES = ("manifest.json", "chunk_*.npz", "step_*.npz", ".manifest.json.*.tmp",
               ".chunk_*.tmp", ".step_*.tmp")
STORE_VERSION = 1


class ChunkStoreError(SceneError):
    """A chunk store or decomposition that cannot be used for this run (missing, made by
    another problem, stale): bad input, exit code 2. ``ChunkStoreError(path, message)``."""

    def __init__(self, path, message):
        super().__init__(path, None, message)



# ---------------------------------------------------------------------------- chunk store
def store_path(out_dir) -> Path:
    """The chunk store of output directory DIR: the sibling ``DIR.chunks/``."""
    out = Path(out_dir).resolve()
    return out.with_name(out.name + STORE_SUFFIX)


def _atomic_savez(path: Path, **arrays):
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _atomic_write_text(path: Path, text: str):
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


class ChunkStore:
    """Finished chunks of one run, as ``chunk_%05d.npz`` (no transport) or output-time
    checkpoints ``step_%05d.npz`` (transport), plus ``manifest.json`` (fingerprint, layout,
    the scene and output directory, for ``--resume``). Every file is written atomically."""

    def __init__(self, path):
        self.path = Path(path)

    @staticmethod
    def read_manifest(path) -> dict | None:
        """The manifest of a store directory, or None when there is none."""
        f = Path(path) / MANIFEST
        if not f.is_file():
            return None
        try:
            return json.loads(f.read_text())
        except ValueError:
            return None

    def open(self, fingerprint: str, meta: dict, resume: bool) -> "ChunkStore":
        """Prepare the store for a run whose inputs hash to ``fingerprint``. With ``resume``
        the store must exist with that fingerprint (its files are kept); without, an existing
        store is replaced (a fresh run)."""
        manifest = self.read_manifest(self.path)
        if resume:
            if manifest is None:
                raise ChunkStoreError(self.path, "--resume: no chunk store here (it is made by a "
                                      "run with --workers or --scheduler and removed after "
                                      "success)")
            if manifest.get("fingerprint") != fingerprint:
                raise ChunkStoreError(
                    self.path, "--resume: made by a different problem (scene, case, "
                    "partition or method data differ); rerun without --resume to start over")
            return self
        if self.path.exists() and any(self.path.iterdir()):
            if manifest is None:
                raise ChunkStoreError(self.path, "exists and is not a chunk store written by "
                                      "pbe-cfd; nothing was changed: choose another --out "
                                      "or move it away yourself")
            remove_matching(self.path, STORE_FILES)   # only the store's own files
        self.path.mkdir(parents=True, exist_ok=True)
        _atomic_write_text(self.path / MANIFEST, json.dumps(
            {"version": STORE_VERSION, "fingerprint": fingerprint, **meta}, indent=1))
        return self

    def _chunk(self, k: int) -> Path:
        return self.path / f"chunk_{k:05d}.npz"

    def _step(self, k: int) -> Path:
        return self.path / f"step_{k:05d}.npz"

    def finished_chunks(self) -> set:
        """Numbers of the chunks stored complete."""
        out = set()
        for p in self.path.glob("chunk_*.npz"):
            try:
                out.add(int(p.stem.split("_")[1]))
            except ValueError:
                pass
        return out

    def save_chunk(self, k: int, result: dict):
        """Store chunk k's result arrays atomically."""
        _atomic_savez(self._chunk(k), **result)

    def load_chunk(self, k: int) -> dict:
        """Chunk k's stored result arrays."""
        with np.load(self._chunk(k)) as z:
            return {name: z[name] for name in z.files}

    def save_step(self, k: int, arrays: dict):
        """Store the states and counters at output time number k atomically."""
        _atomic_savez(self._step(k), **arrays)

    def stored_steps(self) -> list:
        """Output-time numbers stored, ascending."""
        out = []
        for p in self.path.glob("step_*.npz"):
            try:
                out.append(int(p.stem.split("_")[1]))
            except ValueError:
                pass
        return sorted(out)

    def load_step(self, k: int) -> dict:
        """The arrays stored for output time number k."""
        with np.load(self._step(k)) as z:
            return {name: z[name] for name in z.files}

    def remove(self):
        """Delete the store's own files, and the directory when that empties it (after the
        output was written)."""
        remove_matching(self.path, STORE_FILES)


def fingerprint(*arrays, extra: str = "") -> str:
    """SHA-256 over the bytes, dtypes and shapes of numeric inputs (and a text)."""
    h = hashlib.sha256(extra.encode())
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()
