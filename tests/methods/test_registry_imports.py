"""A scene imports its own method's package only: the registry loads a method's entry (and so
defines its numba functions) when it is first asked for, and asks every package only where
it must (the whole list, a code no loaded entry owns)."""
import subprocess
import sys

from pbe_cfd.methods import registry

_PROBE = """
import sys
from pbe_cfd.scene.scene import load_scene
from pbe_cfd.methods.registry import method_of
import pbe_cfd.integrate, pbe_cfd.runs.couple, pbe_cfd.runs.simulate
import pbe_cfd.distribution.tables, pbe_cfd.transport.operator
scene = load_scene(sys.argv[1])
method_of(scene)
print(" ".join(sorted({m.split(".")[2] for m in sys.modules
                       if m.startswith("pbe_cfd.methods.") and m.count(".") >= 3})))
"""


def _packages_imported(scene_name):
    out = subprocess.run([sys.executable, "-c", _PROBE, scene_name], capture_output=True,
                         text=True, check=True)
    return set(out.stdout.split())


def test_a_scene_imports_its_own_method_package_and_no_other():
    assert _packages_imported("fluid-bed") == {"qmom", "quadrature"}
    assert _packages_imported("seed-wurster-laguerre") == {"laguerre"}


def test_the_whole_registry_lists_every_package_in_order():
    names = tuple(m.name for m in registry.METHOD_REGISTRY)
    assert names == registry.METHOD_NAMES == registry.PACKAGES
    assert set(registry.MOMENT_METHODS) == {m.name for m in registry.METHOD_REGISTRY
                                            if m.integrated}
    for m in registry.METHOD_REGISTRY:
        if m.integrated:
            assert registry.entry_of_code(m.code) is m
    assert registry.entry_of_code(-12345) is None
