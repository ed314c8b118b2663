"""Distances between points and triangle meshes (for deviation maps), vectorized.

``closest_point_on_triangles`` is the region test of Ericson, *Real-Time Collision Detection*
(2005), section 5.1.5, evaluated for many (point, triangle) pairs at once.
``point_mesh_distance`` picks candidate triangles per point with a KD-tree over triangle
centres (the ``k`` nearest) and takes the smallest exact distance among them.
``column_bounds`` is the per-column minimum and maximum of a long ``(n, d)`` array;
``float32_rounding`` says when 32-bit coordinates are already coarsely rounded.
``distances_at_vertices`` carries the data-to-surface distances of a point cloud to the vertices
of the surface mesh (the deviation map of a cloud). ``simple_polygon`` and ``ear_clipping`` test
and triangulate a simple polygon (the holes of a mesh that ``fill_holes`` spans).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .configurations import _segments_cross
from .simplex import orient2d

__all__ = ["closest_point_on_triangles", "column_bounds", "coordinate_order",
           "distances_at_vertices", "ear_clipping", "float32_rounding", "point_mesh_distance",
           "polygon_triangles", "quad_triangles", "simple_polygon"]


def column_bounds(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column minimum and maximum ``(d,)``, ``(d,)`` of an ``(n, d)`` array, ``n >= 1``.

    One 1-D reduction per column: numpy 1.26 reduces a C-ordered ``(n, 2|3)`` array over
    ``axis=0`` about 10x slower (92 ms against 6 ms for min and max of 1e6 x 3).
    """
    a = np.asarray(a)
    lo = np.array([a[:, j].min() for j in range(a.shape[1])])
    hi = np.array([a[:, j].max() for j in range(a.shape[1])])
    return lo, hi


# coordinate_order's grid: a share of the largest extent of the points (see there)
ORDER_QUANTUM = 1e-9


def coordinate_order(points: np.ndarray) -> np.ndarray | None:
    """The order of the rows of ``points`` (n, d) by their coordinates alone, or None when
    they are in that order already. The fit's seeded draws (subsets, the start's knots) pick
    points by their place in this order, so the same data stored in another order gets the
    same surface (a cloud of 3000 points shuffled had got 499 to 507 control points).

    The coordinates are first taken on a grid of ORDER_QUANTUM of the largest extent
    (``floor((p - min) / step + 1/2)``): the first column's cell, ties by the second's, ...; then,
    among rows in the same cells, by the coordinates themselves. Exact ties, as along the
    grid lines of a CAD mesh, were broken by the next column's rounding, so the data moved by
    rounding (translated by 64, scaled by 1e-3, noise of 1e-12 of its diagonal) was drawn
    in another order: patch-01.off got 636 to 731 control points, its max error 5.3e-3 to
    8.8e-3 of the diagonal (user test); in cells 1e-9 apart such moves keep the order but
    where a value lies within them of a cell's edge.

    A stable sort of the first column's cells; rows that share one are sorted among
    themselves (a lexsort of those rows only, their places kept); a check in one pass when the
    rows are sorted. NaN rows go last. 1e6 random points: 0.28-0.33 s (0.21 s without the
    cells); on a 1000 x 1000 lattice, whose rows all share cells, 1.0-1.25 s (0.71-0.88 s)."""
    exact = np.asarray(points)
    n = len(exact)
    if n < 2:
        return None
    finite = np.isfinite(exact).all(axis=1)
    p = exact
    if finite.any():
        lo, hi = column_bounds(exact[finite])
        step = ORDER_QUANTUM * float(np.max(hi - lo))
        if step > 0:
            with np.errstate(invalid="ignore"):
                # (half a cell off: the extremes, and a lattice's nodes at whole shares of
                # the extent, fall mid-cell, not on the edges between cells)
                p = np.floor((exact - lo) / step + 0.5)
    d = np.diff(p, axis=0)
    step_sign = d[:, 0]
    for j in range(1, d.shape[1]):  # the first column that differs decides
        step_sign = np.where(step_sign == 0, d[:, j], step_sign)
    level = np.flatnonzero(step_sign == 0)  # (in the same cells: the coordinates decide)
    if len(level) and p is not exact:
        e = exact[level + 1] - exact[level]
        sign = e[:, 0]
        for j in range(1, e.shape[1]):
            sign = np.where(sign == 0, e[:, j], sign)
        step_sign[level] = sign
    if not (step_sign < 0).any() and not np.isnan(step_sign).any():  # (NaN rows: at the end)
        return None
    order = np.argsort(p[:, 0], kind="stable")
    x = p[order, 0]
    tied = np.zeros(n, dtype=bool)  # (places in the order whose first cell repeats)
    same = x[1:] == x[:-1]
    tied[1:] |= same
    tied[:-1] |= same
    if tied.any():
        at = np.flatnonzero(tied)
        rows = order[at]  # (in cells of the first column, ascending: their places stay)
        order[at] = rows[np.lexsort(np.c_[p[rows], exact[rows]].T[::-1])]
    return order


