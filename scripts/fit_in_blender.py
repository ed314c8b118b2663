#!/usr/bin/env python3
"""Fit a TCB surface in Blender without the user interface (background scripting).

With the ``bpy`` wheel (``.venv``, created by ``bash scripts/test`` or ``scripts/demo``)::

    .venv/bin/python scripts/fit_in_blender.py data/nefertiti.off -o out/nefertiti.blend \\
        --export out/nefertiti_surface.obj --render out/nefertiti.png

With a real Blender (4.2.13 or later; arguments after ``--``)::

    blender -b -P scripts/fit_in_blender.py -- data/nefertiti.off -o out/nefertiti.blend

What it does, with Blender's own operators:

1. makes the extension available: with the ``bpy`` wheel, Blender's user folders point into a
   temporary directory (set before ``import bpy``, as in ``tests/blender/conftest.py``) and the
   extension zip is installed there with ``bpy.ops.extensions.package_install_files`` -- the zip
   in ``dist/`` when it is newer than the sources, otherwise one built on the fly by
   ``scripts/build_extension.py`` (about 1 s). Inside a real Blender an already enabled
   ``tcb_surface`` extension is used as is; otherwise the zip is installed into a temporary
   local repository that is removed again at exit (your preferences are not saved);
2. imports the input: PLY and OBJ with Blender's importers (file coordinates are kept: no axis
   conversion), OFF and the point-cloud formats (``.xyz .txt .csv .pts .npy .npz .asc``,
   including DEMs, which are fitted along their z as Import Points' are) with the extension's
   ``core.meshio`` into a new mesh object;
3. selects it and runs ``bpy.ops.tcb.fit_surface`` (synchronously: ``execute``), then
   ``bpy.ops.tcb.deviation_map`` (the surface's ``tcb_deviation_color`` attribute);
4. saves the ``.blend`` (surface, live control net, source), exports the surface mesh
   (``--export``: ``.obj``/``.ply`` by Blender's exporter, same coordinates as the input file;
   with the engine's float64 vertex coordinates when the surface object is exactly its
   tessellation, so the file keeps full precision far from the origin) and renders a picture
   (``--render``: Cycles on the CPU, surface colored by deviation, control net as tubes);
5. prints a report table (knots, control points, RMS / max errors, seconds).

Bad input (missing file, unknown format, closed mesh, ...) exits with status 1 and a one-line
``fit_in_blender: error: ...`` message on stderr.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXT_ID = "tcb_surface"
BLENDER_IMPORT = {".ply": "ply_import", ".obj": "obj_import"}
OTHER_FORMATS = (".off", ".xyz", ".txt", ".csv", ".pts", ".npy", ".npz", ".asc")
EXPORT_FORMATS = {".obj": "obj_export", ".ply": "ply_export"}
# the limits of the Fit settings (tcb_addon/properties.py; this script checks them before
# Blender starts), and of Blender's integer settings
MIN_BUDGET, MAX_RESOLUTION, MIN_TOLERANCE, MAX_INT = 10, 2048, 1e-9, 2**31 - 1
# keep the coordinates of the file (Blender's OBJ importer would turn Y-up into Z-up)
SAME_AXES = dict(forward_axis="Y", up_axis="Z")
T0 = time.perf_counter()


class ScriptError(Exception):
    """A problem with the input or the environment; printed as one line, exit status 1."""


def log(msg: str) -> None:
    print(f"[fit_in_blender] {msg}", flush=True)


# --- arguments --------------------------------------------------------------------------------


def script_args(argv: list[str]) -> list[str]:
    """The script's own arguments: after ``--`` when there is one (``blender -b -P script --
    ...``), else everything after the script name (``python script ...``)."""
    if "--" in argv:
        return argv[argv.index("--") + 1 :]
    return argv[1:]


def smoothness_arg(text: str):
    """``--smoothness``: a nonnegative number or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (value >= 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a nonnegative number or 'auto', got {text!r}")
    return value


def parse_args(args: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="fit_in_blender.py",
        description="Fit a smooth TCB-spline surface to a scan or disk-like mesh in Blender "
        "(background mode) and save the .blend.",
        epilog="Inside Blender: blender -b -P scripts/fit_in_blender.py -- INPUT -o OUT.blend",
    )
    # an option error is bad input like any other: one line, status 1 (argparse prints its
    # whole usage first, and exits with 2)
    ap.error = lambda message: ap.exit(1, f"fit_in_blender: error: {message} (see --help)\n")
    ap.add_argument("input", type=Path,
                    help="PLY, OBJ, OFF mesh, or XYZ/TXT/CSV/PTS/NPY/NPZ points")
    ap.add_argument("-o", "--output", type=Path, required=True, help="the .blend file to write")
    ap.add_argument("--tolerance", type=float, default=1e-3,
                    help="target error: a fraction of the bounding-box diagonal (--relative, "
                    "the default) or a distance in scene units (--absolute); default %(default)g")
    rel = ap.add_mutually_exclusive_group()
    rel.add_argument("--relative", dest="relative", action="store_true", default=True,
                     help="the tolerance is relative to the bounding-box diagonal (default)")
    rel.add_argument("--absolute", dest="relative", action="store_false",
                     help="the tolerance is a distance in the input's units")
    ap.add_argument("--criterion", choices=("rms", "max"), default="rms",
                    help="which error the tolerance bounds (default %(default)s)")
    ap.add_argument("--max-control-points", type=int, default=2000, metavar="N",
                    help="budget of control points (default %(default)s)")
    ap.add_argument("--max-iterations", type=int, default=20, metavar="N",
                    help="largest number of refinement steps (default %(default)s)")
    ap.add_argument("--degree", type=int, choices=(2, 3), default=2,
                    help="spline degree (default 2)")
    ap.add_argument("--mode", choices=("tcb", "dcb"), default="tcb",
                    help="spline space: tcb or dcb (default %(default)s)")
    ap.add_argument("--smoothness", type=smoothness_arg, default=None,
                    help="weight of the smoothing term, or 'auto' (chosen by cross-validation); "
                    "without it 1e-4, which on sparse clouds, under 2 points per control point, "
                    "is cross-validated as in Blender's panel left at its default (a value "
                    "given, 1e-4 too, is used as it is)")
    ap.add_argument("--drop-outliers", action="store_true",
                    help="leave out points far from all others (point clouds; a mesh is fitted "
                    "without it, with a note)")
    ap.add_argument("--fill-holes", action="store_true",
                    help="meshes with holes: let the surface span them (Blender's Fill Holes)")
    ap.add_argument("--projection", choices=("auto", "x", "y", "z"), default="auto",
                    help="point clouds: project along this world axis (z for terrain tiles that "
                    "meet their neighbours) instead of choosing the direction (default "
                    "%(default)s: the best-fit plane, or a DEM raster's z)")
    ap.add_argument("--resolution", type=int, default=64,
                    help="subdivisions of the output surface mesh per side (default %(default)s)")
    ap.add_argument("--no-live-net", dest="live_net", action="store_false",
                    help="no Geometry Nodes modifier linking the surface to the control net")
    ap.add_argument("--no-deviation", dest="deviation", action="store_false",
                    help="skip the deviation map (the render is then plain grey)")
    ap.add_argument("--export", type=Path, metavar="OUT.obj|OUT.ply",
                    help="also write the surface mesh (same coordinates as the input file)")
    ap.add_argument("--render", type=Path, metavar="OUT.png", help="also render a picture")
    ap.add_argument("--render-size", default="640x480", metavar="WxH",
                    help="render resolution (default %(default)s)")
    ap.add_argument("--samples", type=int, default=24, help="Cycles samples (default %(default)s)")
    ns = ap.parse_args(args)
    try:
        w, h = (int(v) for v in ns.render_size.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        ns.render_size = (w, h)
    except ValueError:
        ap.error(f"--render-size must look like 640x480, not {ns.render_size!r}")
    # the limits of the Fit settings in Blender, which would clamp a value beyond them
    # silently (a tolerance of -1 ran as 1e-9, --resolution 0 as 2: user test)
    if not (ns.tolerance == 0 or MIN_TOLERANCE <= ns.tolerance < math.inf):
        ap.error(f"--tolerance must be 0 (refine to the budget) or at least {MIN_TOLERANCE:g}, "
                 f"got {ns.tolerance:g}")
    for option, value, least in (("--max-control-points", ns.max_control_points, MIN_BUDGET),
                                 ("--max-iterations", ns.max_iterations, 1),
                                 ("--resolution", ns.resolution, 2),
                                 ("--samples", ns.samples, 1)):
        if value < least:
            ap.error(f"{option} must be at least {least}, got {value}")
        if value > MAX_INT:  # (Blender's settings are 32-bit: a traceback; review)
            ap.error(f"{option} must be at most {MAX_INT}, got {value}")
    if ns.resolution > MAX_RESOLUTION:
        ap.error(f"--resolution must be at most {MAX_RESOLUTION}, got {ns.resolution}")
    return ns


def check_paths(ns: argparse.Namespace) -> None:
    """Fail fast (before Blender starts) on what can be checked without it."""
    src = ns.input
    if not src.exists():
        raise ScriptError(f"input file not found: {src}")
    if not src.is_file():
        raise ScriptError(f"input is not a file: {src}")
    suffix = src.suffix.lower()
    if suffix not in BLENDER_IMPORT and suffix not in OTHER_FORMATS:
        known = ", ".join(sorted({*BLENDER_IMPORT, *OTHER_FORMATS}))
        raise ScriptError(f"unsupported input format '{suffix or src.name}' (use one of {known})")
    if ns.output.suffix.lower() != ".blend":
        raise ScriptError(f"the output must be a .blend file, not '{ns.output}'")
    if ns.export is not None and ns.export.suffix.lower() not in EXPORT_FORMATS:
        raise ScriptError(f"--export writes .obj or .ply, not '{ns.export}'")
    if ns.render is not None and ns.render.suffix.lower() != ".png":
        raise ScriptError(f"--render writes a .png, not '{ns.render}'")
    for option, path in (("-o", ns.output), ("--export", ns.export), ("--render", ns.render)):
        if path is None:
            continue
        # never over the input (--export scan.obj replaced the scan with the surface: user
        # test), and a folder that can take the file, found before the fit, not after it
        if path.exists() and (path.resolve() == src.resolve() or os.path.samefile(path, src)):
            raise ScriptError(f"{option} {path} is the input file: the input is never "
                              "overwritten; write the output to another file")
        if path.is_dir():  # (found after the fit, when the save failed: review)
            raise ScriptError(f"{option} {path} is a folder: give a file name")
        folder = path.resolve().parent  # made if missing: its nearest existing folder
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if not folder.is_dir():
            raise ScriptError(f"{option} {path}: {folder} is a file, not a folder")
        if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
            raise ScriptError(f"{option} {path}: cannot write there (permission denied)")


# --- making the extension available -------------------------------------------------------------


def blender_platform() -> str:
    machine = platform.machine().lower()
    arm = machine in {"arm64", "aarch64"}
    if sys.platform.startswith("linux"):
        return "linux-arm64" if arm else "linux-x64"
    if sys.platform == "darwin":
        return "macos-arm64" if arm else "macos-x64"
    if sys.platform == "win32":
        return "windows-arm64" if arm else "windows-x64"
    return sys.platform


def _sources_mtime() -> float:
    files = [ROOT / "__init__.py", ROOT / "blender_manifest.toml"]
    for sub in ("core", "tcb_addon"):
        files += (ROOT / sub).rglob("*.py")
    return max((f.stat().st_mtime for f in files if f.is_file()), default=0.0)


def extension_zip(tmp: Path, blender_binary: str | None) -> Path:
    """``dist/``'s zip for this platform when it is newer than the sources, else a fresh build."""
    plat = blender_platform()
    dist = sorted((ROOT / "dist").glob(f"{EXT_ID}-*-{plat.replace('-', '_')}.zip"))
    if dist and dist[-1].stat().st_mtime >= _sources_mtime():
        return dist[-1]
    pyver = f"{sys.version_info.major}.{sys.version_info.minor}"
    out = tmp / "dist"
    cmd = [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platform", plat,
           "--out", str(out)]  # fmt: skip
    if pyver in ("3.11", "3.13"):
        cmd += ["--python", pyver]
    if blender_binary:
        cmd += ["--blender", blender_binary]
    log(f"building the extension zip for {plat} (dist/ has none newer than the sources)")
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=False)
    zips = sorted(out.glob(f"{EXT_ID}-*.zip"))
    if proc.returncode != 0 or len(zips) != 1:
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-1:] or ["no output"]
        raise ScriptError(
            f"building the extension failed: {tail[0]} (run: bash scripts/build_extension)"
        )
    return zips[0]


