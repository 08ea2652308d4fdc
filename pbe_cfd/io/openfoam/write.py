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
from .readable import foam_path


# --------------------------------------------------------------------------- write back

_CONSTRAINT_TYPES = {"empty", "symmetry", "symmetryPlane", "wedge", "cyclic", "cyclicAMI",
                     "processor"}


def check_foam_fields(case_dir: str | os.PathLike, time_name: str, names,
                      overwrite: bool = False, flag: str = "--foam-fields") -> None:
    """Refuse (``output.OutputRefused``) to write fields ``names`` into ``case_dir/time_name``
    (and every ``processor*/time_name``) where a file of that name exists that pbe-cfd did
    not write (its header lacks the mark), or one it wrote earlier and ``overwrite`` is off."""
    from ..output import OutputRefused, file_is_marked
    case_dir = Path(case_dir)
    dirs = [case_dir / str(time_name)] + sorted(
        p / str(time_name) for p in case_dir.glob("processor*") if p.is_dir())
    foreign, ours = [], []
    for d in dirs:
        for name in names:
            p = d / name
            if p.exists() or p.is_symlink():
                (ours if p.is_file() and file_is_marked(p) else foreign).append(p)
    if foreign:
        raise OutputRefused(f"{flag}: {foreign[0]} exists and was not written by pbe-cfd; "
                            "nothing was changed: move it away yourself to write the fields")
    if ours and not overwrite:
        raise OutputRefused(f"{flag}: {ours[0]} was written by an earlier pbe-cfd run; add "
                            "--overwrite to replace the pbe.* fields of that time")


def write_foam_fields(case_dir: str | os.PathLike, time_name: str,
                      fields: Mapping[str, np.ndarray],
                      dimensions: Mapping[str, str | tuple] | None = None,
                      overwrite: bool = False) -> list[Path]:
    """Write cell values as OpenFOAM volScalarFields into ``case_dir/time_name/``.

    ``fields``: name -> (n_cells,) values in OpenFOAM cell order, SI units. Boundaries are
    zeroGradient (constraint patches such as empty keep their type). ``dimensions``: name ->
    SI exponents "[kg m s K mol A cd]" (e.g. "[0 -3 0 0 0 0 0]" for 1/m3), default
    dimensionless. Plain ASCII. ParaView's OpenFOAM reader lists only numeric time
    directories: use the CFD time (e.g. "1.5", next to alpha and Theta) or the PBE time in s
    (e.g. "600"); other names work but warn. Each file's header says it was written by
    pbe-cfd; a file of the same name that pbe-cfd did not write is never replaced, one it wrote
    only with ``overwrite`` (``check_foam_fields``, ``output.OutputRefused``). Returns the files.
    """
    from foamlib import FoamFile

    from ..output import MARK

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
        boundary = FoamFile(foam_path(mesh_dir / "boundary"))[None]
        n_cells = _n_cells_polymesh(case_dir)
        if n_cells is None:
            n_cells = int(np.asarray(FoamFile(foam_path(mesh_dir / "owner"))[None]).max()) + 1
    except FileNotFoundError as exc:
        raise OpenFOAMError(f"{exc.filename} not found; run blockMesh first") from None
    out_dir = case_dir / time_name
    for name in fields:
        p = out_dir / name
        if p.exists() or p.is_symlink():
            check_foam_fields(case_dir, time_name, [name], overwrite, flag="write_foam_fields")
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
            f"// {name}: {MARK} (population balance moments; any other file of this name",
            "// is never replaced by pbe-cfd)",
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
