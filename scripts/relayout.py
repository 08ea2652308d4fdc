"""Move the package into the folders that are its layers, or rewrite one file's imports to them.

    python scripts/relayout.py --apply            # git mv every module, rewrite every import
    python scripts/relayout.py FILE [FILE ...]    # rewrite the imports of files written for
                                                  # the flat layout (in place, file not moved)
    python scripts/relayout.py --move OLD NEW     # git mv a module written for the flat layout
                                                  # and rewrite its imports for its new place

Imports are rewritten from their syntax tree (every ``import``/``from ... import``, relative or
absolute, at any depth), keeping a statement's text when its meaning and spelling stay; dotted
module names and package paths in the rest of the text (``monkeypatch`` targets,
``python -m``, file lists) are mapped as whole words.
"""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "pbe_cfd"

#: old path -> new path, relative to pbe_cfd/ (a trailing "/" moves a whole directory)
MOVES = {
    "scene.py": "scene/scene.py",
    "limits.py": "scene/limits.py",
    "model.py": "runs/model.py",
    "domain.py": "runs/domain.py",
    "batch.py": "runs/batch.py",
    "simulate.py": "runs/simulate.py",
    "couple.py": "runs/couple.py",
    "plan.py": "runs/plan.py",
    "executor.py": "runs/executor.py",
    "distributed/": "runs/distributed/",
    "transport.py": "transport/operator.py",
    "solids_flux.py": "transport/solids_flux.py",
    "output.py": "io/output.py",
    "manifest.py": "io/manifest.py",
    "output_guard.py": "io/output_guard.py",
    "tables.py": "io/tables.py",
    "results.py": "io/results.py",
    "cfd/openfoam/": "io/openfoam/",
    "cfd/case_keys.py": "io/openfoam/case_keys.py",
    "cfd/cases.py": "io/openfoam/cases.py",
    "cfd/vtk.py": "io/vtk.py",
    "cfd/bed_moments.py": "viz/bed_moments.py",
    "plotting.py": "viz/plotting.py",
    "psd_figure.py": "viz/psd_figure.py",
    "cfd/render.py": "viz/render.py",
    "cfd/section.py": "viz/section.py",
    "cfd/figure_parts.py": "viz/figure_parts.py",
    "cfd/figure_pool.py": "viz/figure_pool.py",
    "progress.py": "util/progress.py",
    "population.py": "util/population.py",
    "methods/quadrature.py": "methods/quadrature/gauss.py",
    "methods/breakage_sources.py": "methods/quadrature/breakage_sources.py",
    "methods/qmom.py": "methods/qmom/qmom.py",
    "methods/cqmom.py": "methods/cqmom/cqmom.py",
    "methods/cqmom_sources.py": "methods/cqmom/sources.py",
    "methods/conditional.py": "methods/cqmom/conditional.py",
    "methods/laguerre.py": "methods/laguerre/rhs.py",
    "methods/laguerre_basis.py": "methods/laguerre/basis.py",
    "methods/laguerre_breakage.py": "methods/laguerre/breakage.py",
    "methods/laguerre_build.py": "methods/laguerre/build.py",
    "methods/laguerre_dry.py": "methods/laguerre/dry.py",
    "methods/laguerre_layout.py": "methods/laguerre/layout.py",
    "methods/laguerre_tensor.py": "methods/laguerre/tensor.py",
    "methods/laguerre_wet.py": "methods/laguerre/wet.py",
    "methods/cnmc.py": "methods/cnmc/ensemble.py",
    "methods/cnmc_box.py": "methods/cnmc/box.py",
    "methods/cnmc_breakage.py": "methods/cnmc/breakage.py",
    "methods/cnmc_slots.py": "methods/cnmc/slots.py",
}
#: packages that go away (their __init__ was empty)
REMOVED = ("cfd/__init__.py",)
#: new packages and the first line of their __init__
NEW_PACKAGES = {
    "scene": "TOML scene files -> validated, frozen dataclasses.",
    "runs": "A run: the scene's arrays, the cell batches, well-mixed and coupled runs, "
            "executors.",
    "transport": "The transport operator between CFD cells and the solids face flux.",
    "io": "Result files, their manifest and guard, OpenFOAM case I/O, VTK series.",
    "viz": "Pictures: plots, the PSD figure, rendered fields and sections.",
    "util": "Small helpers shared by every layer: progress lines, particle populations.",
    "methods/quadrature": "Gaussian quadrature from moments shared by the quadrature methods.",
    "methods/qmom": "Quadrature method of moments with node-wise binder.",
    "methods/cqmom": "Conditional quadrature method of moments for granule mass and binder.",
    "methods/laguerre": "Bivariate Laguerre reduced-order model.",
    "methods/cnmc": "Constant-number Monte Carlo reference.",
}
#: modules that did not exist in the flat layout
NEW_MODULES = {"pbe_cfd.methods.quadrature.binder"}
#: names that moved between modules: (old module, name) -> new module
NAME_MOVES = {
    ("pbe_cfd.methods.qmom", "solve_node_binder"): "pbe_cfd.methods.quadrature.binder",
}


