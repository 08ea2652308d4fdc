"""The solids phase's own material in a case: the particle diameter [m] of a constant
diameterModel (``constant/phaseProperties``) and the density [kg/m3] of a rhoConst equation of
state (``constant/thermophysicalProperties.<phase>``)."""
from __future__ import annotations

import warnings
from pathlib import Path

from .readable import foam_path


def _entry(path: Path, keys: tuple[str, ...]):
    """The entry at ``keys`` of an OpenFOAM dictionary file, or None when absent/unreadable
    (foamlib's notes on duplicate keys, which OpenFOAM resolves the same way, are muted)."""
    from foamlib import FoamFile
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            node = FoamFile(foam_path(path))
            for k in keys:
                node = node[k]
            return node
    except Exception:  # noqa: BLE001 - a case without that entry has no value to compare
        return None


def _lookup(path: Path, keys: tuple[str, ...]):
    value = _entry(path, keys)
    try:
        return float(value) if value is not None else None
    except (TypeError, ValueError):
        return None


def case_material(case_dir, phase: str = "particles") -> dict:
    """{"diameter": (value [m] or None, file), "density": (value [kg/m3] or None, file)} of
    the solids phase ``phase`` of the case (None: not a constant value in that file)."""
    case_dir = Path(case_dir)
    pp = case_dir / "constant" / "phaseProperties"
    tp = case_dir / "constant" / f"thermophysicalProperties.{phase}"
    d = None
    if _model(pp, phase) == "constant":
        d = _lookup(pp, (phase, "constantCoeffs", "d"))
    rho = _lookup(tp, ("mixture", "equationOfState", "rho"))
    return {"diameter": (d, pp), "density": (rho, tp)}


def _model(path: Path, phase: str):
    value = _entry(path, (phase, "diameterModel"))
    return None if value is None else str(value)
