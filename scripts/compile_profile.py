"""Where the compile time of a scene's kernels goes: numba's compile events, per function.

    NUMBA_CACHE_DIR=$(mktemp -d) python scripts/compile_profile.py [SCENE ...] [--top N]
        [--json FILE]

Compiles the kernels ``pbe-cfd compile`` compiles for each scene (default: the README's two
scenes) and prints, per compiled function, its specialisations (signatures compiled), its
inclusive and exclusive CPU seconds (exclusive: less the callees numba compiled while typing
it), then the CPU seconds per compiler pass (exclusive of nested compiles) and in LLVM
(numba's ``llvm_lock`` events: optimisation and code generation). Run it on an empty cache:
a function loaded from the cache fires no compile event.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict

from numba.core import event


def _now():
    return time.process_time()


class CompileProfile(event.Listener):
    """Inclusive and exclusive CPU seconds per (function, signature) from numba:compile
    events; exclusive seconds per compiler pass from numba:run_pass; LLVM seconds."""

    def __init__(self):
        self.stack = []                  # [key, start, child seconds]
        self.inclusive = defaultdict(float)
        self.exclusive = defaultdict(float)
        self.passes = defaultdict(float)
        self.pass_stack = []
        self.llvm = 0.0
        self._llvm_depth = 0
        self._llvm_start = 0.0

    # numba:compile ---------------------------------------------------------------------------
    def on_start(self, ev):
        if ev.kind == "numba:compile":
            d = ev.data["dispatcher"]
            name = f"{d.py_func.__module__}.{d.py_func.__qualname__}"
            self.stack.append([(name, str(ev.data["args"])), _now(), 0.0])
        elif ev.kind == "numba:run_pass":
            self.pass_stack.append([ev.data["name"].split(" [")[0], _now(), 0.0])
        elif ev.kind == "numba:llvm_lock":
            if self._llvm_depth == 0:
                self._llvm_start = _now()
            self._llvm_depth += 1

    def on_end(self, ev):
        if ev.kind == "numba:compile":
            key, start, children = self.stack.pop()
            spent = _now() - start
            self.inclusive[key] += spent
            self.exclusive[key] += spent - children
            if self.stack:
                self.stack[-1][2] += spent
            # a nested compile runs inside the caller's current pass: not that pass's own
            if self.pass_stack:
                self.pass_stack[-1][2] += spent
        elif ev.kind == "numba:run_pass":
            name, start, children = self.pass_stack.pop()
            spent = _now() - start
            self.passes[name] += spent - children
            if self.pass_stack:
                self.pass_stack[-1][2] += spent
        elif ev.kind == "numba:llvm_lock":
            self._llvm_depth -= 1
            if self._llvm_depth == 0:
                self.llvm += _now() - self._llvm_start

    def per_function(self):
        """{function: (signatures, inclusive s, exclusive s)}, largest exclusive first."""
        out = defaultdict(lambda: [0, 0.0, 0.0])
        for (name, _sig), incl in self.inclusive.items():
            row = out[name]
            row[0] += 1
            row[1] = max(row[1], incl)
            row[2] += self.exclusive[(name, _sig)]
        return dict(sorted(out.items(), key=lambda kv: -kv[1][2]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*")
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--json", help="write the whole profile here")
    args = ap.parse_args(argv)
    from pbe_cfd.cli import DEFAULT_COUPLED, DEFAULT_WELL_MIXED
    from pbe_cfd.runs.precompile import compile_scene
    from pbe_cfd.scene.scene import load_scene
    names = args.scenes or [DEFAULT_WELL_MIXED, DEFAULT_COUPLED]
    prof = CompileProfile()
    for kind in ("numba:compile", "numba:run_pass", "numba:llvm_lock"):
        event.register(kind, prof)
    cpu0, wall0 = _now(), time.perf_counter()
    for name in names:
        done = compile_scene(load_scene(name))
        print(f"{name}: {done['kernel']} compiled={done['compiled']} "
              f"{done['seconds']:.1f} s wall, {done['cpu_s']:.1f} s CPU", flush=True)
    total = _now() - cpu0
    rows = prof.per_function()
    print(f"\ntotal {total:.1f} s CPU, {time.perf_counter() - wall0:.1f} s wall; "
          f"{len(rows)} functions, {sum(r[0] for r in rows.values())} signatures; "
          f"LLVM (llvm_lock) {prof.llvm:.1f} s")
    print(f"\n{'exclusive s':>11} {'inclusive s':>11} {'sigs':>4}  function")
    for name, (sigs, incl, excl) in list(rows.items())[:args.top]:
        print(f"{excl:11.2f} {incl:11.2f} {sigs:4d}  {name}")
    print(f"\n{'exclusive s':>11}  compiler pass")
    for name, sec in sorted(prof.passes.items(), key=lambda kv: -kv[1])[:12]:
        print(f"{sec:11.2f}  {name}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"total_cpu_s": total, "llvm_s": prof.llvm,
                       "functions": {k: {"signatures": v[0], "inclusive_s": v[1],
                                         "exclusive_s": v[2]} for k, v in rows.items()},
                       "signatures": [{"function": k[0], "args": k[1],
                                       "inclusive_s": v, "exclusive_s": prof.exclusive[k]}
                                      for k, v in prof.inclusive.items()],
                       "passes": dict(prof.passes)}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
