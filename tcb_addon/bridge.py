"""bpy <-> numpy: read the selection as arrays, write result meshes and attributes.

Everything here moves data; no mathematics. Geometry is read with ``foreach_get`` into float32 /
int32 buffers and written with ``foreach_set`` through the attribute API (``position``,
``.corner_vert``, ``loop_start``); no Python lists of tuples for large data.

Blender keeps vertex coordinates as 32-bit floats (spacing 0.5 at 4.2e6): results far from the
world origin (georeferenced data) are written relative to an object origin near them
(:func:`local_origin`), and object transforms are applied in float64 numpy, never in mathutils.
"""

from __future__ import annotations

import base64
import hashlib
from dataclasses import dataclass, field

import bpy
import numpy as np

# Object types whose evaluated geometry can hold points. EMPTY and the curve-like types count
# only through what they produce (collection instances, Geometry Nodes): checked after
# evaluation.
POINT_TYPES = {"MESH", "POINTCLOUD"}
GEOMETRY_TYPES = POINT_TYPES | {"CURVE", "SURFACE", "META", "FONT", "CURVES", "EMPTY"}

_TYPE_NAMES = {
    "CAMERA": "a camera", "LIGHT": "a light", "LIGHT_PROBE": "a light probe",
    "SPEAKER": "a speaker", "ARMATURE": "an armature", "LATTICE": "a lattice",
    "VOLUME": "a volume", "GREASEPENCIL": "a Grease Pencil object", "EMPTY": "an empty",
    "CURVE": "a curve", "CURVES": "a hair curves object", "SURFACE": "a NURBS surface",
    "META": "a metaball", "FONT": "a text object",
}  # fmt: skip


class SelectionError(Exception):
    """The selection cannot be fitted; the message is shown to the user as is."""


# the words of InputData.notes for a hidden source read without its modifiers
UNMODIFIED = "read without its modifiers"


@dataclass
class InputData:
    """The merged, world-space input of a fit."""

    points: np.ndarray  # (n, 3) float64
    faces: np.ndarray | None  # (f, 3) int64, or None for a point cloud
    sources: list = field(default_factory=list)  # original bpy.types.Object, in selection order
    counts: dict = field(default_factory=dict)  # source name -> number of points read
    notes: list = field(default_factory=list)  # what the user should know about the input
    # source name -> its modifiers as "Kind 'name'" ("(not applied)" after those not applied)
    modifiers: dict = field(default_factory=dict)

    @property
    def rounding(self) -> float:
        """What the points may have been rounded by since a fit (TCBSurface.fitted_to): 4
        float32 steps of their largest coordinate (Blender keeps float32 coordinates: Apply
        Rotation & Scale rounds them again)."""
        return 4 * 2.0**-24 * float(np.abs(self.points).max(initial=0.0))

    def modifier_note(self, applied_only: bool = True) -> str | None:
        """The sources' modifiers in words, or None when they have none: ``applied_only``
        names only those the input was read through (on in the viewport, source shown)."""
        parts = []
        for name, mods in self.modifiers.items():
            mods = [m for m in mods if not (applied_only and m.endswith(" (not applied)"))]
            if mods:
                parts.append(f"'{name}' has the modifier{'s' if len(mods) > 1 else ''} "
                             f"{', '.join(mods)}")
        return "; ".join(parts) or None

    @property
    def unmodified(self) -> list:
        """The notes of hidden sources read without their modifiers (:data:`UNMODIFIED`):
        a fit of such a source is of another shape."""
        return [n for n in self.notes if UNMODIFIED in n]

    @property
    def name(self) -> str:
        names = [o.name for o in self.sources]
        return names[0] if len(names) == 1 else f"{names[0]} +{len(names) - 1}"

    def label(self, i: int) -> str:
        """Point ``i`` of the merged input as the user knows it: ``'Object' #k``, ``k`` its
        index in that object's points."""
        start = 0
        for name, n in self.counts.items():
            if i < start + n:
                return f"'{name}' #{i - start}"
            start += n
        return f"#{i}"

    def digest(self) -> str:
        """A content hash, so a redo with the same input can reuse the last fit."""
        h = hashlib.blake2b(digest_size=16)
        h.update(np.ascontiguousarray(self.points).tobytes())
        if self.faces is not None:
            h.update(np.ascontiguousarray(self.faces).tobytes())
        return h.hexdigest()


def _kind(obj) -> str:
    return _TYPE_NAMES.get(obj.type, f"a {obj.type.lower()} object")


def selection_problem(context) -> str | None:
    """A cheap check for the panel (no evaluation): why the Fit button is disabled, or None."""
    if context.mode == "EDIT_MESH":  # (Fit Surface fits the selected faces; the panel says so)
        return edit_problem(context)
    if context.mode != "OBJECT":
        return "Switch to Object Mode to fit"
    selected = list(getattr(context, "selected_objects", None) or [])
    if not selected:
        return "Select a mesh or point-cloud object"
    if all(_is_result(o) for o in selected):
        return _result_note(selected[0])
    selected = [o for o in selected if not _is_result(o)]
    # (cameras, lights... are left out when geometry is selected with them: read_selection)
    if not any(o.type in GEOMETRY_TYPES for o in selected):
        return f"'{selected[0].name}' is {_kind(selected[0])}, not a mesh or point cloud"
    return None


def _world(positions: np.ndarray, matrix) -> np.ndarray:
    m = np.array(matrix, dtype=np.float64)  # the float32 matrix, exactly, in float64
    # (NaN or infinite coordinates are refused by the caller with a clear error: numpy's
    # "invalid value" warning was printed to the console before it, user test)
    with np.errstate(invalid="ignore", over="ignore"):
        return positions.astype(np.float64) @ m[:3, :3].T + m[:3, 3]


def read_positions(data) -> np.ndarray:
    """(n, 3) float32 positions of a Mesh or PointCloud datablock. A mesh in Edit Mode has no
    "position" attribute (its attributes are the edit mesh's layers): its vertices are read, as
    loaded by ``Object.update_from_editmode``."""
    attr = data.attributes.get("position")
    if attr is None and getattr(data, "is_editmode", False):
        n = len(data.vertices)
        buf = np.empty(n * 3, dtype=np.float32)
        if n:
            data.vertices.foreach_get("co", buf)
        return buf.reshape(n, 3)
    n = len(attr.data) if attr is not None else 0
    buf = np.empty(n * 3, dtype=np.float32)
    if n:
        attr.data.foreach_get("vector", buf)
    return buf.reshape(n, 3)


