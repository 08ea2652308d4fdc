"""OpenFOAM's class method on closed boxes, for ``pbe-cfd bench peer``: a case generator for
reactingTwoPhaseEulerFoam (``populationBalanceTwoPhaseSystem``, ``diameterModel velocityGroup``)
and the moment extraction from its size-group fractions.

The dispersed phase ``air`` carries the population: size group i has the representative volume
x_i [m3] (``formFactor`` pi/6 times d_i^3) and the fraction f_i of the phase, so its number
density is n_i = alpha f_i / x_i [1/m3] and the volume moments are M_k = sum_i n_i x_i^k
[m3^k/m3]. The box is closed (walls only), without gravity, both phases at constant density
and at rest: only the population balance changes the fractions.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: form factor of a sphere: x = pi/6 d^3 [-]
FORM_FACTOR = math.pi / 6.0
#: the solver and the mesher the study runs
SOLVER = "reactingTwoPhaseEulerFoam"
MESHER = "blockMesh"


class PeerUnavailable(RuntimeError):
    """OpenFOAM (its solver, mesher or WM_PROJECT_DIR) is not there."""


class PeerRunError(RuntimeError):
    """An OpenFOAM run failed; the message names the case and the log's last line."""


@dataclass(frozen=True)
class ClassCase:
    """One closed-box class-method problem.

    volumes [m3] the representative volumes x_i (increasing, at least 3), fractions [-] the
    initial f_i (sum 1), alpha [-] the dispersed volume fraction, coalescence_rate [m3/s] the
    ``constant`` model's C (0: none), breakup_power [-] the ``powerLaw`` exponent (None: no
    breakup; S = x^power [1/s], x in m3), dt and end_time [s], cells the number of cells
    along x of the box (each 1 m3)."""
    volumes: tuple
    fractions: tuple
    alpha: float
    coalescence_rate: float
    breakup_power: float | None
    dt: float
    end_time: float
    cells: int = 1


def openfoam_missing() -> str | None:
    """Why OpenFOAM cannot run here (one line), or None if the solver, blockMesh and
    WM_PROJECT_DIR are all present."""
    for tool in (SOLVER, MESHER):
        if shutil.which(tool) is None:
            return f"OpenFOAM is not installed: {tool} is not on PATH"
    wm = os.environ.get("WM_PROJECT_DIR", "")
    if not wm or not Path(wm).is_dir():
        return ("OpenFOAM's WM_PROJECT_DIR is not set to a directory (e.g. "
                "WM_PROJECT_DIR=/usr/share/openfoam)")
    return None


# ============================================================================ dictionaries
def _header(cls, obj, location):
    return ("FoamFile\n{\n    version 2.0;\n    format ascii;\n    class " + cls + ";\n"
            f"    location \"{location}\";\n    object {obj};\n}}\n\n")


def _num(x) -> str:
    return repr(float(x))


def _field(name, cls, dims, value, location="0"):
    kind = "fixedValue" if cls == "volVectorField" else "zeroGradient"
    bc = f"type {kind}; value uniform {value};" if kind == "fixedValue" else f"type {kind};"
    return (_header(cls, name, location) + f"dimensions {dims};\n\ninternalField uniform "
            f"{value};\n\nboundaryField\n{{\n    walls {{ {bc} }}\n}}\n")


def _block_mesh(cells):
    lx = float(cells)
    pts = [(0, 0, 0), (lx, 0, 0), (lx, 1, 0), (0, 1, 0),
           (0, 0, 1), (lx, 0, 1), (lx, 1, 1), (0, 1, 1)]
    vertices = "\n".join(f"    ({a:g} {b:g} {c:g})" for a, b, c in pts)
    return (_header("dictionary", "blockMeshDict", "system") + "convertToMeters 1;\n\n"
            f"vertices\n(\n{vertices}\n);\n\nblocks\n(\n    hex (0 1 2 3 4 5 6 7) "
            f"({cells} 1 1) simpleGrading (1 1 1)\n);\n\nboundary\n(\n    walls\n    {{\n"
            "        type wall;\n        faces\n        (\n            (0 4 7 3) (1 2 6 5)"
            " (0 1 5 4) (3 7 6 2) (0 3 2 1) (4 5 6 7)\n        );\n    }\n);\n")


