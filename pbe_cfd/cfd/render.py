"""Off-screen renders of a VTK series (pyvista) and a plot of bed-integrated moments.

``render_series(out_dir, fields, times)`` draws cell fields of the pseudo-2-D bed viewed
along z, one PNG per (field, time), with a colour bar in SI units and a log scale where a
field spans decades. ``plot_bed_moments(csv_path, png_path)`` plots ``bed_moments.csv``.
No display is needed: VTK renders off-screen (EGL/OSMesa); Xvfb is started only if that fails.
"""

from __future__ import annotations

import csv
import os
import re
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["render_series", "render_mesh_field", "plot_bed_moments", "field_label",
           "image_stats", "DEFAULT_FIELDS"]

#: Fields drawn by default (those present in the series).
DEFAULT_FIELDS = ("alpha", "Theta", "M00", "d43_m", "binder_fraction")

_LABELS = {
    "alpha": ("alpha", "-"),
    "alpha.particles": ("alpha", "-"),
    "alpha.particlesMean": ("mean alpha", "-"),
    "Theta": ("Theta", "m2/s2"),
    "Theta.particles": ("Theta", "m2/s2"),
    "Theta.particlesMean": ("mean Theta", "m2/s2"),
    "d32_m": ("d32", "m"),
    "d43_m": ("d43", "m"),
    "binder_fraction": ("binder fraction", "-"),
    "droplet_number_density": ("droplets", "1/m3"),
    "cell_volume": ("cell volume", "m3"),
}


def field_label(name: str) -> str:
    """Short colour-bar title with SI unit, e.g. 'Theta' -> 'Theta [m2/s2]'."""
    if name in _LABELS:
        text, unit = _LABELS[name]
        return f"{text} [{unit}]"
    m = re.fullmatch(r"M(\d)(\d)", name)
    if m:
        k = int(m.group(1)) + int(m.group(2))
        unit = "1/m3" if k == 0 else ("kg/m3" if k == 1 else f"kg{k}/m3")
        return f"{name} [{unit}]"
    unit = "m" if name.endswith("_m") else "SI"
    return f"{name} [{unit}]"


_BACKEND_READY = False


def _pyvista():
    """Import pyvista set up for off-screen rendering; start Xvfb only when VTK needs it."""
    global _BACKEND_READY
    if not os.environ.get("DISPLAY"):
        # no X server: let VTK pick its EGL window directly instead of trying X first
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    pv.OFF_SCREEN = True
    if not _BACKEND_READY:
        try:
            pl = pv.Plotter(off_screen=True, window_size=(8, 8))
            pl.add_mesh(pv.Sphere())
            pl.screenshot(return_img=True)
            pl.close()
        except Exception as exc:  # noqa: BLE001 - any render failure: try a virtual display
            if shutil.which("Xvfb") is None or os.environ.get("DISPLAY"):
                raise RuntimeError(f"pyvista cannot render off-screen here ({exc}) and no "
                                   "Xvfb is available to provide a display") from exc
            pv.start_xvfb()
        _BACKEND_READY = True
    return pv


def _find_pvd(out_dir: Path) -> Path:
    if out_dir.is_file() and out_dir.suffix == ".pvd":
        return out_dir
    pvds = sorted(out_dir.glob("*.pvd"))
    if not pvds:
        raise FileNotFoundError(f"render_series: no .pvd collection in {out_dir}")
    if len(pvds) > 1:
        names = [p.name for p in pvds]
        for pref in ("fields.pvd", "pbe.pvd", "moments.pvd"):
            if pref in names:
                return out_dir / pref
        raise ValueError(f"render_series: several .pvd files in {out_dir} ({names}); "
                         "pass the one to draw")
    return pvds[0]


def _pick_times(available: list[float], times: Sequence[float] | None) -> list[int]:
    """Indices of the requested output times (s); default the first and the last."""
    if not available:
        raise ValueError("render_series: the series has no time steps")
    if times is None:
        return sorted({0, len(available) - 1})
    arr = np.asarray(available, dtype=float)
    idx = []
    for t in times:
        i = int(np.argmin(np.abs(arr - float(t))))
        if abs(arr[i] - float(t)) > 1e-6 * max(1.0, abs(float(t))):
            raise ValueError(f"render_series: t = {t} s is not an output time; the series "
                             f"has {available}")
        idx.append(i)
    return idx


#: Fractions: always a linear scale from 0.
LINEAR_FIELDS = frozenset({"alpha", "alpha.particles", "alpha.particlesMean",
                           "binder_fraction"})