def read_triangles(mesh, matrix=None, positions=None, polygons: bool = False):
    """(t, 3) int32 vertex indices of the mesh's triangulated faces (Blender's triangulation,
    with quads cut along the diagonal their shape gives in world space (``matrix``, the
    object's; ``positions``: the mesh's :func:`read_positions` when already read;
    :func:`_quads_by_shape`) and n-gons that cut the same diagonal triangulated again:
    :func:`_untangle_diagonals`); with ``polygons``, also the polygon of each triangle (t,)."""
    tris = mesh.loop_triangles
    buf = np.empty(len(tris) * 3, dtype=np.int32)
    poly = np.empty(len(tris), dtype=np.int32)
    if len(tris):
        tris.foreach_get("vertices", buf)
        tris.foreach_get("polygon_index", poly)
    tris = _quads_by_shape(mesh, buf.reshape(-1, 3), poly, matrix, positions)
    tris, poly = _untangle_diagonals(mesh, tris, poly)
    return (tris, poly) if polygons else tris


# quads whose diagonals' squared lengths differ by at most this share keep Blender's cut (a
# square's): Apply Rotation & Scale rounds the vertices to float32 again, by 1.2e-7 of their
# distance from the origin (a grid 2e4 away with quads 13 wide: 5e-4 of a squared diagonal;
# at 1e-4 Refine saw other faces there)
QUAD_TIE_RTOL = 1e-2


def _quads_by_shape(mesh, tris: np.ndarray, poly: np.ndarray, matrix=None,
                    positions=None) -> np.ndarray:
    """``tris`` (Blender's loop triangles, of the polygons ``poly``) with each quad's two
    triangles replaced, in their places, by the cut of ``core.geometry.quad_triangles`` in
    world space: the shorter diagonal, whatever corner the quad starts at (Blender cuts from
    its first corner unless that is concave, so a 6 x 6 quad grid whose corners were turned had got 142-335 control
    points: review); of diagonals within QUAD_TIE_RTOL (a square), Blender's, from the first
    corner. World space: Apply Rotation & Scale leaves the cut as it was."""
    n_poly = len(mesh.polygons)
    if len(tris) == n_poly or n_poly == 0:  # all triangles (most scans)
        return tris
    total = np.empty(n_poly, dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", total)
    if not (total == 4).any():
        return tris
    slots = np.flatnonzero(total[poly] == 4).reshape(-1, 2)  # a quad's two, side by side
    quads = poly[slots[:, 0]]
    start = np.empty(n_poly, dtype=np.int32)
    mesh.polygons.foreach_get("loop_start", start)
    loops = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    corners = loops[start[quads, None] + np.arange(4)]
    from .. import core  # the extension's own engine

    pos = (read_positions(mesh) if positions is None else positions).astype(np.float64)
    if matrix is not None:
        pos = pos @ np.array(matrix, dtype=np.float64)[:3, :3].T
    out = tris.copy()
    cut = core.geometry.quad_triangles(pos, corners, tie_rtol=QUAD_TIE_RTOL, tie_first=True)
    out[slots.reshape(-1)] = cut
    return out


def _untangle_diagonals(mesh, tris: np.ndarray, poly: np.ndarray):
    """Blender triangulates each n-gon on its own: two bent n-gons that share a chain through a
    vertex of no other face (Limited Dissolve leaves these; so does Suzanne) can both cut the
    diagonal across that vertex, which then has four triangles, and a disk read as
    non-manifold. Those n-gons are triangulated again as fans from a corner whose diagonals no
    other face uses and whose triangles all face the polygon's way (a fan from a corner of a
    concave n-gon can leave it: overlapping triangles). An n-gon so bent that no such corner
    faces its way (noise larger than the spacing: Suzanne with noise of 1% of its size was
    refused as "non-manifold", user test) is cut by ear clipping (:func:`_clip_ears`), and
    where that gets stuck, as the fan from the free corner whose worst triangle turns least: a
    disk's parameterization needs its topology, not flat n-gons. An n-gon without a free corner
    keeps Blender's triangles (a loop over the few n-gons concerned). Edges of the mesh itself
    in more than two faces, and crowded diagonals that no fan resolves, are left for the
    engine to name. ``poly``: the polygon of each of ``tris`` (Blender's
    ``polygon_index``); returned with the triangles, in their new order."""
    n = len(mesh.vertices)
    if len(tris) == len(mesh.polygons):  # all triangles: no diagonals (most scans; no sort)
        return tris, poly
    t = tris.astype(np.int64)
    ends = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1), axis=2)
    key = ends[..., 0] * n + ends[..., 1]  # (t, 3)
    uniq, count = np.unique(key, return_counts=True)
    crowded = uniq[count > 2]
    if not len(crowded):
        return tris, poly
    ev = np.empty(len(mesh.edges) * 2, dtype=np.int32)
    if len(mesh.edges):
        mesh.edges.foreach_get("vertices", ev)
    ev = np.sort(ev.reshape(-1, 2).astype(np.int64), axis=1)
    real = ev[:, 0] * n + ev[:, 1]
    diagonals = np.setdiff1d(crowded, real)
    if not len(diagonals):
        return tris, poly
    redo = np.unique(poly[np.isin(key, diagonals).any(axis=1)])
    keep = ~np.isin(poly, redo)
    used = set(key[keep].ravel().tolist()) | set(real.tolist())
    pos = read_positions(mesh).astype(np.float64)
    out, out_poly = [tris[keep]], [poly[keep]]
    for p in redo.tolist():
        vs = np.array(mesh.polygons[p].vertices)
        m = len(vs)
        corners = pos[vs]
        # the polygon's normal (Newell): the way every triangle of a valid fan faces
        normal = np.cross(corners, np.roll(corners, -1, axis=0)).sum(axis=0)
        best = None  # (the worst triangle's cosine to the normal, its diagonals, the fan)
        for i in range(m):
            j = (i + np.arange(1, m - 1)) % m
            cut = set((np.minimum(vs[i], vs[j[1:]]) * n + np.maximum(vs[i], vs[j[1:]])).tolist())
            if cut & used:
                continue
            fan = np.c_[np.full(m - 2, vs[i]), vs[j], vs[(j + 1) % m]]
            a, b, c = pos[fan[:, 0]], pos[fan[:, 1]], pos[fan[:, 2]]
            facing = np.cross(b - a, c - a)
            size = np.linalg.norm(facing, axis=1) * np.linalg.norm(normal)
            # a flat triangle (three corners in a row) ranks below one turned over
            cos = np.where(size > 0, facing @ normal / np.where(size > 0, size, 1.0), -2.0)
            if best is None or cos.min() > best[0]:
                best = (float(cos.min()), cut, fan)
            if best[0] > 1e-3:  # every triangle faces the polygon's way, none flat
                break
        if best is not None and best[0] <= 1e-3:  # no fan faces its way: ears may
            ears = _clip_ears(vs, corners, normal, used, n)
            if ears is not None:
                best = (1.0, *ears)
        if best is None:  # no free corner: Blender's triangles stay (the engine names the edge)
            out.append(tris[poly == p])
        else:
            used |= best[1]
            out.append(best[2].astype(np.int32))
        out_poly.append(np.full(len(out[-1]), p, dtype=np.int32))
    return np.vstack(out), np.concatenate(out_poly)


