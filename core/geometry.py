"""Distances between points and triangle meshes (for deviation maps), vectorized.

``closest_point_on_triangles`` is the region test of Ericson, *Real-Time Collision Detection*
(2005), section 5.1.5, evaluated for many (point, triangle) pairs at once.
``point_mesh_distance`` picks candidate triangles per point with a KD-tree over triangle
centres (the ``k`` nearest) and takes the smallest exact distance among them.
``column_bounds`` is the per-column minimum and maximum of a long ``(n, d)`` array.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["closest_point_on_triangles", "column_bounds", "point_mesh_distance"]


def column_bounds(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column minimum and maximum ``(d,)``, ``(d,)`` of an ``(n, d)`` array, ``n >= 1``.

    One 1-D reduction per column: numpy 1.26 reduces a C-ordered ``(n, 2|3)`` array over
    ``axis=0`` about 10x slower (92 ms against 6 ms for min and max of 1e6 x 3).
    """
    a = np.asarray(a)
    lo = np.array([a[:, j].min() for j in range(a.shape[1])])
    hi = np.array([a[:, j].max() for j in range(a.shape[1])])
    return lo, hi


def closest_point_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray):
    """Closest points (n, 3) on triangles ``abc`` to points ``p`` (all (n, 3), row by row)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    out = np.empty_like(p)
    done = np.zeros(len(p), dtype=bool)

    def put(mask, value):
        m = mask & ~done
        out[m] = value[m] if value.ndim == 2 else value
        done[m] = True

    put((d1 <= 0) & (d2 <= 0), a)  # vertex regions
    put((d3 >= 0) & (d4 <= d3), b)
    put((d6 >= 0) & (d5 <= d6), c)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = d1 / (d1 - d3)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + v[:, None] * ab)  # edge ab
        w = d2 / (d2 - d6)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + w[:, None] * ac)  # edge ac
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b + w[:, None] * (c - b))  # bc
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        face = a + v[:, None] * ab + w[:, None] * ac
    face = np.where(np.isfinite(face), face, a)  # degenerate triangle: its first vertex
    put(np.ones(len(p), dtype=bool), face)
    return out


def point_mesh_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                        k: int = 8, chunk: int = 100_000) -> np.ndarray:
    """Distance (m,) from each point (m, 3) to the triangle mesh ``vertices``/``faces``.

    Candidates: the ``k`` triangles with the nearest centres. The result is exact whenever the
    closest triangle is among them (it was on the sample meshes, checked against an exhaustive
    search in the tests) and otherwise an upper bound, never smaller than the true distance.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(F) == 0:
        return cKDTree(V).query(points)[0]
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    tree = cKDTree((A + B + C) / 3)
    k = int(min(k, len(F)))
    out = np.empty(len(points))
    for s in range(0, len(points), chunk):
        p = points[s : s + chunk]
        _, idx = tree.query(p, k=k)
        idx = idx.reshape(len(p), k)
        rep = np.repeat(p, k, axis=0)
        t = idx.ravel()
        q = closest_point_on_triangles(rep, A[t], B[t], C[t])
        out[s : s + chunk] = np.linalg.norm(q - rep, axis=1).reshape(len(p), k).min(axis=1)
    return out
