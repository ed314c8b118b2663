"""Live control net: a Geometry Nodes modifier that recomputes the surface from the net.

The surface vertices are ``verts = M @ control_points`` with ``M = surf.evaluation_matrix(uv)``
(sparse, at most ``K`` non-zero basis functions per vertex). The add-on stores ``M`` once, as a
hidden "weights" mesh with ``m * K`` vertices (row ``r`` uses vertices ``r*K .. r*K+K-1``) and
three point attributes: ``tcb_index`` (column = control point), ``tcb_weight`` (value, 0 for
padding) and ``tcb_vertex`` (row). The node group then evaluates, per surface vertex ``r``::

    position[r] = sum_j weight[rK+j] * net_position[index[rK+j]]

with Sample Index (net position at ``tcb_index``), a scale, an Accumulate Field grouped by
``tcb_vertex`` and a second Sample Index at ``r*K``. No Python runs at update time: it works in
Object Mode and while dragging net vertices in Edit Mode, with undo, animation and rendering, and
survives saving and reopening the file without the add-on.

When the net or the weights cannot drive the surface (deleted, so their geometry is empty, or
with other vertex counts; a modifier on the net that adds or removes vertices, such as
Wireframe, Skin or Subdivision) the modifier passes the surface's own mesh through: the stored
spline's tessellation, never a collapsed surface. The weights end with one more point, whose
``tcb_vertex`` is the number of control points, for that check. Every surface has weights of its own; Shift+D
copies a surface but not its hidden weights object, so :func:`attach` makes a private one for a
surface whose weights are shared before writing them, and :func:`own_net` does the same for a
shared net before Refine rewrites it.
"""

from __future__ import annotations

import bpy
import numpy as np

GROUP_NAME = "TCB Live Surface"
MODIFIER_NAME = "TCB Live Net"
INPUTS = ("Net", "Weights", "Terms")
# Bumped when the node tree changes: an older group in a file is rebuilt in place (same
# interface, so the modifiers' inputs are kept) when a file is loaded or the add-on enabled
# (upgrade_groups) and the next time a surface is linked.
# 2: falls back to the surface's own mesh when the net or the weights cannot drive it.
# 3: ... also when the net has other than as many vertices as control points (weights made
#    since end with a point that holds that number; older weights are checked as before)
GROUP_VERSION = 3


def _is_ours(ng) -> bool:
    """A node group made by this add-on: named ``GROUP_NAME`` (``.001`` etc. after an Append
    into a file that has one) with its inputs."""
    base, _, suffix = ng.name.rpartition(".")
    name = base if suffix.isdigit() and len(suffix) == 3 else ng.name
    if name != GROUP_NAME or ng.bl_idname != "GeometryNodeTree":
        return False
    items = [(i.in_out, i.name, getattr(i, "socket_type", "")) for i in ng.interface.items_tree
             if getattr(i, "in_out", None) in {"INPUT", "OUTPUT"}]
    return sorted(items) == sorted([
        ("INPUT", "Geometry", "NodeSocketGeometry"), ("INPUT", "Net", "NodeSocketObject"),
        ("INPUT", "Weights", "NodeSocketObject"), ("INPUT", "Terms", "NodeSocketInt"),
        ("OUTPUT", "Geometry", "NodeSocketGeometry")])


def upgrade_groups() -> None:
    """Rebuild in place the add-on's node groups older than :data:`GROUP_VERSION` (the one of
    the file and any appended with a surface), so that old surfaces get the fallback before
    any operator touches them."""
    for ng in list(bpy.data.node_groups):
        try:
            if ng.library is None and ng.get("tcb_version", 1) < GROUP_VERSION and _is_ours(ng):
                _build_nodes(ng)
        except Exception as ex:  # noqa: BLE001 (a handler must not stop the file loading)
            print(f"TCB: could not update the node group '{ng.name}': {ex}")


@bpy.app.handlers.persistent
def on_load(_file) -> None:
    """``load_post`` handler: bring older node groups of the loaded file up to date."""
    upgrade_groups()


