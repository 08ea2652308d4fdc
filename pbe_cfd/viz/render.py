"""Pictures of a coupled run: cell fields of the VTK series and the bed-averaged moments.

``render_series(out_dir, fields, times)`` draws each cell field on the mid-plane section of
the bed (the pseudo-2-D fluid bed seen along its thin axis, or a plane ``section`` names), one
PNG per (field, time) and, for several times, one sequence figure sharing one colour bar. Axes
are in m and equal in scale; the colour bar names the field, its unit (SI; diameters in um)
and, where used, the log scale, with distinct tick labels; a 0/1 flag (``active``,
``spray_zone``) gets two colours and two labels. The CFD input fields (alpha, Theta) are titled
with the time of the CFD fields, not the process time. Cells holding no
granules (alpha below the scene's alpha_min: the freeboard) are drawn in one light grey in
every field, so an empty cell never looks like a dry or small one.
``plot_bed_moments(csv_path, png_path)`` plots ``bed_moments.csv`` in the VTK's units.

meshio reads a one-cell-thick mesh, VTK (pyvista) cuts any other (viz/section.py); figures are
drawn by matplotlib (Agg) outside pyplot, on two cores (viz/figure_pool.py), so no
display or OpenGL is needed.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .bed_moments import (BED_MOMENTS_COST, BED_PANELS, bed_moments_figure,  # noqa: F401
                          plot_bed_moments)  # (re-exported: part of this module's API)
from .figure_parts import (_LABELS, FLAG_FIELDS, _figure, _png_meta, _run_info,  # noqa: F401
                           distinct_formatter, field_label, picture_label, picture_scale)
from .section import parse_plane, read_section, section  # noqa: F401 - part of the API

__all__ = ["render_series", "render_mesh_field", "field_figure", "plot_bed_moments",
           "bed_moments_figure",
           "field_label", "image_stats", "pick_times", "section", "plan_render", "png_names",
           "DEFAULT_FIELDS", "EMPTY_COLOUR"]

#: Fields drawn by default (those present in the series).
DEFAULT_FIELDS = ("alpha", "Theta", "M00", "d43_m", "binder_fraction")
#: Colour of cells that hold no granules, in every field.
EMPTY_COLOUR = "#d4d4d4"

def _find_pvd(out_dir: Path) -> Path:
    if out_dir.is_file() and out_dir.suffix == ".pvd":
        return out_dir
    if not out_dir.is_dir():
        raise FileNotFoundError(f"{out_dir}: no such directory (expected the output directory "
                                "of `pbe-cfd couple`)")
    pvds = sorted(out_dir.glob("*.pvd"))
    if not pvds:
        raise FileNotFoundError(f"{out_dir}: no VTK series (.pvd) here (expected the output "
                                "directory of `pbe-cfd couple`)")
    if len(pvds) > 1:
        names = [p.name for p in pvds]
        for pref in ("fields.pvd", "pbe.pvd", "moments.pvd"):
            if pref in names:
                return out_dir / pref
        raise ValueError(f"{out_dir}: several .pvd files ({names}); pass the one to draw")
    return pvds[0]


def pick_times(available: Sequence[float], times: Sequence[float] | None,
               notes: list | None = None) -> list[int]:
    """Indices of the written output times nearest to the requested ones (s), in the order
    asked, without repeats; default the first and the last. A request that is not a written
    time adds a sentence to ``notes`` saying which time is drawn instead."""
    if not len(available):
        raise ValueError("the series has no time steps")
    if times is None:
        return sorted({0, len(available) - 1})
    arr = np.asarray(available, dtype=float)
    idx = []
    for t in times:
        t = float(t)
        if not np.isfinite(t):
            raise ValueError(f"--times {t}: expected a time in s")
        i = int(np.argmin(np.abs(arr - t)))
        if abs(arr[i] - t) > 1e-6 * max(1.0, abs(t)) and notes is not None:
            notes.append(f"t = {t:g} s is not an output time; drawing the nearest written "
                         f"one, t = {arr[i]:g} s (written: {arr[0]:g} to {arr[-1]:g} s every "
                         f"{_step_text(arr)})")
        if i not in idx:
            idx.append(i)
    return idx


def _step_text(arr: np.ndarray) -> str:
    if arr.size < 2:
        return "-"
    d = np.diff(arr)
    return f"{d[0]:g} s" if np.allclose(d, d[0]) else "varying steps"


#: Fractions: always a linear scale from 0.
LINEAR_FIELDS = frozenset({"alpha", "alpha.particles", "alpha.particlesMean",
                           "binder_fraction", "active", "spray_zone"})


def _colour_limits(values: list[np.ndarray], field: str = "") -> tuple[float, float, bool]:
    """(lo, hi, log) over the arrays (cells holding granules only): log when positive values
    span more than 2 decades, floored at 1e-6 of the maximum (never for the fractions in
    LINEAR_FIELDS, which start at 0)."""
    v = np.concatenate([np.ravel(a) for a in values]) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0, False
    pos = v[v > 0]
    hi, lo = float(v.max()), float(v.min())
    if field in LINEAR_FIELDS:
        lo = min(lo, 0.0)
    elif lo >= 0 and pos.size and hi > 0:
        plo = float(pos.min())
        if hi / plo > 100.0:
            return max(plo, hi * 1e-6), hi, True
        if field.endswith("_m"):
            lo = plo                         # a size range, not from zero
    if hi <= lo:
        hi = lo + (abs(lo) * 1e-6 or 1.0)
    return lo, hi, False


# ---------------------------------------------------------------------------- geometry
def _empty_mask(data: dict) -> np.ndarray | None:
    """Cells that hold no granules: ``active`` = 0 where the series has it, else M00 <= 0."""
    if "active" in data:
        return np.asarray(data["active"]) < 0.5
    if "M00" in data:
        return ~(np.asarray(data["M00"]) > 0)
    return None


def _values(data: dict, field: str) -> np.ndarray:
    """The cell values of ``field`` in the picture's unit (``picture_scale``: um for m)."""
    if field not in data:
        raise KeyError(field)
    v = np.asarray(data[field], dtype=float)
    v = np.linalg.norm(v, axis=1) if v.ndim > 1 else v
    return v * picture_scale(field)[0]


