"""Where a test module lives: tests/ mirrors the package's folders.

The rule is the table RULES: the first row whose prefix starts the module's file name gives
its folder under tests/ ("" = tests/ root, for the checks over the whole package and the
tests of the shared test helpers). A name no row matches belongs at the root until a row is
added for it.

    python scripts/test_layout.py            # list root-level modules the rule places elsewhere
    python scripts/test_layout.py --apply    # git mv each of them into its folder

tests/test_layout.py fails when a module sits at tests/ root although the table places it in
a folder, and when a module sits in a folder other than its row's.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"

# (file-name prefix, folder under tests/); first match wins, so longer prefixes come first
RULES = (
    # whole-package checks and the tests of the shared helpers stay at tests/ root
    ("test_layers", ""),
    ("test_layout", ""),
    ("test_tolerances", ""),
    ("test_method_names", ""),
    ("test_error_bounds", ""),
    ("test_install", ""),
    ("test_mutation_list", ""),
    # physics: kernels, factors, breakage functions, registries and their recipe
    ("test_physics_", "physics"),
    ("test_breakage_hand_values", "physics"),
    ("test_kernel_", "physics"),
    ("test_registries", "physics"),
    ("test_recipe", "physics"),
    ("test_stokes_", "physics"),
    ("test_drying", "physics"),
    # methods: one folder per method, shared method checks beside them
    ("test_qmom", "methods/qmom"),
    ("test_cqmom", "methods/cqmom"),
    ("test_eqmom", "methods/eqmom"),
    ("test_laguerre", "methods/laguerre"),
    ("test_cnmc", "methods/cnmc"),
    ("test_registry_imports", "methods"),
    ("test_toy_method", "methods"),
    ("test_breakage", "methods"),
    ("test_hard_cases", "methods"),
    ("test_method", "methods"),
    ("test_spray", "methods"),
    # the per-cell integrators
    ("test_integrat", "integrate"),
    # scene: TOML -> dataclasses, limits, the key reference
    ("test_scene", "scene"),
    ("test_resource_limits", "scene"),
    # runs: model, domain, coupling, plan, executors
    ("test_couple", "runs"),
    ("test_air", "runs"),
    ("test_batch", "runs"),
    ("test_coupling", "runs"),
    ("test_run_", "runs"),
    ("test_plan", "runs"),
    ("test_distributed", "runs"),
    ("test_decompose", "runs"),
    ("test_pack", "runs"),
    ("test_model", "runs"),
    # transport
    ("test_transport", "transport"),
    ("test_halo", "transport"),
    ("test_substeps", "transport"),
    # io: output guard, manifest, OpenFOAM case I/O, user cases
    ("test_openfoam", "io"),
    ("test_bed3d", "io"),
    ("test_spool", "io"),
    ("test_output", "io"),
    ("test_data_safety", "io"),
    ("test_cfd_input", "io"),
    ("test_faults", "io"),
    ("test_own_case", "io"),
    ("test_paraview", "io"),
    # viz: pictures and their drawing processes
    ("test_pictures", "viz"),
    ("test_moisture", "viz"),
    ("test_render", "viz"),
    ("test_vtk", "viz"),
    ("test_drawing", "viz"),
    # size distributions
    ("test_distribution", "distribution"),
    ("test_reference_particles", "distribution"),
    ("test_psd_against_particles", "distribution"),
    ("test_support_fit", "distribution"),
    # studies and their result documents
    ("test_bench", "bench"),
    ("test_peer", "bench"),
    ("test_results", "bench"),
    # the command line
    ("test_cli", "cli"),
)


def folder_of(name: str) -> str | None:
    """Folder under tests/ (posix, "" = root) that the rule gives the module file `name`, None
    when no row names its prefix (a new kind of test needs a row)."""
    for prefix, folder in RULES:
        if name.startswith(prefix):
            return folder
    return None


def test_modules(tests: Path = TESTS):
    """Every test module under `tests` (test_*.py), as paths relative to it."""
    return sorted(p.relative_to(tests) for p in tests.rglob("test_*.py")
                  if "__pycache__" not in p.parts)


def misplaced(tests: Path = TESTS):
    """[(module path relative to tests/, folder the rule gives it)] for every module that
    sits elsewhere than its row says."""
    out = []
    for rel in test_modules(tests):
        want = folder_of(rel.name)
        if want is None or rel.parent.as_posix() != (want or "."):
            out.append((rel, want))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--apply", action="store_true",
                    help="git mv each root-level module the rule places in a folder")
    args = ap.parse_args(argv)
    moves = [(rel, want) for rel, want in misplaced() if len(rel.parts) == 1 and want]
    others = [(rel, want) for rel, want in misplaced() if len(rel.parts) > 1 and want is not None]
    unknown = [rel for rel, want in misplaced() if want is None]
    for rel in unknown:
        print(f"tests/{rel}: no row of RULES names its prefix (add one)", file=sys.stderr)
    for rel, want in moves:
        dest = Path("tests") / want / rel.name
        print(f"tests/{rel} -> {dest.as_posix()}")
        if args.apply:
            (ROOT / dest).parent.mkdir(parents=True, exist_ok=True)
            subprocess.run(["git", "mv", f"tests/{rel}", dest.as_posix()], cwd=ROOT,
                           check=True)
    for rel, want in others:
        print(f"tests/{rel}: the table places it in tests/{want or '.'} (move it by hand)",
              file=sys.stderr)
    if moves and not args.apply:
        print("run with --apply to move them", file=sys.stderr)
    return 1 if unknown or others or (moves and not args.apply) else 0


if __name__ == "__main__":
    sys.exit(main())