def _colour_limits(values: list[np.ndarray], field: str = "") -> tuple[float, float, bool]:
    """(lo, hi, log) over all arrays: log when the positive values span > 2 decades
    (never for the fractions in LINEAR_FIELDS, which start at 0; sizes ``*_m`` range over
    their positive values, zeros being empty cells)."""
    v = np.concatenate([np.ravel(a) for a in values])
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0, False
    pos = v[v > 0]
    hi = float(v.max())
    lo = float(v.min())
    if field in LINEAR_FIELDS:
        lo = min(lo, 0.0)
    elif field.endswith("_m") and lo >= 0 and pos.size:
        # sizes: a zero marks an empty cell (drawn grey), not a size
        lo = float(pos.min())
        if hi / lo > 100.0:
            return max(lo, hi * 1e-6), hi, True
        if hi == lo:
            hi = lo * (1 + 1e-6)
        return lo, hi, False
    elif lo >= 0 and pos.size and hi > 0:
        plo = float(pos.min())
        if hi / plo > 100.0:
            # floor at 1e-6 of the maximum so a few near-empty cells do not wash out the rest
            return max(plo, hi * 1e-6), hi, True
    if hi == lo:
        hi = lo + (abs(lo) * 1e-6 or 1.0)
    return lo, hi, False


def render_mesh_field(mesh, field: str, png_path: str | os.PathLike, *, title: str = "",
                      clim: tuple[float, float] | None = None, log_scale: bool | None = None,
                      window_size: tuple[int, int] = (600, 1000), cmap: str = "viridis") -> Path:
    """Render one cell field of a pyvista mesh (a pseudo-2-D bed, viewed along z) to a PNG.

    ``clim`` and ``log_scale`` default to the field's own range (log over > 2 decades).
    Cells below the colour range (e.g. empty cells on a log scale) are drawn light grey.
    """
    pv = _pyvista()
    if field not in mesh.cell_data:
        raise KeyError(f"no cell field '{field}' (have {sorted(mesh.cell_data.keys())})")
    values = np.asarray(mesh.cell_data[field], dtype=float)
    if values.ndim > 1:
        values = np.linalg.norm(values, axis=1)
    if clim is None or log_scale is None:
        lo, hi, lg = _colour_limits([values], field)
        clim = clim or (lo, hi)
        log_scale = lg if log_scale is None else log_scale
    grid = mesh.copy(deep=False)
    grid.cell_data.clear()
    grid.cell_data[field] = values
    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.set_background("white")
    big = max(abs(clim[0]), abs(clim[1]))
    bar = dict(title=field_label(field), vertical=True, position_x=0.66, position_y=0.10,
               width=0.10, height=0.78, color="black", title_font_size=16,
               label_font_size=14, n_labels=5,
               fmt="%.2e" if log_scale or big < 1e-2 or big >= 1e4 else "%.3g")
    extra = {}
    if np.any(values < clim[0]):
        # e.g. empty cells under a log scale
        extra["below_color"] = "lightgrey"
        bar["below_label"] = "< min"
    pl.add_mesh(grid, scalars=field, preference="cell", cmap=cmap, clim=list(clim),
                log_scale=bool(log_scale), lighting=False, scalar_bar_args=bar,
                show_edges=False, **extra)
    if title:
        pl.add_text(title, position="upper_left", font_size=12, color="black")
    # pseudo-2-D bed seen along z, in the left ~60 % of the window (colour bar on the right)
    pl.view_xy()
    pl.enable_parallel_projection()
    x0, x1, y0, y1, z0, z1 = grid.bounds
    h = y1 - y0
    aspect = window_size[0] / window_size[1]
    scale = 0.55 * h                       # half the visible height
    cx = x0 + 0.42 * (2 * scale * aspect)   # bed starts 8 % in from the left edge
    cy = (y0 + y1) / 2 + 0.02 * h           # room for the title above
    cam = pl.camera
    dist = 10 * h
    cam.focal_point = (cx, cy, (z0 + z1) / 2)
    cam.position = (cx, cy, (z0 + z1) / 2 + dist)
    cam.up = (0, 1, 0)
    cam.parallel_scale = scale
    pl.screenshot(str(png_path))
    pl.close()
    return png_path


def render_series(out_dir: str | os.PathLike, fields: Sequence[str] | None = None,
                  times: Sequence[float] | None = None,
                  png_dir: str | os.PathLike | None = None) -> list[Path]:
    """Render cell fields of the VTK series in ``out_dir`` (its .pvd) at chosen times (s).

    ``fields``: names to draw (default: those of alpha, Theta, M00, d43_m, binder_fraction
    present). ``times``: output times in s (each must be a written step; default first and last).
    One PNG per field and time, ``<png_dir>/<field>_t<time>s.png`` (png_dir defaults to
    ``out_dir/png``), with the same colour range for a field at every time. Returns the paths.
    """
    from pbe_cfd.cfd.vtk import read_pvd

    pv = _pyvista()
    out_dir = Path(out_dir)
    pvd = _find_pvd(out_dir)
    entries = read_pvd(pvd)
    idx = _pick_times([t for t, _ in entries], times)
    meshes = {i: pv.read(entries[i][1]) for i in sorted(set(idx))}
    have = set.intersection(*(set(m.cell_data.keys()) for m in meshes.values()))
    if fields is None:
        fields = [f for f in DEFAULT_FIELDS if f in have]
        if not fields:
            raise ValueError(f"render_series: none of {list(DEFAULT_FIELDS)} in {pvd}; "
                             f"fields there: {sorted(have)}")
    else:
        missing = [f for f in fields if f not in have]
        if missing:
            raise ValueError(f"render_series: fields {missing} not in {pvd} at the chosen "
                             f"times; fields there: {sorted(have)}")
    png_dir = Path(png_dir) if png_dir is not None else pvd.parent / "png"
    out = []
    for field in fields:
        lo, hi, lg = _colour_limits([np.asarray(meshes[i].cell_data[field]) for i in idx],
                                    field)
        for i in idx:
            t = entries[i][0]
            path = png_dir / f"{field}_t{t:g}s.png"
            out.append(render_mesh_field(meshes[i], field, path, clim=(lo, hi), log_scale=lg,
                                         title=f"{field}   t = {t:g} s"))
    return out