def _is_flag(field: str) -> bool:
    return field in FLAG_FIELDS


def _field_empty(data: dict, field: str) -> np.ndarray | None:
    """Cells drawn as holding no granules in ``field``: none for a flag, whose 0 is drawn in
    its own colour."""
    return None if _is_flag(field) else _empty_mask(data)


#: Fields the CFD run computed (the inputs of the population balance), not this run.
def is_cfd_field(field: str) -> bool:
    """True for the CFD input fields (alpha, Theta and their OpenFOAM names)."""
    return field.split(".")[0] in ("alpha", "Theta")


def panel_title(field: str, time_s: float, cfd_time_s: float | None) -> str:
    """The title of one field's picture at process time ``time_s`` [s]: a CFD input field
    says the time of the CFD fields [s] instead ("alpha (CFD, t = 0.5 s)")."""
    label = picture_label(field).split(" [")[0]
    if is_cfd_field(field):
        return (f"{label} (CFD, t = {cfd_time_s:g} s)" if cfd_time_s is not None
                else f"{label} (CFD input)")
    return f"{label} at t = {time_s:g} s"


# ---------------------------------------------------------------------------- drawing
def _norm(clim, log_scale, flag=False):
    from matplotlib.colors import BoundaryNorm, LogNorm, Normalize
    if flag:
        return BoundaryNorm([-0.5, 0.5, 1.5], 2)
    return LogNorm(*clim) if log_scale else Normalize(*clim)


