"""docs/scene-keys.md, the scene-key reference, is generated from the scene's dataclasses
(scripts/scene_keys.py): it is current, it holds every key the bundled scenes use, and the
generator reads whatever dataclasses a scene exposes (a union of per-method option classes
included) with their types, defaults and comments."""
from __future__ import annotations

import importlib.util
import re
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "scene-keys.md"
SCENES = ROOT / "pbe_cfd" / "scenes"


def _generator():
    spec = importlib.util.spec_from_file_location("scene_keys", ROOT / "scripts" / "scene_keys.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("scene_keys", module)       # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def documented_keys(text):
    """table -> keys with a row in the reference (its own Markdown, parsed here)."""
    keys, table = {}, None
    for line in text.splitlines():
        head = re.match(r"## \[([\w.]+)\]", line)
        if head:
            table = head.group(1)
            keys.setdefault(table, set())
            continue
        row = re.match(r"\| `(\w+)` \|", line) or re.match(r'\| `"\w+"` \| `(\w+)` \|', line)
        if row and table:
            keys[table].add(row.group(1))
    return keys


def test_the_reference_is_current():
    assert DOC.read_text() == _generator().render(), (
        "docs/scene-keys.md is stale: run python scripts/scene_keys.py --write")


@pytest.mark.parametrize("scene", sorted(p.name for p in SCENES.glob("*.toml")))
def test_every_key_of_a_bundled_scene_has_a_row(scene):
    documented = documented_keys(DOC.read_text())
    data = tomllib.loads((SCENES / scene).read_text())
    for table, keys in data.items():
        assert table in documented, (scene, table)
        for key, value in keys.items():
            if isinstance(value, dict):           # an inline table: binder_injection.zone
                for inner in value:
                    assert inner in documented.get(f"{table}.{key}", set()), (scene, key, inner)
            else:
                assert key in documented[table], (scene, table, key)


# a scene of the shape method packages give it: the method options a union of dataclasses
@dataclass(frozen=True)
class ToyQuadrature:
    """Options of a toy quadrature: nodes [-]."""
    name: str = "toyq"
    # quadrature nodes per cell
    nodes: int = 2
    rtol: float = 1e-6      # relative tolerance [-]


@dataclass(frozen=True)
class ToyGrid:
    """Options of a toy grid method: cells [-], span [m]."""
    name: str = "toyg"
    cells: int = 40
    span: float = 1e-3
    """the grid's extent"""


@dataclass(frozen=True)
class ToyScene:
    name: str
    end_time: float
    method: ToyQuadrature | ToyGrid | None = None
    source: str = ""


def test_the_generator_reads_any_dataclasses_the_scene_exposes():
    gen = _generator()
    tables = {t.name: t for t in gen.scene_tables(ToyScene)}
    assert [k.name for k in tables["scene"].keys] == ["name", "end_time"]   # source: not a key
    assert [k.default for k in tables["scene"].keys] == ["required", "required"]
    # both members of the union are tables of [method], in order, each with its own keys
    quad = [t for t in gen.scene_tables(ToyScene) if t.cls is ToyQuadrature]
    grid = [t for t in gen.scene_tables(ToyScene) if t.cls is ToyGrid]
    assert len(quad) == 1 and len(grid) == 1
    q = {k.name: k for k in quad[0].keys}
    assert (q["nodes"].type, q["nodes"].default, q["nodes"].text) == (
        "int", "2", "quadrature nodes per cell")
    assert (q["rtol"].default, q["rtol"].text) == ("1e-06", "relative tolerance [-]")
    g = {k.name: k for k in grid[0].keys}
    assert (g["span"].type, g["span"].default, g["span"].text) == (
        "float", "0.001", "the grid's extent")
    assert gen._unit_in(grid[0].doc, "span") == "m"
    text = gen.render(tables=gen.scene_tables(ToyScene), methods=[])
    assert "| `cells` | `int` | 40 |" in text and "| `nodes` | `int` | 2 |" in text