def redirect_user_folders(tmp: Path) -> None:
    """Point the ``bpy`` wheel's user folders at ``tmp`` (must happen before ``import bpy``)."""
    os.environ["BLENDER_USER_RESOURCES"] = str(tmp)
    for sub, var in (("config", "CONFIG"), ("scripts", "SCRIPTS"), ("extensions", "EXTENSIONS"),
                     ("datafiles", "DATAFILES")):  # fmt: skip
        os.environ[f"BLENDER_USER_{var}"] = str(tmp / sub)


def enabled_addon(bpy) -> str | None:
    for name in bpy.context.preferences.addons.keys():
        if name == EXT_ID or name.endswith("." + EXT_ID):
            return name
    return None


def install_extension(bpy, tmp: Path, real_blender: bool, cleanup: list) -> str:
    """Install and enable the extension; returns its module name (``bl_ext.<repo>.tcb_surface``).
    Appends to ``cleanup`` what must be undone before exiting (the temporary repository)."""
    name = enabled_addon(bpy)
    if name is not None:
        log(f"using the installed extension {name}")
        return name
    zip_path = extension_zip(tmp, bpy.app.binary_path if real_blender else None)
    repo_module = "user_default"
    if real_blender:
        # not into the user's own repository: a temporary local one, removed at exit
        repos = bpy.context.preferences.extensions.repos
        repo_module = f"tcb_tmp_{os.getpid()}"
        repo = repos.new(name=repo_module, module=repo_module,
                         custom_directory=str(tmp / "repo"), source="USER")  # fmt: skip

        def _remove_repo():
            try:
                bpy.ops.preferences.addon_disable(module=f"bl_ext.{repo_module}.{EXT_ID}")
                repos.remove(repo)
            except Exception:  # noqa: BLE001 (best effort at exit)
                pass

        cleanup.append(_remove_repo)
    t0 = time.perf_counter()
    try:
        result = bpy.ops.extensions.package_install_files(
            filepath=str(zip_path), repo=repo_module, enable_on_install=True
        )
    except RuntimeError as ex:
        raise ScriptError(f"installing {zip_path.name} failed: {first_line(ex)}") from None
    name = f"bl_ext.{repo_module}.{EXT_ID}"
    if result != {"FINISHED"} or name not in bpy.context.preferences.addons:
        raise ScriptError(f"installing {zip_path.name} did not enable {name}")
    rel = zip_path.relative_to(ROOT) if zip_path.is_relative_to(ROOT) else zip_path.name
    log(f"installed {rel} in {time.perf_counter() - t0:.1f} s")
    return name