def _shown(values, empty, norm):
    """Cell values as drawn: empty cells masked (EMPTY_COLOUR), zero in a granule cell at the
    floor of a log scale."""
    shown = np.where(empty, np.nan, values) if empty is not None else values
    if norm.__class__.__name__ == "LogNorm":
        shown = np.where(shown > 0, shown, norm.vmin)
    return np.ma.masked_invalid(shown)


def _draw_section(ax, polys, values, empty, norm, cmap):
    from matplotlib.collections import PolyCollection

    if len({len(p) for p in polys}) == 1:
        polys = np.stack(polys)          # one array: matplotlib builds the paths in one go
    full = PolyCollection(polys, cmap=cmap, norm=norm, edgecolors="face", linewidths=0.3,
                          antialiased=False)     # no light seams between cells
    full.set_array(_shown(values, empty, norm))
    ax.add_collection(full)
    pts = np.concatenate(polys)
    ax.set_xlim(pts[:, 0].min(), pts[:, 0].max())
    ax.set_ylim(pts[:, 1].min(), pts[:, 1].max())
    ax.set_aspect("equal")
    return full


#: Layout of a field figure in inches: axes height, left/right/bottom/top margins, gap
#: between panels, colour bar width and the space its labels need.
_AX_H, _LEFT, _BOTTOM, _TOP, _GAP, _BAR_W, _BAR_LABELS = 4.6, 0.8, 0.75, 0.45, 0.25, 0.16, 1.15


def _layout(polys, panels: int, head_lines: int):
    """Figure size and the axes / colour-bar rectangles (figure fractions) for ``panels``
    sections side by side, drawn to scale (equal axes) at _AX_H inches high."""
    pts = np.concatenate(polys)
    w = float(np.ptp(pts[:, 0])) or 1.0
    h = float(np.ptp(pts[:, 1])) or 1.0
    ax_h = _AX_H
    ax_w = ax_h * w / h
    if ax_w > 6.0:                        # a wide domain: keep the figure at most ~6 in wide
        ax_w, ax_h = 6.0, 6.0 * h / w
    top = _TOP + 0.2 * head_lines
    width = _LEFT + panels * ax_w + (panels - 1) * _GAP + 0.2 + _BAR_W + _BAR_LABELS
    height = _BOTTOM + ax_h + top
    rects = [((_LEFT + k * (ax_w + _GAP)) / width, _BOTTOM / height, ax_w / width,
              ax_h / height) for k in range(panels)]
    x_bar = _LEFT + panels * ax_w + (panels - 1) * _GAP + 0.2
    bar = (x_bar / width, _BOTTOM / height, _BAR_W / width, ax_h / height)
    return (width, height), rects, bar


def _colour_bar(fig, mappable, rect, field, log_scale, below):
    cax = fig.add_axes(rect)
    if _is_flag(field):
        cb = fig.colorbar(mappable, cax=cax, ticks=[0, 1])
        cb.ax.set_yticklabels(["0 no", "1 yes"])
        cb.set_label(field_label(field).split(" [")[0], fontsize=9)
        cb.ax.tick_params(labelsize=8)
        return cb
    cb = fig.colorbar(mappable, cax=cax, extend="min" if below else "neither")
    label = picture_label(field)
    if log_scale:
        label += ", log scale"
    else:
        # a power of ten goes into the unit ("M00 [1e10 1/m3]"), not above the bar; the
        # tick labels keep as many digits as they need to differ
        big = max(abs(mappable.norm.vmin), abs(mappable.norm.vmax))
        exp = int(np.floor(np.log10(big))) if big > 0 else 0
        exp = exp if exp <= -3 or exp >= 4 else 0
        cb.formatter = distinct_formatter(exp)
        cb.update_ticks()
        if exp:
            name, unit = label.rsplit(" [", 1)
            label = f"{name} [1e{exp} {unit}" if unit != "-]" else f"{name} [1e{exp}]"
    cb.set_label(label, fontsize=9)
    cb.ax.tick_params(labelsize=8)
    return cb


