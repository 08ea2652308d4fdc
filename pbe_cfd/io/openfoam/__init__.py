"""OpenFOAM I/O for the fluid-bed case: run it, pick a time, read cell fields, write fields.

I/O only, no physics. All quantities are SI: lengths in m, volumes in m3, times in s,
granular temperature Theta in m2/s2, solids volume fractions dimensionless, face fluxes of
the solids volume (``alphaPhi.particles``) in m3/s.

Cell order is always OpenFOAM's cell order (cell i here is cell i of ``constant/polyMesh``).
foamToVTK writes its internal mesh (``VTK/<case>_<index>/internal.vtu``) with a ``cellID``
cell array (``-with-ids``); where polyhedra were split into several VTK cells, the VTK cells
are mapped back through ``cellID``.

Modules: ``install`` (finding OpenFOAM, ``OpenFOAMError``), ``case`` (copy and run the case,
its written times), ``fields`` (cell fields, volumes, centres), ``flux`` (face flux),
``snapshot`` (compact snapshots, the bundled one), ``write`` (fields written back).
"""
from .case import (RunResult, copy_case, default_case_dir, pick_time, run_case, time_name,
                   written_times)
from .fields import CellData, cell_volumes_and_centres, read_cell_fields
from .flux import FaceFlux, read_face_flux
from .install import (ALPHA_FIELDS, FLUX_FIELDS, THETA_FIELDS, TOOLS, OpenFOAMError,
                      OpenFOAMInstall, bound_to_parent, find_openfoam, have_openfoam)
from .snapshot import (FLUX_NAME, SNAPSHOT_NAME, default_flux_path, default_snapshot_path,
                       load_snapshot, write_snapshot)
from .write import check_foam_fields, write_foam_fields

__all__ = [
    "OpenFOAMError",
    "OpenFOAMInstall",
    "RunResult",
    "CellData",
    "FaceFlux",
    "find_openfoam",
    "have_openfoam",
    "bound_to_parent",
    "default_case_dir",
    "copy_case",
    "run_case",
    "written_times",
    "pick_time",
    "time_name",
    "read_cell_fields",
    "read_face_flux",
    "write_snapshot",
    "load_snapshot",
    "default_snapshot_path",
    "default_flux_path",
    "write_foam_fields",
    "check_foam_fields",
    "cell_volumes_and_centres",
    "TOOLS", "ALPHA_FIELDS", "THETA_FIELDS", "FLUX_FIELDS", "SNAPSHOT_NAME", "FLUX_NAME",
]
