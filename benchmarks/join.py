"""Joined patches: a mesh cut in two, its first patch fitted, its second fitted on its own and
joined to the first's surface along their shared border (``fit_surface(join=...)``,
``core.join``), in the same run.

    .venv/bin/python benchmarks/join.py [--quick]

Cases: the cap (faces with centroid z > 0.2) and the rest of a 64 x 32 UV sphere, the same cut at
z > 0.3 of a 32 x 16 one, a grid mesh of 80 x 80 vertices of a bump and waves over the unit
square cut along the wavy line ``x = 0.5 + 0.1 sin 9y``, and nefertiti.off cut in halves across
its longest axis. Tolerance 1e-3 (the 32 x 16 sphere: 3e-3), other settings default.
Columns: the shared border edges; the gap between the two surfaces' borders (``report["join"]``:
the largest and RMS distance from the second's border to the first's along the shared edges,
over the diagonal), alone -> joined; *mesh gap*: the same seen on the tessellations at
resolution 256 (``--quick``: 128; the largest distance from the second mesh's border vertices
near the seam to the first mesh), measured without ``core.join``; the second patch's RMS at its
vertices over the diagonal, its control points and seconds, alone -> joined; the share of its mesh's
area where the joined surface folds over (``report["folded"]``); and at how many of the points
on its triangles along the seam it turns over (``report["join"]["seam_folds"]`` of
``"seam_samples"``, ``core.join.seam_folds``).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from core import fit_surface  # noqa: E402
from core.geometry import point_mesh_distance  # noqa: E402
from core.join import border_edges, shared_border_edges, shared_vertices  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from meshes import split_mesh, uv_sphere  # noqa: E402


def bump_grid(n: int = 80):
    x, y = (g.ravel() for g in np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n)))
    z = 0.3 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) / 0.05) + 0.1 * np.sin(4 * x) * np.cos(3 * y)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    return np.c_[x, y, z], np.vstack([np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]])


def cases(quick: bool):
    pts, faces = uv_sphere(64, 32)
    c = pts[faces].mean(axis=1)
    yield "sphere 64x32, cap and rest", 1e-3, split_mesh(pts, faces, c[:, 2] > 0.2)
    pts, faces = uv_sphere(32, 16)
    c = pts[faces].mean(axis=1)
    yield "sphere 32x16, cap and rest", 3e-3, split_mesh(pts, faces, c[:, 2] > 0.3)
    if quick:
        return
    pts, faces = bump_grid()
    c = pts[faces].mean(axis=1)
    yield "grid 80x80, wavy cut", 1e-3, split_mesh(pts, faces,
                                                   c[:, 0] < 0.5 + 0.1 * np.sin(9 * c[:, 1]))
    pts, faces = read_geometry(ROOT / "data" / "nefertiti.off")
    c = pts[faces].mean(axis=1)
    axis = int(np.argmax(np.ptp(pts, axis=0)))
    yield "nefertiti, halves", 1e-3, split_mesh(pts, faces, c[:, axis] < np.median(pts[:, axis]))


def mesh_gap(first, second, seam_points, reach, ends, resolution: int = 256) -> float:
    """The largest distance from ``second``'s tessellation's (at ``resolution``) border
    vertices within ``reach`` of the seam (``seam_points``, dense along the shared edges), and
    not within 4 ``reach`` of its ``ends`` (an open seam's: the border goes on there along the
    second patch alone), to ``first``'s tessellation."""
    va, fa = first.tessellate(resolution)
    vb, fb = second.tessellate(resolution)
    edge = np.unique(border_edges(fb))
    near = cKDTree(seam_points).query(vb[edge])[0] <= reach
    if len(ends):
        near &= cKDTree(ends).query(vb[edge])[0] > 4 * reach
    return float(point_mesh_distance(vb[edge][near], va, fa).max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="the two spheres only, mesh gap at resolution 128")
    args = ap.parse_args()
    resolution = 128 if args.quick else 256
    warnings.simplefilter("ignore")
    print("| case | shared edges | gap max alone -> joined | gap RMS | mesh gap | second's RMS "
          "| control points | seconds | folded | seam turned |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, tol, ((pa, fa), (pb, fb)) in cases(args.quick):
        first = fit_surface(pa, fa, tolerance=tol)
        pairs = shared_vertices(pb, pa)
        t = time.perf_counter()
        alone = fit_surface(pb, fb, tolerance=tol)
        t_alone = time.perf_counter() - t
        t = time.perf_counter()
        joined = fit_surface(pb, fb, tolerance=tol, join=(first, pairs))
        t_joined = time.perf_counter() - t
        j, d = joined.report["join"], joined.report["diagonal"]
        mine = shared_border_edges(fb, fa, pairs)[0]
        s = np.linspace(0, 1, 9)[:, None, None]
        seam = ((1 - s) * pb[mine[:, 0]] + s * pb[mine[:, 1]]).reshape(-1, 3)
        reach = 0.5 * float(np.median(np.linalg.norm(pb[mine[:, 0]] - pb[mine[:, 1]], axis=1)))
        at, count = np.unique(mine, return_counts=True)
        ends = pb[at[count == 1]]
        gaps = [mesh_gap(first, s_, seam, reach, ends, resolution) / d for s_ in (alone, joined)]
        print(f"| {name} | {j['shared_edges']} | {j['gap_max_unjoined_rel']:.2e} -> "
              f"{j['gap_max_rel']:.2e} | {j['gap_rms_unjoined_rel']:.2e} -> {j['gap_rms_rel']:.2e} "
              f"| {gaps[0]:.2e} -> {gaps[1]:.2e} | {alone.report['rms_rel']:.2e} -> "
              f"{joined.report['rms_rel']:.2e} | {alone.report['control_points']} -> "
              f"{joined.report['control_points']} | {t_alone:.1f} -> {t_joined:.1f} "
              f"| {joined.report.get('folded', 0.0):.2g} "
              f"| {j['seam_folds']} of {j['seam_samples']} |", flush=True)


if __name__ == "__main__":
    main()