def _read_csv(csv_path: Path) -> tuple[list[str], np.ndarray]:
    with open(csv_path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{csv_path}: empty file")
    header = [h.strip() for h in rows[0]]
    if not header or header[0] != "time_s":
        raise ValueError(f"{csv_path}: first column must be 'time_s', got {header[:1]}")
    try:
        data = np.array([[float(x) for x in r] for r in rows[1:] if r], dtype=float)
    except ValueError as exc:
        raise ValueError(f"{csv_path}: non-numeric value ({exc})") from None
    if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] != len(header):
        raise ValueError(f"{csv_path}: expected rows of {len(header)} numbers under the header")
    return header, data


def plot_bed_moments(csv_path: str | os.PathLike, png_path: str | os.PathLike) -> Path:
    """Plot ``bed_moments.csv`` (time_s, then M.. and derived columns) to a PNG.

    Panel 1: each moment M_ij relative to its initial value (or to its final value when it
    starts at zero, e.g. binder moments), log axis when they span decades. Panel 2: the
    diameters (``*_m`` columns) in um. Panel 3: binder_fraction [-] and any other column
    relative to its first non-zero value. Time axis in s.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    csv_path, png_path = Path(csv_path), Path(png_path)
    header, data = _read_csv(csv_path)
    t = data[:, 0]
    mcols = [i for i, h in enumerate(header) if re.fullmatch(r"M\d\d", h)]
    sizes = [i for i, h in enumerate(header) if i > 0 and h.endswith("_m")]
    rest = [i for i, h in enumerate(header) if i > 0 and i not in mcols and i not in sizes]
    panels = [p for p in (mcols, sizes, rest) if p]
    if not panels:
        raise ValueError(f"{csv_path}: no columns to plot besides time_s")
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.2), squeeze=False)
    axes = list(axes[0])
    ax_i = 0
    if mcols:
        ax = axes[ax_i]
        ax_i += 1
        span = []
        for i in mcols:
            y = data[:, i]
            if y[0] != 0:
                ref, how = y[0], "initial"
            elif y[-1] != 0:
                ref, how = y[-1], "final"
            else:
                ax.plot(t, y, label=f"{header[i]} (all zero)")
                continue
            rel = y / ref
            span.append(rel)
            ax.plot(t, rel, label=f"{header[i]} / {how} {ref:.3g}")
        if span:
            s = np.concatenate(span)
            s = s[np.isfinite(s) & (s > 0)]
            if s.size and s.max() / s.min() > 100:
                ax.set_yscale("log", nonpositive="mask")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("bed moment, relative [-]")
        ax.set_title("bed-integrated moments")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if sizes:
        ax = axes[ax_i]
        ax_i += 1
        for i in sizes:
            ax.plot(t, data[:, i] * 1e6, label=header[i][:-2])
        ax.set_xlabel("time [s]")
        ax.set_ylabel("diameter [um]")
        ax.set_title("mean diameters")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if rest:
        ax = axes[ax_i]
        twin = None
        lines = []
        for i in rest:
            h, y = header[i], data[:, i]
            if h == "binder_fraction":
                lines += ax.plot(t, y, "k-", label="binder fraction [-]")
            else:
                twin = twin or ax.twinx()
                nz = np.flatnonzero(y != 0)
                ref = y[nz[0]] if nz.size else 1.0
                lines += twin.plot(t, y / ref, ":", label=f"{h} / {ref:.3g}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("binder fraction [-]")
        if twin is not None:
            twin.set_ylabel("relative to first non-zero value [-]")
        ax.set_title("binder and droplets")
        ax.grid(True, alpha=0.3)
        ax.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="best")
    fig.suptitle(str(csv_path.name), fontsize=9)
    fig.tight_layout()
    png_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return png_path


def image_stats(png_path: str | os.PathLike) -> tuple[float, int]:
    """(pixel variance, number of distinct colours) of an image, to check it is not blank."""
    import matplotlib.image as mpimg

    img = mpimg.imread(str(png_path))
    if img.ndim == 3:
        img = img[..., :3]
        flat = img.reshape(-1, 3)
    else:
        flat = img.reshape(-1, 1)
    colours = np.unique(np.round(flat * 255).astype(np.int32), axis=0)
    return float(np.var(img)), int(len(colours))