def _dotted(rel: str) -> str:
    parts = ["pbe_cfd"] + rel.removesuffix(".py").split("/")
    if parts[-1] == "__init__" or parts[-1] == "":
        parts = parts[:-1]
    return ".".join(parts)


def _path_map(rel: str) -> str | None:
    """New path (relative to pbe_cfd/) of an old one; None if unchanged."""
    for old, new in MOVES.items():
        if old.endswith("/") and rel.startswith(old):
            return new + rel[len(old):]
        if rel == old:
            return new
    return None


def _module_map() -> dict[str, str]:
    out = {}
    for old, new in MOVES.items():
        if old.endswith("/"):
            out[_dotted(old)] = _dotted(new)
        else:
            out[_dotted(old)] = _dotted(new)
    return out


MODULE_MAP = _module_map()
INVERSE = {v: k for k, v in MODULE_MAP.items()}


def map_module(name: str) -> str:
    """New dotted name of an old module (or attribute path below it)."""
    best = None
    for old in MODULE_MAP:
        if name == old or name.startswith(old + "."):
            if best is None or len(old) > len(best):
                best = old
    return name if best is None else MODULE_MAP[best] + name[len(best):]


def _applied() -> bool:
    return (PKG / "scene").is_dir()


def old_modules() -> set[str]:
    """The dotted names of the flat layout's modules (read from the tree before or after the
    move)."""
    mods = set()
    for path in PKG.rglob("*.py"):
        name = _dotted(path.relative_to(PKG).as_posix())
        if _applied():
            best = None
            for new, old in INVERSE.items():
                if name == new or name.startswith(new + "."):
                    if best is None or len(new) > len(best):
                        best = new
            if best is not None:
                name = INVERSE[best] + name[len(best):]
            elif name in {_dotted(p) for p in NEW_PACKAGES} or name in NEW_MODULES:
                continue            # a package or module of the folder layout
        mods.add(name)
    mods.add("pbe_cfd.cfd")
    return mods


def _package_of(module: str, is_init: bool) -> list[str]:
    parts = module.split(".")
    return parts if is_init else parts[:-1]


def _relative(from_pkg: list[str], target: str) -> str:
    t = target.split(".")
    common = 0
    while common < min(len(from_pkg), len(t)) and from_pkg[common] == t[common]:
        common += 1
    level = len(from_pkg) - common + 1
    return "." * level + ".".join(t[common:])