def _empty_legend(fig, empty, alpha_min):
    from matplotlib.patches import Patch
    if empty is None or not np.any(empty):
        return
    text = "no granules" + (f" (alpha < {alpha_min:g})" if alpha_min is not None else "")
    fig.legend(handles=[Patch(facecolor=EMPTY_COLOUR, edgecolor="0.5", label=text)],
               loc="lower right", fontsize=8, frameon=False, bbox_to_anchor=(1.0, 0.0),
               handlelength=1.2, borderaxespad=0.1)


def render_mesh_field(mesh, field: str, png_path: str | os.PathLike, *, title: str = "",
                      clim: tuple[float, float] | None = None, log_scale: bool | None = None,
                      cmap: str = "viridis", alpha_min: float | None = None,
                      subtitle: str = "") -> Path:
    """Draw one cell field of a VTK mesh (pyvista) on its mid-plane section to a PNG.

    Axes in m; ``clim``/``log_scale`` default to the field's own range over the cells holding
    granules (log over > 2 decades); empty cells (``active`` = 0, or M00 = 0) in EMPTY_COLOUR.
    """
    polys, data, axes_names, note = section(mesh)
    return _render_panels([(polys, data, title)], field, Path(png_path), clim=clim,
                          log_scale=log_scale, cmap=cmap, alpha_min=alpha_min,
                          suptitle=subtitle, axes_names=axes_names, note=note)


def _render_panels(panels, field, png_path: Path, **kw) -> Path:
    return _render_times([(panels, png_path)], field, **kw)[0]


def _render_times(items, field, **kw) -> list[Path]:
    """Draw one field at several times (``items``: [(panels, png path)]) on one colour range
    (``kw``: those of ``field_figure``). The figure is built once and refilled with each
    time's values where only the values and titles change (same cells, same empty-cell
    legend, same end of the colour bar); else it is built anew."""
    out, fig = [], None
    for panels, png_path in items:
        if fig is None or not _refill(fig, panels, field):
            fig = field_figure(panels, field, **kw)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(png_path, dpi=110, metadata=_png_meta("render"))
        out.append(png_path)
    return out


def _stacked(polys) -> np.ndarray:
    return np.concatenate([np.asarray(p, dtype=float).ravel() for p in polys])


def _marks(values, empties, clim) -> tuple[bool, bool]:
    """(a live cell below the colour range, an empty cell to name in the legend)."""
    below = False
    for v, e in zip(values, empties):
        live = v[~e] if e is not None else v
        below = below or bool(np.any(live[np.isfinite(live)] < clim[0] * (1 - 1e-12)))
    return below, any(e is not None and e.any() for e in empties)


def _refill(fig, panels, field) -> bool:
    """Put the values and titles of ``panels`` into a figure ``field_figure`` drew for the same
    cells; False (figure unchanged) where more than that would change."""
    state = getattr(fig, "_pbe_cfd_state", None)
    if state is None or len(panels) != len(state["collections"]):
        return False
    values = [_values(d, field) for _, d, _ in panels]
    empties = [_field_empty(d, field) for _, d, _ in panels]
    if _marks(values, empties, state["clim"]) != state["marks"]:
        return False
    if any(not np.array_equal(_stacked(polys), old)
           for (polys, _, _), old in zip(panels, state["polys"])):
        return False
    for coll, ax, (_, _, title), v, e in zip(state["collections"], state["axes"], panels,
                                            values, empties):
        coll.set_array(_shown(v, e, coll.norm))
        ax.set_title(title, fontsize=10, y=1.0)
    return True


