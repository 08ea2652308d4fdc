"""The package's structure: arrows point down the layers, no import cycle, modules and functions
of a readable size. Read from the source (every import statement, including those inside
functions), so the checks see what a reader sees."""
import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "pbe_cfd"

#: the package's folders (and top-level modules) from the bottom layer up; a module may import
#: its own layer and the ones below. A module's layer is the one of its top-level folder.
LAYERS = [
    ("utilities", ("__init__.py", "util/", "io/", "viz/")),
    ("physics", ("physics/",)),
    ("methods", ("methods/", "integrate/")),
    ("scene", ("scene/",)),
    ("runs", ("distribution/", "runs/", "transport/")),
    ("studies", ("bench/",)),
    ("cli", ("cli.py", "cli_args.py", "cli_bench.py")),
]

#: imports exempt from the checks (none: the Laguerre ROM's cycle and upward import are gone)
PENDING = set()


def modules(root=PACKAGE):
    """Dotted module name -> file, for every .py file of the package."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def import_graph(mods):
    """Module -> set of package modules it imports (anywhere in its source)."""
    graph = {}
    for name, path in mods.items():
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package[:len(package) - node.level + 1] if node.level else []
                module = ".".join(base + ([node.module] if node.module else []))
                targets = [f"{module}.{a.name}" for a in node.names] + [module]
            for t in targets:
                while t and t not in mods:
                    t = t.rpartition(".")[0]
                if t and t != name and not (name.startswith(t + ".") and t == "pbe_cfd"):
                    edges.add(t)
        graph[name] = edges - {"pbe_cfd"} if name != "pbe_cfd" else edges
    return graph


def strongly_connected(graph):
    """The import cycles: strongly connected sets of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def layer_of(module):
    """Rank in LAYERS of a dotted module name (None if its top-level folder has no layer)."""
    parts = module.split(".")[1:]
    top = "__init__.py" if not parts else (parts[0] + "/" if len(parts) > 1 or
                                           (PACKAGE / parts[0]).is_dir() else parts[0] + ".py")
    for rank, (_, places) in enumerate(LAYERS):
        if top in places:
            return rank
    return None


def without_pending(graph):
    return {m: {t for t in e if (m, t) not in PENDING} for m, e in graph.items()}


def test_every_module_has_a_layer():
    assert [m for m in modules() if layer_of(m) is None] == []
    listed = {p for _, places in LAYERS for p in places}
    present = {p.name + ("/" if p.is_dir() else "") for p in PACKAGE.iterdir()
               if p.suffix == ".py" or (p / "__init__.py").is_file()}
    assert listed == present            # every folder has a layer, every layer entry exists


def test_no_import_cycle():
    assert strongly_connected(without_pending(import_graph(modules()))) == []


def test_imports_point_down_the_layers():
    up = []
    for m, edges in without_pending(import_graph(modules())).items():
        for t in edges:
            if layer_of(t) > layer_of(m):
                up.append(f"{m} ({LAYERS[layer_of(m)][0]}) imports {t} "
                          f"({LAYERS[layer_of(t)][0]})")
    assert up == []


JIT_DECORATOR = re.compile(r"@(nb\.|numba\.)?(njit|jit|vectorize|guvectorize|cfunc)\b")


def reached_by_compiled_code(mods, graph):
    """Modules holding numba-compiled functions and every package module they import,
    directly or through others: what compiled code can read."""
    seen, stack = set(), [m for m, p in mods.items() if JIT_DECORATOR.search(p.read_text())]
    while stack:
        m = stack.pop()
        if m not in seen:
            seen.add(m)
            stack.extend(graph.get(m, ()))
    return seen


def test_files_left_out_of_the_kernel_cache_key_hold_nothing_compiled_code_reads():
    """The numba cache directory is keyed by a hash of the sources under pbe_cfd.COMPILED; a
    file outside them that compiled code reads would let a stale kernel run."""
    import pbe_cfd
    mods = modules()
    reached = reached_by_compiled_code(mods, import_graph(mods))
    hashed = set(pbe_cfd._compiled_sources(PACKAGE))
    wrong = sorted(m for m in reached if mods[m] not in hashed)
    assert wrong == []
    assert len(hashed) < len(mods)                 # the exemption does exempt something
    for c in pbe_cfd.COMPILED:                     # every entry names a file or directory
        assert (PACKAGE / c).exists(), c


def test_the_cache_key_check_sees_compiled_code_behind_an_import(tmp_path):
    pkg = tmp_path / "pbe_cfd"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "kernel.py").write_text("from . import constants\n@nb.njit\ndef f(): pass\n")
    (pkg / "sub" / "constants.py").write_text("X = 1\n")
    (pkg / "sub" / "draw.py").write_text("from . import kernel\n")
    mods = modules(pkg)
    reached = reached_by_compiled_code(mods, import_graph(mods))
    assert {"pbe_cfd.sub.kernel", "pbe_cfd.sub.constants"} <= reached
    assert "pbe_cfd.sub.draw" not in reached


def test_the_checks_see_a_cycle_and_an_upward_import(tmp_path):
    """The checks on a toy package: a <-> b is a cycle, physics importing cli points up."""
    pkg = tmp_path / "pbe_cfd"
    (pkg / "physics").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "physics" / "__init__.py").write_text("")
    (pkg / "physics" / "a.py").write_text("from . import b\n")
    (pkg / "physics" / "b.py").write_text("def f():\n    from .a import g\n")
    (pkg / "cli.py").write_text("from .physics import a\n")
    (pkg / "physics" / "c.py").write_text("def f():\n    from ..cli import main\n")
    graph = import_graph(modules(pkg))
    assert strongly_connected(graph) == [["pbe_cfd.physics.a", "pbe_cfd.physics.b"]]
    assert "pbe_cfd.cli" in graph["pbe_cfd.physics.c"]
    assert layer_of("pbe_cfd.physics.c") < layer_of("pbe_cfd.cli")


MODULE_LINES = 600
FUNCTION_LINES = 100


def test_modules_and_functions_are_readable_sizes():
    """No module over 600 lines, no function over 100 (numba kernels included: each was split
    into inlined steps or helpers without changing a result bit)."""
    too_long = []
    for name, path in modules().items():
        text = path.read_text()
        if len(text.splitlines()) > MODULE_LINES:
            too_long.append(f"module {name} ({len(text.splitlines())} lines)")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > FUNCTION_LINES:
                    too_long.append(f"function {name}.{node.name} ({length} lines)")
    assert too_long == []
