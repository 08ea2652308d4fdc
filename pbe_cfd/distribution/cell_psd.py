"""The per-cell size distribution of a coupled run (``[output] cell_psd``): ``cell_psd.csv``.

One long table (a row per output time, selected cell and diameter), so that any number of
cells and times stay one file a spreadsheet or ``pandas.groupby`` reads: ``time_s`` [s],
``cell`` (the mesh cell id, OpenFOAM's order), ``x_m``, ``y_m``, ``z_m`` (its centre [m]),
``active`` (1: the cell holds granules at that time; 0: alpha < alpha_min in the CFD fields of
that time, a stated empty row: Q3 = q3 = 0), then the columns of ``psd.csv`` on the bed's own
diameter grid (``distribution.tables``: ``d_m`` [m], ``Q3`` [-], ``q3_per_ln_d`` [-],
``binder_fraction`` [-] for bivariate scenes), so that a cell's curve and the bed's compare
point by point. A cell's distribution is the same reconstruction as its d10/d50/d90 cell
fields (``tables.reconstruction_of``).

Selection (``select_cells``): a mesh cell id, or a point [x, y, z] [m] resolved to the cell
whose vertices' bounding box holds it (the nearest centre among several, on a shared face); an
id beyond the mesh, a point in no cell, or a cell that holds no granules when the run starts
(alpha < alpha_min) is a ``SceneError`` naming ``output.cell_psd`` (exit 2). In a two-way run a
cell that empties in a later segment gets the stated empty rows (``active`` = 0) and a note.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import tables
from ..scene.scene import SceneError

KEY = "output.cell_psd"
#: the columns cell_psd.csv adds before psd.csv's
CELL_COLUMNS = ("time_s", "cell", "x_m", "y_m", "z_m", "active")


@dataclass(frozen=True)
class CellSelection:
    """The resolved ``[output] cell_psd``: mesh cell ids (k,) and their centres (k, 3) [m]."""
    cells: np.ndarray
    centres: np.ndarray

    def label(self, j: int) -> str:
        """'cell N at (x, y, z) mm' of selected cell j."""
        x, y, z = np.round(self.centres[j] * 1e3, 6) + 0.0     # no -0 or 1e-15 of round-off
        return f"cell {int(self.cells[j])} at ({x:.4g}, {y:.4g}, {z:.4g}) mm"


def cell_boxes(cells) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) corner [m] of each mesh cell's vertices, shape (n_cells, 3) each."""
    mesh = cells.mesh
    points = np.asarray(mesh.points, dtype=float)
    lows = np.concatenate([points[np.asarray(b.data)].min(axis=1) for b in mesh.cells])
    highs = np.concatenate([points[np.asarray(b.data)].max(axis=1) for b in mesh.cells])
    owner = np.asarray(cells.vtk_cell_id, dtype=int)
    n = cells.n_cells
    lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    np.minimum.at(lo, owner, lows)
    np.maximum.at(hi, owner, highs)
    return lo, hi


def _cell_of_point(point, cells, boxes, source) -> int:
    lo, hi = boxes
    p = np.asarray(point, dtype=float)
    inside = np.flatnonzero(np.all((lo <= p) & (p <= hi), axis=1))
    if inside.size == 0:
        span = ", ".join(f"{a} {lo[:, k].min():.4g} .. {hi[:, k].max():.4g}"
                         for k, a in enumerate("xyz"))
        raise SceneError(source, KEY, f"the point ({p[0]:g}, {p[1]:g}, {p[2]:g}) m lies in no "
                         f"cell of the mesh (it spans {span} m): expected a point inside the "
                         "mesh, or a mesh cell id")
    centre = np.asarray(cells.cell_centre, dtype=float)[inside]
    return int(inside[np.argmin(np.sum((centre - p) ** 2, axis=1))])


