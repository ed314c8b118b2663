"""Knot configurations by the link-triangulation procedure (method.md section 2.1).

A configuration of degree ``l`` is ``(T, I)``: a CCW knot triangle ``T`` and ``l`` interior knots
``I`` (disjoint from ``T``). :func:`link_triangulation_procedure` builds the families
``Gamma_0, ..., Gamma_k`` from a triangulation ``Gamma_0`` of the knots:

* each ``(T = (a, b, c), I)`` of ``Gamma_l`` gives, for each vertex ``v`` of ``T``, the directed
  edge opposite ``v`` to the link of ``J = I u {v}``;
* per ``J``, pairs of opposite edges cancel and the rest is chained head to tail; a chain that
  closes into one simple CCW polygon is triangulated by the *link triangulator*, and each of its
  triangles ``T'`` gives ``(T', J)`` in ``Gamma_{l+1}``; any other ``J`` lies at the border of the
  knot set and emits nothing.

Link triangulators are pluggable: any callable
``triangulator(polygon, knots, J, level) -> sequence of (a, b, c)`` receiving the CCW polygon as a
tuple of knot indices, all knots (n, 2), the interior set ``J`` (sorted tuple) and the level
``l + 1`` being built, and returning ``len(polygon) - 2`` knot-index triangles that triangulate
the polygon (orientation is fixed here). A triangulator may also offer
``triangulate_many(polygons, knots, Js, level)`` returning those lists for all links of a level in
order; the procedure then calls it once per level (batched costs). Provided: :func:`ear_clipping`,
:func:`constrained_delaunay` (the DCB choice) and :class:`RandomTriangulator` (for tests).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .errors import InvalidKnotsError
from .simplex import orient2d

__all__ = [
    "Configurations",
    "LinkTriangulator",
    "link_triangulation_procedure",
    "ear_clipping",
    "constrained_delaunay",
    "RandomTriangulator",
    "delaunay_triangulation",
    "triangulate_polygon",
]

LinkTriangulator = Callable[[Sequence[int], np.ndarray, tuple, int], Sequence[Sequence[int]]]


@dataclass(frozen=True)
class Configurations:
    """The configuration families ``Gamma_0 .. Gamma_k`` of one knot set.

    ``triangles[l]`` is (c_l, 3) int, CCW knot triangles; ``interior[l]`` is (c_l, l) int, the
    sorted interior sets. ``open_links[l]`` counts the sets ``J`` of level ``l`` whose link did not
    close (they lie at the border and emit nothing).
    """

    knots: np.ndarray
    triangles: list = field(default_factory=list)
    interior: list = field(default_factory=list)
    open_links: list = field(default_factory=list)

    @property
    def degree(self) -> int:
        return len(self.triangles) - 1

    def level(self, l: int) -> tuple[np.ndarray, np.ndarray]:
        return self.triangles[l], self.interior[l]


# --------------------------------------------------------------------------------------------
# small geometric predicates on Python floats (link polygons have ~5-15 vertices)


def _orient(p, q, r) -> float:
    return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])


def _in_triangle_closed(p, a, b, c) -> bool:
    """``p`` inside or on the CCW triangle ``abc``."""
    return _orient(a, b, p) >= 0 and _orient(b, c, p) >= 0 and _orient(c, a, p) >= 0


def _incircle(a, b, c, d) -> float:
    """> 0 when ``d`` is strictly inside the circumcircle of the CCW triangle ``abc``."""
    adx, ady = a[0] - d[0], a[1] - d[1]
    bdx, bdy = b[0] - d[0], b[1] - d[1]
    cdx, cdy = c[0] - d[0], c[1] - d[1]
    return (
        (adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
        - (bdx * bdx + bdy * bdy) * (adx * cdy - cdx * ady)
        + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady)
    )


def _is_ear(pts, ring, i, eps) -> bool:
    m = len(ring)
    a, b, c = pts[ring[i - 1]], pts[ring[i]], pts[ring[(i + 1) % m]]
    if _orient(a, b, c) <= eps:
        return False
    for j in range(m):
        if j in (i, (i - 1) % m, (i + 1) % m):
            continue
        p = pts[ring[j]]
        if p == a or p == b or p == c:
            continue
        if _in_triangle_closed(p, a, b, c):
            return False
    return True


def _ear_clip(pts, choose=None) -> list[tuple[int, int, int]]:
    """Triangulate the simple CCW polygon ``pts`` (list of (x, y)) by ear clipping.

    Returns triangles as index triples into ``pts``. ``choose(ears)`` picks which ear to cut (the
    first by default). Vertices with a straight angle are never ears, so no degenerate triangle is
    made while a proper ear exists.
    """
    ring = list(range(len(pts)))
    scale = max(max(abs(p[0]), abs(p[1])) for p in pts) or 1.0
    eps = 1e-14 * scale * scale
    tris = []
    while len(ring) > 3:
        ears = [i for i in range(len(ring)) if _is_ear(pts, ring, i, eps)]
        if not ears:
            raise InvalidKnotsError("a link polygon could not be triangulated (not simple)")
        i = ears[0] if choose is None else choose(ears)
        tris.append((ring[i - 1], ring[i], ring[(i + 1) % len(ring)]))
        del ring[i]
    tris.append(tuple(ring))
    return tris


def triangulate_polygon(pts, choose=None) -> list[tuple[int, int, int]]:
    """Ear-clipping triangulation of a simple CCW polygon given as (m, 2) coordinates."""
    return _ear_clip([(float(p[0]), float(p[1])) for p in pts], choose)


def ear_clipping(polygon, knots, J=(), level=0):
    """Link triangulator: deterministic ear clipping (any valid triangulation)."""
    pts = [(float(knots[v, 0]), float(knots[v, 1])) for v in polygon]
    return [(polygon[a], polygon[b], polygon[c]) for a, b, c in _ear_clip(pts)]


def _lawson_delaunay(pts, tris, max_flips=None):
    """Flip interior diagonals of a polygon triangulation until locally Delaunay.

    Only diagonals (edges shared by two triangles) are flipped, and only when the quadrilateral
    is strictly convex, so polygon edges stay fixed: the result is the constrained Delaunay
    triangulation of the polygon. An edge stack with an incrementally kept edge -> triangle map
    (each flip pushes the four quad edges); at most ``max_flips`` flips (default ``4 m^2``),
    which also stops a cycle between nearly co-circular choices.
    """
    tris = [list(t) for t in tris]
    owner: dict = {}
    for ti, t in enumerate(tris):
        for e in range(3):
            owner[(t[e], t[(e + 1) % 3])] = ti
    stack = [e for e in owner if (e[1], e[0]) in owner and e[0] < e[1]]
    limit = max_flips if max_flips is not None else 4 * len(pts) ** 2
    flips = 0
    while stack and flips < limit:
        a, b = stack.pop()
        t1, t2 = owner.get((a, b)), owner.get((b, a))
        if t1 is None or t2 is None:
            continue
        c = next(v for v in tris[t1] if v != a and v != b)
        d = next(v for v in tris[t2] if v != a and v != b)
        # t1 = (a, b, c) and t2 = (b, a, d) as cycles; flip ab -> cd if d in circle(a, b, c)
        pa, pb, pc, pd = pts[a], pts[b], pts[c], pts[d]
        if _orient(pa, pb, pc) < 0:  # t1 stores (b, a, c): swap roles
            a, b = b, a
            pa, pb = pb, pa
            t1, t2 = t2, t1
            c, d = d, c
            pc, pd = pd, pc
        if not _incircle(pa, pb, pc, pd) > 1e-14 * _scale4(pts, a, b, c, d):
            continue
        if not (_orient(pc, pa, pd) > 0 and _orient(pd, pb, pc) > 0):
            continue
        for t in (t1, t2):
            for e in range(3):
                owner.pop((tris[t][e], tris[t][(e + 1) % 3]), None)
        tris[t1], tris[t2] = [c, a, d], [d, b, c]
        for t in (t1, t2):
            for e in range(3):
                owner[(tris[t][e], tris[t][(e + 1) % 3])] = t
        flips += 1
        stack.extend([(a, d), (d, b), (b, c), (c, a)])
    return [tuple(t) for t in tris]


def _scale4(pts, *idx):
    s = max(max(abs(pts[i][0]), abs(pts[i][1])) for i in idx) or 1.0
    return s**4


def constrained_delaunay(polygon, knots, J=(), level=0):
    """Link triangulator: constrained Delaunay triangulation of the link polygon (DCB choice)."""
    pts = [(float(knots[v, 0]), float(knots[v, 1])) for v in polygon]
    tris = _lawson_delaunay(pts, _ear_clip(pts))
    return [(polygon[a], polygon[b], polygon[c]) for a, b, c in tris]


class RandomTriangulator:
    """Link triangulator choosing a random valid triangulation (random ears, then random flips).

    Deterministic for a given ``seed`` and call sequence. Used by the tests: the TCB space is a
    partition of unity for *any* link triangulations (method.md section 2.2).
    """

    def __init__(self, seed: int = 0, levels: Sequence[int] | None = None, fallback=None):
        self.rng = np.random.default_rng(seed)
        self.levels = None if levels is None else set(levels)
        self.fallback = fallback or ear_clipping

    def __call__(self, polygon, knots, J=(), level=0):
        if self.levels is not None and level not in self.levels:
            return self.fallback(polygon, knots, J, level)
        pts = [(float(knots[v, 0]), float(knots[v, 1])) for v in polygon]
        tris = _ear_clip(pts, choose=lambda ears: ears[int(self.rng.integers(len(ears)))])
        return [(polygon[a], polygon[b], polygon[c]) for a, b, c in tris]


def delaunay_triangulation(knots: np.ndarray) -> np.ndarray:
    """Delaunay triangulation ``Gamma_0`` of the knots, (t, 3) int CCW, zero-area triangles dropped.

    Co-circular knots (lattices) make the Delaunay triangulation ambiguous; Qhull breaks the tie
    consistently ('Qt'), which is all the spline space needs (any triangulation is valid).
    """
    from scipy.spatial import Delaunay

    tri = Delaunay(knots, qhull_options="Qbb Qc Qz Qt").simplices.astype(np.int64)
    a, b, c = knots[tri[:, 0]], knots[tri[:, 1]], knots[tri[:, 2]]
    det = orient2d(a, b, c)
    scale = np.ptp(knots, axis=0).max() ** 2
    tri = tri[np.abs(det) > 1e-14 * scale]
    det = det[np.abs(det) > 1e-14 * scale]
    tri[det < 0] = tri[det < 0][:, [0, 2, 1]]
    return tri


# --------------------------------------------------------------------------------------------
# the link-triangulation procedure


def _segments_cross(p1, p2, q1, q2) -> np.ndarray:
    """Vectorized test: closed segments p1p2 and q1q2 intersect (inputs (N, 2))."""

    d1, d2 = orient2d(q1, q2, p1), orient2d(q1, q2, p2)
    d3, d4 = orient2d(p1, p2, q1), orient2d(p1, p2, q2)
    proper = ((d1 > 0) != (d2 > 0)) & ((d3 > 0) != (d4 > 0)) & (d1 != 0) & (d2 != 0)
    proper &= (d3 != 0) & (d4 != 0)

    def on_seg(a, b, c, d):  # c collinear with ab (d == 0) and within its bbox
        return (
            (d == 0)
            & (np.minimum(a[:, 0], b[:, 0]) <= c[:, 0])
            & (c[:, 0] <= np.maximum(a[:, 0], b[:, 0]))
            & (np.minimum(a[:, 1], b[:, 1]) <= c[:, 1])
            & (c[:, 1] <= np.maximum(a[:, 1], b[:, 1]))
        )

    touch = on_seg(q1, q2, p1, d1) | on_seg(q1, q2, p2, d2) | on_seg(p1, p2, q1, d3)
    return proper | touch | on_seg(p1, p2, q2, d4)


def _unique_rows(rows: np.ndarray, return_counts: bool = False):
    """``np.unique(rows, axis=0, return_inverse=True[, return_counts])`` for nonnegative int
    rows, through one int64 key per row when the values fit (5-10x faster than sorting rows)."""
    rows = np.asarray(rows, dtype=np.int64)
    m = rows.shape[1]
    base = int(rows.max(initial=0)) + 1
    if m == 0 or len(rows) == 0 or base ** m >= 2**62:
        out = np.unique(rows, axis=0, return_inverse=True, return_counts=return_counts)
        return (out[0], out[1].reshape(-1)) + tuple(out[2:])
    key = np.zeros(len(rows), dtype=np.int64)
    for c in range(m):
        key = key * base + rows[:, c]
    # lexicographic row order is the order of the keys
    ukey, first, inv, *counts = np.unique(
        key, return_index=True, return_inverse=True, return_counts=return_counts
    )
    return (rows[first], inv.reshape(-1)) + tuple(counts)


def _close_links(J_rows: np.ndarray, heads: np.ndarray, tails: np.ndarray):
    """Group directed link edges by ``J``, cancel opposite pairs and chain each group.

    Returns the unique ``J`` rows and, per group, the CCW polygon as a list of knot indices or
    None when the link does not close into one simple loop. Vectorized over all groups: each
    edge ``a -> b`` points to the edge of its group that leaves ``b``; walking those pointers
    from each group's first edge must come back after exactly as many steps as the group has
    edges (one simple loop through all of them).
    """
    groups, inv = _unique_rows(J_rows)
    # cancel opposite pairs: canonical undirected key per group, +1 for lo->hi, -1 for hi->lo
    lo, hi = np.minimum(heads, tails), np.maximum(heads, tails)
    sign = np.where(heads < tails, 1, -1)
    ukey, kinv, kcount = _unique_rows(np.stack([inv, lo, hi], axis=1), return_counts=True)
    net = np.zeros(len(ukey), dtype=np.int64)
    np.add.at(net, kinv, sign)
    bad_group = np.zeros(len(groups), dtype=bool)
    # the same directed edge twice (or more than one pair) cannot form a simple link
    bad_group[ukey[(np.abs(net) > 1) | (kcount > 2), 0]] = True
    keep = net != 0
    g = ukey[keep, 0]
    a = np.where(net[keep] > 0, ukey[keep, 1], ukey[keep, 2])
    b = np.where(net[keep] > 0, ukey[keep, 2], ukey[keep, 1])
    # edges sorted by (group, head); ukey rows are sorted by (group, lo, hi), so the first
    # edge of each group is the one the loop used to start from
    start_edge = np.r_[0, np.flatnonzero(np.diff(g)) + 1] if len(g) else np.zeros(0, np.int64)
    order = np.lexsort((a, g))
    gs, as_ = g[order], a[order]
    size = np.bincount(g, minlength=len(groups))
    # two edges leaving one vertex: pinched or several loops
    dup_head = (gs[1:] == gs[:-1]) & (as_[1:] == as_[:-1])
    bad_group[gs[1:][dup_head]] = True
    # successor of each edge: the edge of the same group whose head is its tail
    n_v = int(max(a.max(initial=0), b.max(initial=0))) + 1
    skey = gs * n_v + as_
    want = g * n_v + b
    pos = np.minimum(np.searchsorted(skey, want), max(len(skey) - 1, 0))
    found = skey[pos] == want if len(skey) else np.zeros(0, dtype=bool)
    bad_group[g[~found]] = True
    succ = np.where(found, order[pos], -1)
    gid = g[start_edge]
    ok = ~bad_group[gid] & (size[gid] >= 3)
    gid, start = gid[ok], start_edge[ok]
    length = size[gid]
    steps = int(length.max(initial=0))
    walk = np.empty((len(gid), steps), dtype=np.int64)
    closed_at = np.full(len(gid), -1)
    cur = start
    for t in range(steps):
        walk[:, t] = a[cur]
        cur = succ[cur]
        back = (cur == start) & (closed_at < 0)
        closed_at[back] = t + 1
    simple = closed_at == length
    polys: list = [None] * len(groups)
    for gi, row, m in zip(gid[simple].tolist(), walk[simple].tolist(), length[simple].tolist()):
        polys[gi] = row[:m]
    return groups, polys


def _valid_polygons(knots: np.ndarray, polys: list) -> np.ndarray:
    """Mask of polygons that are simple and CCW (positive area); vectorized over all polygons."""
    idx = [i for i, p in enumerate(polys) if p is not None]
    ok = np.zeros(len(polys), dtype=bool)
    if not idx:
        return ok
    sizes = np.array([len(polys[i]) for i in idx])
    flat = np.concatenate([polys[i] for i in idx])
    pid = np.repeat(np.arange(len(idx)), sizes)
    offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    pos = np.arange(len(flat)) - offs[pid]
    nxt = flat[offs[pid] + (pos + 1) % sizes[pid]]
    P, Q = knots[flat], knots[nxt]
    area = np.zeros(len(idx))
    np.add.at(area, pid, P[:, 0] * Q[:, 1] - P[:, 1] * Q[:, 0])
    good = area > 0
    # every pair of non-adjacent edges of the same polygon must not touch
    pairs_i, pairs_j = [], []
    for m in np.unique(sizes):
        ii, jj = np.triu_indices(m, 2)
        nonadj = ~((ii == 0) & (jj == m - 1))
        ii, jj = ii[nonadj], jj[nonadj]
        sel = np.flatnonzero(sizes == m)
        pairs_i.append((offs[sel][:, None] + ii[None, :]).ravel())
        pairs_j.append((offs[sel][:, None] + jj[None, :]).ravel())
    pi, pj = np.concatenate(pairs_i), np.concatenate(pairs_j)
    cross = _segments_cross(P[pi], Q[pi], P[pj], Q[pj])
    good[np.unique(pid[pi[cross]])] = False
    ok[np.array(idx)[good]] = True
    return ok


def link_triangulation_procedure(
    knots: np.ndarray,
    degree: int,
    triangulation: np.ndarray | None = None,
    link_triangulator: LinkTriangulator | None = None,
) -> Configurations:
    """Run the link-triangulation procedure of method.md section 2.1 up to ``degree``.

    Parameters
    ----------
    knots : (n, 2) float64
    degree : int, 0..3 (higher degrees work but are untested)
    triangulation : (t, 3) int, optional
        ``Gamma_0``; Delaunay by default. Triangles are re-oriented CCW.
    link_triangulator : callable, optional
        Chooses the triangulation of every closed link (see the module docstring);
        :func:`constrained_delaunay` by default.
    """
    knots = np.asarray(knots, dtype=np.float64)
    tri0 = delaunay_triangulation(knots) if triangulation is None else np.array(triangulation)
    tri0 = np.asarray(tri0, dtype=np.int64).reshape(-1, 3)
    if len(tri0) == 0:
        raise InvalidKnotsError("the triangulation Gamma_0 is empty")
    if tri0.min() < 0 or tri0.max() >= len(knots):
        raise InvalidKnotsError("the triangulation refers to knots that do not exist")
    a, b, c = knots[tri0[:, 0]], knots[tri0[:, 1]], knots[tri0[:, 2]]
    det = orient2d(a, b, c)
    if np.any(det == 0):
        raise InvalidKnotsError("the triangulation Gamma_0 has degenerate (zero-area) triangles")
    tri0 = np.where((det < 0)[:, None], tri0[:, [0, 2, 1]], tri0)
    triangulator = link_triangulator or constrained_delaunay

    triangles = [tri0]
    interior = [np.zeros((len(tri0), 0), dtype=np.int64)]
    open_links = [0]
    for level in range(1, degree + 1):
        T, I = triangles[-1], interior[-1]
        if len(T) == 0:
            triangles.append(np.zeros((0, 3), np.int64))
            interior.append(np.zeros((0, level), np.int64))
            open_links.append(0)
            continue
        Js, heads, tails = [], [], []
        for v in range(3):
            Js.append(np.sort(np.concatenate([I, T[:, v : v + 1]], axis=1), axis=1))
            heads.append(T[:, (v + 1) % 3])
            tails.append(T[:, (v + 2) % 3])
        groups, polys = _close_links(
            np.concatenate(Js), np.concatenate(heads), np.concatenate(tails)
        )
        valid = _valid_polygons(knots, polys)
        new_T, new_I = [], []
        chosen = np.flatnonzero(valid)
        link_J = [tuple(int(j) for j in groups[gi]) for gi in chosen]
        link_poly = [tuple(polys[gi]) for gi in chosen]
        many = getattr(triangulator, "triangulate_many", None)
        if many is not None:  # a triangulator that batches the links of a level
            results = list(many(link_poly, knots, link_J, level))
            if len(results) != len(link_poly):
                raise ValueError(
                    f"the link triangulator returned {len(results)} triangulations for "
                    f"{len(link_poly)} links"
                )
        else:
            results = [triangulator(p, knots, J, level) for p, J in zip(link_poly, link_J)]
        for J, poly, tris in zip(link_J, link_poly, results):
            if len(tris) != len(poly) - 2:
                raise ValueError(
                    f"the link triangulator returned {len(tris)} triangles for a polygon with "
                    f"{len(poly)} vertices (expected {len(poly) - 2})"
                )
            new_T.extend(tris)
            new_I.extend([J] * len(tris))
        open_links.append(int(len(groups) - valid.sum()))
        if new_T:
            Tn = np.asarray(new_T, dtype=np.int64).reshape(-1, 3)
            In = np.asarray(new_I, dtype=np.int64).reshape(-1, level)
            p, q, r = knots[Tn[:, 0]], knots[Tn[:, 1]], knots[Tn[:, 2]]
            d = orient2d(p, q, r)
            Tn = np.where((d < 0)[:, None], Tn[:, [0, 2, 1]], Tn)
            keep = d != 0
            Tn, In = Tn[keep], In[keep]
        else:
            Tn, In = np.zeros((0, 3), np.int64), np.zeros((0, level), np.int64)
        triangles.append(Tn)
        interior.append(In)
    return Configurations(knots=knots, triangles=triangles, interior=interior, open_links=open_links)
