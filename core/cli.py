"""Command line: ``python -m core fit INPUT -o OUTPUT [options]``.

Reads a point cloud or a disk-like mesh (.ply .obj .off .xyz .pts .txt .csv .npy .npz; a DEM
as .npz or an ESRI ASCII grid .asc), fits a
TCB surface (method.md sections 4-6), writes the tessellated surface (.obj or .ply), optionally
the control net and the spline itself, shows a progress line per iteration and a final report.
Bad input ends with a one-line message and exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from .errors import HolesError, InvalidInputError, OutlierError, TCBError
from .fit import DEFAULT_SMOOTHNESS
from .meshio import WRITE_EXTENSIONS, is_dem, read_geometry, write_mesh
from .parameterize import (SPIKES_DISSOLVED, fill_value_rows, fill_value_words,
                          projection_direction)
from .refine import (SWINGS_LEFT, mostly_taken_back, replaced_default_reason,
                     returned_why)
from .surface import (FOLDED_SHARE, MAX_RESOLUTION, SPIKES_HELD_OFF, default_swung, grid_frame,
                      finer_resolution, sag_target, tessellation_fill,
                      noise_near_tolerance, stopped_at_noise, fall_rate, STILL_FALLING,
                      flat_height_field, sag_target_words)

__all__ = ["main"]


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, as the issue asks of bad input: the
    error and where to read the options (argparse prints its whole usage first, ten lines
    for ``fit``). Its subcommands' parsers are of the same class."""

    def error(self, message: str):  # (argparse's signature; it does not return)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="python -m core",
        description="Fit smooth TCB-spline surfaces to scanned points and disk-like meshes.",
    )
    sub = p.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fit", help="fit a surface to a point cloud or a disk-like mesh")
    f.add_argument("input", nargs="+",
                   help="points or mesh: .ply .obj .off .xyz .pts .txt .csv .npy .npz "
                   "(a DEM .npz: 'elevation' with xmin/xmax/ymin/ymax, row 0 at ymin; a "
                   "north-up raster needs dy < 0 or its 'transform' / 'geotransform'), or a "
                   "DEM as an ESRI ASCII grid .asc. Several point files (DEM tiles, scans "
                   "of one surface) are fitted together as one cloud")
    f.add_argument("-o", "--output", required=True, help="tessellated surface: .obj or .ply")
    f.add_argument("--tolerance", type=float, default=1e-3,
                   help="stop when the error (RMS, or max with --criterion max) is at most "
                   "this (default 1e-3); the control net is sized to it")
    rel = f.add_mutually_exclusive_group()
    rel.add_argument("--relative", dest="relative", action="store_true", default=True,
                     help="tolerance relative to the bounding-box diagonal (default)")
    rel.add_argument("--absolute", dest="relative", action="store_false",
                     help="tolerance in the data's units")
    f.add_argument("--criterion", choices=("rms", "max"), default="rms",
                   help="which error the tolerance bounds (default rms)")
    f.add_argument("--max-control-points", type=int, default=2000)
    f.add_argument("--max-iterations", type=int, default=20)
    f.add_argument("--degree", type=int, choices=(2, 3), default=2)
    f.add_argument("--mode", choices=("tcb", "dcb"), default="tcb")
    f.add_argument("--smoothness", type=_smoothness, default=DEFAULT_SMOOTHNESS,
                   help="fairing weight relative to the data term, or 'auto': chosen by "
                   "5-fold cross-validation for the final surface (default 1e-4; on sparse "
                   "clouds, under 2 points per control point, and when the error stopped "
                   "falling above the tolerance, the default is cross-validated)")
    f.add_argument("--resolution", type=int, default=None,
                   help="tessellation steps across the longer side of the domain (default: 64, or "
                   "2 sqrt(control points) for a larger net, at most 512, more where the surface "
                   "leaves out most of the domain; at least 8 across the shorter one; a "
                   "domain filling under half the square on its longer side gets as many grid "
                   "cells as a half-filled square; then 128 or 256 if the mesh would stray "
                   "from the spline by more than the fit's max error)")
    f.add_argument("--net", help="write the control net (.obj or .ply) here")
    f.add_argument("--spline", help="write the spline (.npz, TCBSurface.save) here")
    f.add_argument("--drop-invalid", action="store_true",
                   help="leave out points with NaN or infinite coordinates, or a raster's "
                   "no-data fill value (such as -9999) far below all others (point clouds)")
    f.add_argument("--drop-outliers", action="store_true",
                   help="leave out points far from all others instead of refusing the cloud, "
                   "and spikes and pits inside it; on a mesh, dissolve its spike vertices "
                   "(raised far out of their neighbours' surface) instead of refusing it")
    f.add_argument("--fill-holes", action="store_true",
                   help="meshes with holes (boundary loops besides the outer one): map them as "
                   "if the holes were filled, so that the surface spans them, instead of "
                   "refusing them; point clouds: cover the gaps inside the cloud (occlusions, "
                   "dropouts) with surface, which the output mesh otherwise leaves open")
    f.add_argument("--projection", type=_projection, default=None,
                   metavar="auto|x|y|z|DX,DY,DZ",
                   help="point clouds: project along this direction (a height field over the "
                   "plane across it) instead of choosing it (auto: the best-fit plane, or a "
                   "direction the cloud is less steep over); still checked for folds. Its sign "
                   "does not matter (a leading minus needs the form --projection=-1,0,0). "
                   "Default: z for a DEM raster (.asc grid, .npz elevation, or x y z text on a "
                   "grid of x and y), whose tiles then keep their straight edges; auto for "
                   "other clouds")
    f.add_argument("--join", nargs=2, action="append", metavar=("DATA", "SPLINE"),
                   help="join the surface to a neighbour's along the border the two share: "
                        "DATA is the neighbour's file, SPLINE the .npz its fit wrote with "
                        "--spline; repeat for more neighbours (core.join). Meshes: patches of "
                        "one mesh (vertices at identical coordinates); point clouds: clouds "
                        "fitted along the same projection, such as DEM tiles that share their "
                        "edge row of nodes or overlap, joined where this one's border lies on "
                        "the neighbour's surface")
    f.add_argument("--quiet", action="store_true", help="no progress output")
    h = sub.add_parser("heights", help="the z of a fitted point cloud's surface over the x "
                       "and y of points (resampling a terrain, checking survey points)")
    h.add_argument("spline", help="the spline: the .npz that fit wrote with --spline")
    h.add_argument("points", help="points whose x and y are taken (their z is compared): any "
                   "input fit reads (.xyz .csv .txt .ply .obj .off .npy .npz .asc; a DEM: "
                   "its nodes)")
    h.add_argument("-o", "--output", required=True,
                   help="a text file (.xyz, .txt: spaces; .csv: commas) of x, y, the "
                   "surface's z there (TCBSurface.heights) and dz, the point's z minus it; "
                   "nan where no fitted part of the surface is over the point")
    return p