def select_cells(entries, cells, active, alpha_min: float, source="<scene>") -> CellSelection:
    """The mesh cells of ``entries`` (``[output] cell_psd``: ids, or points [x, y, z] [m]) on
    ``cells`` (``CellData``) with ``active`` (n_cells,) the cells holding granules (alpha >=
    alpha_min [-]); SceneError naming output.cell_psd for an id beyond the mesh, a point in no
    cell, a cell named twice or a cell without granules."""
    n = cells.n_cells
    centres = np.asarray(cells.cell_centre, dtype=float)
    alpha = np.asarray(cells.alpha, dtype=float)
    boxes = cell_boxes(cells) if any(not isinstance(e, int) for e in entries) else None
    ids = []
    for entry in entries:
        if isinstance(entry, int):
            if entry >= n:
                raise SceneError(source, KEY, f"cell {entry}: the mesh has {n} cells (ids 0 .. "
                                 f"{n - 1}); expected a mesh cell id or a point [x, y, z] in m")
            ids.append(entry)
        else:
            ids.append(_cell_of_point(entry, cells, boxes, source))
    for j, c in enumerate(ids):
        if c in ids[:j]:
            raise SceneError(source, KEY, f"entries {ids.index(c)} and {j} both name cell {c}: "
                             "expected each cell once")
        if not active[c]:
            on = np.flatnonzero(active)
            near = int(on[np.argmin(np.sum((centres[on] - centres[c]) ** 2, axis=1))])
            x, y, z = centres[c]
            raise SceneError(source, KEY, f"cell {c} at ({x:.4g}, {y:.4g}, {z:.4g}) m has alpha "
                             f"= {alpha[c]:.3g} below alpha_min = {alpha_min:g}: it holds no "
                             "granules; expected a cell with alpha >= alpha_min (the nearest "
                             f"is cell {near} at ({', '.join(f'{v:.4g}' for v in centres[near])})"
                             " m)")
    ids = np.asarray(ids, dtype=int)
    return CellSelection(cells=ids, centres=centres[ids])


class _Picked:
    """The selected cells of one output time's reconstruction (rows: the active cells), seen
    as a reconstruction with a row per selected cell; a cell not among the rows (-1) is
    empty (Q3 = 0 everywhere)."""

    def __init__(self, parts, rows):
        self.parts, self.picked = parts, np.asarray(rows, dtype=int)
        self.on = self.picked >= 0
        self.rows = self.picked.size
        self.mass = np.zeros(self.rows)
        self.mass[self.on] = np.asarray(parts.mass, dtype=float)[self.picked[self.on]]
        self.empty = ~(self.mass > 0)
        self.notes = []

    def _spread(self, values, k):
        out = np.zeros((self.rows, k))
        out[self.on] = values[self.picked[self.on]]
        return out

    def cdf(self, d):
        """Q3 [-] of the selected cells at diameters d [m] (k,): (cells, k)."""
        d = np.asarray(d, dtype=float).reshape(-1)
        return self._spread(np.asarray(self.parts.cdf(d), dtype=float), d.size)

    def class_binder(self, d_lo, d_hi):
        """Binder fraction [-] per class [d_lo, d_hi] [m] of the selected cells, or None."""
        y = self.parts.class_binder(d_lo, d_hi)
        return None if y is None else self._spread(np.asarray(y, dtype=float), len(d_lo))


def cell_psd_columns(selection: CellSelection, times, recons, cell_ids, grid):
    """(cell_psd.csv columns, notes): per output time ``times`` [s] the selected cells'
    distributions from ``recons`` (one reconstruction per time, a row per active cell) whose
    rows are the mesh cells ``cell_ids`` (one sorted id array per time) on ``grid`` [m]."""
    parts, notes = [], []
    k = len(selection.cells)
    for t, recon, ids in zip(times, recons, cell_ids):
        ids = np.asarray(ids, dtype=int)
        pos = np.searchsorted(ids, selection.cells)
        pos = np.minimum(pos, ids.size - 1)
        rows = np.where(ids[pos] == selection.cells, pos, -1)
        picked = _Picked(recon, rows)
        cols, grid_notes = tables.psd_columns(np.full(k, float(t)), picked, grid)
        notes.extend(x for x in grid_notes if x not in notes)
        for j in np.flatnonzero(~picked.on):
            notes.append(f"cell_psd.csv: {selection.label(j)} holds no granules at t = "
                         f"{float(t):.6g} s (alpha < alpha_min in that time's CFD fields); its "
                         "rows there are 0 with active = 0")
        m = len(grid)
        lead = {"time_s": cols.pop("time_s"),
                "cell": np.repeat(selection.cells.astype(float), m),
                "x_m": np.repeat(selection.centres[:, 0], m),
                "y_m": np.repeat(selection.centres[:, 1], m),
                "z_m": np.repeat(selection.centres[:, 2], m),
                "active": np.repeat(picked.on.astype(float), m)}
        parts.append({**lead, **cols})
    out = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    return out, notes


def cell_psd_labels(plan, columns) -> dict:
    """name -> meaning of the cell_psd.csv columns (columns.json); ``plan`` the scene's
    ``distribution.tables.DistributionPlan``."""
    texts = {"cell": "mesh cell id (OpenFOAM's cell order) [-]",
             "x_m": "x of the cell's centre [m]", "y_m": "y of the cell's centre [m]",
             "z_m": "z of the cell's centre [m]",
             "active": "1: the cell holds granules at that time; 0: alpha < alpha_min, its Q3 "
                       "and q3 are 0 (a stated empty row)"}
    common = tables.psd_labels(plan, [c for c in columns if c not in texts])
    common["d_m"] = "diameter [m], log-spaced: the bed's psd.csv grid"
    return {c: texts.get(c, common.get(c)) for c in columns}