# --- scene ------------------------------------------------------------------------------------


def first_line(ex: BaseException) -> str:
    text = str(ex).strip()
    for prefix in ("Error: ", "Warning: "):
        text = text.removeprefix(prefix)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    msg = lines[0] if lines else type(ex).__name__
    return msg.removeprefix("Error: ")


def clear_scene(bpy) -> None:
    """An empty scene without reloading the preferences (which would drop the extension)."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for coll in (bpy.data.collections, bpy.data.meshes, bpy.data.cameras, bpy.data.lights,
                 bpy.data.materials):  # fmt: skip
        for block in list(coll):
            if block.users == 0:
                coll.remove(block)


def import_input(bpy, addon: str, path: Path) -> list:
    """Import ``path`` into the scene; returns the new mesh objects."""
    before = set(bpy.data.objects)
    suffix = path.suffix.lower()
    op_name = BLENDER_IMPORT.get(suffix)
    if op_name is not None and hasattr(bpy.ops.wm, op_name):
        try:
            getattr(bpy.ops.wm, op_name)(filepath=str(path), **SAME_AXES)
        except RuntimeError as ex:
            raise ScriptError(f"cannot read {path}: {first_line(ex)}") from None
        objs = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
        if not objs or not any(len(o.data.vertices) for o in objs):
            raise ScriptError(f"{path} contains no vertices")
        return objs
    meshio = importlib.import_module(f"{addon}.core.meshio")
    errors = importlib.import_module(f"{addon}.core.errors")
    bridge = importlib.import_module(f"{addon}.tcb_addon.bridge")
    try:
        points, faces = meshio.read_geometry(path)
    except (errors.TCBError, OSError, ValueError) as ex:
        raise ScriptError(first_line(ex)) from None
    if len(points) == 0:
        raise ScriptError(f"{path} contains no points")
    # far from the world origin (georeferenced data) the object gets an origin near the points
    # and the mesh coordinates relative to it: 32-bit world coordinates would round them
    origin = bridge.local_origin(points)
    mesh = bridge.new_mesh(path.stem, points - origin, faces)
    obj = bridge.link_new_object(bpy.context.scene.collection, path.stem, mesh, origin)
    if faces is None and meshio.is_dem(path, points):  # (fitted along its z, as Import Points')
        obj[importlib.import_module(f"{addon}.tcb_addon.operators").RASTER_KEY] = True
    return [obj]


def select_only(bpy, objs) -> None:
    view_layer = bpy.context.view_layer
    view_layer.update()
    for o in view_layer.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    view_layer.objects.active = objs[0] if objs else None


def fit(bpy, objs, ns):
    select_only(bpy, objs)
    before = set(bpy.data.objects)
    props = dict(
        tolerance=ns.tolerance, relative=ns.relative, criterion=ns.criterion.upper(),
        max_control_points=ns.max_control_points, max_iterations=ns.max_iterations,
        degree=str(ns.degree), mode=ns.mode.upper(),
        auto_smoothness=ns.smoothness == "auto", drop_outliers=ns.drop_outliers,
        fill_holes=ns.fill_holes, projection=ns.projection.upper(),
        resolution=ns.resolution, show_net=True, live_net=ns.live_net,
    )  # fmt: skip
    if ns.smoothness not in (None, "auto"):  # (a Smoothness set is used as it is, 1e-4 too)
        props["smoothness"] = ns.smoothness
    override = dict(selected_objects=list(objs), active_object=objs[0], object=objs[0])
    try:
        with bpy.context.temp_override(**override):
            bpy.ops.tcb.fit_surface(**props)
    except (RuntimeError, TypeError) as ex:  # (the panel's words for the script's options)
        raise ScriptError(first_line(ex).replace("turn on Fill Holes in the fit settings",
                                                 "pass --fill-holes")) from None
    surfaces = [o for o in bpy.data.objects if o not in before and o.tcb.role == "SURFACE"]
    if len(surfaces) != 1:
        raise ScriptError("the fit produced no surface object")
    return surfaces[0]


def deviation_map(bpy, surface) -> None:
    override = dict(selected_objects=[surface], active_object=surface, object=surface)
    try:
        with bpy.context.temp_override(**override):
            bpy.ops.tcb.deviation_map(points_copy=True)
    except RuntimeError as ex:
        raise ScriptError(f"deviation map: {first_line(ex)}") from None


def engine_tessellation(bpy, addon: str, surface):
    """(vertices, triangles) in float64 when the surface object shows exactly the stored
    spline's tessellation at its resolution (its net unedited, or edited and re-tessellated):
    the same faces, and vertices within 32-bit rounding of it. Else None."""
    import numpy as np

    ops = importlib.import_module(f"{addon}.tcb_addon.operators")
    bridge = importlib.import_module(f"{addon}.tcb_addon.bridge")
    try:
        verts, tris = ops.stored_surface(surface).tessellate(surface.tcb.resolution)
    except ops._user_errors():
        return None
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = surface.evaluated_get(depsgraph).data
    if len(mesh.vertices) != len(verts) or len(mesh.polygons) != len(tris):
        return None
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", corners)
    if np.any(sizes != 3) or not np.array_equal(corners, np.ravel(tris)):
        return None
    shown = bridge.read_world_positions(surface, depsgraph)
    size = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))
    tol = 1e-5 * size + 2 * np.spacing(np.abs(shown).astype(np.float32))
    return (verts, tris) if np.all(np.abs(shown - verts) <= tol) else None


def export_surface(bpy, addon: str, surface, path: Path) -> None:
    """The surface mesh, in the input file's coordinates, by Blender's exporter (OBJ: vertex
    normals; PLY: the deviation colors and ``tcb_deviation``). Its 32-bit world coordinates are
    coarse far from the origin (0.5 apart at 4.2e6): when the surface object is exactly the
    engine's tessellation, the file's vertex coordinates are then replaced with the float64
    ones (OBJ: 17 digits; PLY: ``double x, y, z``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    select_only(bpy, [surface])
    op = getattr(bpy.ops.wm, EXPORT_FORMATS[path.suffix.lower()])
    kwargs = dict(filepath=str(path), export_selected_objects=True, apply_modifiers=True,
                  export_uv=False, **SAME_AXES)  # fmt: skip
    if path.suffix.lower() == ".obj":
        kwargs.update(export_materials=False)
    try:
        op(**kwargs)
    except RuntimeError as ex:
        raise ScriptError(f"exporting {path}: {first_line(ex)}") from None
    mesh = engine_tessellation(bpy, addon, surface)
    if mesh is None:
        log("the surface is not the stored spline's tessellation: 32-bit coordinates exported")
    elif not full_precision(path, mesh[0]):
        log(f"{path.name}: unexpected layout, kept the 32-bit coordinates of Blender's exporter")


def _matches(found, verts) -> bool:
    """``found`` are the file's 32-bit coordinates of ``verts`` (float64), in the same order."""
    import numpy as np

    if found.shape != verts.shape:
        return False
    size = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))
    tol = 1e-4 * size + 4 * np.spacing(np.abs(verts).astype(np.float32)).astype(np.float64)
    return bool(np.all(np.abs(found - verts) <= tol))


