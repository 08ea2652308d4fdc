"""Prove that a change of code leaves the results bitwise the same.

Runs the same commands with the package of a base commit (``git archive``, into a temporary
directory) and with the working tree, then compares every written result file byte for byte:
``moments.csv``, ``bed_moments.csv``, every ``.vtu``/``.pvd`` of the VTK series, and
``summary.json`` without its wall-clock entries (and ``segments.csv`` of the two-way case
without its wall-seconds columns; its echo of the scene's ``[method]`` table
may list only the keys the method reads, with the same values). Exit status 0 when every file
agrees.

    python scripts/bitwise_check.py --base 16e56e6            # all cases
    python scripts/bitwise_check.py --base 16e56e6 --only seed-wurster fluid-bed

The base runs are kept under ``--work`` (default /tmp/pbe_cfd_bitwise/<base>) and reused when
present, so a second check after more edits only reruns the working tree.
"""
from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: the two-way case: two segments of 2 s on the template's small mesh, 0.05 s of flow each
#: (tests/runs/test_coupling_two_way.py), the spray zone inside the packed bed
TWO_WAY = {"coupling": {"interval": 2.0, "flow_time": 0.05, "average_from": 0.02},
           "binder_injection": {"zone": {"alpha_high": 0.6, "box_min": [0.0, 0.1, -1.0],
                                         "box_max": [0.15, 0.3, 1.0]}},
           "scene": {"output_interval": 1.0}}

#: name -> (command words after ``pbe-cfd``, None or the derived scene: (bundled scene,
#: [method] entries, [initial] entries, end time [s], further tables' entries))
CASES = {
    "seed-wurster": (["run", "seed-wurster"], None),
    "seed-wurster-laguerre": (["run", "seed-wurster-laguerre"], None),
    "seed-wurster-cnmc": (["run", "seed-wurster-cnmc"], None),
    "seed-wurster-cqmom": (["run", "seed-wurster-cqmom"], None),
    "seed-wurster-eqmom": (["run", "{scene}"], ("seed-wurster", {"name": "eqmom", "nodes": 3},
                                                None, None)),
    "constant-kernel": (["run", "constant-kernel"], None),
    "study-analytic": (["run", "study-analytic"], None),
    "fluid-bed": (["couple"], None),
    "fluid-bed-transport": (["couple", "fluid-bed-transport"], None),
    "fluid-bed-breakage": (["couple", "fluid-bed-breakage"], None),
    "fluid-bed-qmom3": (["couple", "{scene}"], ("fluid-bed", {"nodes": 3}, None, 20.0)),
    "fluid-bed-laguerre": (["couple", "{scene}"],
                           ("fluid-bed", {"name": "laguerre", "order": 3},
                            {"droplet_number_density": 8.5e10}, 10.0)),
    "fluid-bed-workers": (["couple", "--workers", "2"], None),
    "two-way": (["couple", "{scene}"], ("fluid-bed-transport", None, None, 4.0, TWO_WAY)),
    # drying, the bed's air balance and the spray schedule: the batch's first 5 s
    "fluid-bed-batch": (["couple", "{scene}"], ("fluid-bed-batch", None, None, 6.0,
                                                {"scene": {"output_interval": 2.0}})),
}

WALL_KEYS = ("wall_time_s", "cell_steps_per_second", "cluster", "threads", "source",
             "compile_time_s", "kernels_compiled", "phases",
             "transport_wall_s", "source_wall_s", "transport_first_call_s",
             "transport_s_per_cell_substep", "source_s_per_cell_split_step",
             "cfd_wall_s", "pbe_wall_s")


def _derived_scene(work: Path, name: str, spec) -> Path:
    """A scene TOML: a bundled scene with [method] / [initial] entries replaced (and its end
    time, unless None; further tables' entries merged, tables within tables key by key)."""
    import tomllib
    base, method, initial, end_time, *more = spec
    text = (ROOT / "pbe_cfd" / "scenes" / f"{base}.toml").read_text()
    data = tomllib.loads(text)
    data["scene"]["name"] = name
    if end_time is not None:
        data["scene"]["end_time"] = end_time
    if method and "name" in method:
        data["method"] = dict(method)
    elif method:
        data["method"].update(method)
    if initial:
        data["initial"].update(initial)
    for table, entries in (more[0] if more else {}).items():
        into = data.setdefault(table, {})
        for k, v in entries.items():
            if isinstance(v, dict) and isinstance(into.get(k), dict):
                into[k] = {**into[k], **v}
            else:
                into[k] = v
    lines = []
    for table, values in data.items():
        lines.append(f"[{table}]")
        for k, v in values.items():
            lines.append(f"{k} = {_toml(v)}")
    path = work / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _toml(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def run_case(code: Path, work: Path, name: str, out: Path) -> bool:
    """Run one case with the package at ``code`` into ``out``; False (and the error) if it
    failed."""
    words, spec = CASES[name]
    if spec is not None:
        scene = _derived_scene(work, name, spec)
        words = [w.replace("{scene}", str(scene)) for w in words]
    env = dict(os.environ, PYTHONPATH=str(code))
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "pbe_cfd.cli", *words, "--out", str(out)]
    r = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        print(f"{name} failed with {code}:\n{r.stderr[-2000:]}")
        return False
    return True


