"""How faithful the default surface mesh is: vertices, seconds and distances at resolution 64.

    .venv/bin/python benchmarks/tessellation_fidelity.py [--resolution 64] [--brow FILE.npz]

Users judge a fit by the displayed mesh. Per dataset (fitted with the defaults): the fit's
control points and largest error at the data, the tessellation's vertices and seconds
(``tessellate``, cache cleared), the share of the square on the longer side of the grid frame
that the domain fills and the resulting ``tessellation_fill`` (1: the step is ``side /
resolution``), and two distances over the bounding-box diagonal: from the spline at the data's
parameters to the mesh ("mesh-spline", the tessellation's own error, which should stay a
fraction of the fit's), and from the data points to the mesh ("data-mesh", what a user sees;
at least about the fit's error).

Datasets: a square 40 x 40 grid cloud of ``0.2 sin 3x cos 2y``; nefertiti.off (a disk map);
a half ring of quads 0.4 wide and 3.8 long (its map keeps its boundary, 0.15 of its square);
``--brow``: an npz with ``V`` (n, 3) and ``F`` (f, 4) quads (the Suzanne brow patch of the
user test, exported from Blender: /tmp/h80_scratch/export_brow.py of the session).
Run it in two checkouts to compare.
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

from core import fit_surface  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from core.surface import grid_frame  # noqa: E402


def point_triangle_distance(p, a, b, c):
    """Distances (m,) from points p to triangles (a, b, c), all (m, 3) (Ericson's regions)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(all="ignore"):
        den = va + vb + vc
        q = a + ab * (vb / den)[:, None] + ac * (vc / den)[:, None]
        t = d1 / (d1 - d3)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        q[m] = (a + ab * t[:, None])[m]
        t = d2 / (d2 - d6)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        q[m] = (a + ac * t[:, None])[m]
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        q[m] = (b + (c - b) * t[:, None])[m]
        q[(d1 <= 0) & (d2 <= 0)] = a[(d1 <= 0) & (d2 <= 0)]
        q[(d3 >= 0) & (d4 <= d3)] = b[(d3 >= 0) & (d4 <= d3)]
        q[(d6 >= 0) & (d5 <= d6)] = c[(d6 >= 0) & (d5 <= d6)]
    return np.linalg.norm(p - q, axis=1)


def to_mesh(points, verts, tris, k=48):
    """Distance from each point to the triangle mesh (the nearest of the k triangles whose
    centroids are nearest)."""
    _, near = cKDTree(verts[tris].mean(axis=1)).query(points, k=min(k, len(tris)))
    best = np.full(len(points), np.inf)
    for j in range(near.shape[1]):
        t = tris[near[:, j]]
        corners = (verts[t[:, i]] for i in range(3))
        best = np.minimum(best, point_triangle_distance(points, *corners))
    return best


def half_ring(nr=6, nt=40):
    r, t = np.meshgrid(np.linspace(1.0, 1.4, nr), np.linspace(0, np.pi, nt))
    x, y = r * np.cos(t), r * np.sin(t)
    z = 1.5 * np.sin(4 * t) * (r - 1.2) + 0.1 * np.cos(3 * x)
    idx = np.arange(nr * nt).reshape(nt, nr)
    a, b, c, d = (idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(),
                  idx[1:, :-1].ravel())
    return np.c_[x.ravel(), y.ravel(), z.ravel()], np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def datasets(brow):
    g = np.linspace(0, 1, 40)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    yield "square grid cloud", np.c_[x, y, 0.2 * np.sin(3 * x) * np.cos(2 * y)], None
    yield "nefertiti", *read_geometry(ROOT / "data" / "nefertiti.off")
    yield "half ring", *half_ring()
    if brow:
        z = np.load(brow)
        F = z["F"]
        yield "suzanne brow", z["V"], np.vstack([F[:, [0, 1, 2]], F[:, [0, 2, 3]]])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--brow", default=None)
    args = ap.parse_args()
    try:
        from core.surface import tessellation_fill
    except ImportError:  # (before it)
        def tessellation_fill(param):
            return float("nan")
    print("| data | control points | fit max | share of square | fill | vertices | seconds "
          "| mesh-spline max | data-mesh max |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, pts, faces in datasets(args.brow):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            surf = fit_surface(pts, faces)
        diag = surf.report["diagonal"]
        poly = np.asarray(surf.parameterization.domain_polygon)
        area = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1))
                         - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
        _, lo, hi = grid_frame(surf.parameterization)
        share = area / float(np.max(hi - lo)) ** 2
        surf._tess_cache.clear()
        t0 = time.perf_counter()
        verts, tris = surf.tessellate(args.resolution)
        seconds = time.perf_counter() - t0
        uv = surf.parameterization.uv
        at = surf(uv[np.isfinite(uv).all(axis=1)])
        spline_gap = to_mesh(at[np.isfinite(at).all(axis=1)], verts, tris).max() / diag
        data_gap = to_mesh(np.asarray(pts, dtype=float), verts, tris).max() / diag
        print(f"| {name} | {surf.report['control_points']} | {surf.report['max_rel']:.2e} "
              f"| {share:.2f} | {tessellation_fill(surf.parameterization):.2f} | {len(verts)} "
              f"| {seconds:.2f} | {spline_gap:.2e} | {data_gap:.2e} |", flush=True)


if __name__ == "__main__":
    main()