def field_figure(panels, field, *, clim=None, log_scale=None, cmap="viridis", alpha_min=None,
                 suptitle="", axes_names=("x", "y"), note=""):
    """The matplotlib Figure of one field on one or more sections side by side: ``panels`` a
    list of (polygons, cell data, panel title) from ``section``; one colour bar (log scale
    named in its label), axes in m drawn to scale, empty cells in EMPTY_COLOUR."""
    import matplotlib
    values = [_values(d, field) for _, d, _ in panels]
    empties = [_field_empty(d, field) for _, d, _ in panels]
    if clim is None or log_scale is None:
        sel = [v[~e] if e is not None else v for v, e in zip(values, empties)]
        lo, hi, lg = _colour_limits(sel, field)
        clim = clim or (lo, hi)
        log_scale = lg if log_scale is None else log_scale
    norm = _norm(clim, log_scale, _is_flag(field))
    cm = matplotlib.colormaps[cmap]
    if _is_flag(field):                    # two colours: the ends of the colour map
        from matplotlib.colors import ListedColormap
        cm = ListedColormap([cm(0.15), cm(0.85)], name=f"{cmap}_flag")
    cm = cm.with_extremes(bad=EMPTY_COLOUR)
    head = "\n".join(x for x in (suptitle, note) if x)
    size, rects, bar_rect = _layout(panels[0][0], len(panels), head.count("\n") + 1 if head else 0)
    fig = _figure(figsize=size)
    below, _ = marks = _marks(values, empties, clim)
    state = {"collections": [], "axes": [], "polys": [], "clim": clim, "marks": marks}
    for k, ((polys, _, title), v, e) in enumerate(zip(panels, values, empties)):
        ax = fig.add_axes(rects[k])
        mappable = _draw_section(ax, polys, v, e, norm, cm)
        state["collections"].append(mappable)
        state["axes"].append(ax)
        state["polys"].append(_stacked(polys))
        ax.set_title(title, fontsize=10, y=1.0)     # a fixed y: no tight-bbox search per draw
        ax.set_xlabel(f"{axes_names[0]} [m]", fontsize=9)
        ax.tick_params(labelsize=8)
        if k == 0:
            ax.set_ylabel(f"{axes_names[1]} [m]", fontsize=9)
        else:
            ax.tick_params(labelleft=False)
    _colour_bar(fig, mappable, bar_rect, field, log_scale, below)
    _empty_legend(fig, next((e for e in empties if e is not None and e.any()), None),
                  alpha_min)
    if head:
        fig.suptitle(head, fontsize=9, color="0.25", y=1 - 0.08 / size[1], va="top")
    fig._pbe_cfd_state = state              # what _refill needs to draw another time
    return fig


def png_names(fields: Sequence[str], times: Sequence[float], sequence: bool = False
              ) -> list[str]:
    """The file names ``render_series`` writes for these fields and output times (s)."""
    out = []
    for field in fields:
        out += [f"{field}_t{t:g}s.png" for t in times]
        if sequence and len(times) > 1:
            out.append(f"{field}_sequence.png")
    return out


def plan_render(out_dir, fields: Sequence[str] | None = None,
                times: Sequence[float] | None = None, plane: tuple[str, float] | None = None):
    """What ``render_series`` would draw: (pvd, entries, chosen indices, fields, notes);
    ``plane`` (axis, position [m]) is checked against the mesh. Raises FileNotFoundError /
    ValueError with a message for the user."""
    from pbe_cfd.io.vtk import read_pvd

    pvd = _find_pvd(Path(out_dir))
    entries = read_pvd(pvd)
    notes: list[str] = []
    idx = pick_times([t for t, _ in entries], times, notes)
    if not idx:
        raise ValueError("--times: name at least one output time in s")
    if fields is not None and not fields:
        raise ValueError("--fields: name at least one field")
    have = set(read_section(entries[idx[0]][1], plane)[1])
    if fields is None:
        fields = [f for f in DEFAULT_FIELDS if f in have]
        if not fields:
            raise ValueError(f"{pvd}: none of {list(DEFAULT_FIELDS)} in the series; fields "
                             f"there: {sorted(have)}")
    else:
        missing = [f for f in fields if f not in have]
        if missing:
            raise ValueError(f"no field {', '.join(missing)} in {pvd}; fields there: "
                             f"{', '.join(sorted(have))}")
        fields = list(dict.fromkeys(fields))
    return pvd, entries, idx, list(fields), notes


