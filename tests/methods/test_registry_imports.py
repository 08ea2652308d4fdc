"""A scene imports its own method's package and no other method's: the registry loads a
method's entry (and so defines its numba functions) when it is first asked for, and asks every
package only where it must (the whole list, a code no loaded entry owns). ``quadrature`` is not
a method but the helpers methods share (Gauss rules, the sources on quadrature points, the
free droplets' class, which the Laguerre ROM uses too)."""
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
entry = method_of(scene)
if len(sys.argv) > 2:          # what the integration kernel asks: the entry of the scene's code
    from pbe_cfd.integrate.kernel_types import functions_of
    assert functions_of(entry.code).rhs is entry.rhs
print(" ".join(sorted({m.split(".")[2] for m in sys.modules
                       if m.startswith("pbe_cfd.methods.") and m.count(".") >= 3})))
"""


def _packages_imported(scene_name, *more):
    out = subprocess.run([sys.executable, "-c", _PROBE, scene_name, *more], capture_output=True,
                         text=True, check=True)
    return set(out.stdout.split())


def test_a_scene_imports_its_own_method_package_and_no_other():
    assert _packages_imported("fluid-bed") == {"qmom", "quadrature"}
    assert _packages_imported("seed-wurster-laguerre") == {"laguerre", "quadrature"}


def test_the_entry_of_a_loaded_methods_code_imports_no_other_package():
    """The integration kernel looks its method's functions up by code at every run
    (``kernel_types.functions_of``): a loaded entry owns it, so no other package is imported
    (importing them all cost 0.18 s of every run's setup)."""
    assert _packages_imported("fluid-bed", "code") == {"qmom", "quadrature"}
    assert _packages_imported("seed-wurster-laguerre", "code") == {"laguerre", "quadrature"}


def test_the_whole_registry_lists_every_package_in_order():
    names = tuple(m.name for m in registry.METHOD_REGISTRY)
    assert names == registry.METHOD_NAMES == registry.PACKAGES
    assert set(registry.MOMENT_METHODS) == {m.name for m in registry.METHOD_REGISTRY
                                            if m.integrated}
    for m in registry.METHOD_REGISTRY:
        if m.integrated:
            assert registry.entry_of_code(m.code) is m
    assert registry.entry_of_code(-12345) is None


_DRAW_PROBE = """
import sys
import numpy as np
from pbe_cfd.distribution.kernel_mixture import of_nodes
w = np.array([1.0e9, 2.0e9, 5.0e8])                     # 1/m3
p = np.array([1.0e-9, 3.0e-9, 8.0e-9])                  # kg
mix = of_nodes([(w, p, 0.1 * p)], 1500.0, False)
print(int((mix.w[0] > 0).sum()), "pbe_cfd.methods.eqmom" in sys.modules)
"""


def test_a_quadrature_distribution_is_drawn_without_the_eqmom_package():
    """QMOM's and CQMOM's size distribution (gamma kernels fitted to the nodes' moments by the
    shared inversion in methods.quadrature) needs no EQMOM module."""
    out = subprocess.run([sys.executable, "-c", _DRAW_PROBE], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out[0] == "2"                           # n - 1 = 2 kernels fitted to 3 nodes
    assert out[1] == "False"