def _clip_ears(vs, corners, normal, used, n):
    """(diagonal keys, triangles) of the n-gon with vertices ``vs`` at ``corners`` cut by ear
    clipping in the plane across its Newell ``normal``: each triangle cut off turns the
    polygon's way (by more than 1e-3 of its edges' product), holds none of the other corners,
    and adds a diagonal that is not in ``used``; None when it gets stuck (a concave n-gon whose
    every fan leaves it can still have such a triangulation: :func:`_untangle_diagonals`)."""
    axis = normal / np.linalg.norm(normal)
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    xy = np.c_[corners @ u, corners @ np.cross(axis, u)]  # counter-clockwise seen from axis
    left = list(range(len(vs)))
    cuts, out = set(), []

    def cross(a, b, c):
        return (xy[b, 0] - xy[a, 0]) * (xy[c, 1] - xy[a, 1]) \
            - (xy[b, 1] - xy[a, 1]) * (xy[c, 0] - xy[a, 0])

    def turns(a, b, c):  # not reflex, and not three corners in a row
        return cross(a, b, c) > 1e-3 * np.linalg.norm(xy[b] - xy[a]) * np.linalg.norm(xy[c] - xy[b])

    while len(left) > 3:
        for k in range(len(left)):
            a, b, c = left[k - 1], left[k], left[(k + 1) % len(left)]
            if not turns(a, b, c):
                continue
            key = min(vs[a], vs[c]) * n + max(vs[a], vs[c])
            if key in used:
                continue
            others = [o for o in left if o not in (a, b, c)]
            # no other corner inside the ear or on its sides
            if any(min(cross(a, b, o), cross(b, c, o), cross(c, a, o)) >= 0 for o in others):
                continue
            cuts.add(int(key))
            out.append((vs[a], vs[b], vs[c]))
            del left[k]
            break
        else:
            return None
    if not turns(*left):
        return None
    out.append(tuple(vs[left]))
    return cuts, np.array(out)


def _world_checked(obj, pts: np.ndarray, matrix) -> np.ndarray:
    """``pts`` of ``obj`` in world space (:func:`_world`); a :class:`SelectionError` when its
    transform flattens them (a Scale of 0 along an axis: the 3x3 part's determinant below 1e-12
    of the product of its column lengths) so that distinct vertices coincide: the engine
    would advise merging coincident vertices, which destroys the mesh (user test). A
    flattening that keeps the points distinct (a terrain scaled to 0 in z) is data as any."""
    world = _world(pts, matrix)
    m = np.array(matrix, dtype=np.float64)[:3, :3]
    size = float(np.prod(np.linalg.norm(m, axis=0)))
    if size > 0 and abs(float(np.linalg.det(m))) > 1e-12 * size:
        return world
    if len(np.unique(world, axis=0)) < len(np.unique(np.asarray(pts, dtype=np.float64), axis=0)):
        raise SelectionError(
            f"'{obj.name}' is flattened by its object transform (a Scale of 0 along an axis, its "
            "own or a parent's), which makes distinct vertices coincide: give it a non-zero "
            "Scale and try again"
        )
    return world


def _world_faces(tris, matrix):
    """``tris`` wound as they are seen in world space: reversed under a mirroring transform
    (a negative determinant; Blender shows such an object's faces turned, and its fitted
    surface had faced the other way: user test)."""
    if tris is None or np.linalg.det(np.array(matrix, dtype=np.float64)[:3, :3]) >= 0:
        return tris
    return np.ascontiguousarray(tris[:, ::-1])


# a note when the stored float32 coordinates are farther apart than this share of the extent
ROUNDED = 1e-4


def _rounding_note(obj, pts: np.ndarray, notes: list) -> None:
    """A note (once per object) when ``obj``'s stored vertex coordinates ``pts`` (float32, its
    own space) are so far from its origin that 32-bit floats there are more than ROUNDED of
    their extent apart: the scan is already rounded to that lattice (Apply Transforms on a
    georeferenced object at 1e5 m: 0.0078 m; its refit's RMS was 16x the one before, and
    Refine called it noise: user test)."""
    if len(pts) < 2 or any(n.startswith(f"'{obj.name}': its vertex coordinates") for n in notes):
        return
    p = np.asarray(pts, dtype=np.float32)
    with np.errstate(over="ignore", invalid="ignore"):  # (float32's largest value: named by
        extent = float(np.ptp(p, axis=0).max())  # the fit, core.parameterize.huge_rows)
        step = float(np.spacing(np.abs(p).max()))
    if not (np.isfinite(step) and np.isfinite(extent)):
        return
    if extent > 0 and step > ROUNDED * extent:
        notes.append(
            f"'{obj.name}': its vertex coordinates are stored {step:.3g} apart (32-bit floats "
            f"far from the object's origin: {step / extent:.1e} of its size), so the scan is "
            "already rounded to that (Apply Transforms on a far-away object does this): keep "
            "the offset in the object's Location (Object > Set Origin > Origin to Geometry) "
            "or import the scan again")


def modifier_names(obj) -> list:
    """``obj``'s modifiers as "Kind 'name'" (Blender's name of the kind: Solidify,
    Subdivision Surface), with "(not applied)" after those off in the viewport, or after all
    of them when ``obj`` is hidden (a hidden object is read without them)."""
    shown = obj.visible_get()
    out = []
    for m in getattr(obj, "modifiers", ()):
        try:
            kind = m.bl_rna.properties["type"].enum_items[m.type].name
        except (KeyError, AttributeError):
            kind = m.type.replace("_", " ").title()
        out.append(f"{kind} '{m.name}'" + ("" if shown and m.show_viewport else " (not applied)"))
    return out


def _layer_paths(layer, path=()):
    """The layer collections of a view layer, each with the path of those above it."""
    path = (*path, layer)
    yield path
    for child in layer.children:
        yield from _layer_paths(child, path)