def node_group() -> bpy.types.NodeTree:
    """The shared node group (created once per file, brought up to date if older)."""
    ng = bpy.data.node_groups.get(GROUP_NAME)
    if ng is not None and ng.bl_idname == "GeometryNodeTree":
        if ng.get("tcb_version", 1) < GROUP_VERSION and ng.library is None:
            _build_nodes(ng)
        return ng
    ng = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    iface = ng.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Net", in_out="INPUT", socket_type="NodeSocketObject")
    iface.new_socket("Weights", in_out="INPUT", socket_type="NodeSocketObject")
    terms = iface.new_socket("Terms", in_out="INPUT", socket_type="NodeSocketInt")
    terms.default_value, terms.min_value = 1, 1
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    _build_nodes(ng)
    return ng


def _socket(sockets, identifier: str):
    """A node socket by identifier (``inputs[name]`` finds the first of that name)."""
    return next(s for s in sockets if s.identifier == identifier)


def _build_nodes(ng) -> None:
    """(Re)create the nodes of the group; its interface is :data:`INPUTS` and the geometry.

    The spline evaluation replaces the positions only when the net and the weights fit the
    surface: the weights hold ``Terms`` points per surface vertex and the net has every control
    point they index; weights with one point more (:func:`padded_weights`) also need the net
    to have exactly the number of control points that point holds (a Wireframe modifier on
    the net, to see the cage, gave it 8x as many points, and the surface became garbage half
    a diagonal off: user test). Otherwise (the net or the weights object was deleted, so its geometry is
    empty; vertices were added to or deleted from the surface mesh or the net) the surface's own
    mesh passes through unchanged, the tessellation written by the last fit, refine or
    re-tessellate, as Blender's deform modifiers leave a mesh when their object is gone.
    """
    nodes, links = ng.nodes, ng.links
    nodes.clear()
    gin = nodes.new("NodeGroupInput")
    gout = nodes.new("NodeGroupOutput")
    net_info = nodes.new("GeometryNodeObjectInfo")
    net_info.transform_space = "RELATIVE"  # net positions in the surface object's space
    w_info = nodes.new("GeometryNodeObjectInfo")
    w_info.transform_space = "ORIGINAL"

    def named(name, data_type):
        node = nodes.new("GeometryNodeInputNamedAttribute")
        node.data_type = data_type
        node.inputs["Name"].default_value = name
        return node

    index, weight, vertex = (
        named("tcb_index", "INT"),
        named("tcb_weight", "FLOAT"),
        named("tcb_vertex", "INT"),
    )
    position = nodes.new("GeometryNodeInputPosition")
    sample_net = nodes.new("GeometryNodeSampleIndex")
    sample_net.data_type, sample_net.domain = "FLOAT_VECTOR", "POINT"
    scale = nodes.new("ShaderNodeVectorMath")
    scale.operation = "SCALE"
    accumulate = nodes.new("GeometryNodeAccumulateField")
    accumulate.data_type, accumulate.domain = "FLOAT_VECTOR", "POINT"
    row = nodes.new("GeometryNodeInputIndex")
    first = nodes.new("FunctionNodeIntegerMath")  # r * K, exact beyond 2**24 too
    first.operation = "MULTIPLY"
    sample_sum = nodes.new("GeometryNodeSampleIndex")
    sample_sum.data_type, sample_sum.domain = "FLOAT_VECTOR", "POINT"
    set_pos = nodes.new("GeometryNodeSetPosition")

    links.new(gin.outputs["Net"], net_info.inputs["Object"])
    links.new(gin.outputs["Weights"], w_info.inputs["Object"])
    links.new(net_info.outputs["Geometry"], sample_net.inputs["Geometry"])
    links.new(position.outputs["Position"], sample_net.inputs["Value"])
    links.new(index.outputs["Attribute"], sample_net.inputs["Index"])
    links.new(sample_net.outputs["Value"], scale.inputs[0])
    links.new(weight.outputs["Attribute"], scale.inputs["Scale"])
    links.new(scale.outputs["Vector"], accumulate.inputs["Value"])
    links.new(vertex.outputs["Attribute"], accumulate.inputs["Group ID"])
    links.new(w_info.outputs["Geometry"], sample_sum.inputs["Geometry"])
    links.new(accumulate.outputs["Total"], sample_sum.inputs["Value"])
    links.new(row.outputs["Index"], first.inputs[0])
    links.new(gin.outputs["Terms"], first.inputs[1])
    links.new(first.outputs["Value"], sample_sum.inputs["Index"])
    links.new(gin.outputs["Geometry"], set_pos.inputs["Geometry"])
    links.new(sample_sum.outputs["Value"], set_pos.inputs["Position"])

    # the fallback: weights points == surface points * Terms, and net points > largest index
    def count(geometry_socket):
        node = nodes.new("GeometryNodeAttributeDomainSize")
        node.component = "MESH"
        links.new(geometry_socket, node.inputs["Geometry"])
        return node.outputs["Point Count"]

    def int_math(operation, a, b):
        """An Integer Math node on sockets (or a number for ``b``); its output."""
        node = nodes.new("FunctionNodeIntegerMath")
        node.operation = operation
        links.new(a, node.inputs[0])
        if isinstance(b, int):
            node.inputs[1].default_value = b
        else:
            links.new(b, node.inputs[1])
        return node.outputs["Value"]

    def compare(operation, a, b):
        node = nodes.new("FunctionNodeCompare")
        node.data_type, node.operation = "INT", operation
        links.new(a, _socket(node.inputs, "A_INT"))
        links.new(b, _socket(node.inputs, "B_INT"))
        return node.outputs["Result"]

    def boolean(operation, a, b):
        node = nodes.new("FunctionNodeBooleanMath")
        node.operation = operation
        links.new(a, node.inputs[0])
        links.new(b, node.inputs[1])
        return node.outputs["Boolean"]

    def sample_int(geometry_socket, value, index):
        node = nodes.new("GeometryNodeSampleIndex")
        node.data_type, node.domain = "INT", "POINT"
        links.new(geometry_socket, node.inputs["Geometry"])
        links.new(value, node.inputs["Value"])
        links.new(index, node.inputs["Index"])
        return node.outputs["Value"]

    w_count, net_count = count(w_info.outputs["Geometry"]), count(net_info.outputs["Geometry"])
    expected = int_math("MULTIPLY", count(gin.outputs["Geometry"]), gin.outputs["Terms"])
    same = compare("EQUAL", w_count, expected)
    # the largest index: a Field Min & Max read on the weights (Attribute Statistic would
    # also sort them for the median, 2x the time of the whole evaluation)
    min_max = nodes.new("GeometryNodeFieldMinAndMax")
    min_max.data_type, min_max.domain = "INT", "POINT"
    links.new(index.outputs["Attribute"], min_max.inputs["Value"])
    largest = nodes.new("GeometryNodeSampleIndex")
    largest.data_type, largest.domain = "INT", "POINT"
    links.new(w_info.outputs["Geometry"], largest.inputs["Geometry"])
    links.new(min_max.outputs["Max"], largest.inputs["Value"])
    covered = compare("GREATER_THAN", net_count, largest.outputs["Value"])
    # weights with one more point, whose tcb_vertex is the net's point count
    stored = sample_int(w_info.outputs["Geometry"], vertex.outputs["Attribute"],
                        int_math("SUBTRACT", w_count, 1))
    counted = boolean("AND", compare("EQUAL", w_count, int_math("ADD", expected, 1)),
                      compare("EQUAL", net_count, stored))
    valid = boolean("AND", boolean("OR", same, counted), covered)
    switch = nodes.new("GeometryNodeSwitch")
    switch.input_type = "GEOMETRY"
    switch.name = switch.label = "Net and Weights Fit"
    links.new(valid, switch.inputs["Switch"])
    links.new(gin.outputs["Geometry"], switch.inputs["False"])
    links.new(set_pos.outputs["Geometry"], switch.inputs["True"])
    links.new(switch.outputs["Output"], gout.inputs["Geometry"])
    for i, node in enumerate(nodes):
        node.location = (200 * (i % 6), -200 * (i // 6))
    ng["tcb_version"] = GROUP_VERSION


def padded_weights(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(index, weight, vertex) arrays of length m*K + 1 from a CSR matrix (m, n); and K. The
    last point has weight 0 and ``vertex`` n: the number of control points, which the node
    group checks against the net's point count (:func:`_build_nodes`)."""
    csr = matrix.tocsr()
    csr.sort_indices()
    m = csr.shape[0]
    counts = np.diff(csr.indptr)
    k = max(int(counts.max(initial=0)), 1)
    slot = np.repeat(np.arange(m) * k, counts) + (
        np.arange(csr.nnz) - np.repeat(csr.indptr[:-1], counts)
    )
    index = np.zeros(m * k + 1, np.int32)
    weight = np.zeros(m * k + 1, np.float32)
    index[slot] = csr.indices
    weight[slot] = csr.data
    vertex = np.append(np.repeat(np.arange(m, dtype=np.int32), k), np.int32(csr.shape[1]))
    return index, weight, vertex, k


def _input_ids(ng) -> dict:
    return {
        item.name: item.identifier
        for item in ng.interface.items_tree
        if getattr(item, "in_out", None) == "INPUT"
    }


def _users(obj, pointer: str, socket: str) -> list:
    """The objects that use ``obj`` as their net or weights: through ``object.tcb.<pointer>``
    or through the ``socket`` input of a live-net modifier."""
    ng = bpy.data.node_groups.get(GROUP_NAME)
    ident = _input_ids(ng).get(socket) if ng is not None else None
    found = []
    for ob in bpy.data.objects:
        if getattr(ob.tcb, pointer) == obj or (
            ident is not None
            and any(
                mod.type == "NODES" and mod.node_group == ng and mod.get(ident) == obj
                for mod in ob.modifiers
            )
        ):
            found.append(ob)
    return found


def _others(obj, surface_obj, pointer: str, socket: str) -> list:
    """The surfaces other than ``surface_obj`` that share ``obj`` (a net or weights object,
    e.g. after Shift+D of a surface), keeping ``obj.tcb.surface`` on one of them."""
    others = [o for o in _users(obj, pointer, socket) if o != surface_obj]
    if others and obj.tcb.surface in (None, surface_obj):
        obj.tcb.surface = others[0]
    return others


def _set_input(ob, socket: str, value) -> None:
    mod = ob.modifiers.get(MODIFIER_NAME)
    if mod is not None and mod.node_group is not None:
        ident = _input_ids(mod.node_group).get(socket)
        if ident is not None:
            mod[ident] = value
            mod.node_group = mod.node_group  # its update rebuilds the depsgraph relations


def own_net(surface_obj):
    """The control net of ``surface_obj``, made its own before it is rewritten (Refine).

    A net shared with other surfaces (Shift+D of a surface without its net) is copied: the
    net's own surface (``net.tcb.surface``) keeps the net and the others get the copy, so
    rewriting it leaves the other surfaces as they were. None without a net."""
    net = surface_obj.tcb.net
    if net is None:
        return None
    if not net.users_collection:  # deleted with X (only unlinked): relink() drops it, no copy
        return net
    owner = net.tcb.surface
    others = []
    for ob in _users(net, "net", "Net"):
        if ob == surface_obj:
            continue
        own = ob.tcb.net
        if own is not None and own != net and own.type == "MESH":
            _set_input(ob, "Net", own)  # its modifier only strayed to this net: set it back
        else:
            others.append(ob)
    if not others:
        return net
    copy = net.copy()
    copy.data = net.data.copy()
    for coll in net.users_collection or surface_obj.users_collection:
        coll.objects.link(copy)
    try:
        copy.hide_set(net.hide_get())
    except RuntimeError:  # not in the current view layer
        pass
    moved = others if owner == surface_obj else [surface_obj]
    copy.tcb.surface = moved[0]
    if owner not in (surface_obj, *others):
        net.tcb.surface = others[0]
    for ob in moved:
        ob.tcb.net = copy
        _set_input(ob, "Net", copy)
    return surface_obj.tcb.net


def _remove(obj) -> None:
    """Remove an object of ours (weights, a deleted net) and its mesh if nothing else uses it."""
    mesh = obj.data
    bpy.data.objects.remove(obj)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def deleted(obj) -> bool:
    """Whether ``obj`` was deleted by the user (X unlinks it from every collection; our
    pointers keep it in the file). Not "in no scene": a collection shown only through a
    collection instance is in none, and its objects are in use (review)."""
    return obj is None or not obj.users_collection


def drop_orphaned_weights() -> int:
    """Remove the hidden weights objects whose surface was deleted (X leaves it in the file,
    held by the pointers of its net and weights, in no collection): the user cannot select
    them, and they kept the deleted surface and its spline in the .blend (user test). How
    many."""
    gone = 0
    for ob in list(bpy.data.objects):
        if ob.tcb.role != "WEIGHTS" or not deleted(ob.tcb.surface):
            continue
        if any(not deleted(o) for o in _users(ob, "weights", "Weights")):
            continue  # (a surface not deleted still reads it)
        _remove(ob)
        gone += 1
    return gone


def drop_deleted_results() -> int:
    """Remove the surfaces, nets and deviation points deleted (X) together with every object
    that uses them (``bpy.data.user_map``): a surface and its net deleted at once held each
    other through their pointers and the live-net modifier, and both were saved in the .blend,
    the spline too (10 objects after 5 fits deleted in a batch script; user test). A net
    deleted alone still drives its surface and stays; so do a result with a fake user and
    what it uses. Run after :func:`drop_orphaned_weights` (a deleted surface's weights use
    it). How many."""
    gone = 0
    while True:
        ours = [ob for ob in bpy.data.objects
                if ob.library is None and not ob.use_fake_user and deleted(ob)
                and ob.tcb.role in ("SURFACE", "NET", "DEVIATION")]
        if not ours:
            return gone
        users = bpy.data.user_map(subset=ours)
        drop = [ob for ob in ours if all(isinstance(u, bpy.types.Object) and deleted(u)
                                         and not u.use_fake_user for u in users[ob])]
        if not drop:
            return gone
        for ob in drop:
            _remove(ob)
        gone += len(drop)


def drop_deleted_links() -> int:
    """Clear the pointers that objects in use (in a collection) hold to deleted objects, and
    remove the weights of deleted surfaces (:func:`drop_orphaned_weights`) and the results
    deleted with all their users (:func:`drop_deleted_results`). X only unlinks an
    object that a pointer holds: a deleted scan stayed in the .blend, saved with it, through
    its surface's source pointer, and so did a deleted surface (its spline too) through its
    net's. Refine and the Deviation Map already refused a deleted source, so nothing is lost.
    (Not a deleted net: the surface's live-net modifier holds it too; nor an object with a
    fake user.) How many were cleared.
    """
    def gone(obj) -> bool:  # (one kept with a fake user is kept on purpose: review)
        return obj is not None and deleted(obj) and not obj.use_fake_user

    cleared = drop_orphaned_weights()
    cleared += drop_deleted_results()
    for ob in bpy.data.objects:
        if ob.library is not None or deleted(ob) or ob.tcb.role == "NONE":
            continue
        st = ob.tcb
        for src in st.sources:
            if gone(src.object):
                src.object = None
                cleared += 1
        for key in ("surface", "deviation_points"):
            if gone(getattr(st, key)):
                setattr(st, key, None)
                cleared += 1
    return cleared


@bpy.app.handlers.persistent
def on_save(_file) -> None:
    """``save_pre`` handler: :func:`drop_deleted_links` (deleted objects are not written)."""
    try:
        drop_deleted_links()
    except Exception as ex:  # noqa: BLE001 (a handler must not stop the file being saved)
        print(f"TCB: could not drop the links to deleted objects: {ex}")


def detach(surface_obj) -> None:
    """Remove the live link of ``surface_obj``: its modifier and its weights object (unless
    another surface uses it). The surface keeps its own mesh."""
    mod = surface_obj.modifiers.get(MODIFIER_NAME)
    if mod is not None:
        surface_obj.modifiers.remove(mod)
    holder = surface_obj.tcb.weights
    surface_obj.tcb.weights = None
    if holder is not None and not _others(holder, surface_obj, "weights", "Weights"):
        _remove(holder)


def relink(surface_obj, surf, resolution: int, report=None, rewrite: bool = True,
           weights=None) -> bool:
    """Bring the live link of ``surface_obj`` up to date after its mesh was rewritten from
    ``surf`` at ``resolution`` (Refine, Re-tessellate). Surfaces without a live net (fitted
    without, or the modifier and weights removed) keep none.

    - The net is gone: removed from the file, or deleted with X in the viewport, which only
      unlinks it from the scene as the surface still refers to it (the hidden net would then
      go on driving the surface). With ``rewrite`` the net is dropped, the live link removed
      (:func:`detach`) and ``report`` gets a warning; the surface shows its spline, rewritten
      by the caller, and True is returned (``surf`` holds the dropped net's edits: the
      caller may store it). Without ``rewrite`` nothing changes (the modifier already passes
      the surface's own mesh through, or the hidden net drives it as before).
    - Otherwise the weights are rewritten (with ``rewrite``; without it, only when the link
      is broken: weights deleted, modifier inputs not the surface's net and weights, an old
      node group), in a weights object of the surface's own (see :func:`attach`; ``weights``:
      the :func:`padded_weights` of its tessellation, computed already).
    """
    st = surface_obj.tcb
    mod = surface_obj.modifiers.get(MODIFIER_NAME)
    net = st.net
    if net is None or net.type != "MESH" or not net.users_collection:
        if not rewrite:
            return False
        dropped = net is not None
        if dropped:
            st.net = None
            if not net.users_collection and not _others(net, surface_obj, "net", "Net"):
                _remove(net)  # deleted with X: no scene shows it, nothing else uses it
        if mod is None and st.weights is None:
            return dropped  # no live link to remove
        detach(surface_obj)
        if report is not None:
            report(
                {"WARNING"},
                f"The control net of '{surface_obj.name}' was deleted: its live link was "
                "removed, the surface keeps its spline but no net edits update it any more "
                "(Fit Surface makes a new net)",
            )
        return dropped
    if mod is None and st.weights is None:
        return False
    if not rewrite and st.weights is not None and mod is not None and mod.node_group is not None:
        ng = mod.node_group
        ids = _input_ids(ng)
        if (
            ng.name == GROUP_NAME
            and ng.get("tcb_version", 1) >= GROUP_VERSION
            and mod.get(ids.get("Net", "")) == net
            and mod.get(ids.get("Weights", "")) == st.weights
        ):
            return False
    attach(surface_obj, net, surf, resolution, weights)
    return False


def attach(surface_obj, net_obj, surf, resolution: int, weights=None) -> bpy.types.Object:
    """Make ``surface_obj`` follow ``net_obj`` live; returns the (hidden) weights object.

    The weights are written into the surface's own weights object: a new one if it has none
    (or it was deleted), or if the one it has is shared with another surface (Shift+D copies
    the surface but not its hidden weights), so that the other surface keeps its weights."""
    from . import bridge

    if weights is None:
        uv, _ = surf.tessellation_uv(resolution)
        weights = padded_weights(surf.evaluation_matrix(uv))
    index, weight, vertex, k = weights
    mesh = bridge.new_mesh(f"{surface_obj.name} Weights", np.zeros((len(index), 3), np.float32))
    for name, values, kind in (
        ("tcb_index", index, "INT"),
        ("tcb_weight", weight, "FLOAT"),
        ("tcb_vertex", vertex, "INT"),
    ):
        attr = mesh.attributes.new(name, kind, "POINT")
        attr.data.foreach_set("value", values)

    holder = surface_obj.tcb.weights
    if holder is not None and _others(holder, surface_obj, "weights", "Weights"):
        holder = None  # shared: the other surface keeps it
    if holder is None:
        holder = bpy.data.objects.new(f"{surface_obj.name} Weights", mesh)
        for coll in surface_obj.users_collection:
            coll.objects.link(holder)
        holder.hide_viewport = holder.hide_render = holder.hide_select = True
        holder.tcb.role = "WEIGHTS"
        holder.tcb.surface = surface_obj
        surface_obj.tcb.weights = holder
    else:
        bridge.replace_mesh(holder, mesh, f"{surface_obj.name} Weights")
        if not holder.name.startswith(f"{surface_obj.name} Weights"):
            holder.name = f"{surface_obj.name} Weights"  # (the surface renamed: user test)

    mod = surface_obj.modifiers.get(MODIFIER_NAME)
    if mod is None:
        mod = surface_obj.modifiers.new(MODIFIER_NAME, "NODES")
    # first in the stack: it needs the surface's own vertices (after a Subdivision of the
    # user's the surface stopped following the net, with no word: user test)
    at = list(surface_obj.modifiers).index(mod)
    if at > 0:
        surface_obj.modifiers.move(at, 0)
    mod.node_group = node_group()
    ids = _input_ids(mod.node_group)
    mod[ids["Net"]] = net_obj
    mod[ids["Weights"]] = holder
    mod[ids["Terms"]] = k
    surface_obj.update_tag()
    return holder
