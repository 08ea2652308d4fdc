"""CFD input is checked when it is read: a bad cell of a snapshot (or case) is an exit-2 error
in one line naming the field, the time, the count of bad cells and the first one."""
from __future__ import annotations

import shutil
from pathlib import Path

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pbe_cfd.io import openfoam as of
from pbe_cfd.runs.domain import load_domain
from pbe_cfd.scene.scene import SceneError, load_scene, resolve_scene_path

BUNDLED = of.default_snapshot_path()


def _scene(tmp: Path, case: str, extra: str = "", transport: bool = False) -> Path:
    text = resolve_scene_path("fluid-bed").read_text().replace(
        'case = "bundled:fluid_bed_small"', f'case = "{case}"\n{extra}')
    if transport:
        text += "\n[transport]\ncourant = 0.5\n"
    path = tmp / "s.toml"
    path.write_text(text)
    return path


def _snapshot(tmp: Path, field: str | None = None, cells=(), value=np.nan) -> Path:
    """A copy of the bundled snapshot (and its flux file) with ``field`` set to ``value`` in
    ``cells`` (VTK cell order)."""
    mesh = meshio.read(BUNDLED)
    if field is not None:
        arr = np.array(mesh.cell_data[field][0], dtype=float)
        arr[list(cells)] = value
        mesh.cell_data[field] = [arr]
    out = tmp / "snap.vtu"
    meshio.write(out, mesh)
    shutil.copyfile(BUNDLED.with_name(BUNDLED.stem + "_flux.npz"),
                    tmp / "snap_flux.npz")
    return out


def _refused(scene_path: Path, *phrases, need_flux=False):
    with pytest.raises(SceneError) as err:
        load_domain(load_scene(scene_path), need_flux=need_flux)
    text = str(err.value)
    assert "\n" not in text
    for p in phrases:
        assert p in text, text
    return text


@pytest.mark.parametrize("field,value,phrase", [
    ("alpha", np.nan, "not finite"), ("alpha", -0.1, "outside [0, 1]"),
    ("alpha", 1.5, "outside [0, 1]"), ("alpha", 0.63, "above alpha_max = 0.62"),
    ("Theta", -1e-3, "negative"), ("Theta", np.inf, "not finite"),
    ("cell_volume", 0.0, "not positive"), ("cell_volume", -1e-6, "not positive")])
def test_a_bad_cell_is_named(tmp_path, field, value, phrase):
    """Cells 7 and 30 (VTK order) made bad: the error counts 2 and names the first."""
    snap = _snapshot(tmp_path, field, [7, 30], value)
    order = np.asarray(meshio.read(BUNDLED).cell_data.get("cellID", [np.arange(900)])[0])
    first = int(np.sort(order[[7, 30]])[0])
    name = {"cell_volume": "cell volume"}.get(field, field)
    _refused(_scene(tmp_path, snap.name), name, phrase, "2 cells", f"cell {first}",
             "snap.vtu", "t = 1.5 s")


def test_a_snapshot_read_at_another_time_is_refused(tmp_path):
    snap = _snapshot(tmp_path)
    for t in ("99", "inf"):
        s = _scene(tmp_path, snap.name).read_text().replace('time = "latest"', f"time = {t}")
        (tmp_path / "s.toml").write_text(s)
        if t == "inf":
            with pytest.raises(SceneError, match="domain.time"):
                load_scene(tmp_path / "s.toml")
        else:
            _refused(tmp_path / "s.toml", "99", "t = 1.5 s")


def test_alpha_min_above_every_cell_is_refused(tmp_path):
    s = _scene(tmp_path, "bundled:fluid_bed_small").read_text().replace(
        "alpha_min = 0.05", "alpha_min = 0.9")
    (tmp_path / "s.toml").write_text(s)
    _refused(tmp_path / "s.toml", "alpha_min = 0.9", "max alpha")


def test_unreadable_snapshot_and_flux_are_one_line(tmp_path):
    snap = _snapshot(tmp_path)
    data = snap.read_bytes()
    snap.write_bytes(data[: len(data) // 3])                    # truncated .vtu
    _refused(_scene(tmp_path, snap.name), "cannot read snapshot")
    snap = _snapshot(tmp_path)
    (tmp_path / "snap_flux.npz").write_bytes(b"PK\x03\x04 not a zip")   # corrupt flux
    _refused(_scene(tmp_path, snap.name, transport=True), "cannot read snapshot",
             need_flux=True)


@settings(max_examples=25, deadline=None)
@given(field=st.sampled_from(["alpha", "Theta", "cell_volume"]),
       cells=st.lists(st.integers(0, 899), min_size=1, max_size=5, unique=True),
       value=st.sampled_from([np.nan, np.inf, -np.inf, -1.0, -1e-3, 2.0]),
       truncate=st.sampled_from([None, 0.1, 0.5, 0.9]))
def test_fuzzed_cfd_input_is_one_line_exit_2(tmp_path_factory, field, cells, value, truncate):
    """Random cells made negative, non-finite or out of range, or the file truncated: the
    domain is refused with one line (SceneError: exit 2), never a traceback."""
    if field == "Theta" and value == 2.0:
        value = -2.0                        # Theta has no upper bound
    tmp = tmp_path_factory.mktemp("fuzz")
    snap = _snapshot(tmp, field, cells, value)
    if truncate is not None:
        data = snap.read_bytes()
        snap.write_bytes(data[: int(len(data) * truncate)])
    _refused(_scene(tmp, snap.name))


def test_exit_2_from_the_command_line(tmp_path, capsys, monkeypatch):
    from pbe_cfd.cli import main
    snap = _snapshot(tmp_path, "Theta", [3], -1.0)
    monkeypatch.chdir(tmp_path)
    assert main(["couple", str(_scene(tmp_path, snap.name)), "--out", "o"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Theta" in err[0] and "negative" in err[0]
    assert not (tmp_path / "o").exists()


def test_well_mixed_number_density_beyond_packing_is_refused(scene_factory):
    """1e20 granules of 100 um per m3 fill about 5e7 times the volume: exit 2 naming the
    key, not a run. Just below packing (0.6 of the volume) still runs the check silently."""
    from pbe_cfd.runs.batch import check_physics
    mass = 1000.0 * np.pi / 6 * (100e-6) ** 3          # kg, a 100 um granule of 1000 kg/m3
    with pytest.raises(SceneError, match="initial.number_density.*above alpha_max"):
        check_physics(scene_factory(initial={"number_density": 1e20, "mean_mass": mass}))
    check_physics(scene_factory(initial={"number_density": 0.6 / (mass / 1000.0),
                                         "mean_mass": mass}))


def test_alpha_just_above_packing_is_kept_below_it(tmp_path):
    """A solver's overshoot of alpha_max within 1% (validate.PACKING_OVERSHOOT) is read, and
    build_cells keeps those cells just below alpha_max, counting them."""
    from pbe_cfd.runs.domain import build_cells
    snap = _snapshot(tmp_path, "alpha", [7, 30], 0.62 * 1.005)
    scene = load_scene(_scene(tmp_path, snap.name))
    dom = load_domain(scene)
    _, _, _, notes = build_cells(scene, dom.cells)
    assert notes["cells_capped_below_alpha_max"] == 2