def full_precision(path: Path, verts) -> bool:
    """Replace the vertex coordinates of an OBJ / binary little-endian PLY file written by
    Blender's exporter with ``verts`` (float64, the same vertices in the same order: checked).
    Returns False, leaving the file as it is, when its layout is not the expected one."""
    import numpy as np

    data = path.read_bytes()
    if path.suffix.lower() == ".obj":
        lines = data.decode("utf-8").splitlines(keepends=True)
        rows = [i for i, ln in enumerate(lines) if ln.startswith("v ")]
        try:
            found = np.array([[float(t) for t in lines[i].split()[1:4]] for i in rows])
        except ValueError:
            return False
        if not _matches(found.reshape(-1, 3), verts):
            return False
        for i, v in zip(rows, verts):
            lines[i] = "v %.17g %.17g %.17g\n" % tuple(v)
        path.write_text("".join(lines), encoding="utf-8")
        return True
    end = data.find(b"end_header\n")
    if end < 0:
        return False
    header = data[: end + len(b"end_header\n")].decode("ascii").splitlines()
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "char": "i1", "ushort": "<u2",
             "short": "<i2", "uint": "<u4", "int": "<i4"}  # fmt: skip
    fields, out, count, in_vertex, elements = [], [], 0, False, []
    for ln in header:
        words = ln.split()
        if words[:1] == ["element"]:
            if len(words) != 3 or not words[2].isdigit():
                return False
            elements.append(words[1])
            in_vertex = words[1] == "vertex"
            count = int(words[2]) if in_vertex else count
        elif in_vertex and words[:1] == ["property"]:
            if len(words) != 3 or words[1] not in types:
                return False
            fields.append((words[2], types[words[1]]))
            if words[2] in ("x", "y", "z"):  # the first three (checked below)
                ln = f"property double {words[2]}"
        out.append(ln)
    names = [f for f, _ in fields]
    if "format binary_little_endian 1.0" not in header or elements[:1] != ["vertex"]:
        return False  # the vertex records must come first, right after the header
    if names[:3] != ["x", "y", "z"] or len(set(names)) != len(names):
        return False
    old = np.dtype(fields)
    start = end + len(b"end_header\n")
    if len(data) < start + count * old.itemsize:
        return False
    rec = np.frombuffer(data, dtype=old, count=count, offset=start)
    if not _matches(np.c_[rec["x"], rec["y"], rec["z"]].astype(np.float64), verts):
        return False
    xyz = ("x", "y", "z")
    new = np.empty(count, dtype=np.dtype([(n, "<f8" if n in xyz else t) for n, t in fields]))
    for name, _ in fields:
        new[name] = rec[name]
    new["x"], new["y"], new["z"] = verts.T
    rest = data[start + count * old.itemsize :]
    path.write_bytes(("\n".join(out) + "\n").encode("ascii") + new.tobytes() + rest)
    return True