def show_advice(context, obj) -> str:
    """How to show the hidden ``obj`` so that its modifiers are evaluated, in the Outliner's
    words, step by step: "show it (Alt+H)" did nothing for an object whose collection is
    excluded (user test), nor for one in a hidden collection, or a hidden parent collection
    (review)."""
    paths = [p for p in _layer_paths(context.view_layer.layer_collection)
             if obj.name in p[-1].collection.objects]
    if not paths:
        return f"link it into a collection of the scene '{context.scene.name}'"
    usable = [p for p in paths if not any(lc.exclude for lc in p)]
    if not usable:
        first = next(lc for lc in paths[0] if lc.exclude)
        return (f"include the collection '{first.name}' in the view layer (its checkbox in "
                "the Outliner)")
    steps = [f"show the collection '{lc.name}'" for lc in usable[0]
             if lc.hide_viewport or lc.collection.hide_viewport]
    if obj.hide_viewport:
        steps.append("enable it in viewports (the monitor icon in the Outliner)")
    if obj.hide_get():
        steps.append("show it (Alt+H)")
    return " and ".join(steps) or "show it"


def read_selection(context, objects=None) -> InputData:
    """World-space points (and faces) of the selected objects, after modifiers.

    Meshes are read evaluated (modifiers and Geometry Nodes applied), point clouds directly, and
    geometry that Geometry Nodes or collection instancing produce through
    ``depsgraph.object_instances``. Several objects are merged; faces are kept only when a
    single mesh is the whole input (merged meshes are fitted as a point cloud).
    Raises :class:`SelectionError` with a message for the user.
    """
    notes = []
    if objects is None:
        objects = list(getattr(context, "selected_objects", None) or [])
        # the add-on's own results (surface, net, deviation points) are not input: after
        # Select All they would be fitted together with the scan
        results = [o for o in objects if o is not None and _is_result(o)]
        objects = [o for o in objects if o is not None and not _is_result(o)]
        if results and not objects:
            raise SelectionError(
                _result_note(results[0]) if _left_over(results[0]) else
                f"'{results[0].name}' is a TCB result, not input: select the scan to fit (to "
                "change a surface, use Refine)"
            )
        if results:
            notes.append(f"left out of the input: {', '.join(repr(o.name) for o in results)} "
                         "(TCB results)")
    objects = [o for o in objects if o is not None]
    if not objects:
        raise SelectionError("Nothing selected: select a mesh or point-cloud object to fit")
    # objects that are no geometry (cameras, lights...) are left out, as the results are, when
    # geometry is selected with them (Select All had refused the fit for the camera: user test)
    if not any(o.type in GEOMETRY_TYPES for o in objects):
        raise SelectionError(
            f"'{objects[0].name}' is {_kind(objects[0])}, not a mesh or point cloud: "
            "select the mesh or point-cloud object to fit"
        )
    objects = [o for o in objects if o.type in GEOMETRY_TYPES]
    for obj in objects:
        if obj.mode == "EDIT":  # (its mesh is in the edit mesh: "has no vertices": user test)
            raise SelectionError(in_edit_mode(obj))
        if obj.type == "FONT":  # (its letters' faces: "4 separate pieces", "a tube": user test)
            raise SelectionError(
                f"'{obj.name}' is a text object: its letters make no surface to fit; select "
                "the mesh or point-cloud object to fit"
            )

    wanted = {o.as_pointer(): o for o in objects}
    depsgraph = context.evaluated_depsgraph_get()
    parts: dict[int, list] = {k: [] for k in wanted}  # owner -> [(points, faces|None)]
    for inst in depsgraph.object_instances:
        owner = inst.parent.original if inst.is_instance else inst.object.original
        key = owner.as_pointer()
        if key not in parts:
            continue
        ob = inst.object
        if ob.type == "MESH":
            mesh = ob.data
            pts = read_positions(mesh)
            tris = (read_triangles(mesh, inst.matrix_world, pts)
                    if len(mesh.polygons) else None)
            tris = _faces_or_cloud(owner, pts, tris, notes)
        elif ob.type == "POINTCLOUD":
            pts, tris = read_positions(ob.data), None
        else:
            continue
        if len(pts):
            parts[key].append((_world_checked(owner, pts, inst.matrix_world),
                               _world_faces(tris, inst.matrix_world)))
            _rounding_note(owner, pts, notes)
    # hidden objects (H, the viewport toggle, an excluded collection) are not evaluated: read
    # their own data (the modifiers cannot be applied without showing them)
    for key, obj in wanted.items():
        if parts[key] or obj.type not in POINT_TYPES or obj.visible_get():
            continue
        data = obj.data
        pts = read_positions(data)
        tris = (read_triangles(data, obj.matrix_world, pts)
                if obj.type == "MESH" and len(data.polygons) else None)
        tris = _faces_or_cloud(obj, pts, tris, notes)
        if len(pts):
            parts[key].append((_world_checked(obj, pts, obj.matrix_world),
                               _world_faces(tris, obj.matrix_world)))
            _rounding_note(obj, pts, notes)
            if any(m.show_viewport for m in getattr(obj, "modifiers", ())):
                notes.append(f"'{obj.name}' is hidden: {UNMODIFIED} ("
                             f"{show_advice(context, obj)} to read the modified shape)")

    points, faces, counts, modifiers = [], [], {}, {}
    if any(parts.values()):  # an empty that makes no geometry is no input beside geometry
        wanted = {k: o for k, o in wanted.items() if parts[k] or o.type != "EMPTY"}
    for key, obj in wanted.items():
        got = parts[key]
        n = sum(len(p) for p, _ in got)
        if n == 0:
            what = "vertices" if obj.type == "MESH" else "points"
            if not obj.visible_get():  # its geometry may come from modifiers, not evaluated
                raise SelectionError(f"'{obj.name}' is hidden and has no {what} of its own: "
                                     f"{show_advice(context, obj)} (its modifiers make its "
                                     "geometry) and try again")
            if obj.type == "EMPTY":  # (instancing a collection that has no geometry)
                raise SelectionError(
                    f"'{obj.name}' is an empty that instances no mesh or point cloud: select "
                    "the objects to fit")
            if obj.type not in POINT_TYPES:  # a curve, text, metaball... that makes no mesh
                raise SelectionError(
                    f"'{obj.name}' is {_kind(obj)} that makes no surface to fit: give it "
                    "geometry (a curve: Extrude or Bevel) or convert it to a mesh (Object > "
                    "Convert > Mesh) and try again")
            raise SelectionError(f"'{obj.name}' has no {what}: nothing to fit")
        bad = sum(int((~np.isfinite(p).all(axis=1)).sum()) for p, _ in got)
        what = "points" if obj.type == "POINTCLOUD" else "vertices"
        if bad:
            raise SelectionError(
                f"'{obj.name}': {bad} of its {n} {what} {'has' if bad == 1 else 'have'} NaN "
                "or infinite coordinates (after modifiers): delete or fix them and try again"
            )
        counts[obj.name] = n
        points += [p for p, _ in got]
        modifiers[obj.name] = modifier_names(obj)
        faces += [f for _, f in got]

    pts = np.concatenate(points) if len(points) > 1 else points[0]
    tri = faces[0] if len(faces) == 1 and faces[0] is not None else None
    if len(counts) > 1:  # (an error about "the point cloud" did not say so: user test)
        notes.append(f"the {len(counts)} selected objects ({', '.join(repr(n) for n in counts)}) "
                     "were fitted together as one point cloud")
    elif len(points) > 1:  # one object's instances (user test: "the 58 selected objects")
        notes.append(f"the {len(points)} instances that '{next(iter(counts))}' makes were "
                     "fitted together as one point cloud")
    return InputData(points=pts, faces=None if tri is None else tri.astype(np.int64),
                     sources=list(wanted.values()), counts=counts, notes=notes,
                     modifiers=modifiers)  # fmt: skip


