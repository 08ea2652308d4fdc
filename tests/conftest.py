"""Shared helpers: scenes built from dicts, so each test states the physics it runs."""
import copy
import sys
from pathlib import Path

import pytest
from hypothesis import settings

from pbe_cfd.scene.scene import scene_from_dict

# tests/ mirrors the package's folders (scripts/test_layout.py); a module anywhere under it
# imports the shared helpers (conftest, error_bounds, references) and another module's
# fixtures (test_data_safety, test_breakage, ...) by name: tests/ and its folders are on sys.path
_TESTS = Path(__file__).resolve().parent
for _folder in [_TESTS, *sorted(p for p in _TESTS.rglob("*") if p.is_dir()
                                and p.name not in ("__pycache__", "references"))]:
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

# property tests draw a fixed sequence of examples (chosen before looking, the same on every
# run): a red test is a property that fails, never a draw that happened to be unlucky
settings.register_profile("fixed", derandomize=True, print_blob=True)
settings.load_profile("fixed")

BASE = {
    "scene": {"name": "test", "end_time": 10.0, "output_interval": 1.0},
    "domain": {"type": "well-mixed"},
    "material": {"density": 1000.0, "binder_density": 1000.0},
    "initial": {"distribution": "monodisperse", "number_density": 1.0e10,
                "mean_mass": 1.0e-9},
    "method": {"name": "qmom", "nodes": 3},
}

AVICEL = {
    "density": 1021.0, "binder_density": 1000.0, "binder_viscosity": 0.762,
    "accessible_binder_slope": 35.1, "accessible_binder_centre": 0.129,
    "binder_layer_slope": 25.9, "binder_layer_centre": 0.327,
    "asperity": 6.3e-6, "gyration_radius": 60e-6,
    "porosity": 0.4, "saturation_max": 1.0,
}


def make_scene(**tables):
    """A scene from BASE with tables replaced or extended (key=None removes a table)."""
    data = copy.deepcopy(BASE)
    for name, value in tables.items():
        if value is None:
            data.pop(name, None)
        elif name in data and isinstance(value, dict) and not value.get("_replace"):
            data[name] = {**data[name], **value}
        else:
            data[name] = {k: v for k, v in value.items() if k != "_replace"}
    return scene_from_dict(data, "test-scene.toml")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """A study (minutes to tens of minutes) is also slow: the fast tier's
    ``-m "not slow and not openfoam"`` replaces the default ``-m "not study"`` (pyproject.toml),
    so a study marked ``study`` alone would run in it. Runs before the marker selection; puts
    the files with slow or OpenFOAM tests first."""
    for item in items:
        if item.get_closest_marker("study") and not item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.slow)
    # the files holding a slow or an OpenFOAM test first, each file's tests in their order: the
    # workers (--dist loadfile, one file per worker) start on the long files, and the run does
    # not end on one worker finishing a long file while the other waits
    long_files = {item.path for item in items
                  if item.get_closest_marker("slow") or item.get_closest_marker("openfoam")}
    items.sort(key=lambda item: item.path not in long_files)


@pytest.fixture
def scene_factory():
    return make_scene


@pytest.fixture(autouse=True, scope="session")
def _pbe_cfd_cache(tmp_path_factory):
    """pbe-cfd's cache (readable case copies, ``readable.cache_root``; the Laguerre ROM's tables,
    ``methods.laguerre.build.default_cache_dir``) in a temporary directory of the session, never
    the user's ~/.cache; one for all of the session's xdist workers (both caches write a new
    entry beside its place and rename it in, so two workers building one entry both end with
    it), so a table or a case copy is built once per session."""
    import os
    base = tmp_path_factory.getbasetemp()
    path = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "pbe-cfd-cache"
    path.mkdir(exist_ok=True)
    old = os.environ.get("PBE_CFD_CACHE")
    os.environ["PBE_CFD_CACHE"] = str(path)
    yield path
    if old is None:
        os.environ.pop("PBE_CFD_CACHE", None)
    else:
        os.environ["PBE_CFD_CACHE"] = old