def quad_triangles(points: np.ndarray, quads: np.ndarray, tie_rtol: float = 0.0,
                   tie_first: bool = False) -> np.ndarray:
    """Two triangles ``(2 m, 3)`` of each quad ``(a, b, c, d)`` of ``quads`` (m, 4), quad by
    quad, cut along the shorter diagonal (``(a, b, c), (a, c, d)`` or ``(b, c, d), (b, d, a)``,
    the quad's winding) of those whose two triangles face the quad's way (its Newell normal;
    a concave quad has one such diagonal); of equal diagonals (a square), the one through the
    corner of least coordinates (x, then y, then z). The cut does not depend on which corner a
    quad starts at (a fan from the first corner did: a 6 x 6 quad grid got 142-335 control
    points as its quads' corners were turned; review), and the shorter diagonal is Blender's
    Triangulate default (Shortest Diagonal). Quads with neither diagonal facing their way (a
    bow tie) are cut along the shorter too; with NaN corners along ``a c``.

    ``tie_rtol``: diagonals whose squared lengths differ by at most this share of the larger
    are a tie; ``tie_first``: ties are cut along ``a c`` (the extension, for Blender's
    vertices rounded to float32 by Apply Rotation & Scale: a square's cut by its least corner
    could flip, and Refine then saw other faces)."""
    q = np.asarray(quads, dtype=np.int64)
    if len(q) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    P = np.asarray(points, dtype=np.float64)[q]  # (m, 4, 3)
    a, b, c, d = (P[:, j] for j in range(4))
    with np.errstate(invalid="ignore", over="ignore"):
        normal = np.cross(P, np.roll(P, -1, axis=1)).sum(axis=1)
        facing = lambda u, v, w: np.einsum("ij,ij->i", np.cross(v - u, w - u), normal) > 0  # noqa: E731
        ok_ac = facing(a, b, c) & facing(a, c, d)
        ok_bd = facing(b, c, d) & facing(b, d, a)
        ac = np.einsum("ij,ij->i", c - a, c - a)
        bd = np.einsum("ij,ij->i", d - b, d - b)
    # the corner of least coordinates: compared two by two, lexicographically
    least = np.zeros(len(q), dtype=np.int64)
    for j in range(1, 4):
        x, y = P[np.arange(len(q)), least], P[:, j]
        less = x[:, 0] > y[:, 0]
        for k in (1, 2):
            tie = x[:, :k] == y[:, :k]
            less |= tie.all(axis=1) & (x[:, k] > y[:, k])
        least = np.where(less, j, least)
    with np.errstate(invalid="ignore"):
        tie = np.abs(bd - ac) <= tie_rtol * np.maximum(ac, bd)
    shorter = np.where(tie, False if tie_first else least % 2 == 1, bd < ac)
    by_bd = np.where(ok_ac == ok_bd, shorter, ok_bd)
    first = np.where(by_bd[:, None], q[:, [1, 2, 3]], q[:, [0, 1, 2]])
    second = np.where(by_bd[:, None], q[:, [1, 3, 0]], q[:, [0, 2, 3]])
    return np.stack([first, second], axis=1).reshape(-1, 3)


