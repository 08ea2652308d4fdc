"""The ``[output]`` table: outputs a run writes on request (OpenFOAM domains).

``cell_psd``: the cells whose own size distribution is written (``cell_psd.csv``, one long
table of time, cell, centre, d, Q3, q3; ``png/cell_psd.png``), each a mesh cell id (an integer
>= 0, OpenFOAM's cell order) or a point [x, y, z] in m (the cell holding it). The selection is
checked against the mesh when the run starts (``distribution.cell_psd.select_cells``).
"""
from dataclasses import dataclass

#: most cells a run's ``cell_psd`` may name (ours: the figure's legend stays readable, and a
#: granulation engineer compares a few places of the bed: spray zone, dense bottom, freeboard)
MAX_CELL_PSD = 12


@dataclass(frozen=True)
class Output:
    """Outputs on request (OpenFOAM domains). cell_psd: the cells whose size distribution is
    written to cell_psd.csv and png/cell_psd.png, each a mesh cell id (integer) or a point
    [x, y, z] in m (the mesh cell holding it); at most 12 entries (MAX_CELL_PSD). A point
    outside the mesh or a cell with alpha < alpha_min when the run starts is refused (exit 2);
    in a two-way run a cell that empties later gets rows of 0 with active = 0."""
    # mesh cell ids and/or points [x, y, z] in m, e.g. [412, [0.075, 0.305, 0.0]]
    cell_psd: tuple = ()


def parse_output(path, data, domain, table, vector3, error) -> Output:
    """The [output] table ``data`` of a scene (``domain``: its ``Domain``) as an ``Output``;
    ``table``, ``vector3``, ``error``: the scene reader's ``_Table``, ``_vector3`` and
    ``SceneError``."""
    t = table(path, "output", data)
    entries = t.raw("cell_psd", [])
    key = "output.cell_psd"
    expected = ("expected a list of mesh cell ids (integers >= 0) or points [x, y, z] in m, "
                "e.g. cell_psd = [412, [0.075, 0.05, 0.0]]")
    if not isinstance(entries, list) or not entries:
        raise error(path, key, f"{expected}; got {entries!r}")
    if len(entries) > MAX_CELL_PSD:
        raise error(path, key, f"expected at most {MAX_CELL_PSD} cells, got {len(entries)}")
    if domain.type != "openfoam":
        raise error(path, key, "a per-cell size distribution needs cells: expected "
                    "domain.type = \"openfoam\"")
    cells = []
    for k, entry in enumerate(entries):
        if isinstance(entry, int) and not isinstance(entry, bool):
            if entry < 0:
                raise error(path, key, f"entry {k}: {expected}; got {entry}")
            cells.append(int(entry))
        elif isinstance(entry, list):
            cells.append(vector3(path, f"{key}[{k}]", entry))
        else:
            raise error(path, key, f"entry {k}: {expected}; got {entry!r}")
    if len(set(cells)) != len(cells):
        raise error(path, key, f"expected each entry once, got {entries!r}")
    t.finish()
    return Output(cell_psd=tuple(cells))