def _control_dict(case):
    return (_header("dictionary", "controlDict", "system") + f"application {SOLVER};\n"
            "startFrom startTime;\nstartTime 0;\nstopAt endTime;\n"
            f"endTime {_num(case.end_time)};\ndeltaT {_num(case.dt)};\n"
            f"writeControl runTime;\nwriteInterval {_num(case.end_time)};\npurgeWrite 0;\n"
            "writeFormat ascii;\nwritePrecision 15;\nwriteCompression off;\n"
            "timeFormat general;\ntimePrecision 12;\nrunTimeModifiable no;\n"
            "adjustTimeStep no;\n")


def _fv_schemes():
    return (_header("dictionary", "fvSchemes", "system")
            + "ddtSchemes { default Euler; }\ngradSchemes { default Gauss linear; }\n"
            "divSchemes\n{\n    default Gauss upwind;\n"
            "    \"div\\(\\(\\(\\(alpha.*\\*thermo:rho.*\\)\\*nuEff.*\\)\\*dev2\\(T\\(grad\\(U.*"
            "\\)\\)\\)\\)\\)\" Gauss linear;\n}\n"
            "laplacianSchemes { default Gauss linear uncorrected; }\n"
            "interpolationSchemes { default linear; }\nsnGradSchemes { default uncorrected; }\n")


def _fv_solution():
    smooth = "solver smoothSolver; smoother symGaussSeidel; tolerance 1e-10; relTol 0;"
    return (_header("dictionary", "fvSolution", "system") + "solvers\n{\n"
            "    \"alpha.*\" { nAlphaCorr 1; nAlphaSubCycles 1; }\n"
            "    bubbles { nCorr 1; tolerance 1e-12; renormalize false; "
            "solveOnFinalIterOnly true; }\n"
            "    p_rgh { solver PCG; preconditioner DIC; tolerance 1e-10; relTol 0; }\n"
            "    p_rghFinal { $p_rgh; }\n"
            f"    \"U.*\" {{ {smooth} minIter 1; }}\n"
            # the phases' temperatures do not enter (constant densities, no transfer)
            f"    \"(e|h).*\" {{ {smooth} maxIter 1; }}\n"
            "    \"f.*\" { solver PBiCGStab; preconditioner DILU; tolerance 1e-14; relTol 0; }\n"
            "}\n\nPIMPLE\n{\n    nOuterCorrectors 1;\n    nCorrectors 1;\n"
            "    nNonOrthogonalCorrectors 0;\n"
            "    pRefCell 0;\n    pRefValue 1e5;\n}\n\n"
            "relaxationFactors { equations { \".*\" 1; } }\n")


def _thermo(rho, cv, mu, compressibility_R=None):
    """Constant density rho [kg/m3], or a slightly compressible liquid (perfectFluid, rho =
    rho0 + p / (R T)) when compressibility_R [J/(kg K)] is given: the pressure equation of a
    box of several cells needs it (an incompressible closed box has a singular one)."""
    eos = ("rhoConst", f"rho {_num(rho)};") if compressibility_R is None else (
        "perfectFluid", f"R {_num(compressibility_R)}; rho0 {_num(rho)};")
    return (_header("dictionary", "thermophysicalProperties", "constant")
            + "thermoType\n{\n    type heRhoThermo;\n    mixture pureMixture;\n"
            f"    transport const;\n    thermo eConst;\n    equationOfState {eos[0]};\n"
            "    specie specie;\n    energy sensibleInternalEnergy;\n}\n\nmixture\n{\n"
            "    specie { molWeight 28.9; }\n"
            f"    equationOfState {{ {eos[1]} }}\n"
            f"    thermodynamics {{ Cv {_num(cv)}; Hf 0; }}\n"
            f"    transport {{ mu {_num(mu)}; Pr 1; }}\n}}\n")


def _size_groups(case):
    lines = []
    for i, (x, f) in enumerate(zip(case.volumes, case.fractions)):
        d = (float(x) / FORM_FACTOR) ** (1.0 / 3.0)
        lines.append(f"            f{i} {{ d {d!r}; value {_num(f)}; }}")
    return "\n".join(lines)


def _models(case):
    coal = (f"constant {{ rate {_num(case.coalescence_rate)}; }}"
            if case.coalescence_rate > 0 else "")
    brk = (f"powerLaw {{ power {_num(case.breakup_power)}; "
           "daughterSizeDistributionModel uniformBinary; }"
           if case.breakup_power is not None else "")
    return coal, brk


