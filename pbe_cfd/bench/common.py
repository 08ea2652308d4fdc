"""What every study shares: the machine the numbers were measured on, the commit, progress
lines and the CSV / Markdown writers."""
from __future__ import annotations

import math
import os
import platform
import sys
from pathlib import Path

import numba as nb
import numpy as np

from ..methods.cnmc import ENTRY as _cnmc_entry
from ..methods.laguerre import ENTRY as _laguerre_entry


# ============================================================================ machine, timing
def machine_info() -> dict:
    """The machine the numbers were measured on (cores, CPU, load, versions)."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    import scipy
    return {"cpu": cpu, "logical_cores": os.cpu_count(),
            "numba_threads": nb.config.NUMBA_NUM_THREADS,
            "load_average_1_5_15min": [round(x, 2) for x in load],
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": nb.__version__,
            "platform": platform.platform()}


def _machine_line(info) -> str:
    la = info["load_average_1_5_15min"]
    return (f"{info['cpu'] or 'unknown CPU'}, {info['logical_cores']} logical cores, numba "
            f"{info['numba']} with {info['numba_threads']} threads; load average "
            f"{la[0]:.1f} / {la[1]:.1f} / {la[2]:.1f} (1 / 5 / 15 min) when the study started")


def _git_describe() -> str:
    try:
        import subprocess
        root = Path(__file__).resolve().parent.parent
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=5)
        return out.stdout.strip()
    except Exception:  # noqa: BLE001 - informative only
        return ""


def _say(quiet, text):
    if not quiet:
        print(text, file=sys.stderr, flush=True)


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    return str(v)


def _write_csv(path, lines):
    import csv
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        for rec in lines:
            w.writerow([_csv_value(v) for v in rec])


def _write_simple(out_dir, name, rows, markdown, result):
    from ..io import output
    keys = list(rows[0]) if rows else []
    lines = [keys] + [[r.get(k) for k in keys] for r in rows]
    with output.add_to_directory(out_dir, kind="bench") as d:
        _write_csv(d / f"{name}.csv", lines)
        (d / f"{name}.md").write_text(markdown)
        output.write_json(d / f"{name}.json", result)


def failure_status(exc) -> str:
    """The whole reason a variant failed, on one line (a table cell)."""
    return "failed: " + " ".join(str(exc).split())


#: the studies of one method, named like it (``pbe-cfd bench cnmc``, ``... laguerre``)
CNMC_STUDY, LAGUERRE_STUDY = _cnmc_entry.name, _laguerre_entry.name
#: the studies that write <name>.csv, .md and .json
SIMPLE_STUDIES = (CNMC_STUDY, LAGUERRE_STUDY, "couple", "integrators", "cluster", "batch",
                  "hard-cases")

#: The files each study writes into --out (several studies may share one directory).
STUDY_FILES = {
    "accuracy": ["accuracy.csv", "accuracy.md", "pareto.png", "accuracy.json"],
    "throughput": ["throughput.csv", "throughput.md", "throughput.png", "throughput.json",
                   "machine.json"],
    **{name: [f"{name}.csv", f"{name}.md", f"{name}.json"]
       for name in SIMPLE_STUDIES},
    "peer": ["peer.csv", "peer.md", "peer.png", "peer.json"],
}
