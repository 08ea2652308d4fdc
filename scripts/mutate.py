#!/usr/bin/env python3
"""Mutation check of the test suite: does each test catch the error it is named for?

Each mutation in MUTATIONS is (name, area, file, exact original text, replacement, tests). For
each one the script copies the package and its tests into a scratch directory, applies the
single text replacement (the original must occur exactly once), and runs only the tests listed
for it with a fresh NUMBA_CACHE_DIR: numba's cache is keyed by each module's own source file,
so a caller keeps stale inlined code of a mutated callee from another module; an empty cache
compiles the mutant for real. A mutation is *caught* when the listed tests fail, *survived*
when they pass; the baseline (no mutation) must pass the union of the selections first.

Compiling is most of the cost, so each mutant's fresh cache directory starts as a copy of the
baseline's compiled cache (built by the baseline run in the same directory, so numba's cache
locations and source stamps match) with every entry removed that could hold the mutated code:
the entries of the mutated module and of every package module that imports it, directly or
through others (a compiled caller embeds its callees' code), and those of physics/registry.py
(its dispatch closures embed the registries' functions). A mutant of a file without compiled
code (no ``njit``) keeps the whole baseline cache: a numba kernel cannot call an interpreted
function. Mutants run one after another in each of ``--jobs`` work directories.

Usage (slow: minutes per compiled mutation; run it outside CI):
    python scripts/mutate.py [--only NAME ...] [--jobs N] [--report docs/results/mutations.md]
"""
import argparse
import concurrent.futures as cf
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mutations_list import MUTATIONS  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from pbe_cfd import COMPILED  # noqa: E402
from pbe_cfd.util.kernel_cache import source_hash  # noqa: E402


ROOT = Path(__file__).resolve().parent.parent
TIMEOUT_S = 1800


