"""Coarse meshes: a mesh's face samples on its flat facets against samples on curved
(point-normal) triangles through its vertices (``core.surface.mesh_samples``), in the same run.

A mesh is fitted to its vertices and to points sampled on its faces (20 per vertex). On the flat
faces a coarse mesh of a smooth shape is fitted as its facets, with the creases between them;
on the curved triangles of ``core.surface.curved_points`` (PN triangles, a face's own normal at
a crease's corners) as the smooth shape through its vertices. Cases with a known true surface:
caps of a unit sphere cut from icospheres (z > 0.3), grid meshes of ``0.3 sin 2x cos y`` over
[-1, 1]^2, half cylinders of radius 1 with few segments, and a grid folded along a 90-degree
crease (``z = |y|``: its facets are the truth, so curving them would be wrong); then the three
bundled meshes, whose truth is not known. Columns per variant: control points, RMS and max
error at the vertices, and RMS and max distance of the tessellation (resolution 64) from the
true surface (all over the bounding-box diagonal), seconds. Default settings otherwise
(tolerance 1e-3 RMS, budget 2000).

    .venv/bin/python benchmarks/coarse_meshes.py [--quick]
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
                ("90-degree crease, 21 x 21", *grid(21, crease))]
        for name in ("nefertiti", "patch-01", "three_peaks"):
            out.append((f"{name}.off", read_geometry(ROOT / "data" / f"{name}.off"), None))
    return out


def run(mesh, truth, curved: bool) -> dict:
    original = surface_module.mesh_samples

    def samples(*args, **kwargs):
        return original(*args, **{**kwargs, "curved": curved and kwargs.get("curved", True)})

    surface_module.mesh_samples = samples
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            t0 = time.perf_counter()
            surf = fit_surface(*mesh)
            seconds = time.perf_counter() - t0
    finally:
        surface_module.mesh_samples = original
    r = surf.report
    out = {"cp": r["control_points"], "rms": r["rms_rel"], "max": r["max_rel"], "s": seconds}
    if truth is not None:
        off = truth(surf.tessellate(64)[0]) / r["diagonal"]
        out["true_rms"], out["true_max"] = float(np.sqrt(np.mean(off**2))), float(off.max())
    return out


def cell(x: dict) -> str:
    true = (f"{x['true_rms']:.2e} | {x['true_max']:.2e}" if "true_rms" in x else "- | -")
    return f"{x['cp']} | {x['rms']:.2e} | {x['max']:.2e} | {true} | {x['s']:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="three small cases")
    args = ap.parse_args()
    head = " | ".join(f"{v}: cp | RMS | max | true RMS | true max | s" for v in ("flat", "curved"))
    print(f"| mesh | {head} |")
    print("|---|" + "---|" * 12)
    for name, mesh, truth in cases(args.quick):
        flat, curved = run(mesh, truth, False), run(mesh, truth, True)
        print(f"| {name} | {cell(flat)} | {cell(curved)} |", flush=True)


if __name__ == "__main__":
    main()