def _projection(text: str):
    """``--projection``: ``auto``, an axis name, or three comma-separated numbers."""
    if text.strip().lower() in ("auto", "x", "y", "z"):
        return text.strip().lower()
    try:
        d = [float(t) for t in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected auto, x, y, z or three numbers such as 0,0,1; got {text!r}") from None
    try:
        projection_direction(d)
    except InvalidInputError:
        raise argparse.ArgumentTypeError(
            f"expected auto, x, y, z or three numbers, not all zero, such as 0,0,1; got "
            f"{text!r}"
        ) from None
    return d


def _smoothness(text: str):
    """``--smoothness``: a nonnegative number or ``auto``."""
    from .fit import check_smoothness

    try:
        return check_smoothness(text.strip() if text.strip().lower() == "auto" else float(text))
    except (ValueError, InvalidInputError):
        raise argparse.ArgumentTypeError(
            f"expected a nonnegative number or 'auto', got {text!r}") from None


def _returned(report: dict, criterion: str = "rms") -> str:
    """Which iteration's fit was returned, when it is not the last one, and why
    (core.refine.returned_why)."""
    k = report.get("returned_iteration", report["iterations"])
    how = returned_why(report, criterion)
    return f"; the surface is iteration {k}'s ({how})" if 0 < k < report["iterations"] else ""


def _smoothness_text(report: dict) -> str:
    """The fairing weight used, and how it was chosen."""
    text = f"{report['smoothness']:.3g}"
    sel = report.get("smoothness_selection")
    why = replaced_default_reason(sel)
    if default_swung(sel):
        text += f" (with the default {sel['chosen']:.3g} the surface swung away from the data)"
    elif sel is not None:
        text += (f" (auto chose {sel['chosen']:.3g}, which misses the tolerance: default kept)"
                 if "kept" in sel else f" (cross-validated: {why})" if why else " (auto)")
        if "smoother" in sel:  # core.surface._smoother_if_swinging
            text += f"; {sel['chosen']:.3g} swung away from the data between points"
    return text


def _check_output(path: str | None, what: str, extensions=WRITE_EXTENSIONS) -> None:
    """Refuse an output path before the fit, not after it: a wrong extension, a folder in its
    place, a missing folder (or a file where one of its folders should be) or one that does
    not accept new files, a file that cannot be replaced."""
    if path is None:
        return
    if Path(path).suffix.lower() not in extensions:
        raise TCBError(
            f"cannot write the {what} as {Path(path).suffix or 'a file without extension'}: "
            f"use one of {', '.join(sorted(extensions))}"
        )
    if Path(path).is_dir():
        raise TCBError(f"cannot write the {what} to {path}: it is a folder; give a file name")
    folder = Path(path).parent
    if not folder.is_dir():
        # a file where a folder of the path should be was called a missing folder (user test)
        blocking = next((a for a in (folder, *folder.parents) if a.exists()), None)
        if blocking is not None and not blocking.is_dir():
            raise TCBError(f"cannot write the {what} to {path}: {blocking} is a file, not a "
                           "folder")
        raise TCBError(f"cannot write the {what} to {path}: the folder {folder} does not exist")
    if Path(path).exists() and not os.access(path, os.W_OK):
        raise TCBError(f"cannot write the {what} to {path}: the file is read-only")
    try:  # a file without a name (or removed at once): os.access says yes to root everywhere
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise TCBError(
            f"cannot write the {what} to {path}: the folder {folder} does not accept new files "
            f"({exc.strerror or exc})"
        ) from None


def _same_file(a: str, b: str) -> bool:
    """Whether two paths name the same file: equal once resolved (symbolic links followed), or,
    when both exist, the same file on disk (hard links)."""
    if Path(a).resolve() == Path(b).resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def _check_distinct(args) -> None:
    """Refuse, before the fit, an output that would replace the input or another output."""
    paths = [*(("the input", i) for i in args.inputs), ("-o", args.output),
             ("--net", args.net), ("--spline", args.spline)]
    paths = [(name, p) for name, p in paths if p is not None]
    for i, (name, path) in enumerate(paths):
        for other, earlier in paths[:i]:
            if _same_file(earlier, path) and name == other == "the input":
                raise TCBError(f"{path} is given twice as input")
            if _same_file(earlier, path):
                raise TCBError(
                    f"{name} {path} is the same file as {other}"
                    + (" (the input is never overwritten)" if other == "the input" else "")
                    + f"; give {name} another path"
                )


# default_resolution over a domain mostly left out: at most this many grid cells (a 2048 x 2048
# grid took a minute and 2 GiB: MAX_RESOLUTION)
MAX_AUTO_CELLS = 1 << 20


def default_resolution(control_points: int, surf=None) -> int:
    """The tessellation resolution for a net of ``control_points``: 64, or ``2
    sqrt(control points)`` for a larger net (at most 512), so that the written mesh keeps up
    with the spline. At 64 a DEM net of 5980 control points was written as 4090 vertices,
    whose error (a piecewise-linear surface against the points) was 1.9x the spline's; at 128
    1.13x, at 256 1.0x (user test).

    With the surface ``surf``: where its tessellation covers less than half of the square on
    the longer side of its domain (patches far apart, a long strip), the resolution grows
    until the triangles kept are as many as that square would hold (at most MAX_AUTO_CELLS
    grid cells): two 1 x 1 patches 20 apart were written with 93 vertices each at
    64, 4x farther from the data than the spline (user test)."""
    base = int(min(512, max(64, np.ceil(2.0 * np.sqrt(max(control_points, 1))))))
    if surf is None:
        return base
    uv, tri = surf.tessellation_uv(base)
    if len(tri) == 0:
        return base
    a, b, c = (uv[tri[:, k]] for k in range(3))
    covered = 0.5 * float(np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                                 - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])).sum())
    _, lo, hi = grid_frame(surf.parameterization)  # (the grid's: tessellation_uv)
    extent = hi - lo
    side, across = float(extent.max()), float(extent.min())
    if covered >= 0.5 * side * side:
        return base
    # tessellation_uv's step over such a domain is already finer than side / resolution by
    # ``finer`` (a domain polygon filling less than TESSELLATION_FULL_SHARE of its square:
    # tessellation_fill); the resolution asked for is smaller by that much, for the same step
    finer = tessellation_fill(surf.parameterization)
    want = base * side / np.sqrt(max(covered, 1e-300)) * finer
    cap = np.sqrt(MAX_AUTO_CELLS * side / max(across, 1e-300 * side))  # (cells: r^2 across/side)
    return int(max(base, min(MAX_RESOLUTION, cap * finer, np.ceil(want))))


