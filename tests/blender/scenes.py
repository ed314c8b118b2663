"""Helpers shared by the Blender tests: build scenes (grids, meshes, selections), read an
object's vertex positions, move a net vertex, decode a result's spline."""

from __future__ import annotations

import base64
import importlib

import numpy as np

ADDON = "bl_ext.user_default.tcb_surface"


def grid(n=24, size=1.0, f=lambda x, y: 0.3 * (x * x - 0.5 * y * y), triangles=False):
    """An ``n`` x ``n`` height-field grid over ``[-size, size]^2``: vertices and faces (quads, or
    two triangles per quad)."""
    t = np.linspace(-size, size, n)
    x, y = np.meshgrid(t, t, indexing="ij")
    verts = np.c_[x.ravel(), y.ravel(), f(x, y).ravel()]
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    if triangles:
        return verts, np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    return verts, np.c_[a, b, c, d]


def halves(bpy, n):
    """Two vertex-only objects 'Left' and 'Right', the halves (x <= 0, x > 0) of an ``n`` x
    ``n`` :func:`grid`, and the grid's vertices: data fitted as one cloud of two sources."""
    verts, _ = grid(n)
    left = add_mesh(bpy, "Left", verts[verts[:, 0] <= 0])
    right = add_mesh(bpy, "Right", verts[verts[:, 0] > 0])
    return left, right, verts


def add_mesh(bpy, name, verts, faces=None, location=(0.0, 0.0, 0.0)):
    """A new mesh object (vertices only when ``faces`` is None) linked to the scene."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    if len(verts):
        mesh.attributes["position"].data.foreach_set(
            "vector", np.asarray(verts, np.float32).ravel()
        )
    if faces is not None and len(faces):
        faces = np.asarray(faces, np.int32)
        mesh.loops.add(faces.size)
        mesh.polygons.add(len(faces))
        mesh.polygons.foreach_set(
            "loop_start", np.arange(0, faces.size, faces.shape[1], dtype=np.int32)
        )
        mesh.attributes[".corner_vert"].data.foreach_set("value", faces.ravel())
    mesh.update(calc_edges=True)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def select(bpy, *objs):
    """A temp_override context with exactly ``objs`` selected (first one active)."""
    bpy.context.view_layer.update()
    for o in bpy.context.scene.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None
    return dict(selected_objects=list(objs), active_object=objs[0] if objs else None,
                object=objs[0] if objs else None)  # fmt: skip


def core_module():
    """The installed extension's ``core`` package."""
    return importlib.import_module(ADDON + ".core")


def spline_of(surface_obj):
    """The spline stored with a result object (base64 text of TCBSurface.to_bytes())."""
    return core_module().TCBSurface.from_bytes(base64.b64decode(surface_obj["tcb_spline"]))


def positions(obj) -> np.ndarray:
    """(n, 3) float64 positions of a mesh or point-cloud object's own data (no modifiers)."""
    attr = obj.data.attributes["position"]
    buf = np.empty(len(attr.data) * 3, np.float32)
    attr.data.foreach_get("vector", buf)
    return buf.reshape(-1, 3).astype(np.float64)


def move_net_vertex(bpy, net, j, offset):
    """Move vertex ``j`` of the control net by ``offset`` (as a drag would); its new positions."""
    p = positions(net)
    p[j] += offset
    net.data.attributes["position"].data.foreach_set("vector", p.astype(np.float32).ravel())
    net.data.update()
    bpy.context.view_layer.update()
    return p


def delete_first(mesh, what: str = "faces") -> None:
    """Delete the first of ``mesh``'s ``what`` ("faces": the face alone; "verts": the vertex
    and what uses it), through bmesh, as an edit in Edit Mode would."""
    import bmesh

    bm = bmesh.new()
    bm.from_mesh(mesh)
    elems = getattr(bm, what)
    elems.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[elems[0]], context="FACES_ONLY" if what == "faces" else "VERTS")
    bm.to_mesh(mesh)
    bm.free()


def fit(bpy, *objs, **props):
    """Fit Surface on exactly ``objs`` (tolerance 2e-3, 400 control points, resolution 24
    unless given)."""
    props.setdefault("tolerance", 2e-3)
    props.setdefault("max_control_points", 400)
    props.setdefault("resolution", 24)
    with bpy.context.temp_override(**select(bpy, *objs)):
        return bpy.ops.tcb.fit_surface(**props)


def failing_fit(core, at: int = 2):
    """``core.fit_surface`` that raises SingularSystemError at iteration ``at`` (an engine
    failure mid-fit), with no tolerance so that it gets there."""
    real = core.fit_surface

    def failing(*args, **kwargs):
        def callback(report):
            if report["iteration"] == at:
                raise core.SingularSystemError(f"injected failure at iteration {at}")
            return False

        kwargs.update(callback=callback, max_iterations=at + 3, tolerance=0.0)
        return real(*args, **kwargs)

    return failing
