"""VTK time series of cell fields: one ``.vtu`` per output time plus a ``.pvd`` collection.

Readable by meshio, pyvista and ParaView. Field values are SI and named by their unit where it
is not obvious (``M00`` per m3, ``d43_m``, ``Theta`` in m2/s2, ...). Each ``.vtu`` carries its
time as FieldData: ``TimeValue`` (the process time [s], which ParaView reads as the file's
time) and, where the mesh came from a CFD case, ``CFDTime`` (the time [s] of the CFD fields).
The ``.pvd`` is rewritten atomically after every step, so a run that stops early still leaves a
valid series. meshio reads each ``.vtu`` but has no ``.pvd`` reader: ``read_series`` gives the
(time, meshio.Mesh) pairs of a collection.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import meshio
import numpy as np

__all__ = ["VtkSeries", "read_pvd", "read_series", "time_values"]


def _mesh_parts(mesh_like) -> tuple[np.ndarray, list[tuple[str, np.ndarray]], np.ndarray]:
    """points (m), cell blocks, and the OpenFOAM cell of each VTK cell."""
    # CellData (duck-typed to avoid an import cycle)
    if hasattr(mesh_like, "mesh") and hasattr(mesh_like, "vtk_cell_id"):
        m = mesh_like.mesh
        ids = np.asarray(mesh_like.vtk_cell_id, dtype=np.int64)
    elif isinstance(mesh_like, meshio.Mesh):
        m = mesh_like
        ids = None
        if "cellID" in m.cell_data:
            ids = np.concatenate([np.asarray(a) for a in m.cell_data["cellID"]]).astype(np.int64)
    elif isinstance(mesh_like, (str, os.PathLike)):
        return _mesh_parts(meshio.read(mesh_like))
    else:
        raise TypeError("VtkSeries: mesh_like must be a CellData, a meshio.Mesh or a path to "
                        f"a mesh file, got {type(mesh_like).__name__}")
    cells = [(b.type, np.asarray(b.data)) for b in m.cells]
    n_vtk = sum(len(c) for _, c in cells)
    if ids is None:
        ids = np.arange(n_vtk)
    if len(ids) != n_vtk:
        raise ValueError(f"VtkSeries: {len(ids)} cell ids for {n_vtk} VTK cells")
    return np.asarray(m.points, dtype=np.float64), cells, ids


class VtkSeries:
    """Write cell fields over time as ``<out_dir>/<name>_<k>.vtu`` + ``<out_dir>/<name>.pvd``.

    ``mesh_like``: a CellData (pbe_cfd.io.openfoam), a meshio.Mesh, or a mesh file path.
    ``write(time_s, fields)`` takes a dict of (n_cells,) float arrays in OpenFOAM cell order
    (or (n_cells, 3) vectors), SI units; every step must carry finite values. Use as a context
    manager or call ``close()``; the .pvd is valid after every ``write``.
    """

    def __init__(self, out_dir: str | os.PathLike, mesh_like, name: str = "fields",
                 static_fields: Mapping[str, np.ndarray] | None = None):
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.name = name
        self.points, self.cells, self.cell_id = _mesh_parts(mesh_like)
        self.n_cells = int(self.cell_id.max()) + 1 if len(self.cell_id) else 0
        self.static_fields = dict(static_fields or {})
        cfd_time = float(getattr(mesh_like, "time", np.nan))   # CellData: the CFD time [s]
        self.cfd_time_s = cfd_time if np.isfinite(cfd_time) else None
        self.entries: list[tuple[float, str]] = []
        self.closed = False

    @property
    def pvd_path(self) -> Path:
        """The collection file."""
        return self.out_dir / f"{self.name}.pvd"

    def _check(self, key: str, values) -> np.ndarray:
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape[0] != self.n_cells or arr.ndim > 2:
            raise ValueError(f"VtkSeries: field '{key}' has shape {arr.shape}, expected "
                             f"({self.n_cells},) or ({self.n_cells}, k)")
        if not np.all(np.isfinite(arr)):
            bad = int(np.count_nonzero(~np.isfinite(arr)))
            raise ValueError(f"VtkSeries: field '{key}' has {bad} non-finite values")
        return arr[self.cell_id]

    def write(self, time_s: float, fields: Mapping[str, np.ndarray]) -> Path:
        """Write one output time (s); returns the .vtu path and rewrites the .pvd."""
        if self.closed:
            raise RuntimeError("VtkSeries: write after close")
        time_s = float(time_s)
        if not np.isfinite(time_s):
            raise ValueError(f"VtkSeries: time must be finite, got {time_s}")
        if self.entries and time_s <= self.entries[-1][0]:
            raise ValueError(f"VtkSeries: times must increase ({time_s} s after "
                             f"{self.entries[-1][0]} s)")
        data = {k: self._check(k, v) for k, v in {**self.static_fields, **fields}.items()}
        # split the cell arrays over meshio's cell blocks
        offsets = np.cumsum([0] + [len(c) for _, c in self.cells])
        cell_data = {k: [v[offsets[i]:offsets[i + 1]] for i in range(len(self.cells))]
                     for k, v in data.items()}
        mesh = meshio.Mesh(self.points, self.cells, cell_data=cell_data)
        fname = f"{self.name}_{len(self.entries):05d}.vtu"
        path = self.out_dir / fname
        tmp = path.with_name(path.name + ".tmp")
        meshio.write(tmp, mesh, file_format="vtu", compression="zlib")
        times = {"TimeValue": time_s}
        if self.cfd_time_s is not None:
            times["CFDTime"] = self.cfd_time_s
        _insert_field_data(tmp, times)
        os.replace(tmp, path)
        self.entries.append((time_s, fname))
        self._write_pvd()
        return path

    def _write_pvd(self) -> None:
        root = ET.Element("VTKFile", type="Collection", version="0.1",
                          byte_order="LittleEndian")
        coll = ET.SubElement(root, "Collection")
        for t, fname in self.entries:
            ET.SubElement(coll, "DataSet", timestep=repr(t), group="", part="0", file=fname)
        ET.indent(root)
        tmp = self.pvd_path.with_name(self.pvd_path.name + ".tmp")
        ET.ElementTree(root).write(tmp, xml_declaration=True, encoding="utf-8")
        os.replace(tmp, self.pvd_path)

    def close(self) -> Path:
        """Finish the series (the .pvd is already complete); returns the .pvd path."""
        if not self.closed:
            self._write_pvd()
            self.closed = True
        return self.pvd_path

    def __enter__(self) -> "VtkSeries":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _insert_field_data(path: Path, values: Mapping[str, float]) -> None:
    """Put one-value FieldData arrays into a .vtu meshio wrote (its writer leaves them out)."""
    arrays = "".join(f'<DataArray type="Float64" Name="{k}" NumberOfTuples="1" '
                     f'format="ascii">\n{float(v)!r}\n</DataArray>\n' for k, v in values.items())
    text = path.read_bytes()
    head = b"<UnstructuredGrid>\n"
    at = text.index(head) + len(head)
    path.write_bytes(text[:at] + f"<FieldData>\n{arrays}</FieldData>\n".encode() + text[at:])


#: FieldData of a .vtu written by VtkSeries: name="..." then the value, at the file's head
_FIELD_VALUE = re.compile(rb'<DataArray type="Float64" Name="(\w+)" NumberOfTuples="1" '
                          rb'format="ascii">\s*([^<\s]+)\s*</DataArray>')


def time_values(vtu_path: str | os.PathLike) -> dict[str, float]:
    """The FieldData times of a .vtu VtkSeries wrote: {"TimeValue": process time [s],
    "CFDTime": CFD field time [s] (where known)}; {} for a file without them."""
    with open(vtu_path, "rb") as fh:
        head = fh.read(4096)
    end = head.find(b"</FieldData>")
    return ({k.decode(): float(v) for k, v in _FIELD_VALUE.findall(head[:end])}
            if end >= 0 else {})


def read_series(pvd_path: str | os.PathLike) -> list[tuple[float, meshio.Mesh]]:
    """Every time of a .pvd collection read with meshio: [(time [s], meshio.Mesh)], in file
    order (meshio itself reads the .vtu files, not the .pvd)."""
    return [(t, meshio.read(p)) for t, p in read_pvd(pvd_path)]


def read_pvd(pvd_path: str | os.PathLike) -> list[tuple[float, Path]]:
    """The (time in s, .vtu path) entries of a .pvd collection, in file order."""
    pvd_path = Path(pvd_path)
    try:
        root = ET.parse(pvd_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ValueError(f"cannot read VTK collection {pvd_path}: {exc}") from None
    out = []
    for ds in root.iter("DataSet"):
        try:
            out.append((float(ds.get("timestep")), pvd_path.parent / ds.get("file")))
        except (TypeError, ValueError):
            raise ValueError(f"{pvd_path}: DataSet without timestep/file: {ds.attrib}") from None
    return out