def _progress(quiet: bool, relative: bool = True):
    """The per-iteration lines: the errors over the diagonal, or with ``relative`` False
    (--absolute) in the data's units, as the tolerance was given (they had been over the
    diagonal either way: user test)."""
    rms, worst, fmt = ("rms_rel", "max_rel", ".2e") if relative else ("rms", "max", ".4g")

    def callback(r: dict) -> bool:
        if not quiet:
            sampled = f", {r['sampled_points']} sampled points" if "sampled_points" in r else ""
            # an uneven cloud meets the tolerance over its area too: why a run goes on
            area = (f"  over area {r[rms.replace('rms', 'rms_area')]:{fmt}}"
                    if "rms_area_rel" in r else "")
            # samples the face check added where the surface strayed between a mesh's points
            stray = (f", {r['stray_samples']} face samples added where it strayed"
                     if r.get("stray_samples") else "")
            print(
                f"  iteration {r['iteration']:3d}  knots {r['knots']:6d}  control points "
                f"{r['control_points']:6d}  rms {r[rms]:{fmt}}{area}  max {r[worst]:{fmt}}  "
                f"({r['seconds']:.1f} s{sampled}{stray})"
                + (f"  swings between the data at {r['swings']} places: the "
                   f"{r['knots_taken_back']} new knots taken back" if "knots_taken_back" in r
                   else ""),
                file=sys.stderr,
                flush=True,
            )
        return False

    return callback