def _phase_properties(case):
    coal, brk = _models(case)
    pair = "(air in water)"
    return (_header("dictionary", "phaseProperties", "constant")
            + "type populationBalanceTwoPhaseSystem;\n\nphases (air water);\n\n"
            "populationBalances (bubbles);\n\nair\n{\n    type purePhaseModel;\n"
            "    diameterModel velocityGroup;\n    velocityGroupCoeffs\n    {\n"
            f"        populationBalance bubbles;\n        formFactor {FORM_FACTOR!r};\n"
            f"        sizeGroups\n        (\n{_size_groups(case)}\n        );\n    }}\n"
            "    residualAlpha 1e-12;\n}\n\n"
            "water\n{\n    type purePhaseModel;\n    diameterModel constant;\n"
            "    constantCoeffs { d 1e-4; }\n    residualAlpha 1e-12;\n}\n\n"
            "populationBalanceCoeffs\n{\n    bubbles\n    {\n        continuousPhase water;\n"
            f"        coalescenceModels ( {coal} );\n        binaryBreakupModels ();\n"
            f"        breakupModels ( {brk} );\n        driftModels ();\n"
            "        nucleationModels ();\n    }\n}\n\n"
            "blending\n{\n    default { type none; continuousPhase water; }\n}\n\n"
            f"surfaceTension ( (air and water) {{ type constant; sigma 0.07; }} );\n"
            f"aspectRatio ( {pair} {{ type constant; E0 1.0; }} );\n"
            f"drag ( {pair} {{ type SchillerNaumann; residualRe 1e-3; "
            "swarmCorrection { type none; } } );\n"
            f"virtualMass ( {pair} {{ type constantCoefficient; Cvm 0.5; }} );\n"
            f"heatTransfer ( {pair} {{ type RanzMarshall; residualAlpha 1e-4; }} );\n"
            "phaseTransfer ();\nlift ();\nwallLubrication ();\nturbulentDispersion ();\n"
            "pMin 10000;\n")


def write_case(case: ClassCase, case_dir) -> Path:
    """Write the dictionaries and initial fields of ``case`` into the new directory
    ``case_dir`` (which must not exist). Returns its path."""
    root = Path(case_dir)
    root.mkdir(parents=True)
    for sub in ("0", "constant", "system"):
        (root / sub).mkdir()
    alpha = float(case.alpha)
    files = {
        "system/blockMeshDict": _block_mesh(case.cells),
        "system/controlDict": _control_dict(case),
        "system/fvSchemes": _fv_schemes(),
        "system/fvSolution": _fv_solution(),
        "constant/g": _header("uniformDimensionedVectorField", "g", "constant")
        + "dimensions [0 1 -2 0 0 0 0];\nvalue (0 0 0);\n",
        "constant/phaseProperties": _phase_properties(case),
        "constant/thermophysicalProperties.air": _thermo(1.0, 718.0, 1.8e-5),
        "constant/thermophysicalProperties.water": _thermo(1000.0, 4195.0, 1e-3, 3000.0),
        "0/alpha.air": _field("alpha.air", "volScalarField", "[0 0 0 0 0 0 0]", _num(alpha)),
        "0/alpha.water": _field("alpha.water", "volScalarField", "[0 0 0 0 0 0 0]",
                                _num(1.0 - alpha)),
        "0/f.air.bubbles": _field("f.air.bubbles", "volScalarField", "[0 0 0 0 0 0 0]", "0"),
        "0/p": _field("p", "volScalarField", "[1 -1 -2 0 0 0 0]", "1e5"),
        "0/p_rgh": _field("p_rgh", "volScalarField", "[1 -1 -2 0 0 0 0]", "1e5"),
        "0/T.air": _field("T.air", "volScalarField", "[0 0 0 1 0 0 0]", "300"),
        "0/T.water": _field("T.water", "volScalarField", "[0 0 0 1 0 0 0]", "300"),
        "0/U.air": _field("U.air", "volVectorField", "[0 1 -1 0 0 0 0]", "(0 0 0)"),
        "0/U.water": _field("U.water", "volVectorField", "[0 1 -1 0 0 0 0]", "(0 0 0)"),
    }
    for phase in ("air", "water"):
        files[f"constant/turbulenceProperties.{phase}"] = (
            _header("dictionary", f"turbulenceProperties.{phase}", "constant")
            + "simulationType laminar;\n")
    for rel, text in files.items():
        (root / rel).write_text(text)
    return root