def _fmt(indent: str, head: str, names: list[str], comment: str) -> str:
    line = f"{indent}{head} import {', '.join(names)}"
    if len(line) + len(comment) <= 100:
        return line + comment + "\n"
    lines, cur = [], f"{indent}{head} import ("
    pad = " " * len(cur)
    for i, n in enumerate(names):
        piece = n + ("," if i < len(names) - 1 else ")")
        limit = 99 - (len(comment) if not lines else 0)
        if len(cur) + len(piece) + 1 > limit and not cur.endswith("("):
            lines.append(cur.rstrip())
            cur = pad
        cur += piece + " "
    lines.append(cur.rstrip())
    lines[0] += comment
    return "\n".join(lines) + "\n"


def rewrite(text: str, old_rel: str | None, new_rel: str | None, mods: set[str]) -> str:
    """``text`` of a file with every import of an old module rewritten. ``old_rel``/``new_rel``:
    the file's path relative to pbe_cfd/ before and after (None: outside the package)."""
    tree = ast.parse(text)
    lines = text.splitlines(keepends=True)
    old_mod = _dotted(old_rel) if old_rel else None
    new_mod = _dotted(new_rel) if new_rel else None
    is_init = bool(old_rel and old_rel.endswith("__init__.py"))
    old_pkg = _package_of(old_mod, is_init) if old_mod else None
    new_pkg = _package_of(new_mod, is_init) if new_mod else None
    edits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = []
            changed = False
            for a in node.names:
                m = map_module(a.name) if a.name.startswith("pbe_cfd") else a.name
                changed |= m != a.name
                if m != a.name and a.asname is None and "." in a.name:
                    raise SystemExit(f"{old_rel}:{node.lineno}: 'import {a.name}' without 'as'")
                names.append(m + (f" as {a.asname}" if a.asname else ""))
            if changed:
                edits.append((node, [("import", names)]))
            continue
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            if old_pkg is None:
                continue
            base = old_pkg[:len(old_pkg) - node.level + 1]
            source = ".".join(base + ([node.module] if node.module else []))
        else:
            source = node.module or ""
        if not source.startswith("pbe_cfd"):
            continue
        groups: dict[str, list[str]] = {}
        for a in node.names:
            sub = f"{source}.{a.name}"
            if sub in mods:
                new = map_module(sub)
                parent, _, last = new.rpartition(".")
                alias = a.asname or (a.name if last != a.name else None)
                groups.setdefault(parent, []).append(last + (f" as {alias}" if alias else ""))
            else:
                target = NAME_MOVES.get((source, a.name), map_module(source))
                groups.setdefault(target, []).append(
                    a.name + (f" as {a.asname}" if a.asname else ""))
        out = []
        for target, names in groups.items():
            if node.level and new_pkg is not None:
                head = _relative(new_pkg, target)
            else:
                head = target
            out.append((f"from {head}", names))
        same = (len(out) == 1 and out[0][0] == "from " + "." * node.level + (node.module or "")
                and out[0][1] == [a.name + (f" as {a.asname}" if a.asname else "")
                                  for a in node.names])
        if not same:
            edits.append((node, out))
    spans = []
    for node, out in edits:
        first, last = node.lineno - 1, node.end_lineno - 1
        indent = lines[first][:node.col_offset]
        original = [a.name + (f" as {a.asname}" if a.asname else "") for a in node.names]
        text_of = "".join(lines[first:last + 1])
        head = re.match(r"\s*(from\s+\S+|import)\s", text_of)
        if len(out) == 1 and out[0][1] == original and head:
            # only the module changed: keep the statement's layout and comments
            new_head = out[0][0] if out[0][0] != "import" else "import"
            shift = len(new_head) - len(head.group(1).strip())
            body = [indent + new_head + text_of[head.end(1):].split("\n")[0] + "\n"]
            for line in lines[first + 1:last + 1]:
                body.append(" " * max(0, shift) + line if shift >= 0 else
                            line[min(-shift, len(line) - len(line.lstrip(" "))):])
            new_text = "".join(body)
            if out[0][0] == "import":
                new_text = indent + "import " + ", ".join(out[0][1]) + text_of[
                    len(text_of.rstrip("\n")):]
            if all(len(x) <= 100 for x in new_text.splitlines()):
                spans.append((first, last, new_text if text_of.endswith("\n")
                              else new_text.rstrip("\n")))
                continue
        comments = []
        for i in range(first, last + 1):
            seg = lines[i][node.end_col_offset:] if i == last else lines[i]
            if "#" in seg:
                comments.append(seg[seg.index("#"):].strip())
        comment = ("  " + "  ".join(comments)) if comments else ""
        new_text = "".join(_fmt(indent, head, names, comment if k == 0 else "")
                           for k, (head, names) in enumerate(out))
        if not lines[last].endswith("\n"):
            new_text = new_text.rstrip("\n")
        spans.append((first, last, new_text))
    # whole-word mapping of dotted names and package paths outside the import statements
    import_lines = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            import_lines.update(range(node.lineno - 1, node.end_lineno))
    for i, line in enumerate(lines):
        if i not in import_lines:
            lines[i] = map_text(line)
    for first, last, new_text in sorted(spans, reverse=True):
        lines[first:last + 1] = [new_text]
    return "".join(lines)


