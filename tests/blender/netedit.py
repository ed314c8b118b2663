"""Helpers shared by the Blender tests: read an object's vertex positions, move a net vertex."""

from __future__ import annotations

import numpy as np


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