def _summary(path: Path, out: Path):
    """summary.json of the output ``out`` without its wall-clock entries, ``out``'s own path
    (a two-way run's segment cases lie beside it) written ``<out>``."""
    data = json.loads(path.read_text().replace(str(out), "<out>"))

    def strip(d):
        if isinstance(d, dict):
            return {k: strip(v) for k, v in d.items() if k not in WALL_KEYS}
        if isinstance(d, list):
            return [strip(x) for x in d]
        return d
    return strip(data)


def _split_method_echo(summary):
    """(summary without its echo of the scene's [method] table, that echo or None)."""
    scene = summary.get("scene") if isinstance(summary, dict) else None
    if not isinstance(scene, dict) or not isinstance(scene.get("method"), dict):
        return summary, None
    return summary | {"scene": {k: v for k, v in scene.items() if k != "method"}}, scene["method"]


def _summaries_agree(a, b) -> bool:
    """Two summaries agree: equal, except that the echo of the [method] table may list only
    the keys its method reads (one echo's items a subset of the other's, same values)."""
    (rest_a, m_a), (rest_b, m_b) = _split_method_echo(a), _split_method_echo(b)
    if rest_a != rest_b:
        return False
    if m_a is None or m_b is None:
        return m_a == m_b
    small, large = sorted((m_a, m_b), key=len)
    return all(k in large and large[k] == v for k, v in small.items())


def _wall_columns(path: Path) -> list[int]:
    """Indices of the wall-clock columns of a CSV file (segments.csv: cfd_wall_s, ...)."""
    with path.open() as f:
        header = f.readline().strip().split(",")
    return [i for i, name in enumerate(header) if name in WALL_KEYS]


def _csv_without_wall(path: Path) -> list[list[str]]:
    """The CSV file's rows as text fields, its wall-clock columns left out."""
    drop = set(_wall_columns(path))
    return [[x for i, x in enumerate(line.rstrip("\n").split(",")) if i not in drop]
            for line in path.open()]


def compare(a: Path, b: Path) -> list[str]:
    """Differences between two output directories (empty list: identical)."""
    diffs = []
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file()
                   and (p.suffix in (".csv", ".vtu", ".pvd") or p.name == "summary.json"))
    if not files:
        diffs.append(f"{a}: no result files")
    for rel in files:
        other = b / rel
        if not other.is_file():
            diffs.append(f"{rel}: missing in {b}")
        elif rel.name == "summary.json":
            if not _summaries_agree(_summary(a / rel, a), _summary(other, b)):
                diffs.append(f"{rel}: summary differs")
        elif rel.suffix == ".csv" and _wall_columns(a / rel):
            if _csv_without_wall(a / rel) != _csv_without_wall(other):
                diffs.append(f"{rel}: bytes differ (wall-clock columns aside)")
        elif not filecmp.cmp(a / rel, other, shallow=False):
            diffs.append(f"{rel}: bytes differ")
    return diffs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="base commit (e.g. 16e56e6)")
    parser.add_argument("--only", nargs="*", default=None, choices=sorted(CASES))
    parser.add_argument("--work", default=None)
    parser.add_argument("--record", action="store_true",
                        help="only run the base commit (record the reference outputs)")
    args = parser.parse_args(argv)
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.base],
                         check=True, capture_output=True, text=True).stdout.strip()
    work = Path(args.work or Path(tempfile.gettempdir()) / "pbe_cfd_bitwise" / sha)
    work.mkdir(parents=True, exist_ok=True)
    base_code = work / "code"
    if not (base_code / "pbe_cfd").is_dir():
        base_code.mkdir(exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", sha, "pbe_cfd"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base_code)], input=archive, check=True)
    failed = 0
    for name in args.only or sorted(CASES):
        ref = work / "base" / name
        if not (ref / "summary.json").is_file() and not run_case(base_code, work, name, ref):
            failed += 1
            continue
        if args.record:
            print(f"{name}: recorded")
            continue
        new = work / "new" / name
        if not run_case(ROOT, work, name, new):
            failed += 1
            continue
        diffs = compare(ref, new) + compare(new, ref)
        n = sum(1 for p in ref.rglob("*") if p.is_file())
        if diffs:
            failed += 1
            print(f"{name}: DIFFERENT\n  " + "\n  ".join(sorted(set(diffs))[:20]))
        else:
            print(f"{name}: identical ({n} files)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