def in_edit_mode(obj) -> str:
    """Why ``obj``, in Edit Mode while another object is active, cannot be read."""
    return (f"'{obj.name}' is in Edit Mode, where its mesh cannot be read: switch it to Object "
            "Mode (Tab) and try again")


# --- a part of a mesh: the faces (or vertices) selected in Edit Mode -------------------------------


def edit_problem(context) -> str | None:
    """Why Fit Surface cannot fit the selection of the meshes in Edit Mode, or None: one is the
    add-on's result (dragging its net's vertices is what its Edit Mode is for: its net had been
    fitted as a scan; review), or several are (one mesh's faces at a time)."""
    objs = [o for o in (getattr(context, "objects_in_mode", None) or []) if o.type == "MESH"]
    objs = objs or [o for o in [getattr(context, "edit_object", None)] if o is not None]
    result = next((o for o in objs if _is_result(o)), None)
    if result is not None:
        return (f"'{result.name}' is a TCB result, not input: in its Edit Mode drag the net's "
                "vertices; to fit, switch to Object Mode (Tab) and select the scan")
    if len(objs) > 1:
        return (f"{len(objs)} meshes are in Edit Mode: Fit Surface fits the selected faces of "
                "one mesh at a time (switch the others to Object Mode)")
    return None


def edit_selection(obj) -> tuple[str, np.ndarray]:
    """``(kind, mask)`` of the part of mesh ``obj`` selected in Edit Mode: ``"FACES"`` and a
    mask over its polygons when a face is selected, else ``"VERTICES"`` and a mask over its
    vertices (fitted as a point cloud); a :class:`SelectionError` when nothing is. The edit
    mesh is loaded into the mesh first (``update_from_editmode``)."""
    obj.update_from_editmode()
    mesh = obj.data
    faces = np.zeros(len(mesh.polygons), dtype=bool)
    if len(faces):
        mesh.polygons.foreach_get("select", faces)
    if faces.any():
        return "FACES", faces
    verts = np.zeros(len(mesh.vertices), dtype=bool)
    if len(verts):
        mesh.vertices.foreach_get("select", verts)
    if verts.any():
        return "VERTICES", verts
    raise SelectionError(
        f"Nothing is selected in '{obj.name}' (Edit Mode): select the faces to fit (or "
        "vertices, fitted as a point cloud), or switch to Object Mode (Tab) to fit the whole "
        "object")


def reshaped(obj) -> tuple[bool, bool]:
    """Whether mesh ``obj`` has modifiers shown in the viewport, and shape keys in effect (a
    key other than the basis with a value, not muted): Object Mode reads it so shaped, a part
    (:func:`read_part`) from its own vertices."""
    mesh = obj.data
    modified = any(m.show_viewport for m in getattr(obj, "modifiers", ()))
    keys = mesh.shape_keys is not None and any(
        k.value != 0 and not k.mute for k in mesh.shape_keys.key_blocks[1:])
    return modified, keys


def read_part(obj, kind: str, mask: np.ndarray, digest: str | None = None,
              whole: bool = False) -> tuple[InputData, str]:
    """World-space points (and faces) of the part of mesh ``obj`` that ``mask`` selects
    (:func:`edit_selection`): the selected polygons, triangulated as :func:`read_triangles`
    does, with their vertices only, or (``"VERTICES"``) the selected vertices as a point
    cloud; and a digest of the part (its vertices' own coordinates as a set:
    ``core.surface.rounded_set_digest``). Read from the mesh itself, without its modifiers
    (the selection is of its own faces: a modifier may make others) and its shape keys (the
    basis shape), a note says so when it has any (the basis had been fitted without a word:
    user test). A :class:`SelectionError` when the mesh no longer has as many polygons
    or vertices as ``mask``, or the part is not the one of ``digest`` (its faces renumbered,
    Sort Elements, or edited since: the mask had picked other faces, and the Deviation Map
    had measured them; user test). ``whole``: all of a mesh that no modifier or shape key
    reshapes (:func:`reshaped`), read with all its vertices as Object Mode reads it (a loose
    one too, which the engine leaves out and counts), without the part's note."""
    from .. import core  # the extension's own engine

    mesh = obj.data
    faces = kind == "FACES"
    what = "faces" if faces else "vertices"
    again = ": select the part in Edit Mode and use Fit Surface to fit it as it is now"
    n = len(mesh.polygons) if faces else len(mesh.vertices)
    if n != len(mask):
        raise SelectionError(f"'{obj.name}' has {n} {what} now, {len(mask)} when its selected "
                             f"{what} were fitted{again}")
    modified, keys = reshaped(obj)
    pts = read_positions(mesh)
    matrix = obj.matrix_world
    tris = None
    if faces:
        tris, poly = read_triangles(mesh, matrix, pts, polygons=True)
        tris = tris[mask[poly]]
        used = np.arange(len(pts)) if whole else np.unique(tris)
        where = np.full(len(pts), -1, dtype=np.int64)
        where[used] = np.arange(len(used))
        pts, tris = pts[used], where[tris]
    else:
        pts = pts[mask]
    part = core.surface.rounded_set_digest(pts)
    if digest is not None and part != digest:
        raise SelectionError(
            f"the {what} of '{obj.name}' that were selected for the fit are not as they were: "
            f"its {what} were renumbered (Sort Elements, or some deleted and others added) or "
            f"edited since{again}")
    bad = int((~np.isfinite(pts).all(axis=1)).sum())
    if bad:
        raise SelectionError(
            f"'{obj.name}': {bad} of its {len(pts)} selected vertices "
            f"{'has' if bad == 1 else 'have'} NaN or infinite coordinates: delete or fix them "
            "and try again")
    notes = [] if whole else [f"the {int(mask.sum())} selected {what} of '{obj.name}'"
                              + (", as a point cloud" if not faces else "")]
    if modified or keys:
        # (not UNMODIFIED's words: Refine and the Deviation Map take those for a source hidden
        # since its fit, and a part is always read so; review)
        without = " and ".join(w for w, on in (("modifiers", modified), ("shape keys", keys))
                               if on)
        notes.append(f"its own {what}, without the {without} of '{obj.name}'"
                     + (" (its basis shape)" if keys else ""))
    _rounding_note(obj, pts, notes)
    data = InputData(points=_world_checked(obj, pts, matrix),
                     faces=None if tris is None else _world_faces(tris, matrix).astype(np.int64),
                     sources=[obj], counts={obj.name: len(pts)}, notes=notes)
    return data, part


