"""Verbs that read finished runs back: ``compare`` (trajectories of several runs in one
figure) and ``render`` (PNGs of a coupled run's VTK series).

Both write only what the output rules of ``pbe_cfd.io.output`` allow, check that before drawing,
and turn a bad input (a missing run, an unknown field, a file that is not a table) into a
``UsageError`` with a one-line message (exit code 2).
"""
from __future__ import annotations

import sys
from pathlib import Path

from . import output
from .output import UsageError

#: Figure formats ``compare --out`` writes (the ones that carry the pbe-cfd mark).
FIGURE_FORMATS = (".png", ".pdf", ".svg")


def load_run(arg) -> tuple[str, dict, Path]:
    """(label, columns, csv path) of a run directory or results CSV: ``moments.csv`` of
    ``pbe-cfd run``, else ``bed_moments.csv`` of ``pbe-cfd couple`` (bed averages per m3 of
    bed). Raises UsageError naming what was expected."""
    path = Path(arg)
    if path.is_dir():
        for name in ("moments.csv", "bed_moments.csv"):
            if (path / name).is_file():
                csv_path = path / name
                break
        else:
            raise UsageError(f"{path}: neither moments.csv (a `pbe-cfd run` output) nor "
                             "bed_moments.csv (a `pbe-cfd couple` output) in it")
        label = path.resolve().name + (" (bed average)" if csv_path.name.startswith("bed")
                                       else "")
    elif path.is_file():
        csv_path, label = path, path.stem
    else:
        raise UsageError(f"{path}: no such run directory or results file")
    try:
        cols = output.read_columns_csv(csv_path)
    except (ValueError, OSError) as exc:
        raise UsageError(str(exc)) from None
    return label, cols, csv_path


def compare_runs(results, out, overwrite: bool = False, say=print) -> int:
    """``pbe-cfd compare A B ... --out F.png``: the columns all runs share, one panel each,
    with a cNMC's 95% band filled and its mean on top, and below each panel every run's
    deviation from the cNMC mean in %. When every run has a psd.csv, ``F_psd.png`` overlays
    their size distributions at each run's last output time (a cNMC's band filled)."""
    from ..viz import plotting

    out = Path(out)
    target = output.prepare_file(out, overwrite)
    if out.suffix.lower() not in FIGURE_FORMATS:
        raise UsageError(f"--out {out}: expected a figure file ending in "
                         f"{', '.join(FIGURE_FORMATS)}")
    runs, seen, psds = [], {}, []
    for arg in results:
        label, cols, csv_path = load_run(arg)
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:
            label = f"{label} #{seen[label]}"
        runs.append((label, cols))
        psds.append((label, _read_psd(csv_path.parent / "psd.csv")))
    common = set.intersection(*(set(plotting.plotted_columns(c)) for _, c in runs))
    if not common:
        raise UsageError("the runs share no moment column to compare: "
                         + "; ".join(f"{lb}: {', '.join(plotting.plotted_columns(c))}"
                                     for lb, c in runs))
    psd_out = out.with_name(f"{out.stem}_psd{out.suffix}")
    with_psd = all(cols is not None for _, cols in psds)
    psd_target = output.prepare_file(psd_out, overwrite) if with_psd else None
    with output.atomic_file(target, overwrite) as tmp:
        plotting.plot_trajectories(tmp, runs, title=" vs ".join(lb for lb, _ in runs),
                                   common_only=True,
                                   metadata=output.figure_metadata(out.suffix, "compare"))
    say(f"wrote {out}")
    if with_psd:
        from ..viz import psd_figure
        with output.atomic_file(psd_target, overwrite) as tmp:
            psd_figure.psd_overlay(tmp, psds, title="granule size distributions (mass-based)",
                                   metadata=output.figure_metadata(out.suffix, "compare"))
        say(f"wrote {psd_out}")
    else:
        say(f"no {psd_out.name}: no psd.csv in "
            + ", ".join(lb for lb, cols in psds if cols is None))
    return 0


def _read_psd(path):
    """The columns of a run's psd.csv, or None when the run has none (or it is not one)."""
    if not path.is_file():
        return None
    try:
        cols = output.read_columns_csv(path)
    except (ValueError, OSError):
        return None
    return cols if {"d_m", "q3_per_ln_d"} <= set(cols) else None


def render_run(directory, fields=None, times=None, overwrite: bool = False,
               note=None, section: str | None = None) -> list[Path]:
    """``pbe-cfd render DIR``: PNGs of the VTK series of a coupled run into ``DIR/png/`` (and
    ``bed_moments.png`` when DIR holds bed_moments.csv). Times that are not written are drawn
    at the nearest written time; ``note`` (default: stderr) is told which. Pictures drawn
    already are skipped (``note`` says which, in one line) and redrawn only with
    ``overwrite``; a request of nothing but those is refused; other files are never replaced.
    ``section``: "AXIS=POSITION" (m) of the plane drawn (default the mid-plane). Returns the
    PNGs written."""
    from ..viz import render

    say = note or (lambda text: print(f"render: {text}", file=sys.stderr))
    d = Path(directory)
    if not d.is_dir():
        raise UsageError(f"{d}: no such directory (expected the output directory of "
                         "`pbe-cfd couple`)")
    vtk_dir = d / "vtk" if (d / "vtk").is_dir() else d
    try:
        plane = render.parse_plane(section) if section is not None else None
        plan = render.plan_render(vtk_dir, fields, times, plane)
    except (FileNotFoundError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    pvd, entries, idx, fields, notes = plan
    for text in notes:
        say(text)
    # the run directory's manifest lists the renders; a foreign series gets its own png/
    in_run = output.read_manifest(d) is not None
    root = d if in_run else d / "png"
    prefix = "png/" if in_run else ""
    # bed_moments.png does not depend on --fields/--times: drawn when missing (or replaced)
    bed = (d / "bed_moments.csv").is_file() and (
        overwrite or not (root / (prefix + "bed_moments.png")).exists())
    sequence = times is not None and len(idx) > 1
    wanted = render.png_names(fields, [entries[i][0] for i in idx], sequence)
    drawn = [] if overwrite else [n for n in wanted if (root / (prefix + n)).exists()]
    names = [prefix + n for n in wanted if n not in drawn]
    if drawn and not names:
        raise UsageError(f"every picture asked for is drawn already in {root} "
                         f"({_short_list(drawn)}); --overwrite redraws them")
    if drawn:
        say(f"skipped {len(drawn)} picture(s) drawn already ({_short_list(drawn)}); "
            "--overwrite redraws them")
    if bed:
        names.append(prefix + "bed_moments.png")
    output.prepare_directory(root, overwrite, flag="render", names=names, allow_cwd=True,
                            kind="render")
    with output.add_to_directory(root, kind="render", flag="render") as tmp:
        png_dir = tmp / "png" if in_run else tmp
        extra = [(render.plot_bed_moments, (d / "bed_moments.csv", png_dir / "bed_moments.png"),
                  {}, render.BED_MOMENTS_COST)] if bed else []
        render.render_series(vtk_dir, png_dir=png_dir, notes=[], plan=plan, sequence=sequence,
                             extra_tasks=extra, skip=drawn, plane=plane)
    return [root / n for n in names]


def _short_list(names, first: int = 4) -> str:
    more = len(names) - first
    return ", ".join(names[:first]) + (f" and {more} more" if more > 0 else "")
