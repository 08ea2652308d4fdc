"""No tolerance hidden from the reader: every approximate comparison in tests/ states its
absolute tolerance.

`pytest.approx(x, rel=r)` keeps pytest's default absolute tolerance of 1e-12, and
`np.isclose`/`np.allclose` keep an atol of 1e-8: moment rates in SI units sit far below both,
so such a comparison accepts almost any value (0.0 == approx(1.8e-13, rel=1e-14) is True).
The check reads each test module's syntax tree, so it sees calls however they are spelled
(`pytest.approx`, `approx`, `np.allclose`, `numpy.testing.assert_allclose`, `math.isclose`).
"""
import ast
import pathlib

import pytest

TESTS = pathlib.Path(__file__).parent

# the keyword that states the absolute tolerance, per comparison function
ABSOLUTE_KEYWORD = {"approx": "abs", "isclose": "atol", "allclose": "atol",
                    "assert_allclose": "atol"}


def _callee(call):
    """(module name or None, function name) of a call node."""
    f = call.func
    if isinstance(f, ast.Attribute):
        owner = f.value.id if isinstance(f.value, ast.Name) else None
        return owner, f.attr
    if isinstance(f, ast.Name):
        return None, f.id
    return None, None


def hidden_tolerances(source, filename="<test>"):
    """[(line, text)] of approx/isclose/allclose calls in `source` without an absolute
    tolerance keyword."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if not isinstance(node, ast.Call):
            continue
        owner, name = _callee(node)
        if name not in ABSOLUTE_KEYWORD:
            continue
        keyword = "abs_tol" if (owner, name) == ("math", "isclose") else ABSOLUTE_KEYWORD[name]
        keywords = {k.arg for k in node.keywords}
        if None in keywords:            # **kwargs: cannot be judged, name it
            found.append((node.lineno, ast.unparse(node)))
        elif keyword not in keywords:
            found.append((node.lineno, ast.unparse(node)))
    return found


@pytest.mark.parametrize("snippet, hidden", [
    ("assert x == pytest.approx(y, rel=1e-9)", True),
    ("assert x == approx(y)", True),
    ("assert np.allclose(a, b, rtol=1e-6)", True),
    ("assert numpy.isclose(a, b)", True),
    ("np.testing.assert_allclose(a, b, rtol=1e-3)", True),
    ("assert math.isclose(a, b, rel_tol=1e-9)", True),
    ("assert x == pytest.approx(y, rel=1e-9, abs=0)", False),
    ("assert np.allclose(a, b, rtol=1e-6, atol=1e-20)", False),
    ("assert math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)", False),
    ("assert x == pytest.approx(y, **tol)", True),
])
def test_the_check_recognises_hidden_tolerances(snippet, hidden):
    assert bool(hidden_tolerances(snippet)) is hidden


def test_every_comparison_in_the_suite_states_its_absolute_tolerance():
    offenders = []
    for path in sorted(TESTS.rglob("*.py")):
        for line, text in hidden_tolerances(path.read_text(), str(path)):
            offenders.append(f"{path.relative_to(TESTS)}:{line}: {text[:100]}")
    assert not offenders, ("state abs= (approx) / atol= (isclose, allclose) / abs_tol= "
                           "(math.isclose):\n" + "\n".join(offenders))