def part_text(kind: str, mask: np.ndarray, digest: str) -> str:
    """``kind``, ``mask`` and the part's ``digest`` (:func:`read_part`) as text (a surface
    keeps it: Refine and the Deviation Map read the same part again, Fit Surface replaces the
    result of the same part): ``"FACES:<count>:<digest>:<base64 of the packed bits>"``;
    167 000 characters for a million faces (0.4 ms)."""
    bits = base64.b64encode(np.packbits(mask.astype(bool)).tobytes()).decode("ascii")
    return f"{kind}:{len(mask)}:{digest.replace(':', '/')}:{bits}"


def part_of_text(text: str) -> tuple[str, np.ndarray, str]:
    """The ``(kind, mask, digest)`` of :func:`part_text`."""
    kind, n, digest, bits = text.split(":", 3)
    packed = np.frombuffer(base64.b64decode(bits), dtype=np.uint8)
    return kind, np.unpackbits(packed, count=int(n)).astype(bool), digest.replace("/", ":")


def part_identity(text: str) -> str:
    """What makes two parts (:func:`part_text`) the same: their kind and digest, the faces at
    the same places whatever their numbers ("" for all of a mesh)."""
    if not text:
        return ""
    kind, _, digest, _ = text.split(":", 3)
    return f"{kind}:{digest}"


def _faces_or_cloud(obj, pts, tris, notes):
    """A mesh whose faces hold fewer than half of its vertices is spot heights with a stray
    face or two: its vertices are fitted as a point cloud (faces None), and a note says so."""
    if tris is None or not len(pts):
        return tris
    in_faces = int(np.count_nonzero(np.bincount(tris.ravel(), minlength=len(pts))))
    if in_faces >= 0.5 * len(pts):
        return tris
    notes.append(f"'{obj.name}': only {in_faces} of its {len(pts)} vertices are in faces, so its "
                 "vertices were fitted as a point cloud")
    return None


def _is_result(obj) -> bool:
    """A surface, control net, deviation-points or weights object made by the add-on."""
    tcb = getattr(obj, "tcb", None)
    return tcb is not None and tcb.role != "NONE"


def _left_over(obj) -> bool:
    """A net (or deviation points) whose surface was deleted (user test: nothing said so)."""
    surface = obj.tcb.surface if obj.tcb.role != "SURFACE" else obj
    return surface is None or not surface.users_scene


def _result_note(obj) -> str:
    """What to do with a result object selected as if it were input."""
    if _left_over(obj):
        return (f"'{obj.name}' is left over from a TCB surface that was deleted: delete it too, "
                "or select the scan to fit")
    return f"'{obj.name}' is a TCB result: select the scan"


# --- writing -------------------------------------------------------------------------------


def new_mesh(name: str, verts: np.ndarray, faces: np.ndarray | None = None) -> bpy.types.Mesh:
    """A mesh from (n, 3) positions and (f, k) polygon vertex indices (k = 3 or 4)."""
    verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    if len(verts):
        mesh.attributes["position"].data.foreach_set("vector", verts.ravel())
    if faces is not None and len(faces):
        faces = np.ascontiguousarray(faces, dtype=np.int32)
        nf, k = faces.shape
        mesh.loops.add(nf * k)
        mesh.polygons.add(nf)
        mesh.polygons.foreach_set("loop_start", np.arange(0, nf * k, k, dtype=np.int32))
        mesh.attributes[".corner_vert"].data.foreach_set("value", faces.ravel())
    mesh.update(calc_edges=True)
    return mesh


def set_uv_map(mesh, uv: np.ndarray, name: str = "UVMap") -> None:
    """A UV map ``name`` on ``mesh`` from per-vertex texture coordinates ``uv`` (n, 2): each
    face corner takes its vertex's."""
    layer = mesh.uv_layers.get(name) or mesh.uv_layers.new(name=name)
    corner = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", corner)
    layer.data.foreach_set("uv", np.ascontiguousarray(
        np.asarray(uv, dtype=np.float32)[corner]).ravel())


def set_positions(mesh, verts: np.ndarray) -> None:
    mesh.attributes["position"].data.foreach_set(
        "vector", np.ascontiguousarray(verts, dtype=np.float32).ravel()
    )
    mesh.update()


def set_float_attribute(data, name: str, values: np.ndarray, domain: str = "POINT") -> None:
    attr = data.attributes.get(name)
    if attr is not None and (attr.data_type != "FLOAT" or attr.domain != domain):
        data.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = data.attributes.new(name, "FLOAT", domain)
    attr.data.foreach_set("value", np.ascontiguousarray(values, dtype=np.float32).ravel())


def set_color_attribute(mesh, name: str, rgba: np.ndarray) -> None:
    """A per-vertex float color attribute, made the active and render color."""
    attr = mesh.color_attributes.get(name)
    if attr is not None and (attr.data_type != "FLOAT_COLOR" or attr.domain != "POINT"):
        mesh.color_attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    attr.data.foreach_set("color", np.ascontiguousarray(rgba, dtype=np.float32).ravel())
    mesh.color_attributes.active_color = attr
    mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index


def read_world_positions(obj, depsgraph=None) -> np.ndarray:
    """(n, 3) float64 world-space positions of a mesh object's vertices (evaluated, with
    modifiers, when a depsgraph is given)."""
    if depsgraph is not None:
        obj = obj.evaluated_get(depsgraph)
    return _world(read_positions(obj.data), obj.matrix_world)


def read_world_positions_and_rounding(obj) -> tuple[np.ndarray, np.ndarray]:
    """World positions of a mesh object's vertices (as :func:`read_world_positions`, original
    data) and, per coordinate, the float32 spacing of the stored vertex coordinates carried into
    world space: writing float64 positions into the mesh moves them by at most half of it."""
    local = read_positions(obj.data)
    m = np.array(obj.matrix_world, dtype=np.float64)
    spacing = np.spacing(np.abs(local)).astype(np.float64)
    return _world(local, m), spacing @ np.abs(m[:3, :3]).T