_DOTTED = re.compile(r"(?<![\w.])pbe_cfd(?:\.\w+)+")
_PATH = re.compile(r"(?<![\w/])pbe_cfd/[\w/]+(?:\.py)?/?")


def map_text(line: str) -> str:
    def dotted(m):
        return map_module(m.group(0))

    def path(m):
        rel = m.group(0)[len("pbe_cfd/"):]
        new = _path_map(rel)
        return m.group(0) if new is None else "pbe_cfd/" + new
    return _PATH.sub(path, _DOTTED.sub(dotted, line))


def _git(*args):
    subprocess.run(["git", "-C", str(ROOT), *args], check=True)


def apply():
    if _applied():
        raise SystemExit("already applied")
    mods = old_modules()
    files = {}
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG).as_posix()
        if rel in REMOVED:
            continue
        files[rel] = _path_map(rel) or rel
    texts = {rel: rewrite((PKG / rel).read_text(), rel, new, mods)
             for rel, new in files.items()}
    outside = [p for d in ("tests", "scripts", "postprocess") for p in (ROOT / d).rglob("*.py")
               if p.resolve() != Path(__file__).resolve()]
    for p in outside:
        p.write_text(rewrite(p.read_text(), None, None, mods))
    for rel in REMOVED:
        _git("rm", "-q", str(PKG / rel))
    for pkg, doc in NEW_PACKAGES.items():
        (PKG / pkg).mkdir(parents=True, exist_ok=True)
    for rel, new in files.items():
        if new != rel:
            (PKG / new).parent.mkdir(parents=True, exist_ok=True)
            _git("mv", str(PKG / rel), str(PKG / new))
    for rel, new in files.items():
        (PKG / new).write_text(texts[rel])
    for pkg, doc in NEW_PACKAGES.items():
        init = PKG / pkg / "__init__.py"
        if not init.exists():
            init.write_text(f'"""{doc}"""\n')
            _git("add", str(init))


def main(argv):
    if argv == ["--apply"]:
        apply()
        return 0
    mods = old_modules()
    if argv[:1] == ["--move"]:
        old, new = (Path(a).resolve().relative_to(PKG).as_posix() for a in argv[1:3])
        text = rewrite((PKG / old).read_text(), old, new, mods)
        (PKG / new).parent.mkdir(parents=True, exist_ok=True)
        _git("mv", str(PKG / old), str(PKG / new))
        (PKG / new).write_text(text)
        return 0
    for a in argv:
        p = Path(a).resolve()
        try:
            rel = p.relative_to(PKG).as_posix()
        except ValueError:
            rel = None
        p.write_text(rewrite(p.read_text(), rel, rel, mods))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