def _read_inputs(paths: list) -> tuple[np.ndarray, np.ndarray | None, list]:
    """The points and faces of the input files (``read_geometry``, fill values kept), and
    each file's path and count of rows, in order. Several files are point clouds put together
    (DEM tiles: their shared nodes are the same point twice, which is one node of the grid:
    ``core.parameterize.on_xy_grid``); a mesh among several, and DEMs converted from degrees
    (each to metres from its own south-west corner, so tiles would lie on each other), are
    refused in one line."""
    if len(paths) == 1:
        points, faces = read_geometry(paths[0], keep_fill_values=True)
        return points, faces, [(paths[0], len(points))]
    parts, files = [], []
    for path in paths:
        points, faces = _read_tile(path, str(path), "several such tiles do not line up",
                                   "fit them together")
        if faces is not None:
            raise TCBError(f"{path} is a mesh: several inputs are point clouds fitted together "
                           "(fit a mesh alone, or its patches one by one with --join)")
        parts.append(points)
        files.append((path, len(points)))
    return np.vstack(parts), None, files


def _read_tile(path, who: str, why: str, to: str, keep_fill_values: bool = True):
    """``read_geometry(path)`` of a tile put beside others (several inputs, a neighbour to
    join), its warnings shown as reading shows them; a DEM whose bounds are in degrees is
    refused (``who`` is it, ``why`` the harm, ``to`` what projected bounds allow): each is
    put in metres from its own south-west corner, so tiles would lie on each other."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        read = read_geometry(path, keep_fill_values=keep_fill_values)
    if read[1] is None and any("bounds are in degrees" in str(w.message) for w in said):
        raise TCBError(f"{who} is a DEM with its bounds in degrees, which is converted to "
                       f"metres from its own south-west corner, so {why}; save the tiles with "
                       f"projected bounds (units='metres') to {to}")
    for w in said:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return read


def _all_dems(files: list, points: np.ndarray, bad: np.ndarray) -> bool:
    """Whether every input file is a DEM (``meshio.is_dem``), each judged by its rows of
    ``points`` that are fitted (``bad``: those left out, NaN or no-data fill values, which
    are on no grid)."""
    start = 0
    for path, n in files:
        rows = slice(start, start + n)
        start += n
        if not is_dem(path, points[rows][~bad[rows]]):
            return False
    return True


def _input_text(paths: list) -> str:
    """The input files as the messages name them: ``a.xyz``, ``a.xyz, b.xyz``, or the first
    two and how many more."""
    names = [str(p) for p in paths]
    if len(names) <= 3:
        return ", ".join(names)
    return f"{names[0]}, {names[1]} and {len(names) - 2} more files"


def _fit(args) -> int:
    from .parameterize import holes_error, outlier_error, spike_error
    from .surface import fit_surface

    _check_output(args.output, "surface")
    _check_output(args.net, "control net")
    _check_output(args.spline, "spline", {".npz"})
    _check_distinct(args)
    if args.resolution is not None and args.resolution < 2:
        raise TCBError(f"--resolution must be at least 2, got {args.resolution}")
    if args.resolution is not None and args.resolution > MAX_RESOLUTION:
        raise TCBError(f"--resolution must be at most {MAX_RESOLUTION} (about 12 million "
                       f"vertices), got {args.resolution}")
    t0 = time.perf_counter()
    # a DEM's no-data cells come back as points, found and refused or left out below as a
    # cloud's (the reader had refused them before --drop-invalid was seen: user test)
    points, faces, files = _read_inputs(args.inputs)
    if faces is not None and args.projection not in (None, "auto"):
        raise TCBError(
            f"--projection applies to point clouds; {args.input} is a mesh, which is "
            "parameterized by its faces: leave the option out"
        )
    given = points
    bad = ~np.isfinite(points).all(axis=1)
    if faces is not None and len(faces):
        # (a vertex in no face is left out of a mesh's fit as any loose one, NaN or not: the
        # engine does so, and the CLI had refused the file: user test)
        in_faces = np.zeros(len(points), dtype=bool)
        in_faces[np.asarray(faces).ravel()] = True
        bad &= in_faces
    if bad.any() and faces is not None:  # the engine's advice is Python; this is the CLI's
        raise TCBError(
            f"{int(bad.sum())} of the {len(points)} vertices of the mesh {args.input} have NaN "
            "or infinite coordinates; repair or delete them in a mesh editor (--drop-invalid "
            "applies to point clouds: a mesh's faces hold its vertices)"
        )
    if faces is not None and len(faces):  # (a loose vertex is left out of a mesh's fit)
        fill = fill_value_rows(points[in_faces])
        if fill is not None:
            raise TCBError(f"{fill_value_words(fill, len(fill[0]), 'vertices in faces')}: "
                           "repair those vertices or cut them out in a mesh editor")
    fill = fill_value_rows(points) if faces is None else None
    if fill is not None and not args.drop_invalid:  # (a no-data fill: user test)
        raise TCBError(f"{fill_value_words(fill, len(points))}; pass --drop-invalid to leave "
                       "them out")
    if bad.any() and faces is None:
        if not args.drop_invalid:
            raise TCBError(
                f"{int(bad.sum())} of {len(points)} points have NaN or infinite coordinates; "
                "pass --drop-invalid to leave them out"
            )
        if not args.quiet:
            print(f"left out {int(bad.sum())} points with NaN or infinite coordinates",
                  file=sys.stderr)
    if fill is not None:
        if not args.quiet:
            print(f"left out {int(fill[0].sum())} points with {'xyz'[fill[1]]} = {fill[2]:g} "
                  "(a no-data fill value)", file=sys.stderr)
        bad |= fill[0]
    if faces is None:
        points = points[~bad]
    if not args.quiet:
        kind = f"mesh with {len(faces)} faces" if faces is not None else "point cloud"
        print(f"read {args.input}: {len(points)} points, {kind}", file=sys.stderr)
    join = _neighbours(args, points, faces)
    # a DEM is heights over a grid of x and y: fitted along z unless told (meshio.is_dem)
    raster = faces is None and args.projection is None and _all_dems(files, given, bad)
    projection = "z" if raster else None if args.projection == "auto" else args.projection
    if raster and not args.quiet:
        what = "is a DEM raster" if len(args.inputs) == 1 else "are DEM rasters"
        print(f"{args.input} {what} (heights over a grid of x and y): fitted along z "
              "(--projection z; --projection auto chooses the best-fit plane)", file=sys.stderr)
    try:
        surf = fit_surface(
            points, faces, degree=args.degree, mode=args.mode, tolerance=args.tolerance,
            relative=args.relative, max_control_points=args.max_control_points,
            max_iterations=args.max_iterations, smoothness=args.smoothness,
            criterion=args.criterion, callback=_progress(args.quiet, args.relative),
            drop_outliers=args.drop_outliers, projection=projection,
            fill_holes=args.fill_holes, join=join,
        )
    except HolesError as exc:
        raise holes_error(exc.loops, advice="pass --fill-holes") from None
    except OutlierError as exc:
        if faces is not None:  # a mesh's spike vertices (its rows are the file's)
            raise spike_error(given, exc.indices, exc.heights,
                              advice=f"pass --drop-outliers, which {SPIKES_DISSOLVED}"
                              ) from None
        # number the outliers as in the file (not among the points left after --drop-invalid),
        # with this command's option
        raise outlier_error(given, np.flatnonzero(~bad)[exc.indices],
                            advice="pass --drop-outliers") from None
    sag = None
    if args.resolution:
        resolution = args.resolution
    else:  # the mesh within the fit's max error of the spline, as Blender's Auto Resolution
        resolution, sag = surf.auto_resolution(
            least=default_resolution(surf.report["control_points"], surf))
    verts, tris = surf.tessellate(resolution)
    # with a UV map: the spline's parameters as texture coordinates
    write_mesh(args.output, verts, tris,
               uv=surf.texture_coordinates(surf.tessellation_uv(resolution)[0]))
    if args.net:
        net_points, net_faces = surf.control_net()
        write_mesh(args.net, net_points, net_faces)
    if args.spline:
        surf.save(args.spline)
    r = surf.report
    rows = [
        ("input", f"{args.input} ({r['points']} points"
                  + (f", {r['outliers']} outliers left out" if r.get("outliers") else "")
                  + (f", {r['holes_filled']} hole{'s' if r['holes_filled'] > 1 else ''} spanned"
                     if r.get("holes_filled") else "")
                  + ")"),
        ("mode / degree", f"{r['mode']} / {r['degree']}"),
    ]
    param = surf.parameterization
    if param.kind == "plane":  # the direction used, to pass as --projection another time
        chosen = (("a DEM raster" if len(args.inputs) == 1 else "DEM rasters") if raster else
                  "given" if args.projection not in (None, "auto") else "chosen")
        rows.append(("projection", ",".join(f"{x:.4g}" for x in param.axes[2])
                     + f" ({chosen})"))
    rows += [
        ("knots (interior)", f"{r['knots']} ({r['interior_knots']})"),
        ("control points", f"{r['control_points']}"),
        ("iterations", f"{r['iterations']} ({r['stop_reason']})"
         + _returned(r, surf.options.criterion)),
        ("smoothness", _smoothness_text(r)),
    ]
    if "refit" in r:
        refit = r["refit"]
        extra = refit["points"] - r["points"]  # a mesh's: the points sampled on its faces
        what = (f"{r['points']} vertices and the {extra} points sampled on the faces" if extra > 0
                else f"{refit['points']} points")
        rows.append(("final fit", f"all {what} ({refit['seconds']:.1f} s; "
                                  "the iterations fitted a random subset)"))
    rows += [
        ("RMS error", f"{r['rms']:.4g} ({r['rms_rel']:.2e} of the diagonal)"),
        ("max error", f"{r['max']:.4g} ({r['max_rel']:.2e} of the diagonal)"),
    ]
    if "faces_max" in r:  # a mesh: between its vertices too
        # (and the samples fitted where the surface had strayed between the others)
        stray = (f"; fitted to {r['stray_samples']} more samples where it strayed between them"
                 if r.get("stray_samples") else "")
        rows.append(("on the faces", f"RMS {r['faces_rms']:.4g}, max {r['faces_max']:.4g} "
                                     f"({r['faces_max_rel']:.2e} of the diagonal){stray}"))
    near = args.tolerance > 0 and noise_near_tolerance(r, args.tolerance, args.relative,
                                                        args.criterion)
    if stopped_at_noise(r) or near:  # core.parameterize.local_noise
        rows.append(("noise", f"{r['noise']:.4g} ({r['noise_rel']:.2e} of the diagonal; "
                              "a tighter fit would follow it)"))
    if r.get("net_capped"):  # core.refine.NOISY_NET_PER_VERTEX
        rows.append(("net capped", f"{r['net_capped']} control points, one per vertex of the "
                                   "noisy mesh (more would fit its noise)"))
    if "rms_area" in r:  # a cloud: the RMS over its area (uneven density)
        rows.append(("RMS over area", f"{r['rms_area']:.4g} ({r['rms_area_rel']:.2e} of the diagonal)"))
    swings = r.get("swings") or {}
    if swings.get("places"):  # core.surface.data_swings: the warning above says what to do
        rows.append(("swings off data", f"up to {swings['largest']:.4g} ({swings['largest_rel']:.2e} "
                                        f"of the diagonal) at {swings['places']} places"))
    if r.get("folded", 0.0) > FOLDED_SHARE:  # core.surface.mesh_folds: warned of above
        rows.append(("folded over", f"{r['folded']:.2%} of the mesh's area"))
    rows += [
        ("surface", f"{args.output} ({len(verts)} vertices, {len(tris)} triangles, resolution "
                    f"{resolution}" + (", automatic" if not args.resolution else "")
                    + (f": the mesh within {sag:.3g} of the spline" if sag is not None
                       and np.isfinite(sag) else "") + ")"),
    ]
    if "join" in r and r["join"].get("kept_unjoined"):  # (warned of above; it had said
        j = r["join"]  # "joined": user test)
        rows.append(("joined", f"no: fitted on its own (every joined fit folded over the mesh "
                               f"at the shared border); the borders {j['gap_max']:.4g} apart "
                               f"at most ({j['gap_max_rel']:.2e} of the diagonal)"))
    elif "join" in r:
        j = r["join"]
        along = (f"along {j['shared_edges']} shared border edges" if j["shared_edges"]
                 else f"along {j['shared_length']:.4g} of shared border ({j['pins']} pins)")
        rows.append(("joined", f"{j['surfaces']} neighbour{'s' if j['surfaces'] > 1 else ''} "
                               f"{along}: the borders "
                               f"{j['gap_max']:.4g} apart at most ({j['gap_max_rel']:.2e} of "
                               f"the diagonal; {j['gap_max_unjoined_rel']:.2e} unjoined)"
                               + (f", {j['knots_added']} knots added along them"
                                  if j["knots_added"] else "")))
    if args.net:
        rows.append(("control net", args.net))
    if args.spline:
        rows.append(("spline", args.spline))
    rows.append(("seconds", f"{time.perf_counter() - t0:.2f}"))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    advice = {"control-point budget reached": "raise --max-control-points",
              "iteration limit": "raise --max-iterations",
              SWINGS_LEFT: "the rest of the error is where more knots made the surface swing "
                           "between the data points (a sharp step?)"}.get(
        SWINGS_LEFT if mostly_taken_back(r) else r["stop_reason"])
    if advice and r.get("spikes"):  # (the warning above names them: a sharp step had been
        # blamed for 30 stray points, the run spending 20 iterations on them; user test)
        advice = f"{SPIKES_HELD_OFF}: pass --drop-outliers"
    # (the mesh is what the user measures)
    if sag is not None and sag > sag_target(r, surf.options):
        # (at half: kept, or measured whole now if Auto Resolution passed over it on a sample,
        # a quarter of the finest's evaluations)
        finer = finer_resolution(resolution, sag, sag_target(r, surf.options),
                                 surf.tessellation_sag(resolution // 2)
                                 if resolution >= 4 else None)
        print(f"note: the surface mesh (resolution {resolution}, the finest chosen "
              f"automatically) strays up to {sag:.4g} from the spline, more than "
              f"{sag_target_words(r, surf.options)}: pass --resolution {finer} "
              + ("(the finest)" if finer >= MAX_RESOLUTION else "(or more)")
              + " to write the fit as it is", file=sys.stderr)
    gaps = surf.open_holes(resolution) if faces is None else 0
    if gaps:  # (a scan's occlusions came out as holes, the option unknown: user test)
        print(f"note: the surface mesh leaves {gaps} gap{'s' if gaps > 1 else ''} inside the "
              f"point cloud open (no points there); pass --fill-holes to cover "
              f"{'them' if gaps > 1 else 'it'} with the surface", file=sys.stderr)
    flat = flat_height_field(surf, points) if faces is None else None
    if flat is not None and args.relative and args.tolerance > 0:
        # (terrain "tolerance reached" at RMS 42.7 m on 840 m of relief: 1e-3 of a 44 km
        # diagonal; the README says terrain wants --absolute, the CLI said nothing: user test)
        across, height = flat
        print(f"note: the input is a height field {across:.5g} across and {height:.4g} high, "
              f"and the tolerance is relative to the bounding-box diagonal: "
              f"{args.tolerance:g} of it is {args.tolerance * r['diagonal']:.4g} in the "
              f"data's units ({args.tolerance * r['diagonal'] / height:.2g} of the height "
              "range); pass --absolute --tolerance T for a tolerance of T in the data's units",
              file=sys.stderr)
    if advice and args.tolerance > 0:  # the table says why it stopped, not what to change
        unit = " (a fraction of the bounding-box diagonal)" if args.relative else ""
        if near and not mostly_taken_back(r):  # the data's noise is near the tolerance
            key = "max" if args.criterion == "max" else "rms"  # the report's error, and its name
            reached = (f"about the {'max' if key == 'max' else 'RMS'} reached "
                       f"({r[key + '_rel' if args.relative else key]:.3g})")
            rate = fall_rate(r)
            spiky = advice.startswith(SPIKES_HELD_OFF)  # (its own advice: review)
            if rate is not None and rate >= STILL_FALLING and not spiky:  # (detail, or noise)
                advice = (f"the error was still falling (like knots^-{rate:.2f} at the "
                          f"end), so the scatter measured as noise ({r['noise']:.4g}, the "
                          f"row 'noise') may be fine detail of the shape: {advice}; if it is "
                          f"noise, more control points would mostly fit it: loosen --tolerance "
                          f"to {reached}")
            else:
                advice = (f"the data's noise ({r['noise']:.4g}, the row 'noise') held it off, "
                          f"and more control points would mostly fit the noise: loosen "
                          f"--tolerance to {reached}, or {advice}")
            print(f"note: the tolerance {args.tolerance:g}{unit} was not reached: {advice}",
                  file=sys.stderr)
        else:
            print(f"note: the tolerance {args.tolerance:g}{unit} was not reached: {advice}, or "
                  "loosen --tolerance", file=sys.stderr)
    return 0


def _neighbours(args, points: np.ndarray, faces) -> list | None:
    """``fit_surface``'s ``join`` from ``--join DATA SPLINE`` (each neighbour's data file and
    the spline fitted to it), or None; a one-line error for a neighbour of another kind (a
    cloud for a mesh or a mesh for a cloud), a spline not fitted to that data, or a mesh
    sharing no vertex with the input. A point cloud's neighbours are their surfaces
    (``core.join.cloud_seam`` finds the border they share)."""
    from .join import shared_vertices
    from .surface import TCBSurface

    if not args.join:
        return None
    join = []
    for mesh, spline in args.join:
        if any(_same_file(mesh, i) for i in args.inputs):
            raise TCBError(f"--join {mesh} {spline}: {mesh} is an input of this fit; join to "
                           "a neighbour's file and spline")
        # (a DEM in degrees: refused, as for several inputs; review)
        other, other_faces = _read_tile(mesh, f"--join {mesh} {spline}: {mesh}",
                                        "neighbouring tiles do not line up", "join them",
                                        keep_fill_values=faces is None)
        dropped = 0
        if faces is None:  # the rows the input's fit leaves out (--drop-invalid) ...
            bad = ~np.isfinite(other).all(axis=1)
            fill = fill_value_rows(other)
            if fill is not None:
                bad |= fill[0]
            dropped = int(bad.sum())
            if args.drop_invalid:  # ... left out of the neighbour's as they were of its fit
                other = other[~bad]
        if faces is None and other_faces is not None:
            raise TCBError(f"--join {mesh} {spline}: {mesh} is a mesh and {args.input} a "
                           "point cloud; give the neighbouring cloud's file")
        if faces is not None and other_faces is None:
            raise TCBError(f"--join {mesh} {spline}: {mesh} is a point cloud; give the "
                           "neighbouring patch's mesh")
        surf = TCBSurface.load(spline)
        if not surf.fitted_to(other):
            hint = (f"; {mesh} has {dropped} points with no data: pass --drop-invalid, as for "
                    "its fit" if dropped and not args.drop_invalid else "")
            raise TCBError(f"--join {mesh} {spline}: {spline} was not fitted to {mesh} (fit "
                           f"{mesh} with --spline {spline}, then join to it{hint})")
        if faces is None:
            join.append(surf)
            continue
        pairs = shared_vertices(points, other)
        if not len(pairs):
            raise TCBError(f"--join {mesh} {spline}: {mesh} has no vertex at the coordinates "
                           f"of one of {args.input}'s: not a neighbouring patch of the same "
                           "mesh")
        join.append((surf, pairs))
    return join


def _heights(args) -> int:
    """``heights``: the surface of ``args.spline`` over the x and y of ``args.points``
    (:meth:`TCBSurface.heights`), written with the points' own z minus it, and a line on how
    many are over the surface and how far their z is from it."""
    from .surface import TCBSurface

    out = Path(args.output)
    if out.suffix.lower() not in (".xyz", ".txt", ".csv"):
        raise TCBError(f"-o {args.output}: heights are written as text: give a .xyz, .txt or "
                       ".csv file")
    surf = TCBSurface.load(args.spline)
    points, _ = read_geometry(args.points)
    z = surf.heights(points[:, :2])
    dz = points[:, 2] - z
    sep = "," if out.suffix.lower() == ".csv" else " "
    # (12 digits: a millimetre of a UTM northing, 4.2e6 m, and 1e-5 of it)
    np.savetxt(out, np.c_[points[:, :2], z, dz], fmt="%.12g", delimiter=sep,
               header=sep.join(("x", "y", "z", "dz")), comments="")
    over = np.isfinite(z)
    line = f"wrote {out}: {int(over.sum())} of {len(z)} points are over the surface"
    if not over.all():
        line += " (the others: nan, beyond the fitted part)"
    if over.any():
        line += (f"; the points' z minus the surface's: RMS "
                 f"{float(np.sqrt(np.mean(dz[over] ** 2))):.4g}, largest "
                 f"{float(np.abs(dz[over]).max()):.4g}")
    print(line, file=sys.stderr)
    return 0


def _warning_line(message, category, filename, lineno, line=None) -> str:
    """A warning of the engine as one line, ``warning: ...`` (not Python's file:line form)."""
    return f"warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "fit":  # (several input files: args.input names them in messages)
        args.inputs, args.input = list(args.input), _input_text(args.input)
    shown = warnings.formatwarning
    warnings.formatwarning = _warning_line
    try:
        if args.command == "fit":
            return _fit(args)
        if args.command == "heights":
            return _heights(args)
    except TCBError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: {exc.strerror or exc}: {getattr(exc, 'filename', '')}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C: one line, not a traceback (user test)
        print("error: cancelled (Ctrl-C)", file=sys.stderr)
        return 130
    finally:
        warnings.formatwarning = shown
    return 1
