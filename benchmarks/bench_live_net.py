"""Live control net benchmark (issue 4): surface update time after moving one net vertex.

Fits a smooth 40x40 grid patch in background Blender (bpy wheel; the extension is installed
into a temporary user folder exactly as ``scripts/fit_in_blender.py`` does), tessellates it at
about 1e5 vertices with the Geometry Nodes live-net modifier, then moves one net vertex and
times the depsgraph update that re-evaluates the surface (median of 60). Peer in the same run:
what a Python ``depsgraph_update_post`` handler would do instead -- one sparse product
``M @ control_points``, a ``foreach_set`` of the positions and the same depsgraph update, with
the modifier switched off.

    .venv/bin/python benchmarks/bench_live_net.py [--resolution 360]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

import fit_in_blender as fib  # noqa: E402


def positions(obj) -> np.ndarray:
    attr = obj.data.attributes["position"]
    buf = np.empty(len(attr.data) * 3, dtype=np.float32)
    attr.data.foreach_get("vector", buf)
    return buf.reshape(-1, 3)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=360, help="tessellation steps (360: ~1e5 vertices)")
    ap.add_argument("--repeats", type=int, default=60)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="tcb_bench_"))
    fib.redirect_user_folders(tmp)
    import base64
    import importlib

    import bpy

    addon = fib.install_extension(bpy, tmp, real_blender=False, cleanup=[])
    core = importlib.import_module(addon + ".core")
    fib.clear_scene(bpy)
    g = np.linspace(-1, 1, 40)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    verts = np.c_[xy, 0.3 * np.sin(2 * xy[:, 0]) * np.cos(2 * xy[:, 1])]
    i, j = np.meshgrid(np.arange(39), np.arange(39))
    a = (j * 40 + i).ravel()
    faces = np.concatenate([np.c_[a, a + 1, a + 41, a + 40]])
    mesh = bpy.data.meshes.new("Patch")
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    obj = bpy.data.objects.new("Patch", mesh)
    bpy.context.scene.collection.objects.link(obj)
    ns = SimpleNamespace(tolerance=3e-3, relative=True, criterion="rms", max_control_points=2000,
                         max_iterations=20, degree=2, mode="tcb", smoothness=1e-4,
                         resolution=args.resolution, live_net=True)
    surface = fib.fit(bpy, [obj], ns)
    net = surface.tcb.net
    surf = core.TCBSurface.from_bytes(base64.b64decode(surface["tcb_spline"]))
    n_vertices = len(surface.data.vertices)
    p = positions(net).astype(np.float64)
    k = len(p) // 2
    depsgraph = bpy.context.evaluated_depsgraph_get()
    times = []
    for r in range(args.repeats + 1):
        p[k, 2] += 0.01 * (1 if r % 2 else -1)
        net.data.attributes["position"].data.foreach_set("vector", p.astype(np.float32).ravel())
        net.data.update()
        t0 = time.perf_counter()
        bpy.context.view_layer.update()
        ev = surface.evaluated_get(depsgraph)
        _ = len(ev.data.vertices)
        if r:  # the first update builds the node tree's caches
            times.append(time.perf_counter() - t0)
    # peer: a Python handler re-evaluating the surface with the stored sparse matrix
    uv, _ = surf.tessellation_uv(args.resolution)
    M = surf.evaluation_matrix(uv)
    surface.modifiers["TCB Live Net"].show_viewport = False  # the peer replaces the modifier
    peer = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        xyz = (M @ p).astype(np.float32)
        surface.data.attributes["position"].data.foreach_set("vector", xyz.ravel())
        surface.data.update()
        bpy.context.view_layer.update()  # the same depsgraph evaluation, without the modifier
        _ = len(surface.evaluated_get(depsgraph).data.vertices)
        peer.append(time.perf_counter() - t0)
    gn, py = statistics.median(times) * 1e3, statistics.median(peer) * 1e3
    print(f"{'surface vertices':>18} {'control points':>15} {'nnz/row':>8} {'GN update ms':>13} "
          f"{'Python peer ms':>15} {'ratio':>6}")
    print(f"{n_vertices:>18} {len(p):>15} {M.nnz / M.shape[0]:>8.1f} {gn:>13.1f} {py:>15.1f} "
          f"{gn / py:>6.2f}")
    print("GN update = view_layer.update() + evaluated mesh after moving one net vertex (median); "
          "goal <= 16 ms")


if __name__ == "__main__":
    main()
