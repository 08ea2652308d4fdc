"""Code outside a method's package never compares or looks up the method's name: it asks the
method's registry entry. Measured over the syntax tree of pbe_cfd/ (string constants equal to a
registered method's name), so docstrings and messages that mention a method do not count."""
import ast
from collections import Counter
from pathlib import Path

from pbe_cfd.methods.registry import METHOD_REGISTRY

PACKAGE = Path(__file__).resolve().parent.parent / "pbe_cfd"

#: files outside the method packages that still name methods, and how often. This list only
#: shrinks; it is empty: a method's name appears outside its package only in its registration.
PENDING: dict = {}
#: the registry lists the method packages by name (each imported when its entry is first used)
REGISTRY = "methods/registry.py"


def name_literals(root=PACKAGE, names=None):
    """file (relative to the package) -> count of string constants equal to a method's name
    outside that method's own package (``methods/<name>/``)."""
    names = names or {m.name for m in METHOD_REGISTRY}
    found = Counter()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                    and node.value in names and not rel.startswith(f"methods/{node.value}/")
                    and rel != REGISTRY):
                found[rel] += 1
    return found


def test_no_method_name_is_compared_outside_its_package():
    found = name_literals()
    over = {f: n for f, n in found.items() if n > PENDING.get(f, 0)}
    assert over == {}


def test_the_measure_sees_a_name_in_code_and_not_in_text(tmp_path):
    pkg = tmp_path / "pbe_cfd"
    (pkg / "methods" / "qmom").mkdir(parents=True)
    (pkg / "methods" / "qmom" / "entry.py").write_text('NAME = "qmom"\n')
    (pkg / "runs.py").write_text('"""Runs qmom."""\nif name == "qmom":\n    print("qmom run")\n')
    assert name_literals(pkg, {"qmom"}) == Counter({"runs.py": 1})