def _module_of(path: Path, root: Path) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def importers(tree: Path, mutated: str) -> set:
    """Files (relative paths) of the package modules that import ``mutated`` (a relative
    path), directly or through other package modules, the mutated file included."""
    import ast
    files = sorted((tree / "pbe_cfd").rglob("*.py"))
    name_of = {f: _module_of(f, tree) for f in files}
    by_name = {v: f for f, v in name_of.items()}
    imports = {}
    for f in files:
        pkg = name_of[f] if f.name == "__init__.py" else name_of[f].rpartition(".")[0]
        deps = set()
        for node in ast.walk(ast.parse(f.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            for t in targets:
                while t and t not in by_name:
                    t = t.rpartition(".")[0]
                if t:
                    deps.add(by_name[t])
        imports[f] = deps
    target = tree / mutated
    hit = {target}
    changed = True
    while changed:
        changed = False
        for f, deps in imports.items():
            if f not in hit and deps & hit:
                hit.add(f)
                changed = True
    return {f.relative_to(tree).as_posix() for f in hit}


def seed_cache(baseline_cache: Path, cache: Path, tree: Path, mutated: str):
    """A fresh cache directory for a mutant of ``mutated`` (see the module docstring)."""
    shutil.copytree(baseline_cache, cache)
    # the package's kernels sit under pbe_cfd-<hash of its compiled sources>
    # (pbe_cfd/util/kernel_cache.py): the mutant's sources name their own directory
    own = cache / f"pbe_cfd-{source_hash(tree / 'pbe_cfd', COMPILED)}"
    for d in cache.glob("pbe_cfd-*"):
        if d != own:
            d.rename(own)
    if not compiled(tree / mutated):
        return 0
    stale = importers(tree, mutated) | {"pbe_cfd/physics/registry.py"}
    removed = 0
    for rel in stale:
        p = Path(rel)
        for d in own.glob(f"{p.parent.name}_*"):
            for entry in d.glob(f"{p.stem}.*"):
                entry.unlink()
                removed += 1
    return removed


def copy_tree(dest: Path):
    """The package, its tests and the project files the tests read, into ``dest``."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".hypothesis", "*.egg-info")
    for name in ("pbe_cfd", "tests", "docs", "scripts", "postprocess"):
        if (ROOT / name).exists():
            shutil.copytree(ROOT / name, dest / name, ignore=ignore, symlinks=True)
    for name in ("pyproject.toml", "README.md", "CONTRIBUTING.md"):
        shutil.copy2(ROOT / name, dest / name)
    if (ROOT / "openfoam_case").is_symlink():
        os.symlink(os.readlink(ROOT / "openfoam_case"), dest / "openfoam_case")


def apply(dest: Path, mutation) -> None:
    path = dest / mutation["file"]
    text = path.read_text()
    count = text.count(mutation["original"])
    if count != 1:
        raise ValueError(f"{mutation['name']}: the original text occurs {count} times in "
                         f"{mutation['file']} (expected once)")
    path.write_text(text.replace(mutation["original"], mutation["replacement"]))


def compiled(path: Path) -> bool:
    return "njit" in path.read_text()


def run_tests(dest: Path, tests, cache: Path, log: Path) -> tuple[int, float]:
    env = dict(os.environ, PYTHONPATH=str(dest), NUMBA_CACHE_DIR=str(cache),
               PYTHONDONTWRITEBYTECODE="1",
               WM_PROJECT_DIR=os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam"))
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-n", "0", "-p", "no:cacheprovider",
           "--no-header", "-o", "addopts=", *tests]
    t0 = time.perf_counter()
    with open(log, "w") as out:
        try:
            rc = subprocess.run(cmd, cwd=dest, env=env, stdout=out, stderr=subprocess.STDOUT,
                                timeout=TIMEOUT_S).returncode
        except subprocess.TimeoutExpired:
            rc = -1
    return rc, time.perf_counter() - t0


def last_line(log: Path) -> str:
    lines = [ln for ln in log.read_text().splitlines() if ln.strip()]
    failed = [ln for ln in lines if ln.startswith("FAILED") or ln.startswith("ERROR")]
    return (failed[0] if failed else (lines[-1] if lines else "")).strip()[:160]


def one(mutation, slot: Path, pristine: Path, baseline_cache: Path, scratch: Path):
    """Run one mutant in the work directory ``slot`` (restored from ``pristine`` first)."""
    name = mutation["name"]
    path = slot / mutation["file"]
    shutil.copy2(pristine / mutation["file"], path)       # the slot holds the original tree
    apply(slot, mutation)
    cache = scratch / f"cache-{name}"
    seed_cache(baseline_cache, cache, slot, mutation["file"])
    log = scratch / f"{name}.log"
    try:
        rc, wall = run_tests(slot, mutation["tests"], cache, log)
    finally:
        shutil.copy2(pristine / mutation["file"], path)   # undo, stamp included
        shutil.rmtree(cache, ignore_errors=True)
    verdict = {0: "survived", 1: "caught"}.get(rc, "caught (error)" if rc > 0 else "timeout")
    if rc in (2, 3, 4):                  # interrupted / internal error / usage error
        verdict = "broken run"
    return dict(mutation, verdict=verdict, wall=wall, detail=last_line(log), rc=rc)


def run_slot(k, mutations, scratch: Path, pristine: Path, tests, report, on_result):
    """Baseline, then the mutants, in work directory k; returns (baseline text, results)."""
    slot = scratch / f"slot{k}"
    shutil.copytree(pristine, slot, symlinks=True)      # copytree keeps modification times
    baseline_cache = scratch / f"cache-baseline{k}"
    baseline_cache.mkdir()
    log = scratch / f"baseline{k}.log"
    rc, wall = run_tests(slot, tests, baseline_cache, log)
    if rc != 0:
        return f"FAILED (rc {rc}): {last_line(log)}", None
    report(f"baseline (work directory {k}): passed in {wall:.0f} s")
    results = []
    for m in mutations:
        r = one(m, slot, pristine, baseline_cache, scratch)
        report(f"{r['name']:32s} {r['verdict']:16s} {r['wall']:6.0f} s  {r['detail']}")
        results.append(r)
        on_result(r, f"work directory {k}: passed in {wall:.0f} s")
    return f"passed in {wall:.0f} s", results


def write_report(path: Path, results, baseline, started, load):
    own = [r for r in results if r["origin"] == "own"]
    issue = [r for r in results if r["origin"] == "issue"]
    def caught(rs):
        return sum(r["verdict"].startswith("caught") for r in rs)
    lines = ["# Mutation check", "",
             f"`python scripts/mutate.py` on {started} UTC (load average at start {load}); "
             "each mutation applied to a copy of the package, its listed tests run with a fresh "
             "NUMBA_CACHE_DIR (the baseline's compiled cache less every entry that could hold "
             "the mutated code: the mutated module's and its importers').", "",
             f"Baseline (no mutation, the union of the selections): {baseline}.", "",
             f"- issue-33 table: {caught(issue)} of {len(issue)} caught",
             f"- own mutations: {caught(own)} of {len(own)} caught"
             + (f" ({100.0 * caught(own) / len(own):.0f}%)" if own else ""), "",
             "| mutation | area | where | verdict | tests run | wall [s] | first failure |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        tests = " ".join(t.replace("tests/", "") for t in r["tests"]).replace("|", "\\|")
        detail = r["detail"].replace("|", "\\|") if r["verdict"] != "survived" else ""
        lines.append(f"| {r['name']} | {r['area']} | `{r['file']}` | **{r['verdict']}** | "
                     f"{tests} | {r['wall']:.0f} | {detail} |")
    missing = [m for m in MUTATIONS if m["name"] not in {r["name"] for r in results}]
    if missing:
        lines += ["", "Not run yet (no verdict): " + ", ".join(m["name"] for m in missing)
                  + "."]
    notes = [r for r in results if r.get("note")]
    if notes:
        lines += ["", "## Notes", ""]
        lines += [f"- **{r['name']}**: {r['note']}" for r in notes]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def merge_previous(path: Path, results):
    """Results of an earlier run (JSON beside the report) updated with ``results``: a rerun
    of some mutations (``--only``) keeps the others' rows."""
    old = json.loads(path.read_text()) if path.exists() else []
    names = {m["name"] for m in MUTATIONS}
    merged = {r["name"]: r for r in old if r["name"] in names}
    merged.update({r["name"]: r for r in results})
    for r in merged.values():               # the list's current text and notes win
        r.update({k: v for k, v in next(m for m in MUTATIONS if m["name"] == r["name"]).items()
                  if k in ("note", "area", "file", "origin")})
    return list(merged.values())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="run only these mutations (names)")
    ap.add_argument("--jobs", type=int, default=1, help="mutations run at once")
    ap.add_argument("--report", default=str(ROOT / "docs" / "results" / "mutations.md"))
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--report-only", metavar="TEXT", help="rewrite the report from the JSON "
                    "beside it (the list's current notes) with TEXT as the baseline line")
    args = ap.parse_args(argv)
    chosen = [m for m in MUTATIONS if not args.only or m["name"] in args.only]
    if args.list:
        for m in chosen:
            print(f"{m['name']:32s} {m['origin']:5s} {m['area']:10s} {m['file']}")
        return 0
    if args.report_only is not None:
        sidecar = Path(args.report).with_suffix(".json")
        rows = merge_previous(sidecar, [])
        order = {m["name"]: k for k, m in enumerate(MUTATIONS)}
        rows.sort(key=lambda x: order[x["name"]])
        write_report(Path(args.report), rows, args.report_only, "(several runs, rebuilt)",
                     "see the notes")
        return 0
    unknown = set(args.only or ()) - {m["name"] for m in MUTATIONS}
    if unknown:
        print(f"mutate.py: unknown mutation(s) {sorted(unknown)}", file=sys.stderr)
        return 2
    started = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    scratch = Path(tempfile.mkdtemp(prefix="pbe-mutate-"))
    try:
        pristine = scratch / "pristine"
        copy_tree(pristine)
        for m in chosen:                              # every original must apply once
            count = (pristine / m["file"]).read_text().count(m["original"])
            if count != 1:
                raise SystemExit(f"mutate.py: {m['name']}: the original text occurs {count} "
                                 f"times in {m['file']} (expected once)")
        jobs = max(1, min(args.jobs, len(chosen)))
        shares = [chosen[k::jobs] for k in range(jobs)]
        results, baselines = [], []
        lock = threading.Lock()
        order = {m["name"]: k for k, m in enumerate(MUTATIONS)}
        sidecar = Path(args.report).with_suffix(".json")
        seen = {}

        def on_result(r, baseline_text):
            """Keep the report current after every mutant (a long run can be stopped)."""
            with lock:
                seen[baseline_text] = True
                rows = merge_previous(sidecar, [r])
                rows.sort(key=lambda x: order[x["name"]])
                sidecar.parent.mkdir(parents=True, exist_ok=True)
                sidecar.write_text(json.dumps(rows, indent=1) + "\n")
                write_report(Path(args.report), rows, "; ".join(seen), started, load)

        with cf.ThreadPoolExecutor(max_workers=jobs) as pool:
            futures = []
            for k, share in enumerate(shares):
                # each work directory's baseline runs the union of its mutants' tests
                tests = sorted({t for m in share for t in m["tests"]})
                futures.append(pool.submit(run_slot, k, share, scratch, pristine, tests,
                                           lambda text: print(text, flush=True), on_result))
            for fut in futures:
                text, rs = fut.result()
                baselines.append(text)
                if rs is None:
                    print(f"baseline: {text}", flush=True)
                    return 1
                results += rs
        baseline = "; ".join(baselines)
        results = merge_previous(sidecar, results)
        results.sort(key=lambda r: order[r["name"]])
        sidecar.parent.mkdir(parents=True, exist_ok=True)
        sidecar.write_text(json.dumps(results, indent=1) + "\n")
        write_report(Path(args.report), results, baseline, started, load)
        print(f"report: {args.report}")
        return 0
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
