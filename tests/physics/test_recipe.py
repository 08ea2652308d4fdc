"""The recipe of CONTRIBUTING.md, followed literally: a toy kernel, a toy efficiency factor, a
toy breakage selection and a toy daughter rule are added to a copy of the package (numba
functions and one registry entry each, nothing else), and the copy runs them through the
public path (scene -> model.pack -> the numba dispatch, a QMOM run with the breakage) and
through the registry tests, which pick the new entries up by themselves."""
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

KERNEL_FUNCTION = '''
@nb.njit(cache=True, inline="always")
def shear_kernel(props, a, c, cell_factor, params):
    """beta = k0 (d1 + d2)^3 [m3/s]; k0 in 1/s, diameters [m]."""
    s = props[a, DIAMETER] + props[c, DIAMETER]
    return cell_factor * s * s * s


'''
KERNEL_ENTRY = '    Kernel("shear", 5, shear_kernel, "1/s", properties=DIAMETERS),\n'
FACTOR_FUNCTION = '''
@nb.njit(cache=True, inline="always")
def size_ratio_efficiency(props, a, c, u0, params):
    """psi = min(d1, d2) / max(d1, d2) [-]."""
    d1, d2 = props[a, DIAMETER], props[c, DIAMETER]
    return min(d1, d2) / max(d1, d2)


'''
FACTOR_ENTRY = ('    Efficiency("size_ratio", 3, size_ratio_efficiency, properties=DIAMETERS, '
                'uses_binder=False),\n')

SELECTION_FUNCTION = '''
@nb.njit(cache=True, inline="always")
def exponential_selection(p, cell_factor, params):
    """S = g (1 - exp(-p / p_ref)) [1/s]; p, p_ref [kg]."""
    return cell_factor * (1.0 - math.exp(-p / params[P.BREAKAGE_REFERENCE_MASS]))


@nb.njit(cache=True, inline="always")
def parabolic_daughter_moments(k):
    """beta(u) = 12 u (1 - u): F(k) = 12 / ((k + 2)(k + 3))."""
    return 12.0 / ((k + 2.0) * (k + 3.0))


@nb.njit(cache=True, inline="always")
def parabolic_daughter_share(r):
    """Inverse of the Beta(2, 2) distribution function 3 u^2 - 2 u^3 at r."""
    return 0.5 - math.sin(math.asin(1.0 - 2.0 * r) / 3.0)


'''
SELECTION_ENTRY = ('    Selection("exponential", 3, exponential_selection, keys=("reference_mass",), '
                   'formula="S = s0 (1 - exp(-p / p_ref))"),\n')
DAUGHTER_ENTRY = ('    Daughters("parabolic", 2, parabolic_daughter_moments, '
                  'parabolic_daughter_share, formula="beta(u) = 12 u (1 - u)"),\n')

