"""Measures of the package's layout over a package tree (compare a base commit and now).

    python scripts/layout_measures.py /tmp/pbe_cfd_bitwise/<base>/code/pbe_cfd   # a base tree
    python scripts/layout_measures.py pbe_cfd                                   # this tree

1. hand-numbered integer constants: module-level ``NAME = <int>`` or ``NAME = OTHER +/- <int>``
   (ALL_CAPS names), per file; slots/codes of params, config, cell, the Laguerre aux header and
   the integrator codes are listed apart.
2. method names as string constants (AST, so docstrings/messages do not count) outside the
   method's own modules (flat: methods/<name>*.py, conditional.py for cqmom; packages:
   methods/<name>/) and the registration (methods/registry.py), per file: the files a new
   method would have to be added to.
3. the path of ``scene`` through a coupled run: from couple.run_coupled, every call (in source
   order, depth first, each function expanded once) whose arguments hold ``scene`` and whose
   callee resolves to a package function; the sequence of files of the functions entered and
   returned to. stays = runs of one file, returns = stays in a file already left, climbs =
   moves to a file of a higher layer than the one before (the layer of tests/test_layers.py).
   Where the package has the one pass (``runs.problem.problem_of``), the same counts are
   given for the part of the path after the run's call of it returns (the run's own file
   included, the files entered inside a pass left out): what still reads the scene after
   the pass. The same for the two-way run from coupling.run_two_way, whose passes are
   ``two_way_plan`` and each segment's ``segment_problem`` (which calls ``problem_of``).
"""
import ast
import re
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(sys.argv[1]).resolve()
METHODS = ("qmom", "cqmom", "laguerre", "cnmc", "eqmom")
CAPS = re.compile(r"^[A-Z][A-Z0-9_]*$")


def modules():
    out = {}
    for p in sorted(ROOT.rglob("*.py")):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


MODS = modules()


def hand_numbered():
    per_file = Counter()
    for name, p in MODS.items():
        for node in ast.parse(p.read_text()).body:
            if not (isinstance(node, ast.Assign) and len(node.targets) == 1
                    and isinstance(node.targets[0], ast.Name) and CAPS.match(node.targets[0].id)):
                continue
            v = node.value
            is_int = isinstance(v, ast.Constant) and type(v.value) is int
            is_offset = (isinstance(v, ast.BinOp) and isinstance(v.op, (ast.Add, ast.Sub))
                         and isinstance(v.right, ast.Constant) and type(v.right.value) is int)
            if is_int or is_offset:
                per_file[p.relative_to(ROOT).as_posix()] += 1
    return per_file


def own(rel, method):
    if rel.startswith(f"methods/{method}/"):
        return True
    flat = rel.startswith("methods/") and rel.count("/") == 1
    stem = rel.split("/")[-1][:-3]
    return flat and (stem == method or stem.startswith(method + "_")
                     or (method == "cqmom" and stem == "conditional"))


def name_literals():
    per_file = Counter()
    for name, p in MODS.items():
        rel = p.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(p.read_text())):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                    and node.value in METHODS and not own(rel, node.value)
                    and rel != "methods/registry.py"):      # the registration line
                per_file[rel] += 1
    return per_file


# ------------------------------------------------------------------------------ scene path
def _package(name, path):
    return name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]


def imports_of(name):
    """local name -> dotted target (module or module.attr) of every import in the module."""
    path = MODS[name]
    pkg = _package(name, path)
    out = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = pkg[:len(pkg) - node.level + 1] if node.level else []
            src = ".".join(base + ([node.module] if node.module else []))
            for a in node.names:
                out[a.asname or a.name] = f"{src}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                out[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
    return out


