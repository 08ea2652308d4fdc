"""Writing cell values back into a case as OpenFOAM volScalarFields."""
from __future__ import annotations

import os
import re
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .fields import _n_cells_polymesh
from .install import OpenFOAMError


# --------------------------------------------------------------------------- write back

_CONSTRAINT_TYPES = {"empty", "symmetry", "symmetryPlane", "wedge", "cyclic", "cyclicAMI",
                     "processor"}


def write_foam_fields(case_dir: str | os.PathLike, time_name: str,
                      fields: Mapping[str, np.ndarray],
                      dimensions: Mapping[str, str | tuple] | None = None) -> list[Path]:
    """Write cell values as OpenFOAM volScalarFields into ``case_dir/time_name/``.

    ``fields``: name -> (n_cells,) values in OpenFOAM cell order, SI units. Boundaries are
    zeroGradient (constraint patches such as empty keep their type). ``dimensions``: name ->
    SI exponents "[kg m s K mol A cd]" (e.g. "[0 -3 0 0 0 0 0]" for 1/m3), default
    dimensionless. Plain ASCII. ParaView's OpenFOAM reader lists only numeric time
    directories: use the CFD time (e.g. "1.5", next to alpha and Theta) or the PBE time in s
    (e.g. "600"); other names work but warn. Returns the files.
    """
    from foamlib import FoamFile

    case_dir = Path(case_dir)
    time_name = str(time_name)
    if not time_name or "/" in time_name or time_name in (".", ".."):
        raise ValueError(f"write_foam_fields: bad time directory name {time_name!r}")
    try:
        float(time_name)
    except ValueError:
        warnings.warn(f"write_foam_fields: '{time_name}' is not a number; OpenFOAM tools and "
                      "ParaView's OpenFOAM reader only list numeric time directories "
                      "(e.g. '600' or the CFD time '1.5')", stacklevel=2)
    mesh_dir = case_dir / "constant" / "polyMesh"
    try:
        boundary = FoamFile(mesh_dir / "boundary")[None]
    except FileNotFoundError:
        raise OpenFOAMError(f"{mesh_dir / 'boundary'} not found; run blockMesh first") from None
    n_cells = _n_cells_polymesh(case_dir)
    if n_cells is None:
        n_cells = int(np.asarray(FoamFile(mesh_dir / "owner")[None]).max()) + 1
    out_dir = case_dir / time_name
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, values in fields.items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.:]*", name):
            raise ValueError(f"write_foam_fields: {name!r} is not a valid OpenFOAM field name")
        arr = np.asarray(values, dtype=np.float64).ravel()
        if arr.shape != (n_cells,):
            raise ValueError(f"write_foam_fields: field '{name}' has {arr.size} values, the "
                             f"mesh of {case_dir} has {n_cells} cells")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"write_foam_fields: field '{name}' has non-finite values")
        dim = (dimensions or {}).get(name, "[0 0 0 0 0 0 0]")
        if not isinstance(dim, str):
            dim = "[" + " ".join(str(int(x)) for x in dim) + "]"
        lines = [
            "FoamFile", "{", "    version     2.0;", "    format      ascii;",
            "    class       volScalarField;", f'    location    "{time_name}";',
            f"    object      {name};", "}", "",
            f"dimensions      {dim};", "",
            "internalField   nonuniform List<scalar>", str(n_cells), "(",
        ]
        lines.extend(f"{v:.10g}" for v in arr)
        lines += [")", ";", "", "boundaryField", "{"]
        for pname, pdict in boundary:
            ptype = pdict.get("type", "patch")
            btype = ptype if ptype in _CONSTRAINT_TYPES else "zeroGradient"
            lines += [f"    {pname}", "    {", f"        type            {btype};", "    }"]
        lines += ["}", ""]
        p = out_dir / name
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text("\n".join(lines))
        os.replace(tmp, p)
        written.append(p)
    return written
