"""The segment store ``DIR.coupling/`` of a two-way coupled run, next to its output DIR.

It holds what a resume needs and nothing else: one OpenFOAM case per segment
(``segment_NNN/``, each with its own manifest, made by ``io.openfoam.rerun``), the
population's states at the output times of every finished granulation segment
(``granulation_NNN.npz``) and ``progress.json``: the scene's fingerprint and, per finished
step, what it did (diameter [m], CFD times [s], wall seconds). Every file is written whole
(a temporary file renamed), so a killed run leaves the steps it finished. When the output is
written the store is removed, only the files it lists.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from ..io import output
from ..io.openfoam.rerun import SEGMENT_KIND

#: Name of the segment store next to an output directory DIR: DIR.coupling/.
STORE_SUFFIX = ".coupling"
STORE_KIND = "coupling store"
PROGRESS = "progress.json"


def store_path(out_dir) -> Path:
    """The segment store of output directory DIR: the sibling ``DIR.coupling/``."""
    out = Path(out_dir).expanduser().resolve()
    return out.with_name(out.name + STORE_SUFFIX)


def fingerprint(scene) -> str:
    """A hash of everything in the scene that changes the result (its parsed tables)."""
    text = json.dumps(scene.raw, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class SegmentStore:
    """Finished steps of a two-way run: CFD cases and granulation segments."""

    def __init__(self, path):
        self.path = Path(path)
        self.progress = {"fingerprint": None, "scene": None, "cfd": {}, "granulation": {}}

    def open(self, scene, resume: bool, flag: str = "--resume") -> "SegmentStore":
        """A new store, or with ``resume`` the earlier one of the same scene (OutputRefused
        otherwise, before anything is changed)."""
        fp = fingerprint(scene)
        old = self.path / PROGRESS
        if resume:
            if not old.is_file():
                raise output.OutputRefused(f"{flag}: {self.path} holds no finished segment of "
                                           "a two-way run to continue; run without --resume")
            self.progress = json.loads(old.read_text())
            if self.progress.get("fingerprint") != fp:
                raise output.OutputRefused(
                    f"{flag}: the segments in {self.path} were computed for another scene "
                    f"({self.progress.get('scene')}); resume with that scene or start anew")
            self._drop_unfinished()
            return self
        if self.path.exists():
            if output.read_manifest(self.path) is None and any(self.path.iterdir()):
                raise output.OutputRefused(f"{self.path} exists and was not written by pbe-cfd;"
                                           " move it away (two-way runs keep their segments "
                                           "there)")
            self.remove()
        self.path.mkdir(parents=True, exist_ok=True)
        self.progress.update(fingerprint=fp, scene=str(scene.source))
        self._save_progress()
        return self

    def _drop_unfinished(self):
        """Remove the case of a CFD segment that did not finish. pbe-cfd made that directory
        (its manifest says so); a run killed outright leaves in it files the OpenFOAM tools
        wrote after the manifest was last written, which are listed first."""
        for p in sorted(self.path.glob("segment_*")):
            k = int(p.name.split("_")[1])
            if str(k) in self.progress["cfd"]:
                continue
            manifest = output.read_manifest(p)
            if manifest is not None and manifest.get("kind") == SEGMENT_KIND:
                output.record_new_files(p, set(), kind=SEGMENT_KIND)
            output.remove_written(p)

    def case_dir(self, k: int) -> Path:
        """The OpenFOAM case of segment ``k``."""
        return self.path / f"segment_{k:03d}"

    def cfd(self, k: int) -> dict | None:
        """The record of CFD segment ``k`` (None: not finished)."""
        return self.progress["cfd"].get(str(k))

    def save_cfd(self, k: int, record: dict):
        self.progress["cfd"][str(k)] = record
        self._save_progress()

    def granulation(self, k: int) -> dict | None:
        """Record and arrays (times [s], history of states, cell ids) of granulation segment
        ``k``, or None."""
        rec = self.progress["granulation"].get(str(k))
        if rec is None:
            return None
        with np.load(self.path / f"granulation_{k:03d}.npz") as z:
            return {**rec, "times": z["times"], "history": z["history"], "idx": z["idx"]}

    def save_granulation(self, k: int, record: dict, times, history, idx):
        path = self.path / f"granulation_{k:03d}.npz"
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=self.path)
        os.close(fd)
        np.savez(tmp, times=np.asarray(times), history=np.asarray(history),
                 idx=np.asarray(idx))
        os.replace(tmp, path)
        self.progress["granulation"][str(k)] = record
        self._save_progress()

    def _save_progress(self):
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=self.path)
        with os.fdopen(fd, "w") as fh:
            json.dump(self.progress, fh, indent=1)
        os.replace(tmp, self.path / PROGRESS)
        files = [f for f in output.files_under(self.path)
                 if not f.startswith("segment_") and not f.startswith(".tmp-")]
        output.write_manifest(self.path, {f: output.stat_entry(self.path / f) for f in files},
                              STORE_KIND)

    def remove(self):
        """Remove the store: each segment case's files, then the store's own."""
        for p in sorted(self.path.glob("segment_*")):
            output.remove_written(p)
        output.remove_written(self.path)
