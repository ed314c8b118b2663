"""Georeferenced data (a 100 m patch at (5e5, 4.2e6, 0)): Blender keeps vertex coordinates in
32-bit floats, whose spacing is 0.5 at 4.2e6. Net edits must still be seen exactly, unedited
control points must keep their float64 values, and the surface, the net and the exported file
must keep the engine's precision."""

from __future__ import annotations

import base64
import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ADDON = "bl_ext.user_default.tcb_surface"
OFFSET = np.array([5e5, 4.2e6, 0.0])  # float32-exact


def patch(n=2000, seed=0):
    """Scattered points of a smooth 100 m x 100 m height field, in coordinates local to it."""
    xy = np.random.default_rng(seed).random((n, 2)) * 100.0
    return np.c_[xy, 2.0 * np.sin(xy[:, 0] / 20.0) * np.cos(xy[:, 1] / 25.0)]


def positions(obj) -> np.ndarray:
    attr = obj.data.attributes["position"]
    buf = np.empty(len(attr.data) * 3, np.float32)
    attr.data.foreach_get("vector", buf)
    return buf.reshape(-1, 3)


def spline_of(surface_obj):
    core = importlib.import_module(ADDON + ".core")
    return core.TCBSurface.from_bytes(base64.b64decode(surface_obj["tcb_spline"]))


def fit_patch(bpy):
    """A point-cloud mesh at OFFSET (its vertices local, so the input is exact) and its fit."""
    local = patch()
    mesh = bpy.data.meshes.new("Survey")
    mesh.vertices.add(len(local))
    mesh.attributes["position"].data.foreach_set("vector", local.astype(np.float32).ravel())
    src = bpy.data.objects.new("Survey", mesh)
    src.location = OFFSET
    bpy.context.scene.collection.objects.link(src)
    bpy.context.view_layer.update()
    for o in bpy.context.scene.objects:
        o.select_set(o == src)
    bpy.context.view_layer.objects.active = src
    with bpy.context.temp_override(selected_objects=[src], active_object=src, object=src):
        result = bpy.ops.tcb.fit_surface(tolerance=1e-3, max_control_points=150, resolution=16)
    assert result == {"FINISHED"}
    surface = bpy.context.view_layer.objects.active
    assert surface.tcb.role == "SURFACE"
    return src, surface


def override(surface):
    return dict(selected_objects=[surface], active_object=surface, object=surface)


def move_net_vertex(bpy, net, j, offset):
    p = positions(net)
    p[j] += np.asarray(offset, np.float32)
    net.data.attributes["position"].data.foreach_set("vector", p.ravel())
    net.data.update()
    bpy.context.view_layer.update()


def test_a_net_edit_is_seen_exactly_and_the_rest_keeps_float64(clean_scene, addon, tmp_path):
    bpy = clean_scene
    ops = sys.modules[ADDON + ".tcb_addon.operators"]
    _, surface = fit_patch(bpy)
    stored = spline_of(surface).control_points
    assert np.abs(stored).max() > 4e6
    # an unedited net gives the stored float64 control points, bit for bit
    assert np.array_equal(ops.stored_surface(surface).control_points, stored)

    j = len(stored) // 2
    move_net_vertex(bpy, surface.tcb.net, j, (0.0, 0.0, 0.5))
    got = ops.stored_surface(surface).control_points
    others = np.arange(len(stored)) != j
    assert np.array_equal(got[others], stored[others])
    assert np.abs(got[j] - (stored[j] + [0.0, 0.0, 0.5])).max() < 1e-5, got[j] - stored[j]

    # fit_in_blender.py's export: the live surface shows the edited spline, written in float64;
    # without the live modifier the mesh is the unedited one, left to Blender's exporter
    spec = importlib.util.spec_from_file_location("fib", ROOT / "scripts" / "fit_in_blender.py")
    fib = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fib)
    meshio = importlib.import_module(ADDON + ".core.meshio")
    edited = spline_of(surface).with_control_points(got).tessellate(16)[0]
    for name in ("live.obj", "live.ply"):
        fib.export_surface(bpy, ADDON, surface, tmp_path / name)
        assert np.abs(meshio.read_geometry(tmp_path / name)[0] - edited).max() < 1e-6
    surface.modifiers.remove(surface.modifiers["TCB Live Net"])
    fib.export_surface(bpy, ADDON, surface, tmp_path / "static.obj")
    shown = spline_of(surface).tessellate(16)[0]  # unedited mesh: Blender's 32-bit coordinates
    static = meshio.read_geometry(tmp_path / "static.obj")[0]
    assert 1e-4 < np.abs(static - shown).max() < 1.0

    # Export Spline writes the edit; Re-tessellate shows it (the surface mesh is rebuilt from it)
    out = tmp_path / "edited.npz"
    with bpy.context.temp_override(**override(surface)):
        assert bpy.ops.tcb.export_spline(filepath=str(out)) == {"FINISHED"}
        assert bpy.ops.tcb.retessellate(resolution=16) == {"FINISHED"}
    saved = importlib.import_module(ADDON + ".core").TCBSurface.load(out).control_points
    assert np.array_equal(saved, got)
    bridge = sys.modules[ADDON + ".tcb_addon.bridge"]
    shown = bridge.read_world_positions(surface)  # the mesh itself
    assert np.abs(shown - edited).max() < 1e-3


