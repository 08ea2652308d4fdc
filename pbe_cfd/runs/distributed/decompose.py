"""A decomposed OpenFOAM case: decomposePar, the processor directories, their
cellProcAddressing, and fields written per processor."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .store import ChunkStoreError

# ---------------------------------------------------------------------------- decomposed case
def decomposition_dict(n_subdomains: int) -> str:
    """Text of a decomposeParDict splitting the bed into ``n_subdomains`` vertical slabs side
    by side (method simple, n = (N 1 1); y is vertical in the fluid-bed case), so every
    subdomain holds a share of the dense bed at the bottom."""
    return f"""/*--------------------------------*- C++ -*----------------------------------*\\
  Written by pbe_cfd.runs.distributed.decompose_case: {n_subdomains} vertical slabs side by side.
\\*---------------------------------------------------------------------------*/
FoamFile
{{
    version     2.0;
    format      ascii;
    class       dictionary;
    object      decomposeParDict;
}}

numberOfSubdomains {n_subdomains};

method          simple;

simpleCoeffs
{{
    n               ({n_subdomains} 1 1);
    delta           0.001;
}}
"""


def decompose_case(case_dir, n_subdomains: int = 2, time: float | str | None = None) -> list:
    """Run ``decomposePar -force`` on an OpenFOAM case (mesh, and the CFD time ``time`` [s]
    when given, so the processor directories hold alpha and Theta next to written-back
    fields). Uses ``system/decomposeParDict`` when it has ``numberOfSubdomains`` equal to
    ``n_subdomains``, otherwise writes its own in pbe-cfd's cache (``readable.cache_root``) and
    passes it with -decomposeParDict (its log is kept there too).
    Returns the processor directories. Needs OpenFOAM (``decomposePar``)."""
    import hashlib
    import re
    import subprocess

    from ...io import openfoam as of
    from ...io.openfoam.readable import cache_root

    case = Path(case_dir).resolve()
    install = of.find_openfoam(("decomposePar",))
    args = ["decomposePar", "-force"]
    own = case / "system" / "decomposeParDict"
    # pbe-cfd's own dictionary and log live in its cache, never in the user's case
    work = cache_root() / "decompose" / hashlib.sha256(str(case).encode()).hexdigest()[:24]
    work.mkdir(parents=True, exist_ok=True)
    m = None
    if own.is_file():
        m = re.search(r"^\s*numberOfSubdomains\s+(\d+)\s*;", own.read_text(), flags=re.M)
    if m is None or int(m.group(1)) != int(n_subdomains):
        alt = work / "decomposeParDict"
        alt.write_text(decomposition_dict(int(n_subdomains)))
        args += ["-decomposeParDict", str(alt)]
    if time is not None:
        t = of.pick_time(case, time)
        args += ["-time", of.time_name(case, t)]
    log = work / "log.decomposePar"
    with open(log, "w") as fh:
        r = subprocess.run(args, cwd=case, env=install.env(), stdout=fh,
                           stderr=subprocess.STDOUT)
    text = log.read_text(errors="replace")
    if r.returncode != 0 or "FOAM FATAL" in text:
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        raise of.OpenFOAMError(f"decomposePar failed in {case}: "
                               f"{lines[-1] if lines else r.returncode} (log: {log})",
                               tool="decomposePar")
    return processor_dirs(case)


def processor_dirs(case_dir) -> list:
    """The ``processorN`` directories of a case holding cellProcAddressing, by N."""
    from ...io.openfoam.readable import has_foam_file
    case = Path(case_dir)
    out = []
    for p in case.glob("processor*"):
        suffix = p.name[len("processor"):]
        if suffix.isdigit() and has_foam_file(p / "constant" / "polyMesh" / "cellProcAddressing"):
            out.append((int(suffix), p))
    out.sort()
    if out and [n for n, _ in out] != list(range(len(out))):
        raise ChunkStoreError(case, f"processor directories {[n for n, _ in out]} are not "
                              "0..N-1; rerun decomposePar -force")
    return [p for _, p in out]


def read_decomposition(case_dir, n_cells: int | None = None) -> list:
    """cellProcAddressing of every processor directory (the global OpenFOAM cell of each
    local cell, (n_p,) int64), checked to be a partition of the ``n_cells`` cells."""
    from foamlib import FoamFile

    dirs = processor_dirs(case_dir)
    from ...io.openfoam.readable import foam_path
    out = [np.asarray(FoamFile(foam_path(d / "constant" / "polyMesh" / "cellProcAddressing"))
                      [None], dtype=np.int64).ravel() for d in dirs]
    if out and n_cells is not None:
        allc = np.concatenate(out)
        if allc.size != n_cells or not np.array_equal(np.sort(allc), np.arange(n_cells)):
            raise ChunkStoreError(
                case_dir, f"processor directories hold {allc.size} cells, the case has "
                f"{n_cells}; the decomposition is stale (rerun decomposePar -force)")
    return out


def write_processor_fields(case_dir, decomposition: list, time_name: str,
                           fields: dict, dimensions: dict | None = None,
                           overwrite: bool = False) -> list:
    """Write cell fields (name -> (n_cells,) global values, SI) back per processor: each
    ``processorN/<time_name>/`` gets the values of its local cells (cellProcAddressing order)
    via ``openfoam.write_foam_fields`` (``dimensions``: name -> SI exponents, default
    dimensionless). ``reconstructPar -time <time_name>`` reassembles them. Returns the
    files."""
    from ...io.openfoam import write_foam_fields

    written = []
    for d, addr in zip(processor_dirs(case_dir), decomposition):
        local = {k: np.asarray(v, dtype=float)[addr] for k, v in fields.items()}
        written += write_foam_fields(d, time_name, local, dimensions=dimensions,
                                     overwrite=overwrite)
    return written