# --- render -------------------------------------------------------------------------------------

NET_RENDER_GROUP = "TCB Net Tubes"


def _net_tubes_group(bpy, radius: float, tube_material, point_material):
    """Geometry Nodes: the net object's edges as tubes and its vertices as small spheres."""
    ng = bpy.data.node_groups.new(NET_RENDER_GROUP, "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Net", in_out="INPUT", socket_type="NodeSocketObject")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = ng.nodes, ng.links
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    to_curve = nodes.new("GeometryNodeMeshToCurve")
    profile = nodes.new("GeometryNodeCurvePrimitiveCircle")
    profile.inputs["Resolution"].default_value = 8
    profile.inputs["Radius"].default_value = radius
    sweep = nodes.new("GeometryNodeCurveToMesh")
    ball = nodes.new("GeometryNodeMeshIcoSphere")
    ball.inputs["Radius"].default_value = 2.5 * radius
    ball.inputs["Subdivisions"].default_value = 2
    to_points = nodes.new("GeometryNodeMeshToPoints")
    instance = nodes.new("GeometryNodeInstanceOnPoints")
    realize = nodes.new("GeometryNodeRealizeInstances")
    tube_mat = nodes.new("GeometryNodeSetMaterial")
    tube_mat.inputs["Material"].default_value = tube_material
    point_mat = nodes.new("GeometryNodeSetMaterial")
    point_mat.inputs["Material"].default_value = point_material
    join = nodes.new("GeometryNodeJoinGeometry")
    links.new(gin.outputs["Net"], info.inputs["Object"])
    links.new(info.outputs["Geometry"], to_curve.inputs["Mesh"])
    links.new(to_curve.outputs["Curve"], sweep.inputs["Curve"])
    links.new(profile.outputs["Curve"], sweep.inputs["Profile Curve"])
    links.new(sweep.outputs["Mesh"], tube_mat.inputs["Geometry"])
    links.new(info.outputs["Geometry"], to_points.inputs["Mesh"])
    links.new(to_points.outputs["Points"], instance.inputs["Points"])
    links.new(ball.outputs["Mesh"], instance.inputs["Instance"])
    links.new(instance.outputs["Instances"], realize.inputs["Geometry"])
    links.new(realize.outputs["Geometry"], point_mat.inputs["Geometry"])
    links.new(tube_mat.outputs["Geometry"], join.inputs["Geometry"])
    links.new(point_mat.outputs["Geometry"], join.inputs["Geometry"])
    links.new(join.outputs["Geometry"], gout.inputs["Geometry"])
    for i, node in enumerate(nodes):
        node.location = (220 * (i % 5), -220 * (i // 5))
    return ng


def _flat_material(bpy, name, color, emission=0.0, roughness=0.5):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    if emission:
        bsdf.inputs["Emission Color"].default_value = (*color, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    mat.diffuse_color = (*color, 1.0)
    return mat


def setup_render(bpy, surface, sources, ns) -> None:
    """Camera, light, world, net tubes and Cycles settings for ``--render`` (also saved in the
    .blend, so F12 there gives the same picture)."""
    import numpy as np
    from mathutils import Matrix, Vector

    scene = bpy.context.scene
    net = surface.tcb.net
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = surface.evaluated_get(depsgraph)
    verts = np.empty(len(ev.data.vertices) * 3, np.float32)
    ev.data.vertices.foreach_get("co", verts)
    m = np.array(surface.matrix_world)
    verts = verts.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    center = 0.5 * (verts.min(0) + verts.max(0))
    diag = float(np.linalg.norm(verts.max(0) - verts.min(0))) or 1.0

    # view direction: the surface's normal (least principal axis), on its convex side (where
    # the middle of the patch bulges to, away from its border: the side a scanner saw), then
    # from a little above and to the right for some relief. "Above": +z, or +y when the patch
    # faces +-z (a height field or a scan stored facing z).
    mean = verts.mean(0)
    _, _, vt = np.linalg.svd(verts - mean, full_matrices=False)
    normal = vt[2]
    border = np.linalg.norm((verts - mean) @ vt[:2].T, axis=1)
    rim = verts[border >= np.quantile(border, 0.9)]
    if np.dot(mean - rim.mean(0), normal) < 0:
        normal = -normal
    up = np.array([0.0, 1.0, 0.0]) if abs(normal[2]) > 0.7 else np.array([0.0, 0.0, 1.0])
    up = up - np.dot(up, normal) * normal
    up /= np.linalg.norm(up)
    right = np.cross(up, normal)
    view = normal + 0.35 * up + 0.3 * right
    view /= np.linalg.norm(view)
    cam_up = up

    cam_data = bpy.data.cameras.new("TCB Camera")
    cam_data.lens = 50
    cam = bpy.data.objects.new("TCB Camera", cam_data)
    scene.collection.objects.link(cam)
    z = Vector(view)  # the camera looks along -z
    x = Vector(np.cross(cam_up, view)).normalized()
    y = z.cross(x)
    cam.matrix_world = Matrix((x, y, z)).transposed().to_4x4()
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = ns.render_size
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    # framed: the surface and its whole control net (the net's outer points had run off the
    # picture's edges, its lines cut there)
    shown = verts[:: max(1, len(verts) // 4000)]
    if net is not None and net.type == "MESH" and len(net.data.vertices):
        pts = np.empty(len(net.data.vertices) * 3, np.float32)
        net.data.vertices.foreach_get("co", pts)
        mn = np.array(net.matrix_world)
        shown = np.vstack([shown, pts.reshape(-1, 3).astype(np.float64) @ mn[:3, :3].T
                           + mn[:3, 3]])
    coords = [float(c) for c in shown.ravel()]
    loc, _ = cam.camera_fit_coords(bpy.context.evaluated_depsgraph_get(), coords)
    # back off along the view axis so the object does not touch the frame
    depth = max((Vector(loc) - Vector(center)).dot(z), diag * 0.1)
    cam.location = Vector(loc) + z * (0.08 * depth)
    cam_data.clip_start = diag * 1e-3
    cam_data.clip_end = diag * 100

    # light: a key sun from the upper left of the camera, a soft world
    sun_data = bpy.data.lights.new("TCB Sun", "SUN")
    sun_data.energy = 3.0
    sun_data.angle = 0.2
    sun = bpy.data.objects.new("TCB Sun", sun_data)
    scene.collection.objects.link(sun)
    key = np.asarray(view) + 0.6 * np.asarray(y) - 0.5 * np.asarray(x)
    sun.rotation_euler = Vector(key).to_track_quat("Z", "Y").to_euler()
    world = scene.world or bpy.data.worlds.new("TCB World")
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if bg is not None:
        bg.inputs["Color"].default_value = (0.30, 0.32, 0.36, 1.0)
        bg.inputs["Strength"].default_value = 0.6
    world.color = (0.30, 0.32, 0.36)

    # what is rendered: the surface (its deviation material, or grey) and the net as tubes
    if not surface.data.materials:
        surface.data.materials.append(_flat_material(bpy, "TCB Surface", (0.6, 0.6, 0.62)))
    for obj in sources:
        obj.hide_render = True
    if net is not None:
        net.hide_render = True
        tube_mat = _flat_material(bpy, "TCB Net", (0.03, 0.03, 0.035), roughness=0.3)
        point_mat = _flat_material(bpy, "TCB Control Points", (1.0, 0.45, 0.0), emission=1.0)
        tubes_mesh = bpy.data.meshes.new(f"{net.name} tubes")
        tubes = bpy.data.objects.new(f"{net.name} (render)", tubes_mesh)
        for coll in net.users_collection:
            coll.objects.link(tubes)
        tubes.matrix_world = net.matrix_world
        tubes.hide_select = True
        mod = tubes.modifiers.new("Net Tubes", "NODES")
        mod.node_group = _net_tubes_group(bpy, diag * 0.0012, tube_mat, point_mat)
        ident = next(i.identifier for i in mod.node_group.interface.items_tree
                     if getattr(i, "in_out", None) == "INPUT" and i.name == "Net")  # fmt: skip
        mod[ident] = net

    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = ns.samples
    cy.use_adaptive_sampling = True
    cy.max_bounces = 4
    try:
        import _cycles

        denoise = bool(getattr(_cycles, "with_openimagedenoise", False))
    except ImportError:
        denoise = False
    cy.use_denoising = denoise
    if denoise:
        cy.denoiser = "OPENIMAGEDENOISE"
    scene.view_settings.view_transform = "Standard"  # the legend's colors, not AgX's
    scene.view_settings.look = "None"
    scene.render.image_settings.file_format = "PNG"
    scene.render.film_transparent = False


def render(bpy, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.context.scene.render.filepath = str(path.resolve())
    try:
        bpy.ops.render.render(write_still=True)
    except RuntimeError as ex:
        raise ScriptError(f"render: {first_line(ex)}") from None


# --- report -------------------------------------------------------------------------------------


def fit_stats(surface) -> dict:
    """The statistics of the fit (read before the deviation map replaces RMS / max with the
    distances it measures)."""
    st = surface.tcb
    keys = ("degree", "mode", "tolerance", "relative", "criterion", "max_control_points",
            "knots", "control_points", "iterations", "rms", "max", "rms_rel", "max_rel",
            "seconds", "smoothness", "auto_smoothness")  # fmt: skip
    return {k: getattr(st, k) for k in keys}


def report_table(surface, stats: dict, n_points: int, n_faces: int, timings: dict) -> str:
    from types import SimpleNamespace

    st = SimpleNamespace(**stats)
    dev = surface.tcb
    ev_verts = len(surface.data.vertices)
    ev_faces = len(surface.data.polygons)
    rows = [
        ("input", f"{n_points} points" + (f", {n_faces} triangles" if n_faces else "")),
        ("settings", f"degree {st.degree}, {st.mode}, tolerance {st.tolerance:g}"
                     f"{' (relative)' if st.relative else ''} on the {st.criterion or 'RMS'}, "
                     f"max {st.max_control_points} control points"),
        ("knots", f"{st.knots}"),
        ("control points", f"{st.control_points}"),
        ("iterations", f"{st.iterations}"),
        ("smoothness", f"{st.smoothness:.3g}" + (" (auto)" if st.auto_smoothness else "")),
        ("RMS error", f"{st.rms:.6g}  ({100 * st.rms_rel:.3g} % of the diagonal)"),
        ("max error", f"{st.max:.6g}  ({100 * st.max_rel:.3g} % of the diagonal)"),
        ("surface mesh", f"{ev_verts} vertices, {ev_faces} faces"),
        ("fit", f"{st.seconds:.2f} s (engine)"),
    ]  # fmt: skip
    if dev.has_deviation:
        rows.append(("deviation colors", f"0 (blue) .. {dev.deviation_max:.4g} (red)"))
    rows += [(k, f"{v:.2f} s") for k, v in timings.items()]
    width = max(len(k) for k, _ in rows)
    line = "-" * (width + 2 + max(len(v) for _, v in rows))
    return "\n".join([line, *(f"{k:<{width}}  {v}" for k, v in rows), line])


# --- main ---------------------------------------------------------------------------------------


def run(ns: argparse.Namespace, bpy, addon: str, timings: dict) -> None:
    clear_scene(bpy)
    t = time.perf_counter()
    objs = import_input(bpy, addon, ns.input)
    bridge = importlib.import_module(f"{addon}.tcb_addon.bridge")
    select_only(bpy, objs)
    with bpy.context.temp_override(selected_objects=list(objs)):
        try:
            data = bridge.read_selection(bpy.context, objs)
        except bridge.SelectionError as ex:
            raise ScriptError(first_line(ex)) from None
    n_points, n_faces = len(data.points), 0 if data.faces is None else len(data.faces)
    timings["import"] = time.perf_counter() - t
    log(f"imported {ns.input} ({n_points} points, {n_faces} triangles); fitting...")

    t = time.perf_counter()
    surface = fit(bpy, objs, ns)
    timings["fit (operator)"] = time.perf_counter() - t
    stats = fit_stats(surface)
    if ns.deviation:
        t = time.perf_counter()
        deviation_map(bpy, surface)
        timings["deviation map"] = time.perf_counter() - t
    if ns.render is not None:
        setup_render(bpy, surface, objs, ns)
    select_only(bpy, [surface])

    t = time.perf_counter()
    ns.output.parent.mkdir(parents=True, exist_ok=True)
    bpy.context.preferences.filepaths.save_version = 0  # no OUT.blend1 backup on reruns
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(ns.output.resolve()), check_existing=False)
    except RuntimeError as ex:
        raise ScriptError(f"saving {ns.output}: {first_line(ex)}") from None
    timings["save .blend"] = time.perf_counter() - t
    if ns.export is not None:
        t = time.perf_counter()
        export_surface(bpy, addon, surface, ns.export)
        timings["export"] = time.perf_counter() - t
    if ns.render is not None:
        t = time.perf_counter()
        render(bpy, ns.render)
        timings["render"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - T0

    print(f"\nTCB Surface: {ns.input}", flush=True)
    print(report_table(surface, stats, n_points, n_faces, timings))
    for what, path in (("blend", ns.output), ("surface", ns.export), ("picture", ns.render)):
        if path is not None:
            print(f"wrote {what:<8} {path}")
    sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    ns = parse_args(script_args(sys.argv if argv is None else argv))
    real_blender = "bpy" in sys.modules and bool(getattr(sys.modules["bpy"].app, "binary_path", ""))
    tmp = Path(tempfile.mkdtemp(prefix="tcb_fit_"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    timings: dict[str, float] = {}
    cleanup: list = []
    try:
        check_paths(ns)
        t = time.perf_counter()
        if not real_blender:
            redirect_user_folders(tmp / "blender_user")
            try:
                import bpy
            except ImportError as ex:
                raise ScriptError(
                    f"cannot import bpy ({ex}): run with .venv/bin/python (bash scripts/test "
                    "creates it) or with a real Blender: "
                    "blender -b -P scripts/fit_in_blender.py -- ..."
                ) from None
        else:
            import bpy
        addon = install_extension(bpy, tmp, real_blender, cleanup)
        timings["start Blender + extension"] = time.perf_counter() - t
        run(ns, bpy, addon, timings)
    except ScriptError as ex:
        print(f"fit_in_blender: error: {ex}", file=sys.stderr, flush=True)
        return 1
    finally:
        for fn in reversed(cleanup):
            fn()
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.exit(code)