def test_surface_and_net_keep_their_precision_far_from_the_origin(clean_scene, addon):
    bpy = clean_scene
    bridge = sys.modules[ADDON + ".tcb_addon.bridge"]
    src, surface = fit_patch(bpy)
    net = surface.tcb.net
    before = (positions(src).tobytes(), tuple(src.matrix_world.translation))
    surf = spline_of(surface)
    verts = surf.tessellate(16)[0]

    def error(obj, expected, evaluated=True):
        depsgraph = bpy.context.evaluated_depsgraph_get() if evaluated else None
        return np.abs(bridge.read_world_positions(obj, depsgraph) - expected).max()

    assert error(net, surf.control_points, evaluated=False) < 1e-3
    assert error(surface, verts, evaluated=False) < 1e-3  # the mesh written by the fit
    assert error(surface, verts) < 1e-3  # through the live net's Geometry Nodes

    # the live surface follows an edit with the same precision
    j = len(surf.control_points) // 2
    move_net_vertex(bpy, net, j, (0.0, 0.0, 0.5))
    moved = surf.control_points.copy()
    moved[j, 2] += 0.5
    assert error(surface, surf.with_control_points(moved).tessellate(16)[0]) < 1e-3

    # refine and re-tessellate write the surface and the net relative to their origins too
    with bpy.context.temp_override(**override(surface)):
        assert bpy.ops.tcb.refine(tolerance=5e-4, max_control_points=300) == {"FINISHED"}
        assert bpy.ops.tcb.retessellate(resolution=12) == {"FINISHED"}
        assert bpy.ops.tcb.deviation_map() == {"FINISHED"}
    refined = spline_of(surface)
    assert error(net, refined.control_points, evaluated=False) < 1e-3
    assert error(surface, refined.tessellate(12)[0]) < 1e-3
    points = bridge.read_world_positions(surface.tcb.deviation_points)
    assert np.abs(points - (patch() + OFFSET)).max() < 1e-3
    assert (positions(src).tobytes(), tuple(src.matrix_world.translation)) == before


def test_fit_in_blender_exports_at_full_precision(installed, tmp_path):
    """scripts/fit_in_blender.py on an .npy survey at OFFSET: the exported OBJ (Blender's, with
    its normals) has the stored spline's float64 tessellation as vertices (Blender's exporter
    alone gives steps of 0.5 in y)."""
    bpy = installed
    src, blend, obj = tmp_path / "utm.npy", tmp_path / "utm.blend", tmp_path / "utm.obj"
    np.save(src, patch() + OFFSET)
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "fit_in_blender.py"), str(src), "-o", str(blend),
         "--tolerance", "1e-3", "--max-control-points", "150", "--resolution", "16",
         "--export", str(obj), "--no-deviation"],
        capture_output=True, text=True, cwd=ROOT, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    meshio = importlib.import_module(ADDON + ".core.meshio")
    verts, faces = meshio.read_geometry(obj)
    assert sum(ln.startswith("vn ") for ln in obj.read_text().splitlines()) == len(verts)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    surface = next(o for o in bpy.data.objects if o.tcb.role == "SURFACE")
    surf = spline_of(surface)
    expected, tris = surf.tessellate(16)
    assert verts.shape == expected.shape and np.array_equal(faces, tris)
    assert np.abs(verts - expected).max() < 1e-6
    # the fit saw the input at full precision: the imported points are not rounded to 0.5 m
    source = bpy.data.objects["utm"]
    bridge = sys.modules[ADDON + ".tcb_addon.bridge"]
    assert np.abs(bridge.read_world_positions(source) - (patch() + OFFSET)).max() < 1e-3