def to_local(obj, world: np.ndarray) -> np.ndarray:
    """(n, 3) float64 world positions in ``obj``'s object space (its world matrix inverted in
    float64), to be written into its mesh."""
    m = np.array(obj.matrix_world, dtype=np.float64)
    w = np.asarray(world, dtype=np.float64).reshape(-1, 3) - m[:3, 3]
    if np.array_equal(m[:3, :3], np.eye(3)):
        return w
    return np.linalg.solve(m[:3, :3], w.T).T


# Results whose centre is farther from the world origin than this many times their size get an
# object origin near them: there 32-bit world coordinates would lose more than 6 bits of the
# precision that coordinates relative to the result have.
FAR_FROM_ORIGIN = 64.0


def local_origin(points: np.ndarray) -> np.ndarray:
    """An object origin for a new result object around ``points`` (world, float64): (0, 0, 0)
    near the world origin, else a float32-exact point next to their bounding-box centre (a
    multiple of a power of two about 1/16 of their size), so that the mesh's 32-bit coordinates
    relative to it keep the precision of the points' extent instead of their distance from the
    world origin."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(pts):
        return np.zeros(3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = 0.5 * (lo + hi)
    size = float(np.linalg.norm(hi - lo))
    if not np.abs(center).max() > FAR_FROM_ORIGIN * size:
        return np.zeros(3)
    step = 2.0 ** np.floor(np.log2(size / 16)) if size > 0 else 1.0
    return (np.round(center / step) * step).astype(np.float32).astype(np.float64)


# Framing a 3D view on imported data (Import Points): Clip End at least this many times the
# data's diagonal (the eye at about one diagonal from its centre, as View > Frame Selected
# puts it, its farthest point is 1.5 diagonals away: room to zoom out 2.5 times), and Clip
# Start raised only to keep Clip End / Clip Start within Blender's default ratio (0.01 to
# 1000 m): its manual names no number, only that a large range costs depth precision
# (z-fighting) and that a larger Clip Start helps on large scenes.
VIEW_CLIP_DIAGONALS = 4.0
VIEW_CLIP_RATIO = 1e5


def _round_up(value: float) -> float:
    """``value`` (> 0) rounded up to two significant digits (56568 -> 57000)."""
    step = 10.0 ** (np.floor(np.log10(value)) - 1)
    return float(np.ceil(value / step - 1e-9) * step)


def frame_views(spaces, lo, hi) -> list[str]:
    """Frame the 3D views (``SpaceView3D``: ``clip_start``, ``clip_end``, ``region_3d``) on
    the world bounding box ``lo``..``hi`` where some of it may be out of reach: its farthest
    corner from ``view_location`` plus ``view_distance`` (a bound for its distance from the
    eye) beyond ``clip_end``; a map tile imported at its UTM coordinates is 4e6 away from a
    view at the world origin, and a tile a few km across is wider than the default 1000 m.
    Such a view is centred on the box at about its diagonal (leaving camera view, as Frame
    Selected does), its Clip End raised (never lowered) to :data:`VIEW_CLIP_DIAGONALS` times
    the diagonal and its Clip Start only as needed by :data:`VIEW_CLIP_RATIO`. Views that
    reach all of it are left as they are. One note per view changed ("Clip End raised to
    57000, Clip Start to 0.57"), empty where the clip range was kept."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    center, diag = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    notes = []
    for space in spaces:
        r3d = space.region_3d
        at = np.array(r3d.view_location, dtype=np.float64)
        farthest = float(np.linalg.norm(np.maximum(np.abs(lo - at), np.abs(hi - at))))
        # (an orthographic view draws half of Clip End each side of the eye: Blender's
        # BKE_camera_params_from_view3d halves it for depth precision)
        reach = space.clip_end * (0.5 if getattr(r3d, "view_perspective", None) == "ORTHO" else 1.0)
        if farthest + r3d.view_distance <= reach:
            continue
        r3d.view_location = [float(c) for c in center]
        r3d.view_distance = max(diag, 1.0)  # (one point, or a few close together: 1 m away)
        if getattr(r3d, "view_perspective", None) == "CAMERA":
            r3d.view_perspective = "PERSP"
        raised = []
        end = _round_up(VIEW_CLIP_DIAGONALS * max(diag, 1.0))
        if end > space.clip_end:
            space.clip_end = end
            raised.append(f"Clip End raised to {length_text(end, digits=6)}")
            start = end / VIEW_CLIP_RATIO
            if start > space.clip_start:
                space.clip_start = start
                raised.append(f"Clip Start to {length_text(start, digits=6)}")
        notes.append(", ".join(raised))
    return notes


# the scene's length units (Unit Settings > Length): metres per unit, and the symbol
_LENGTH_UNITS = {"KILOMETERS": (1e3, "km"), "METERS": (1.0, "m"), "CENTIMETERS": (1e-2, "cm"),
                 "MILLIMETERS": (1e-3, "mm"), "MICROMETERS": (1e-6, "\u00b5m"),
                 "MILES": (1609.344, "mi"), "FEET": (0.3048, "ft"), "INCHES": (0.0254, "in"),
                 "THOU": (2.54e-5, "thou")}


def length_text(value: float, scene=None, digits: int = 4) -> str:
    """A length given in Blender units, written as the scene shows lengths (its Unit System,
    Unit Scale and Length unit): "0.1191 mm" where the scene shows millimetres (the reports had
    said "max 0.0001191" of a part the scene showed as 100 mm, or 0.1191 at a Unit Scale of
    0.001, with no unit: user test). A plain number in a scene of no units and in one of
    metres at Unit Scale 1 (a Blender unit is a metre there: Blender's default scene); the
    Adaptive length in Blender's own words (``bpy.utils.units.to_string``)."""
    value = float(value)
    units = getattr(scene if scene is not None else bpy.context.scene, "unit_settings", None)
    if units is None or units.system == "NONE" or not np.isfinite(value) or (
            units.system == "METRIC" and units.length_unit == "METERS"
            and units.scale_length == 1.0):
        return f"{value:.{digits}g}"
    metres = value * units.scale_length
    factor, symbol = _LENGTH_UNITS.get(units.length_unit, (None, ""))
    if factor is None:  # Adaptive
        return bpy.utils.units.to_string(units.system, "LENGTH", metres, precision=digits)
    return f"{metres / factor:.{digits}g} {symbol}"


def has_vertex_weights(mesh) -> bool:
    """Whether ``mesh`` holds vertex-group weights (its deform layer, made by the first weight
    given; the weights are not in the attribute API): a surface whose groups are still the
    empty ones a rewrite left loses nothing by the next (its note had been repeated on every
    Refine: user test). Read through a C copy (bmesh): 25 ms at 66 000 vertices."""
    import bmesh

    bm = bmesh.new()
    try:
        bm.from_mesh(mesh, face_normals=False, vertex_normals=False)
        return bm.verts.layers.deform.active is not None
    finally:
        bm.free()


def replace_mesh(obj, mesh, name: str | None = None) -> list:
    """Give ``obj`` a new mesh datablock, keeping its materials and the names of its vertex
    groups (empty: the new mesh has other vertices; they live on the mesh, and modifiers that
    name a group had lost it without a word: user test); free the old one if unused. Once it
    is freed the new mesh takes ``name`` (default: the old mesh's), which the old one held
    while the new one was made: every Refine or Re-tessellate had added a suffix (.001, .002;
    user test). Returns the names of the old mesh's shape keys, which do not carry over to
    other vertices (the caller says so)."""
    old = obj.data
    name = old.name if name is None else name
    for mat in old.materials:
        mesh.materials.append(mat)
    groups = [(g.name, g.lock_weight) for g in obj.vertex_groups]
    active = obj.vertex_groups.active_index
    # (besides the basis, the old vertices themselves: a lone basis is no loss; review)
    keys = ([kb.name for kb in old.shape_keys.key_blocks if kb != old.shape_keys.reference_key]
            if old.shape_keys is not None else [])
    obj.data = mesh
    for group_name, lock in groups:
        obj.vertex_groups.new(name=group_name).lock_weight = lock
    if groups:
        obj.vertex_groups.active_index = active
    if old.users == 0:
        bpy.data.meshes.remove(old)
        mesh.name = name
    return keys


def hiding_collections(view_layer, obj, excluded: bool = False) -> list:
    """The names of the collections that hide ``obj`` in ``view_layer``'s viewports (hidden
    with the outliner's eye or monitor icon, or excluded; with ``excluded``, excluded only),
    on every path to it through the view layer's collections (one shown path shows it); []
    when it is not hidden so."""
    names: list = []

    def walk(lc, hider):
        coll = lc.collection
        if hider is None and (lc.exclude or not excluded and (lc.hide_viewport
                                                              or coll.hide_viewport)):
            hider = coll.name
        found = obj.name in coll.objects
        if found and hider is None:
            return True
        if found and hider not in names:
            names.append(hider)
        return any([walk(child, hider) for child in lc.children])

    return [] if walk(view_layer.layer_collection, None) else names


def result_collection(context, name: str) -> bpy.types.Collection:
    coll = bpy.data.collections.new(name)
    context.scene.collection.children.link(coll)
    return coll


def link_new_object(coll, name: str, data, origin=None) -> bpy.types.Object:
    """A new object in ``coll``; with ``origin`` (float32-exact, see :func:`local_origin`) placed
    there, its world matrix set at once (readers need not wait for a depsgraph update)."""
    obj = bpy.data.objects.new(name, data)
    if origin is not None and np.any(np.asarray(origin) != 0):
        from mathutils import Matrix

        obj.matrix_world = Matrix.Translation([float(c) for c in origin])
    coll.objects.link(obj)
    return obj


# --- deviation colors (presentation) ---------------------------------------------------------

# blue -> cyan -> green -> yellow -> red over [0, 1]; the panel legend uses the same stops.
RAMP_STOPS = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
RAMP_COLORS = np.array(
    [[0.05, 0.15, 0.9], [0.0, 0.75, 0.9], [0.1, 0.8, 0.1], [0.95, 0.85, 0.05], [0.9, 0.05, 0.05]]
)
# Blender 4.2 names; ui.legend_icon maps them to 5.0's STRIP_COLOR_* where those exist
LEGEND_ICONS = ("SEQUENCE_COLOR_05", "SEQUENCE_COLOR_06", "SEQUENCE_COLOR_04",
                "SEQUENCE_COLOR_03", "SEQUENCE_COLOR_01")  # fmt: skip


def ramp_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """(n, 4) RGBA for ``values`` in [0, vmax] on the legend's color ramp."""
    t = np.clip(np.asarray(values, dtype=np.float64) / (vmax if vmax > 0 else 1.0), 0.0, 1.0)
    rgba = np.ones((len(t), 4), dtype=np.float32)
    for c in range(3):
        rgba[:, c] = np.interp(t, RAMP_STOPS, RAMP_COLORS[:, c])
    return rgba


def nearest_distances(query: np.ndarray, data: np.ndarray, faces: np.ndarray | None = None):
    """Distance from each query point to the data: to the data's triangles when ``faces`` are
    given (``core.geometry.point_mesh_distance``, vectorized), else to the nearest data point.
    With sparse meshes (a few hundred vertices) the distance to the vertices alone would mostly
    measure the sampling gaps, not the deviation; for the same reason the Deviation Map colors
    a point cloud's surface with ``core.geometry.distances_at_vertices`` instead."""
    from ..core.geometry import point_mesh_distance

    query = np.asarray(query, dtype=np.float64).reshape(-1, 3)
    if faces is None or len(faces) == 0:
        from scipy.spatial import cKDTree

        return cKDTree(data).query(query, k=1)[0]
    return point_mesh_distance(query, data, faces)


DEVIATION_MATERIAL = "TCB Deviation"
DEVIATION_MATERIAL_KEY = "tcb_deviation_material"  # marks the material as the add-on's


def deviation_material(name: str = DEVIATION_MATERIAL, attribute: str = "tcb_deviation"):
    """A material that shows a color attribute (for renders and Material Preview)."""
    mat = bpy.data.materials.get(name)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(name)
    mat[DEVIATION_MATERIAL_KEY] = True
    if mat.node_tree is None:  # Blender < 5.0 (5.0 materials always have a node tree)
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    attr = nodes.new("ShaderNodeVertexColor")
    attr.layer_name = attribute
    attr.location = (bsdf.location.x - 300, bsdf.location.y)
    links.new(attr.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def drop_deviation_material(mesh) -> None:
    """Take the Deviation Map's material (:func:`deviation_material`) off ``mesh``: it shows a
    colour attribute that a newly written mesh does not have."""
    for i in reversed(range(len(mesh.materials))):
        mat = mesh.materials[i]
        if mat is not None and (mat.get(DEVIATION_MATERIAL_KEY) or mat.name == DEVIATION_MATERIAL):
            mesh.materials.pop(index=i)
