"""The planted errors of ``scripts/mutate.py`` (``scripts/mutations_list.py``) still apply to the
package: each one's original text occurs exactly once in its file, so the mutation check plants
every error it lists instead of failing on text the code no longer holds, and every test it runs
on a mutant still exists."""
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from mutations_list import MUTATIONS  # noqa: E402


@pytest.mark.parametrize("mutation", MUTATIONS, ids=[m["name"] for m in MUTATIONS])
def test_each_mutation_plants_its_error_once(mutation):
    text = (ROOT / mutation["file"]).read_text()
    assert text.count(mutation["original"]) == 1, (mutation["file"], mutation["original"])
    assert mutation["replacement"] != mutation["original"]


@pytest.mark.parametrize("mutation", MUTATIONS, ids=[m["name"] for m in MUTATIONS])
def test_each_mutation_runs_tests_that_exist(mutation):
    assert mutation["tests"]
    for node in mutation["tests"]:
        path, _, name = node.partition("::")
        source = (ROOT / path).read_text()
        if name:
            function = name.split("[")[0]
            assert re.search(rf"^\s*def {re.escape(function)}\(", source, re.M), node


def test_the_names_are_unique():
    names = [m["name"] for m in MUTATIONS]
    assert len(names) == len(set(names))
