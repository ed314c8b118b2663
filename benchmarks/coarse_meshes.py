"""Coarse meshes: a mesh's face samples on its flat facets, on point-normal triangles through its
vertices and on the C^1 interpolant of its map (``core.surface.mesh_samples``), in the same run.

A mesh is fitted to its vertices and to points sampled on its faces (20 per vertex). On the flat
faces a coarse mesh of a smooth shape is fitted as its facets, with the creases between them.
"pn": the samples on point-normal triangles (``core.surface.curved_points``, the thirty-first
session's), only C^0 across the faces' edges in the parameters. "c1" (the default since the
thirty-second session): on the Clough-Tocher interpolant of the map from the parameters
(``core.surface.smooth_points``, ``core.smooth_faces``). Both keep a face's own plane at
creases and in flat regions (``core.surface.flat_corners``). Cases with a known true surface:
caps of a unit sphere cut from icospheres (z > 0.3), grid meshes of ``0.3 sin 2x cos y`` (and
of ``0.3 sin 3x cos 2y``, coarser for its waves) over [-1, 1]^2, half cylinders of radius 1
with few segments, and a grid folded along a 90-degree crease (``z = |y|``: its facets are the
truth); then the three bundled meshes, whose truth is not known. Each case is fitted with the
seeds 0 to ``--seeds`` - 1 (the samples' draw and the start's knots): the columns give the
median over the seeds of the control points, the max error at the vertices and the RMS
distance of the tessellation (resolution 64) from the true surface (over the bounding-box
diagonal), and the total seconds. Default settings otherwise (tolerance 1e-3 RMS, budget 2000),
but no coarser start after one that meets the tolerance by far (see SHRINK_FRACTION below).

    .venv/bin/python benchmarks/coarse_meshes.py [--quick] [--seeds N]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import core.surface as surface_module  # noqa: E402
from core import fit_surface  # noqa: E402
import core.refine  # noqa: E402
from core.meshio import read_geometry  # noqa: E402


def sphere_cap(subdivisions: int):
    """The faces of an icosphere (``subdivisions`` times split in four) with all corners above
    z = 0.3, and the distance from the unit sphere."""
    t = (1 + 5**0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = ConvexHull(v).simplices
    a, b, c = (v[f[:, j]] for j in range(3))
    f = np.where((np.cross(b - a, c - a) * a).sum(axis=1)[:, None] > 0, f, f[:, ::-1])  # outward
    for _ in range(subdivisions):
        edges = np.sort(np.r_[f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1)
        uniq, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].sum(axis=1)
        v = np.r_[v, mid / np.linalg.norm(mid, axis=1, keepdims=True)]
        ab, bc, ca = (len(v) - len(uniq) + inverse.reshape(3, -1))
        a, b, c = f.T
        f = np.r_[np.c_[a, ab, ca], np.c_[b, bc, ab], np.c_[c, ca, bc], np.c_[ab, bc, ca]]
    f = f[(v[f][..., 2] > 0.3).all(axis=1)]
    return _compact(v, f), lambda q: np.abs(np.linalg.norm(q, axis=1) - 1.0)


def _compact(v, f):
    used = np.unique(f)
    index = np.full(len(v), -1)
    index[used] = np.arange(len(used))
    return v[used], index[f]


def grid(n: int, height):
    """An n x n grid mesh over [-1, 1]^2 lifted by ``height``, and the vertical distance."""
    g = np.linspace(-1, 1, n)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    faces = np.r_[np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]]
    return (np.c_[x, y, height(x, y)], faces), lambda q: np.abs(q[:, 2] - height(q[:, 0], q[:, 1]))


def half_cylinder(segments: int, rows: int = 4):
    """Half a cylinder of radius 1 and length 2, ``segments`` facets around, and the distance."""
    th = np.linspace(0, np.pi, segments + 1)
    z = np.linspace(-1, 1, rows)
    t, zz = (a.ravel() for a in np.meshgrid(th, z, indexing="ij"))
    i = np.arange((segments + 1) * rows).reshape(segments + 1, rows)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    faces = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    return (np.c_[np.cos(t), np.sin(t), zz], faces), (
        lambda q: np.abs(np.hypot(q[:, 0], q[:, 1]) - 1.0))


def smooth(x, y):
    return 0.3 * np.sin(2 * x) * np.cos(y)


def waves(x, y):
    return 0.3 * np.sin(3 * x) * np.cos(2 * y)


def crease(x, y):
    return np.abs(y)


def cases(quick: bool):
    out = [("sphere cap, 55 vertices", *sphere_cap(2)),
           ("sphere cap, 223 vertices", *sphere_cap(3)),
           ("grid 11 x 11", *grid(11, smooth))]
    if not quick:
        out += [("sphere cap, 917 vertices", *sphere_cap(4)),
                ("grid 21 x 21", *grid(21, smooth)),
                ("grid 41 x 41", *grid(41, smooth)),
                ("half cylinder, 8 segments", *half_cylinder(8)),
                ("half cylinder, 16 segments", *half_cylinder(16)),
                ("90-degree crease, 21 x 21", *grid(21, crease)),
                ("grid 4 x 4 of 0.3 sin 3x cos 2y", *grid(4, waves)),
                ("grid 8 x 8 of 0.3 sin 3x cos 2y", *grid(8, waves))]
        for name in ("nefertiti", "patch-01", "three_peaks"):
            out.append((f"{name}.off", read_geometry(ROOT / "data" / f"{name}.off"), None))
    return out


VARIANTS = ("flat", "pn", "c1")


def run(mesh, truth, variant: str, seeds: int) -> dict:
    """Fit ``mesh`` with each seed, its face samples on the ``variant``'s surface; medians."""
    original, smooth = surface_module.mesh_samples, surface_module.smooth_points

    def samples(*args, **kwargs):
        return original(*args, **{**kwargs, "curved": variant != "flat" and
                                  kwargs.get("curved", True)})

    def point_normal(points, uv, faces, face, bary, vertex_normals=None, prepared=None):
        return surface_module.curved_points(points, faces, face, bary, vertex_normals)

    surface_module.mesh_samples = samples
    if variant == "pn":
        surface_module.smooth_points = point_normal
    cps, worst, true, seconds = [], [], [], 0.0
    try:
        for seed in range(seeds):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                t0 = time.perf_counter()
                surf = fit_surface(*mesh, seed=seed)
                seconds += time.perf_counter() - t0
            r = surf.report
            cps.append(r["control_points"])
            worst.append(r["max_rel"])
            if truth is not None:
                off = truth(surf.tessellate(64)[0]) / r["diagonal"]
                true.append(float(np.sqrt(np.mean(off**2))))
    finally:
        surface_module.mesh_samples, surface_module.smooth_points = original, smooth
    return {"cp": int(np.median(cps)), "max": float(np.median(worst)), "s": seconds,
            "true": float(np.median(true)) if true else None}


def cell(x: dict) -> str:
    true = "-" if x["true"] is None else f"{x['true']:.2e}"
    return f"{x['cp']} | {x['max']:.2e} | {true} | {x['s']:.1f}"


def main() -> None:
    # no coarser start after one that meets the tolerance by far (core.refine.SHRINK_FRACTION):
    # the variants' smoother samples would meet it with smaller nets, and their distances from
    # the true surface would compare nets of different sizes (the tables here are of same-sized
    # starts, as before the thirty-third session). Here, not at import: a test that imports the
    # meshes of this module had turned them off for the tests after it (review)
    core.refine.SHRINK_FRACTION = 0.0
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="three small cases")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per case (default 3)")
    args = ap.parse_args()
    head = " | ".join(f"{v}: cp | max | true RMS | s" for v in VARIANTS)
    print(f"| mesh | {head} |")
    print("|---|" + "---|" * (4 * len(VARIANTS)))
    for name, mesh, truth in cases(args.quick):
        cells = " | ".join(cell(run(mesh, truth, v, args.seeds)) for v in VARIANTS)
        print(f"| {name} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