# ============================================================================ running
def _run(tool, case_dir, log_name):
    log = Path(case_dir) / log_name
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.run([tool, "-case", str(case_dir)], stdout=fh,
                              stderr=subprocess.STDOUT, env=dict(os.environ))
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
        fatal = [i for i, ln in enumerate(lines) if "FOAM FATAL" in ln]
        last = (lines[fatal[-1] + 1] if fatal and fatal[-1] + 1 < len(lines)
                else (lines[-1] if lines else "no output"))
        raise PeerRunError(f"{tool} failed on {case_dir} (exit {proc.returncode}): "
                           f"{last[:200]} (log: {log})")
    return wall


def run_case(case: ClassCase, case_dir) -> dict:
    """Write ``case`` into ``case_dir``, mesh it and run the solver. Returns {"solver_s":
    wall time of the solver [s], "mesh_s": of blockMesh [s], "steps": time steps,
    "case_dir": path}. Raises PeerUnavailable or PeerRunError."""
    why = openfoam_missing()
    if why:
        raise PeerUnavailable(why)
    root = write_case(case, case_dir)
    mesh_s = _run(MESHER, root, "log.blockMesh")
    solver_s = _run(SOLVER, root, "log.solver")
    return {"solver_s": solver_s, "mesh_s": mesh_s,
            "steps": int(round(case.end_time / case.dt)), "case_dir": str(root)}


# ============================================================================ fields -> moments
_UNIFORM = re.compile(r"internalField\s+uniform\s+([-+0-9.eE]+)\s*;")
_NONUNIFORM = re.compile(r"internalField\s+nonuniform\s+List<scalar>\s*(\d+)\s*\(([^)]*)\)")


def read_internal_field(path, cells: int) -> np.ndarray:
    """Cell values of an ASCII volScalarField file (uniform or nonuniform List<scalar>)."""
    text = Path(path).read_text()
    m = _UNIFORM.search(text)
    if m:
        return np.full(cells, float(m.group(1)))
    m = _NONUNIFORM.search(text)
    if m:
        vals = np.array(m.group(2).split(), dtype=float)
        if vals.size != int(m.group(1)) or vals.size != cells:
            raise ValueError(f"{path}: internalField has {vals.size} values, expected {cells}")
        return vals
    raise ValueError(f"{path}: no ASCII internalField (uniform or nonuniform List<scalar>)")


def latest_time_dir(case_dir) -> Path:
    """The written time directory with the largest time (not 0)."""
    best = None
    for p in Path(case_dir).iterdir():
        try:
            t = float(p.name)
        except ValueError:
            continue
        if p.is_dir() and t > 0 and (best is None or t > best[0]):
            best = (t, p)
    if best is None:
        raise ValueError(f"{case_dir}: no time directory after 0 was written")
    return best[1]


def group_number_densities(alpha, fractions, volumes) -> np.ndarray:
    """n_i = alpha f_i / x_i [1/m3] of each size group (alpha, f_i [-]; x_i [m3]); the
    arrays broadcast (cells x groups)."""
    return np.asarray(alpha, dtype=float)[..., None] * np.asarray(fractions, dtype=float) \
        / np.asarray(volumes, dtype=float)


def volume_moments(numbers, volumes, orders=(0, 1, 2)) -> dict:
    """{"M<k>": sum_i n_i x_i^k} [m3^k/m3] over the last axis (n_i [1/m3], x_i [m3])."""
    x = np.asarray(volumes, dtype=float)
    return {f"M{k}": np.asarray(numbers, dtype=float) @ (x ** k) for k in orders}


def read_class_moments(case: ClassCase, case_dir, orders=(0, 1, 2)) -> dict:
    """Volume moments [m3^k/m3] per cell at the latest written time, and the sum of the
    fractions and alpha there ("sum_f", "alpha")."""
    tdir = latest_time_dir(case_dir)
    alpha = read_internal_field(tdir / "alpha.air", case.cells)
    f = np.stack([read_internal_field(tdir / f"f{i}.air.bubbles", case.cells)
                  for i in range(len(case.volumes))], axis=-1)
    out = volume_moments(group_number_densities(alpha, f, case.volumes), case.volumes, orders)
    out["sum_f"] = f.sum(axis=-1)
    out["alpha"] = alpha
    out["time_s"] = float(tdir.name)
    return out
