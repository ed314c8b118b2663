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
"""

from __future__ import annotations

import bpy
import numpy as np

GROUP_NAME = "TCB Live Surface"
MODIFIER_NAME = "TCB Live Net"
INPUTS = ("Net", "Weights", "Terms")


def node_group() -> bpy.types.NodeTree:
    """The shared node group (created once per file)."""
    ng = bpy.data.node_groups.get(GROUP_NAME)
    if ng is not None and ng.bl_idname == "GeometryNodeTree":
        return ng
    ng = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    iface = ng.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Net", in_out="INPUT", socket_type="NodeSocketObject")
    iface.new_socket("Weights", in_out="INPUT", socket_type="NodeSocketObject")
    terms = iface.new_socket("Terms", in_out="INPUT", socket_type="NodeSocketInt")
    terms.default_value, terms.min_value = 1, 1
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")

    nodes, links = ng.nodes, ng.links
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
    first = nodes.new("ShaderNodeMath")
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
    links.new(set_pos.outputs["Geometry"], gout.inputs["Geometry"])
    for i, node in enumerate(nodes):
        node.location = (200 * (i % 6), -200 * (i // 6))
    return ng


def padded_weights(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(index, weight, vertex) arrays of length m*K from a CSR matrix (m, n); and K."""
    csr = matrix.tocsr()
    csr.sort_indices()
    m = csr.shape[0]
    counts = np.diff(csr.indptr)
    k = max(int(counts.max(initial=0)), 1)
    slot = np.repeat(np.arange(m) * k, counts) + (
        np.arange(csr.nnz) - np.repeat(csr.indptr[:-1], counts)
    )
    index = np.zeros(m * k, np.int32)
    weight = np.zeros(m * k, np.float32)
    index[slot] = csr.indices
    weight[slot] = csr.data
    vertex = np.repeat(np.arange(m, dtype=np.int32), k)
    return index, weight, vertex, k


def attach(surface_obj, net_obj, surf, resolution: int) -> bpy.types.Object:
    """Make ``surface_obj`` follow ``net_obj`` live; returns the (hidden) weights object."""
    from . import bridge

    uv, _ = surf.tessellation_uv(resolution)
    index, weight, vertex, k = padded_weights(surf.evaluation_matrix(uv))
    mesh = bridge.new_mesh(f"{surface_obj.name} Weights", np.zeros((len(index), 3), np.float32))
    for name, values, kind in (
        ("tcb_index", index, "INT"),
        ("tcb_weight", weight, "FLOAT"),
        ("tcb_vertex", vertex, "INT"),
    ):
        attr = mesh.attributes.new(name, kind, "POINT")
        attr.data.foreach_set("value", values)

    holder = surface_obj.tcb.weights
    if holder is None:
        holder = bpy.data.objects.new(f"{surface_obj.name} Weights", mesh)
        for coll in surface_obj.users_collection:
            coll.objects.link(holder)
        holder.hide_viewport = holder.hide_render = holder.hide_select = True
        holder.tcb.role = "WEIGHTS"
        holder.tcb.surface = surface_obj
        surface_obj.tcb.weights = holder
    else:
        bridge.replace_mesh(holder, mesh)

    mod = surface_obj.modifiers.get(MODIFIER_NAME)
    if mod is None:
        mod = surface_obj.modifiers.new(MODIFIER_NAME, "NODES")
    mod.node_group = node_group()
    ids = {
        item.name: item.identifier
        for item in mod.node_group.interface.items_tree
        if getattr(item, "in_out", None) == "INPUT"
    }
    mod[ids["Net"]] = net_obj
    mod[ids["Weights"]] = holder
    mod[ids["Terms"]] = k
    surface_obj.update_tag()
    return holder
