"""Writers for run results: moments.csv, summary.json, and atomic output directories.

Output goes into a temporary sibling directory that is renamed into place only when everything
was written, so a failed run never leaves a half-written ``--out`` directory behind.
"""
from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def atomic_directory(target):
    """Yield a temporary directory next to ``target``; on success it replaces ``target``,
    on any exception it is removed and ``target`` is left as it was."""
    target = Path(target).resolve()
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=target.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if target.exists():
        old = target.parent / f".{target.name}.old-{os.getpid()}"
        target.rename(old)
    tmp.rename(target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_columns_csv(path, columns: dict):
    """Write equal-length 1-D columns (first the time) to CSV with full float precision."""
    names = list(columns)
    rows = len(next(iter(columns.values())))
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(names)
        for r in range(rows):
            writer.writerow([_fmt(columns[n][r]) for n in names])


def _fmt(value):
    value = float(value)
    return repr(value) if math.isfinite(value) else "nan"


def read_columns_csv(path) -> dict:
    """Read a CSV written by ``write_columns_csv`` into name -> float array."""
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        data = [[float(v) for v in row] for row in reader if row]
    arr = np.array(data, dtype=float).reshape(-1, len(header))
    return {name: arr[:, k] for k, name in enumerate(header)}


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else str(v)
    return value


def write_json(path, data: dict):
    """Write a dict as indented JSON (numpy values converted, non-finite floats as strings)."""
    with open(path, "w") as fh:
        json.dump(_jsonable(data), fh, indent=2)
        fh.write("\n")
