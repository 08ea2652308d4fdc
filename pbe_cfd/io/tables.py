"""Tables and JSON of run results: CSV columns with full float precision (SI units as the
column names say), indented JSON with numpy values converted."""
from __future__ import annotations

import csv
import json
import math

import numpy as np


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
    """Read a CSV written by ``write_columns_csv`` into name -> float array. Raises ValueError
    naming the file when it is not such a table."""
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
            data = [[float(v) for v in row] for row in reader if row]
        except StopIteration:
            raise ValueError(f"{path}: empty file") from None
        except (ValueError, csv.Error, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a table of numbers under a header ({exc})") from None
    if not header or header[0] != "time_s" or any(len(r) != len(header) for r in data):
        raise ValueError(f"{path}: expected a header starting with time_s and rows of "
                         f"{len(header)} numbers")
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