PUBLIC_PATH = textwrap.dedent('''
    import math
    from conftest import make_scene
    from pbe_cfd.runs import model
    from pbe_cfd.physics import parameters as P
    from pbe_cfd.physics.rates import aggregation_rate
    scene = make_scene(aggregation={"kernel": "shear", "rate": 1e-3,
                                    "efficiency": ["size_ratio"]})
    arrays = model.pack(scene)
    assert arrays.config[P.KERNEL] == 5 and arrays.config[P.EFFICIENCY_SWITCHES + 3] == 1
    rho = scene.material.density
    p1, p2 = 1e-9, 3e-9
    d1, d2 = (6 * p1 / (math.pi * rho)) ** (1 / 3), (6 * p2 / (math.pi * rho)) ** (1 / 3)
    expected = 1e-3 * (d1 + d2) ** 3 * d1 / d2
    got = aggregation_rate(p1, 0.0, p2, 0.0, 0.0, 0.0, 0.0, 0.0, arrays.params, arrays.config)
    assert abs(got - expected) <= 1e-14 * expected, (got, expected)
    print("public path ok", got)
    from pbe_cfd.physics.breakage import daughter_moment_factor, selection_rate
    from pbe_cfd.runs.simulate import run_well_mixed
    scene = make_scene(aggregation=None, breakage={"selection": "exponential", "rate": 0.1,
                                                   "reference_mass": 2e-9,
                                                   "daughters": "parabolic"})
    arrays = model.pack(scene)
    s = selection_rate(3e-9, 0.0, 0.0, 0.0, arrays.params, arrays.config)
    assert abs(s - 0.1 * (1 - math.exp(-1.5))) <= 1e-14, s
    assert daughter_moment_factor(arrays.config[P.BREAKAGE_DAUGHTERS], 2.0) == 12.0 / 20.0
    res = run_well_mixed(scene.with_method(nodes=2))
    m0 = res.columns["M00"]
    # monodisperse start at p0 = 1e-9 kg: dM00/dt(0) = S(p0) M00(0) (F(0) - 1 = 1)
    rate0 = 0.1 * (1 - math.exp(-0.5)) * 1e10
    # over the first 1 s the mean rate moves by about S dt = 0.04 (smaller daughters): 2x that
    assert abs((m0[1] - m0[0]) / res.columns["time_s"][1] / rate0 - 1) < 0.08
    print("breakage public path ok", s)
''')


def insert(text, marker, addition, after=False):
    """``addition`` before (or after) the line that starts with ``marker``."""
    i = text.index(marker)
    if after:
        i = text.index("\n", i) + 1
    return text[:i] + addition + text[i:]


@pytest.mark.slow
def test_a_kernel_and_a_factor_added_by_the_recipe_run_everywhere(tmp_path):
    shutil.copytree(ROOT / "pbe_cfd", tmp_path / "pbe_cfd",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "tests", tmp_path / "tests",
                    ignore=shutil.ignore_patterns("__pycache__"))
    kernels = tmp_path / "pbe_cfd" / "physics" / "kernels.py"
    text = insert(kernels.read_text(), "# ---- the registry", KERNEL_FUNCTION)
    kernels.write_text(insert(text, "KERNEL_REGISTRY = (", KERNEL_ENTRY, after=True))
    factors = tmp_path / "pbe_cfd" / "physics" / "efficiency.py"
    text = insert(factors.read_text(), "# ---- the registry", FACTOR_FUNCTION)
    factors.write_text(insert(text, "EFFICIENCY_REGISTRY = (", FACTOR_ENTRY, after=True))
    breakage = tmp_path / "pbe_cfd" / "physics" / "breakage.py"
    text = insert(breakage.read_text(), "# ---- the registries", SELECTION_FUNCTION)
    text = insert(text, "SELECTION_REGISTRY = (", SELECTION_ENTRY, after=True)
    breakage.write_text(insert(text, "DAUGHTER_REGISTRY = (", DAUGHTER_ENTRY, after=True))
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}:{tmp_path / 'tests'}",
               NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    run = subprocess.run([sys.executable, "-c", PUBLIC_PATH], cwd=tmp_path, env=env,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    # the registry tests; not the method dispatch's unknown-code test: it compiles every
    # method's right-hand side (150 s on an empty cache) and no entry the recipe adds, which
    # reach the methods through the pair dispatch the tests here compile and the public path's
    # QMOM run integrates
    unknown_method = ("tests/physics/test_registries.py::"
                      "test_an_unknown_method_code_gives_nan_not_another_methods_numbers")
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p",
                          "no:cacheprovider", "tests/physics/test_registries.py",
                          "tests/physics/test_physics_registry.py", "--deselect",
                          unknown_method],
                         cwd=tmp_path, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:]
    passed = [line for line in run.stdout.splitlines() if line.startswith("PASSED")]
    assert any("[shear]" in line for line in passed)
    assert any("[size_ratio]" in line for line in passed)
    assert any("-exponential]" in line for line in passed)
    assert any("[parabolic]" in line for line in passed)