def polygon_triangles(points: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Triangles ``(m (k - 2), 3)`` of the polygons ``polys`` (m, k) of ``points`` (n, 3),
    polygon by polygon, each in its winding, whatever corner it starts at (not in method.md;
    the engine's own reading of a mesh's faces): triangles as given, quads by
    :func:`quad_triangles`, and larger polygons by clipping ears: each step cuts off, of the
    corners left, the one whose triangle with its two neighbours has the largest smallest-angle
    sine (:func:`_min_sine`, in 3D), of those alike to rounding the one with the shorter
    diagonal, then the corner of least coordinates (x, then y, then z): the same triangles
    for either winding. A convex polygon (every corner turns its way about its Newell normal,
    to rounding; corners in a row included) has every corner as an ear: its steps run for all
    such polygons at once. Others are cut by :func:`ear_clipping` in the plane across their
    normal (the same choice among their ears), and one that does not clip (it crosses
    itself) as the fan from its corner of least coordinates; NaN corners: the fan from the
    first. Fans from the first corner (what was done before) made a height field of 140
    convex pentagons to heptagons fit with 107-146 control points as the polygons' first
    corners were turned, 2.4-4.8e-4 of the diagonal (RMS) from the true surface; now 143
    every time, 2.1e-4 (/tmp/s34/ngon.py)."""
    q = np.asarray(polys, dtype=np.int64)
    m, k = q.shape if q.ndim == 2 else (0, 0)
    if k == 3 or m == 0:
        return q.reshape(-1, 3) if k == 3 else np.zeros((0, 3), dtype=np.int64)
    if k == 4:
        return quad_triangles(points, q)
    points = np.asarray(points, dtype=np.float64)
    rank = np.empty(len(points), dtype=np.int64)
    rank[np.lexsort(points.T[::-1])] = np.arange(len(points))
    corner_rank = rank[q]  # (m, k)
    P = points[q]  # (m, k, 3)
    finite = np.isfinite(P).all(axis=(1, 2))
    least = corner_rank.argmin(axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        # centred (far from the origin, float32) at the corner of least coordinates: at the
        # mean, summed in the corners' order, a regular octagon's ears differed in their last
        # bits with the corner it started at, and so did its cut
        P = P - P[np.arange(m), least][:, None]
        normal = np.cross(P, np.roll(P, -1, axis=1)).sum(axis=1)  # Newell: twice the area
        e = np.roll(P, -1, axis=1) - P
        turn = np.einsum("mkj,mj->mk", np.cross(np.roll(e, 1, axis=1), e), normal)
        size = np.einsum("mkj,mkj->mk", e, e).max(axis=1) * np.linalg.norm(normal, axis=1)
        convex = finite & ~(turn < -1e-9 * size[:, None]).any(axis=1)
    tris = np.empty((m, k - 2, 3), dtype=np.int64)
    # convex polygons: the steps for all of them at once; ring holds the corners left
    c = np.flatnonzero(convex)
    ring = np.tile(np.arange(k), (len(c), 1))
    rows = np.arange(len(c))[:, None]
    for step in range(k - 3):
        r = k - step
        prv, nxt = np.roll(ring, 1, axis=1), np.roll(ring, -1, axis=1)
        quality = _min_sine(P[c[:, None], prv].reshape(-1, 3), P[c[:, None], ring].reshape(-1, 3),
                            P[c[:, None], nxt].reshape(-1, 3)).reshape(len(c), r)
        best = quality.max(axis=1, initial=-1.0)
        # of ears alike to rounding, the one with the shorter diagonal (a polygon on a circle
        # has pairs of ears with the same smallest angle, half the arc they share), then the
        # corner of least coordinates (a regular polygon's)
        alike = quality >= best[:, None] * (1.0 - 1e-9)
        d = P[c[:, None], nxt] - P[c[:, None], prv]
        diagonal = np.where(alike, np.einsum("mrj,mrj->mr", d, d), np.inf)
        alike &= diagonal <= diagonal.min(axis=1, keepdims=True) * (1.0 + 1e-9)
        tip = np.where(alike, corner_rank[c[:, None], ring],
                       np.iinfo(np.int64).max).argmin(axis=1)
        at = (rows[:, 0], tip)
        tris[c, step] = q[c[:, None], np.stack([prv[at], ring[at], nxt[at]], axis=1)]
        ring = ring[np.arange(r) != tip[:, None]].reshape(len(c), r - 1)
    if len(c):
        tris[c, k - 3] = q[c[:, None], ring]
    # the others one by one (a concave polygon clipped in its plane; else a fan)
    for i in np.flatnonzero(~convex):
        clip = None
        if finite[i]:
            n = normal[i] / np.linalg.norm(normal[i])
            e1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            e1 /= np.linalg.norm(e1)
            clip = ear_clipping(np.column_stack([P[i] @ e1, P[i] @ np.cross(n, e1)]), P[i],
                                rank=corner_rank[i])
        if clip is None:
            j = (least[i] if finite[i] else 0) + np.arange(k)
            clip = np.c_[j[:1].repeat(k - 2), j[1:-1], j[2:]] % k
        tris[i] = q[i][clip]
    return tris.reshape(-1, 3)


def float32_rounding(points, advice: str, columns=None) -> str | None:
    """A note (ending with ``advice``) when ``points`` are 32-bit floats whose spacing at
    their distance from the origin is more than 1e-4 of their extent (georeferenced scans:
    0.0625 at 1e6), else None: such data is already rounded to a coarse lattice, and a fit of
    it shows steps (or, at worst, is refused as a fold). For ``fit_surface`` and the files
    that store 32-bit coordinates (``core.meshio.read_geometry``). ``columns``: which of the
    three columns were stored in 32 bits (a mask, for files that mix 32-bit x and y with a
    64-bit z); by default all of a float32 array's and none of another's."""
    if not (isinstance(points, np.ndarray) and points.ndim == 2 and points.shape[0] > 1
            and points.shape[1] == 3):
        return None
    # (16-bit floats too: 0.03 apart at 64, and no word had been said; user test)
    small = points.dtype if points.dtype in (np.float16, np.float32) else np.dtype(np.float32)
    columns = (np.full(3, points.dtype in (np.float16, np.float32)) if columns is None
               else np.asarray(columns, dtype=bool).reshape(3))
    if not columns.any() or not np.isfinite(points).all():
        return None
    lo, hi = column_bounds(points.astype(np.float64))
    extent = float((hi - lo).max())
    far = np.maximum(np.abs(lo), np.abs(hi))[columns]
    step = float(np.spacing(far.astype(small)).max())
    if not step > 1e-4 * extent:
        return None
    which = ("the points are" if columns.all() else
             f"the points' {' and '.join(np.array(list('xyz'))[columns])} are")
    return (
        f"{which} {8 * small.itemsize}-bit floats, which far from the origin are {step:.3g} apart, "
        f"{step / max(extent, 1e-300):.1e} of the data's extent: {advice}"
    )


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


def distances_at_vertices(vertices: np.ndarray, feet: np.ndarray, distances: np.ndarray,
                          k: int = 8, radius: float | None = None):
    """The data-to-surface distance near each surface vertex, and where there is data at all.

    ``feet`` (n, 3) are the closest surface points of n data points and ``distances`` (n,) the
    data points' distances to them. Each vertex (m, 3) gets the inverse-distance-weighted mean
    (weights ``1 / |vertex - foot|^2``) of the distances of the ``k`` data points whose feet are
    nearest to it, counting only feet within ``radius``. Feet rather than the data points
    themselves: a data point's neighbourhood on the surface does not depend on how far off the
    surface it lies. Vertices with no foot within ``radius`` have no data near them: value 0
    and False in the returned mask ``(values (m,), has_data (m,))``; so do vertices with NaN
    coordinates. Data points with NaN feet or distances are left out.

    ``radius`` defaults to the largest of 4 data spacings (median distance from a foot to the
    nearest other distinct foot: the tessellation's own trim distance for clouds), 2 vertex
    spacings (likewise among the vertices: a coarse mesh over dense data) and 3 times the
    median distance from a vertex to its nearest foot (the typical gap: scan lines far apart
    compared with the spacing along them). So the vertices without data are those of gaps well
    beyond the sampling's own, at holes and concave edges of the data.

    The distance from a vertex to the nearest data point instead (what the deviation map of a
    cloud showed before) measures the gaps between the samples: on 20 000 points of a smooth
    10 m patch it was 0.034 (median) where the surface was 8.7e-5 from the true shape.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    feet = np.asarray(feet, dtype=np.float64).reshape(-1, 3)
    distances = np.asarray(distances, dtype=np.float64).reshape(-1)
    ok = np.isfinite(feet).all(axis=1) & np.isfinite(distances)
    feet, distances = feet[ok], distances[ok]
    values = np.zeros(len(vertices))
    has = np.zeros(len(vertices), dtype=bool)
    if len(vertices) == 0 or len(feet) == 0:
        return values, has
    finite = np.flatnonzero(np.isfinite(vertices).all(axis=1))  # others: no data
    vertices = vertices[finite]
    if len(vertices) == 0:
        return values, has
    tree = cKDTree(feet)
    if radius is None:
        gap = float(np.median(tree.query(vertices[:: max(1, len(vertices) // 20_000)])[0]))
        radius = max(4.0 * _spacing(feet, tree), 2.0 * _spacing(vertices), 3.0 * gap)
        if not radius > 0:  # all feet and all vertices coincide
            radius = np.inf
    k = int(min(max(k, 1), len(feet)))
    dist, idx = tree.query(vertices, k=k, distance_upper_bound=radius)
    dist, idx = dist.reshape(len(vertices), k), idx.reshape(len(vertices), k)
    near = idx < len(feet)  # the k nearest within the radius (missing ones: inf, n)
    found = near[:, 0]
    tiny = 1e-12 * (radius if np.isfinite(radius) else 1.0)
    w = np.where(near, 1.0 / np.maximum(dist, tiny) ** 2, 0.0)[found]
    d = distances[np.where(near, idx, 0)][found]
    values[finite[found]] = (w * d).sum(axis=1) / w.sum(axis=1)
    has[finite[found]] = True
    return values, has


def _spacing(points: np.ndarray, tree=None, sample: int = 20_000) -> float:
    """Median distance from (up to ``sample`` of) the points to the nearest other point at a
    positive distance (duplicates skipped); 0 when there is none."""
    if len(points) < 2:
        return 0.0
    tree = cKDTree(points) if tree is None else tree
    some = points[:: max(1, len(points) // sample)]
    k = min(8, len(points))
    dist = tree.query(some, k=k)[0].reshape(len(some), k)
    dist = np.where(dist > 0, dist, np.inf).min(axis=1)
    dist = dist[np.isfinite(dist)]
    return float(np.median(dist)) if len(dist) else 0.0


def simple_polygon(xy: np.ndarray) -> bool:
    """Whether the closed polygon ``xy`` (m, 2), ``m >= 3``, is simple: no zero-length edge, no
    two edges that are not neighbours touching (closed segments), and no two neighbours
    folding back onto each other (a vertex of angle 0). The exact test
    (:func:`core.configurations._segments_cross`) runs on the pairs of edges up to 4 times
    the median length whose midpoints are within the longest of them (from a KD-tree), and
    on each longer edge against all (memory O(m) per block)."""
    xy = np.asarray(xy, dtype=np.float64)
    m = len(xy)
    if m < 3 or not np.isfinite(xy).all():
        return False
    nxt = np.roll(xy, -1, axis=0)
    prv = np.roll(xy, 1, axis=0)
    if np.any(np.all(nxt == xy, axis=1)):
        return False
    fold = (orient2d(prv, xy, nxt) == 0) & (np.einsum("ij,ij->i", prv - xy, nxt - xy) > 0)
    if np.any(fold):
        return False
    if m == 3:
        return bool(orient2d(xy[0], xy[1], xy[2]) != 0)
    length = np.sqrt(((nxt - xy) ** 2).sum(axis=1))
    # short edges: pairs from a KD-tree of their midpoints (two touching edges have midpoints
    # within half their lengths' sum); the few long ones (a border with one long side made
    # the tree's pairs m^2 / 2: 1.8 GB at m = 8000; review) against all edges, in blocks
    cut = 4.0 * float(np.median(length))
    short = np.flatnonzero(length <= cut)
    pairs = cKDTree(0.5 * (xy + nxt)[short]).query_pairs(float(length[short].max(initial=0.0)),
                                                          output_type="ndarray")
    blocks = [short[pairs]]
    long_ = np.flatnonzero(length > cut)
    for s in range(0, len(long_), max(1, (1 << 20) // m)):
        li = long_[s : s + max(1, (1 << 20) // m)]
        blocks.append(np.column_stack([np.repeat(li, m), np.tile(np.arange(m), len(li))]))
    for pairs in blocks:
        ii, jj = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
        keep = (jj > ii + 1) & ~((ii == 0) & (jj == m - 1))  # neighbours share an end
        ii, jj = ii[keep], jj[keep]
        if len(ii) and np.any(_segments_cross(xy[ii], nxt[ii], xy[jj], nxt[jj])):
            return False
    return True


def _min_sine(A: np.ndarray, T: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Sine of the smallest angle of the triangles ``A T B`` (k, d), d = 2 or 3: twice the
    area over the product of the two longer sides (the smallest angle is opposite the
    shortest); 0 for a degenerate one."""
    u, v = T - A, B - A
    if A.shape[1] == 2:
        area2 = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    else:
        area2 = np.linalg.norm(np.cross(u, v), axis=1)
    e2 = np.stack([(u * u).sum(1), ((B - T) ** 2).sum(1), (v * v).sum(1)], axis=1)
    e2.sort(axis=1)
    return area2 / np.maximum(np.sqrt(e2[:, 1] * e2[:, 2]), 1e-300)


def ear_clipping(xy: np.ndarray, shape: np.ndarray | None = None,
                 rank: np.ndarray | None = None) -> np.ndarray | None:
    """A triangulation (m - 2, 3) of the simple counter-clockwise polygon ``xy`` (m, 2) by its
    own vertices, or None when the clipping gets stuck (a polygon that is not simple, or
    clockwise). Each step clips, of the ears (a strictly convex vertex whose triangle with
    its two neighbours holds no other remaining vertex, its sides included), the one with the
    largest smallest-angle sine (of the triangle of the points ``shape`` (m, d) when given:
    the polygon's vertices in 3D, clipped in a plane they map to); only the two neighbours
    of a clipped ear are tested again (O(m^2) in all, a step vectorized over the remaining
    vertices). Every simple polygon has
    an ear (Meisters' two-ears theorem); vertices within ``1e-12`` of the polygon's extent
    squared (in ``orient2d`` units) of a line count as on it, so the rounding of a straight
    border run projected into a plane does not leave three nearly collinear vertices last (a
    rotated grid's C-shaped hole did: review). The triangles are counter-clockwise,
    ``(previous, tip, next)`` in the polygon's order. Only vertices
    that are not strictly convex can lie in an ear's triangle, so only those are tested (a
    vertex never turns reflex as its neighbours are clipped). ``rank`` (m,): of ears alike
    in quality to rounding, the one with the shorter diagonal, then of least rank, is clipped
    (:func:`polygon_triangles`' rule; else the first in the polygon's order)."""
    xy = np.asarray(xy, dtype=np.float64)
    m = len(xy)
    if m < 3:
        return None
    nxt = np.roll(np.arange(m), -1)
    prv = np.roll(np.arange(m), 1)
    alive = np.ones(m, dtype=bool)
    span = float(np.ptp(xy, axis=0).max()) if m else 0.0
    floor = 1e-12 * span * span
    reflex = orient2d(xy[prv], xy, xy[nxt]) <= floor
    S = xy if shape is None else np.asarray(shape, dtype=np.float64)

    def quality(tips: np.ndarray) -> np.ndarray:
        a, b = prv[tips], nxt[tips]
        A, T, B = xy[a], xy[tips], xy[b]
        area2 = orient2d(A, T, B)
        q = np.full(len(tips), -1.0)
        convex = np.flatnonzero(area2 > floor)
        if len(convex) == 0:
            return q
        live = np.flatnonzero(alive & reflex)
        J = xy[live]
        for s in range(0, len(convex), 256):
            c = convex[s : s + 256]
            Ac, Tc, Bc = A[c, None], T[c, None], B[c, None]
            # (a vertex straight within the floor counts as reflex above, so as on a side
            # here: else an ear could leave three nearly collinear vertices last; review)
            inside = orient2d(Ac, Tc, J[None]) >= -floor
            inside &= orient2d(Tc, Bc, J[None]) >= -floor
            inside &= orient2d(Bc, Ac, J[None]) >= -floor
            own = (live[None] == a[c, None]) | (live[None] == tips[c, None])
            own |= live[None] == b[c, None]
            free = ~(inside & ~own).any(axis=1)
            q[c] = np.where(free, _min_sine(S[a[c]], S[tips[c]], S[b[c]]), -1.0)
        return q

    q = quality(np.arange(m))
    tris = np.empty((m - 2, 3), dtype=np.int64)
    for step in range(m - 3):
        tip = int(np.argmax(q))
        if q[tip] < 0:
            return None
        if rank is not None:  # (polygon_triangles' rule: whatever corner or winding)
            alike = np.flatnonzero(q >= q[tip] * (1.0 - 1e-9))
            d = S[nxt[alike]] - S[prv[alike]]
            d2 = np.einsum("ij,ij->i", d, d)
            alike = alike[d2 <= d2.min() * (1.0 + 1e-9)]
            tip = int(alike[np.argmin(rank[alike])])
        a, b = int(prv[tip]), int(nxt[tip])
        tris[step] = (a, tip, b)
        alive[tip] = False
        q[tip] = -np.inf
        nxt[a], prv[b] = b, a
        ab = np.array([a, b])
        reflex[ab] = orient2d(xy[prv[ab]], xy[ab], xy[nxt[ab]]) <= floor
        q[ab] = quality(ab)
    a = int(np.flatnonzero(alive)[0])
    last = (a, int(nxt[a]), int(nxt[nxt[a]]))
    if orient2d(xy[last[0]], xy[last[1]], xy[last[2]]) <= floor:
        return None
    tris[m - 3] = last
    return tris