def render_series(out_dir: str | os.PathLike, fields: Sequence[str] | None = None,
                  times: Sequence[float] | None = None,
                  png_dir: str | os.PathLike | None = None, notes: list | None = None,
                  plan=None, sequence: bool = False, info: dict | None = None,
                  extra_tasks: Sequence = (), skip: Sequence[str] = (),
                  plane: tuple[str, float] | None = None) -> list[Path]:
    """Render cell fields of the VTK series in ``out_dir`` (its .pvd) at output times (s).

    ``fields``: names to draw (default: those of alpha, Theta, M00, d43_m, binder_fraction
    present). ``times``: output times in s, each drawn at the nearest written time (a sentence
    per substitution goes to ``notes``, or to stderr without it); default first and last. One
    PNG per field and time, ``<png_dir>/<field>_t<time>s.png`` (png_dir defaults to
    ``out_dir/png``), the same colour range for a field at every time, and with ``sequence``
    ``<field>_sequence.png``: the times side by side on that range. ``plan``: the result of
    ``plan_render`` (else made here); ``info``: {"name", "alpha_min"} (else from summary.json).
    ``extra_tasks``: more figures to draw alongside, as ``figure_pool`` tasks; the pictures are
    drawn on two cores (``figure_pool.run_tasks``). ``skip``: PNG file names not to draw
    (drawn already). ``plane``: (axis, position [m]) of the section, e.g. ("z", 0.01); default
    the mid-plane normal to the thinnest extent."""
    from .figure_pool import run_tasks
    from ..io.vtk import time_values

    pvd, entries, idx, fields, found = plan or plan_render(out_dir, fields, times)
    if notes is None:
        for n in found:
            print(f"render: {n}", file=sys.stderr)
    else:
        notes.extend(found)
    cuts = {i: read_section(entries[i][1], plane) for i in idx}
    cfd_time = time_values(entries[idx[0]][1]).get("CFDTime")
    info = info if info is not None else _run_info(pvd.parent, pvd.parent.parent)
    png_dir = Path(png_dir) if png_dir is not None else pvd.parent / "png"
    skip = set(skip)
    tasks = []
    for field in fields:
        vals = []
        for i in idx:
            _, data, _, _ = cuts[i]
            v, e = _values(data, field), _field_empty(data, field)
            vals.append(v[~e] if e is not None else v)
        lo, hi, lg = _colour_limits(vals, field)
        label = panel_title(field, 0.0, cfd_time).split(" at t = ")[0]
        kw = dict(clim=(lo, hi), log_scale=lg, cmap="viridis", alpha_min=info.get("alpha_min"))
        panels, items = [], []
        for i in idx:
            polys, data, axes_names, note = cuts[i]
            t = entries[i][0]
            panels.append((polys, data, f"process t = {t:g} s" if is_cfd_field(field)
                           else f"t = {t:g} s"))
            if f"{field}_t{t:g}s.png" not in skip:
                items.append(([(polys, data, panel_title(field, t, cfd_time))],
                              png_dir / f"{field}_t{t:g}s.png"))
        kw.update(axes_names=axes_names, note=note)
        if items:
            tasks.append((_render_times, (items, field),
                          {**kw, "suptitle": info.get("name", "")}, 0.4 + 0.6 * len(items)))
        if sequence and len(idx) > 1 and f"{field}_sequence.png" not in skip:
            tasks.append((_render_panels, (panels, field, png_dir / f"{field}_sequence.png"),
                          {**kw, "suptitle": f"{info.get('name', '')}: {label}".lstrip(": ")},
                          0.6 + 0.4 * len(panels)))
    from .figure_pool import drawing_elsewhere
    if not drawing_elsewhere():
        import matplotlib.backends.backend_agg  # noqa: F401 - loaded once, before any fork
    drawn = run_tasks(tasks + list(extra_tasks))[:len(tasks)]
    return [p for d in drawn for p in (d if isinstance(d, list) else [d])]


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