def functions_of(name):
    tree = ast.parse(MODS[name].read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = node
        elif isinstance(node, ast.ClassDef):
            for sub in node.body:
                if isinstance(sub, ast.FunctionDef):
                    out[f"{node.name}.{sub.name}"] = sub
    return out


def resolve(target):
    """(module, function) of a dotted target, following re-exports of packages."""
    for _ in range(5):
        mod, _, attr = target.rpartition(".")
        if mod in MODS:
            funcs = functions_of(mod)
            if attr in funcs:
                return mod, attr
            imp = imports_of(mod)
            if attr in imp:
                target = imp[attr]
                continue
        return None
    return None


def callee(module, func_node, call):
    imp = imports_of(module)
    f = call.func
    if isinstance(f, ast.Name):
        if f.id in functions_of(module):
            return module, f.id
        if f.id in imp:
            return resolve(imp[f.id])
    if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
        base = f.value.id
        if base in imp and imp[base] in MODS:
            return resolve(f"{imp[base]}.{f.attr}")
        if base in imp:
            r = resolve(f"{imp[base]}.{f.attr}")       # a class's method (Class.name)
            if r:
                return r
            tgt = imp[base]
            mod, _, cls = tgt.rpartition(".")
            if mod in MODS and f"{cls}.{f.attr}" in functions_of(mod):
                return mod, f"{cls}.{f.attr}"
    return None


def holds_scene(call):
    for a in list(call.args) + [k.value for k in call.keywords]:
        for n in ast.walk(a):
            if isinstance(n, ast.Name) and n.id == "scene":
                return True
    return False


LAYERS = [("utilities", ("util", "io", "viz", "progress", "output", "plotting", "population",
                         "cfd", "results", "psd_figure", "manifest", "output_guard", "tables")),
          ("physics", ("physics",)), ("methods", ("methods", "integrate")),
          ("scene", ("scene", "limits")),
          ("runs", ("model", "domain", "distribution", "runs", "batch", "simulate", "couple",
                    "executor", "distributed", "transport", "solids_flux", "plan")),
          ("studies", ("bench",)), ("cli", ("cli", "cli_args", "cli_bench"))]


def layer(module):
    top = module.split(".")[1] if "." in module else ""
    for rank, (_, names) in enumerate(LAYERS):
        if top in names:
            return rank
    return -1


def _counts(seq):
    """(runs, stays, files, returns, climbs) of a sequence of files entered and returned to."""
    runs = [m for i, m in enumerate(seq) if i == 0 or seq[i - 1] != m]
    returns = sum(1 for i, m in enumerate(runs) if m in runs[:i])
    climbs = sum(1 for i in range(1, len(runs)) if layer(runs[i]) > layer(runs[i - 1]))
    return runs, len(runs), len(set(runs)), returns, climbs


#: the one pass, and the two-way run's passes (its plan, and the pass of each CFD segment)
PASS = ("pbe_cfd.runs.problem", "problem_of")
PASSES = (PASS, ("pbe_cfd.runs.coupling", "two_way_plan"),
          ("pbe_cfd.runs.coupling", "segment_problem"))


def scene_path(start=("couple", "run_coupled")):
    """The counts of the whole path (``_counts``) from the function ``start`` (a module
    under pbe_cfd/ or pbe_cfd/runs/, a function), and of its part after the first return
    from a pass (``PASSES``), the files entered inside any pass left out (None where the
    package has no pass)."""
    start_mod = next((m for m in (f"pbe_cfd.{start[0]}", f"pbe_cfd.runs.{start[0]}")
                      if m in MODS and start[1] in functions_of(m)), None)
    if start_mod is None:
        return None, None
    seq, inside, seen, after = [], [], set(), []

    def visit(module, fname, depth):
        seq.append(module)
        inside.append(depth > 0)
        if (module, fname) in seen:
            return
        seen.add((module, fname))
        node = functions_of(module)[fname]
        calls = sorted((n for n in ast.walk(node) if isinstance(n, ast.Call) and holds_scene(n)),
                       key=lambda n: (n.lineno, n.col_offset))
        for call in calls:
            target = callee(module, node, call)
            if target and target != (module, fname):
                is_pass = target in PASSES
                visit(*target, depth + (1 if is_pass else 0))
                seq.append(module)
                inside.append(depth > 0)
                if is_pass and depth == 0 and not after:
                    after.append(len(seq) - 1)

    visit(start_mod, start[1], 0)
    if not after:
        return _counts(seq), None
    outside = [m for i, m in enumerate(seq) if i >= after[0] and not inside[i]]
    return _counts(seq), _counts(outside)


def report_path(title, start):
    whole, after = scene_path(start)
    if whole is None:
        print(f"scene through {title}: no such function")
        return
    runs, stays, files, returns, climbs = whole
    print(f"scene through {title}: {stays} stays in {files} files, {returns} returns "
          f"to a file already left, {climbs} climbs to a higher layer")
    print("  " + " > ".join(m.split(".", 1)[1] for m in runs))
    if after is not None:
        a_runs, a_stays, a_files, a_returns, a_climbs = after
        print(f"  after the pass, outside the passes ({', '.join(f for _, f in PASSES)}): "
              f"{a_stays} stays in {a_files} files, {a_returns} returns, {a_climbs} climbs: "
              + " > ".join(m.split(".", 1)[1] for m in a_runs))
    visits = Counter(runs)
    print("  stays per file: " + ", ".join(f"{m.split('.', 1)[1]} {n}"
                                          for m, n in visits.most_common(6)))


if __name__ == "__main__":
    hn = hand_numbered()
    print(f"hand-numbered int constants: {sum(hn.values())} in {len(hn)} files")
    for key in ("physics/parameters.py", "methods/laguerre_layout.py",
                "methods/laguerre/layout.py", "integrate/codes.py"):
        if key in hn or (ROOT / key).exists():
            print(f"  {key}: {hn.get(key, 0)}")
    nl = name_literals()
    print(f"method-name literals outside the method's modules: {sum(nl.values())} in "
          f"{len(nl)} files: {dict(sorted(nl.items()))}")
    report_path("couple.run_coupled", ("couple", "run_coupled"))
    report_path("coupling.run_two_way (two-way)", ("coupling", "run_two_way"))
