"""Feature-sensitive configurations (method.md section 2.4).

The triangulation ``Gamma_0`` and the link triangulations of the levels below the degree are chosen
from the data so that knot lines follow creases (data-dependent triangulation, Dyn-Levin-Rippa):

* :class:`PlaneFitCost` -- the cost of a knot triangle is the sum of squared residuals of the
  least-squares affine map ``(u, v) -> (x, y, z)`` fitted to the data points whose parameters fall
  in it (0 with at most 3 points). Computed from moment sums, batched over many triangles.
* :func:`feature_triangulation` -- ``Gamma_0``: Delaunay, then Lawson-style flips of interior
  edges of strictly convex quadrilaterals when the two-triangle cost drops, in batched rounds;
  only quads that touch data are considered, and new triangles must keep a minimum angle (a
  triangle with <= 3 points costs 0 and would otherwise reward slivers).
* :class:`FeatureLinkTriangulator` -- link triangulator for the link-triangulation procedure
  (:mod:`core.configurations`): at levels below the degree, the minimum-cost triangulation of the
  link polygon by dynamic programming over its admissible diagonals (O(m^3)); at the last level
  (which does not change a TCB basis) and for links without data, constrained Delaunay.

Both reject triangles that would put three (nearly) collinear knots in a configuration ``T u J``,
which keeps quadratic TCB splines C^1 (method.md sections 1 and 2.4).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree

from .configurations import _segments_cross, constrained_delaunay, delaunay_triangulation
from .parallel import pmap
from .simplex import SimplexBatch, orient2d
from .spatial import BoxIndex

__all__ = [
    "PlaneFitCost", "feature_triangulation", "FeatureLinkTriangulator", "min_angle_sine", "locate",
    "constrained_delaunay_many",
]

# Triangles of Gamma_0 made by flips must keep sin(min angle) above this (about 6 degrees).
MIN_SINE = 0.1
# Three knots count as collinear when |det| < COLLINEAR_RTOL * (longest edge)^2.
COLLINEAR_RTOL = 1e-6


_orient = orient2d  # (..., 2) arrays; the engine's one orientation predicate


def min_angle_sine(a, b, c) -> np.ndarray:
    """``sin`` of the smallest angle of triangles ``abc`` (arrays (..., 2)); 0 when degenerate."""
    la = np.linalg.norm(b - c, axis=-1)
    lb = np.linalg.norm(c - a, axis=-1)
    lc = np.linalg.norm(a - b, axis=-1)
    area2 = np.abs(_orient(a, b, c))
    # sin(angle at a) = area2 / (lb lc), etc.; the smallest angle is opposite the shortest edge
    prod = np.stack([lb * lc, lc * la, la * lb], axis=-1).max(axis=-1)
    return np.where(prod > 0, area2 / np.where(prod > 0, prod, 1.0), 0.0)


def _collinear_free(pts: np.ndarray) -> np.ndarray:
    """For point sets (T, s, 2): True where no three of the s points are (nearly) collinear."""
    ok = np.ones(pts.shape[0], dtype=bool)
    for i, j, k in combinations(range(pts.shape[1]), 3):
        a, b, c = pts[:, i], pts[:, j], pts[:, k]
        longest = np.maximum(
            np.maximum(((b - a) ** 2).sum(-1), ((c - a) ** 2).sum(-1)), ((c - b) ** 2).sum(-1)
        )
        ok &= np.abs(_orient(a, b, c)) > COLLINEAR_RTOL * longest
    return ok


def grouped_plane_costs(x: np.ndarray, p: np.ndarray, group: np.ndarray, n_groups: int,
                        quadratic: bool = False) -> np.ndarray:
    """Fit residual of every point group at once, (G,): ``Q - tr(R^T M^-1 R)`` from per-group
    moment sums (``bincount``) of the basis ``phi = (u, v, 1)`` (affine fit ``(u, v) -> p``),
    or with ``quadratic`` also ``(u^2, u v, v^2)`` (a quadratic fit: the residual of what a
    quadratic spline cannot follow locally), in coordinates centred on each group's mean and
    divided by its RMS radius (so the result does not depend on the units of ``x``). Groups
    with at most 3 points cost 0; with ``quadratic``, groups of 4-6 points get the affine
    residual. Points may appear in several groups (pass them repeated)."""
    cnt = np.bincount(group, minlength=n_groups).astype(np.float64)
    safe = np.maximum(cnt, 1.0)
    mx = np.stack([np.bincount(group, x[:, j], n_groups) for j in range(2)], 1) / safe[:, None]
    mp = np.stack([np.bincount(group, p[:, j], n_groups) for j in range(3)], 1) / safe[:, None]
    x = x - np.take(mx, group, axis=0)  # np.take: faster row gathers than mx[group]
    p = p - np.take(mp, group, axis=0)
    # row sums of squares with einsum: 4-6x faster than (x * x).sum(axis=1) on (n, 2|3)
    r = np.sqrt(np.bincount(group, np.einsum("ij,ij->i", x, x), n_groups) / safe) + 1e-300
    inv = np.take(1.0 / r, group)
    xu, xv = x[:, 0] * inv, x[:, 1] * inv
    # the moment sums, one contiguous (G,) array per entry. The basis is the monomials
    # u^i v^j (i + j <= 1, or <= 2 with quadratic), so M[a][b] is the sum of the monomial of
    # exponent e_a + e_b: one bincount per distinct monomial (15 for 21 quadratic entries)
    expo = [(0, 0), (1, 0), (0, 1)] + ([(2, 0), (1, 1), (0, 2)] if quadratic else [])
    powers = {(0, 0): None, (1, 0): xu, (0, 1): xv}
    if quadratic:
        powers.update({(2, 0): xu * xu, (1, 1): xu * xv, (0, 2): xv * xv})
    d = len(expo)
    sums: dict = {(0, 0): cnt}
    M = [[None] * d for _ in range(d)]
    for a in range(d):
        for b in range(a, d):
            e = (expo[a][0] + expo[b][0], expo[a][1] + expo[b][1])
            if e not in sums:
                fa, fb = powers[expo[a]], powers[expo[b]]
                sums[e] = np.bincount(group, fb if fa is None else fa * fb, n_groups)
            M[a][b] = M[b][a] = sums[e]
    pc = [np.ascontiguousarray(p[:, j]) for j in range(3)]
    R = [[np.bincount(group, pc[j] if powers[e] is None else powers[e] * pc[j], n_groups)
          for j in range(3)] for e in expo]
    Q = np.bincount(group, np.einsum("ij,ij->i", p, p), n_groups)
    explained = np.cumsum(_spd_quadratic_terms(M, R), axis=0)  # by the first 1, 2, ... columns
    ssr = np.where(cnt > 3, np.maximum(Q - explained[2], 0.0), 0.0)
    if quadratic:
        ssr = np.where(cnt > 6, np.maximum(Q - explained[5], 0.0), ssr)
    return ssr


def _spd_quadratic_terms(M, R) -> np.ndarray:
    """Terms ``|(L^-1 R)_i|^2 / d_i`` (d, G) of ``tr(R^T (M + eps I)^-1 R)`` for stacks of
    symmetric positive semidefinite ``M`` and ``R``, given entry by entry (``M[a][b]`` and
    ``R[a][j]`` are (G,) arrays; a d x d and a d x k nested list), with
    ``M + eps I = L D L^T`` and ``eps = 1e-12 trace(M)``; the sum of the first ``j`` terms is the
    form of the leading ``j x j`` block (the fit with the first ``j`` columns). ``L D L^T`` is
    vectorized over the stack (a loop over the d columns), each entry a contiguous array: on
    (G, d, d) stacks the strided columns made it 3x slower. Not ``np.linalg.solve``: a LAPACK
    call per small system, which under OpenBLAS threading on a loaded machine took 0.6-4 s for
    5e4 3x3 systems instead of 0.03 s."""
    d = len(M)
    eps = sum(M[j][j] for j in range(d)) * 1e-12 + 1e-300
    L = [[None] * d for _ in range(d)]
    D = [None] * d
    for j in range(d):
        acc = M[j][j] + eps
        for k in range(j):
            acc = acc - L[j][k] ** 2 * D[k]
        D[j] = np.maximum(acc, eps)
        for i in range(j + 1, d):
            acc = M[i][j]
            for k in range(j):
                acc = acc - L[i][k] * L[j][k] * D[k]
            L[i][j] = acc / D[j]
    Y = [list(row) for row in R]
    for i in range(1, d):
        for k in range(i):
            Y[i] = [Y[i][c] - L[i][k] * Y[k][c] for c in range(len(Y[i]))]
    return np.stack([sum(y * y for y in Y[i]) / D[i] for i in range(d)])


def locate(knots: np.ndarray, triangles: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Index of the (half-open) triangle holding each parameter, -1 outside; (N,) int.

    The degree-0 simplex splines ``|det T| M(x | T)`` are the indicators of the triangles
    (method.md section 1), so point location is one evaluation pass over the bucket grid.
    """
    a, b, c = (knots[triangles[:, j]] for j in range(3))
    w = np.abs(orient2d(a, b, c))
    batch = SimplexBatch(knots, triangles, w)
    owner = np.full(len(uv), -1, dtype=np.int64)
    for p, t in BoxIndex(batch.bbox).pairs(uv):
        hit = batch.evaluate(uv[p], t) > 0.5
        owner[p[hit]] = t[hit]
    return owner


class PlaneFitCost:
    """Sum of squared residuals of the affine fit ``(u, v) -> p`` over the points of a triangle.

    With ``phi = (u, v, 1)``, moment sums ``M = sum phi phi^T``, ``R = sum phi p^T`` and
    ``Q = sum |p|^2`` over the triangle's points, the residual is ``Q - tr(R^T M^-1 R)``
    (normal equations; method.md section 2.4). Sums are taken per triangle, in coordinates
    centred on its points' mean and divided by their RMS radius (:func:`grouped_plane_costs`).
    """

    def __init__(self, uv: np.ndarray, points: np.ndarray):
        self.uv = np.asarray(uv, dtype=np.float64)
        self.points = np.asarray(points, dtype=np.float64)
        self.tree = cKDTree(self.uv)

    def near(self, center, radius) -> np.ndarray:
        return np.asarray(self.tree.query_ball_point(center, radius), dtype=np.int64)

    def grouped_costs(self, owner: np.ndarray, n_groups: int) -> np.ndarray:
        """Costs of disjoint point groups (``owner[j]`` = group of point j, -1 none), (G,)."""
        ok = owner >= 0
        return grouped_plane_costs(self.uv[ok], self.points[ok], owner[ok], n_groups)

    def costs(self, tri_pts: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Costs and point counts of triangles ``tri_pts`` (T, 3, 2) over the points ``idx``.

        Membership uses closed triangles (a point on a shared edge counts for both sides, which
        is harmless for a cost); one grouped moment sum over the (triangle, point) pairs.
        """
        tri_pts = np.asarray(tri_pts, dtype=np.float64).reshape(-1, 3, 2)
        idx = np.asarray(idx, dtype=np.int64)
        T, n = len(tri_pts), len(idx)
        t = np.repeat(np.arange(T), n)
        j = np.tile(idx, T)
        x = self.uv[j]
        a, b, c = (tri_pts[t, k] for k in range(3))
        sgn = np.sign(_orient(a, b, c))
        inside = (
            (sgn * _orient(a, b, x) >= 0) & (sgn * _orient(b, c, x) >= 0) & (sgn * _orient(c, a, x) >= 0)
        )
        t, j = t[inside], j[inside]
        count = np.bincount(t, minlength=T).astype(np.int64)
        return grouped_plane_costs(self.uv[j], self.points[j], t, T), count


def feature_triangulation(
    knots: np.ndarray,
    cost: PlaneFitCost,
    movable: np.ndarray | None = None,
    max_rounds: int = 10,
) -> np.ndarray:
    """Data-dependent ``Gamma_0`` (method.md section 2.4): Delaunay + cost-reducing edge flips.

    Lawson-style local optimization in batched rounds: every interior edge of a strictly convex
    quadrilateral whose four knots are ``movable`` (the interior knots: flipping among the
    border rings only adds functions) is a candidate; the plane-fit costs of all candidate
    re-splits come from one grouped moment sum (:func:`grouped_plane_costs`); the improving
    flips are applied greedily by gain, at most one per triangle per round. Every round lowers
    the total cost strictly, so flips cannot cycle. New triangles keep a minimum angle and no
    three collinear knots in the quad (C^1).

    Returns (t, 3) int CCW triangles.
    """
    tri = delaunay_triangulation(knots)
    T = len(tri)
    if movable is None:
        movable = np.ones(len(knots), dtype=bool)
    # (not Qhull's find_simplex: with the 'Qz' option its walk took 10 s for 3e4 points)
    owner = locate(knots, tri, cost.uv)  # -1 outside
    tri_cost = cost.grouped_costs(owner, T)
    P = knots
    for _ in range(max_rounds):
        # interior edges: the directed edge a -> b of t1 = (a, b, c) and b -> a of t2 = (b, a, d)
        a = tri.ravel()
        b = np.roll(tri, -1, axis=1).ravel()
        c = np.roll(tri, -2, axis=1).ravel()
        t_of = np.repeat(np.arange(T), 3)
        key = np.minimum(a, b) * len(knots) + np.maximum(a, b)
        order = np.argsort(key, kind="stable")
        ks = key[order]
        pair = np.flatnonzero(ks[1:] == ks[:-1])
        e1, e2 = order[pair], order[pair + 1]
        A, B, C, D = a[e1], b[e1], c[e1], c[e2]
        t1, t2 = t_of[e1], t_of[e2]
        ok = movable[A] & movable[B] & movable[C] & movable[D]
        ok &= (_orient(P[C], P[A], P[D]) > 0) & (_orient(P[D], P[B], P[C]) > 0)
        count = np.bincount(owner[owner >= 0], minlength=T)
        ok &= count[t1] + count[t2] > 3
        new1 = np.stack([C, A, D], 1)
        new2 = np.stack([D, B, C], 1)
        sine = np.minimum(min_angle_sine(P[new1[:, 0]], P[new1[:, 1]], P[new1[:, 2]]),
                          min_angle_sine(P[new2[:, 0]], P[new2[:, 1]], P[new2[:, 2]]))
        ok &= sine >= MIN_SINE
        ok &= _collinear_free(P[np.stack([A, B, C, D], 1)])
        cand = np.flatnonzero(ok)
        if len(cand) == 0:
            break
        # every point of t1 or t2 joins candidate k, on the side of the new diagonal c -> d
        tri_cands = np.concatenate([t1[cand], t2[cand]])
        cand_ids = np.concatenate([np.arange(len(cand))] * 2)
        by_tri = np.argsort(tri_cands, kind="stable")
        starts = np.searchsorted(tri_cands[by_tri], np.arange(T + 1))
        per_tri = np.diff(starts)
        pts = np.flatnonzero(owner >= 0)
        reps = per_tri[owner[pts]]
        pt = np.repeat(pts, reps)
        local = np.arange(len(pt)) - np.repeat(np.cumsum(reps) - reps, reps)
        k = cand_ids[by_tri[starts[owner[pt]] + local]]
        ck, dk = C[cand][k], D[cand][k]
        side = _orient(P[ck], P[dk], cost.uv[pt]) > 0  # left of c -> d: triangle (c, a, d)
        group = 2 * k + (~side)
        new_cost = grouped_plane_costs(cost.uv[pt], cost.points[pt], group, 2 * len(cand))
        new_cost = new_cost.reshape(-1, 2)
        old = tri_cost[t1[cand]] + tri_cost[t2[cand]]
        gain = old - new_cost.sum(axis=1)
        improving = np.flatnonzero(gain > 1e-9 * old + 1e-15)
        if len(improving) == 0:
            break
        used = np.zeros(T, dtype=bool)
        chosen = []
        for m in improving[np.argsort(-gain[improving], kind="stable")]:
            u, v = t1[cand[m]], t2[cand[m]]
            if not (used[u] or used[v]):
                used[u] = used[v] = True
                chosen.append(m)
        chosen = np.asarray(chosen)
        ci = cand[chosen]
        tri[t1[ci]] = new1[ci]
        tri[t2[ci]] = new2[ci]
        tri_cost[t1[ci]] = new_cost[chosen, 0]
        tri_cost[t2[ci]] = new_cost[chosen, 1]
        # re-own the points of the flipped quads
        flipped = np.zeros(len(cand), dtype=bool)
        flipped[chosen] = True
        moved = flipped[k]
        pm, km, sm = pt[moved], k[moved], side[moved]
        owner[pm] = np.where(sm, t1[cand][km], t2[cand][km])
    return tri


def _candidate_triangles(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For ``L`` CCW simple polygons ``P`` (L, m, 2): the admissible chords ``chord`` (L, m, m)
    (``[l, i, j]``, ``i < j``: an edge of polygon ``l`` or a diagonal inside it), all index
    triples ``trip`` (C, 3), ``i < k < j``, and ``ok`` (L, C): the triple's three sides are
    admissible and it has positive area (then it is a CCW triangle inside the polygon)."""
    L, m = P.shape[:2]
    ii, jj = np.triu_indices(m, 1)
    adjacent = (jj - ii == 1) | ((ii == 0) & (jj == m - 1))
    ok = np.broadcast_to(adjacent, (L, len(ii))).copy()
    diag = np.flatnonzero(~adjacent)
    if len(diag):
        di, dj = ii[diag], jj[diag]
        e0 = np.arange(m)
        # closed-segment intersection of each diagonal with each polygon edge, (L, D, m);
        # edges that share an end with the diagonal do not count
        shape = (L, len(diag), m, 2)
        ends = [np.broadcast_to(q, shape).reshape(-1, 2) for q in
                (P[:, di, None], P[:, dj, None], P[:, None, e0], P[:, None, (e0 + 1) % m])]
        cross = _segments_cross(*ends).reshape(shape[:3])
        touches_end = (e0[None] == di[:, None]) | (e0[None] == dj[:, None])
        touches_end |= ((e0[None] + 1) % m == di[:, None]) | ((e0[None] + 1) % m == dj[:, None])
        crosses = (cross & ~touches_end).any(axis=2)
        # locally inside at vertex i: between the edges (i-1 -> i) and (i -> i+1)
        Ai, Bj = P[:, di], P[:, dj]
        prev, nxt = P[:, (di - 1) % m], P[:, (di + 1) % m]
        convex = _orient(prev, Ai, nxt) > 0
        left_next = _orient(Ai, nxt, Bj) > 0
        left_prev = _orient(prev, Ai, Bj) > 0
        inside_cone = np.where(convex, left_next & left_prev, left_next | left_prev)
        ok[:, diag] = ~crosses & inside_cone
    chord = np.zeros((L, m, m), dtype=bool)
    chord[:, ii, jj] = ok
    trip = np.array(list(combinations(range(m), 3)))
    tp = P[:, trip]  # (L, C, 3, 2)
    good = chord[:, trip[:, 0], trip[:, 1]] & chord[:, trip[:, 1], trip[:, 2]]
    good &= chord[:, trip[:, 0], trip[:, 2]]
    good &= _orient(tp[..., 0, :], tp[..., 1, :], tp[..., 2, :]) > 0
    return chord, trip, good


def _line_forms(P: np.ndarray, ii: np.ndarray, jj: np.ndarray) -> tuple:
    """The lines through the vertex pairs ``(ii, jj)`` of ``L`` polygons ``P`` (L, m, 2) as
    affine forms ``side(x) = A x_u + B x_v + C = det(P_i, P_j, x)``: ``(A, B, C)``, each
    (L, pairs)."""
    A = P[:, ii, 1] - P[:, jj, 1]
    B = P[:, jj, 0] - P[:, ii, 0]
    return A, B, -(A * P[:, ii, 0] + B * P[:, ii, 1])


def _link_sides(P, forms, ii, jj, link: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``det(P_i, P_j, x)`` (b, pairs) for points ``x`` (b, 2) of the polygons ``link`` (b,),
    from the :func:`_line_forms`: three row gathers per point instead of two vertex gathers and
    the full predicate. Exactly 0 at both ends of every line, as :func:`orient2d` is (the form
    alone is exact only at ``P_i``; a data point on a knot then fell out of closed triangles)."""
    A, B, C = forms
    side = np.take(A, link, axis=0) * x[:, 0:1]
    side += np.take(B, link, axis=0) * x[:, 1:2]
    side += np.take(C, link, axis=0)
    # x is vertex k: compared by u first, by v only in the (rare) rows where u matches
    at = x[:, 0:1] == np.take(P[:, :, 0], link, axis=0)  # (b, m)
    rows = np.flatnonzero(at.any(axis=1))
    if len(rows):
        at = at[rows] & (x[rows, 1:2] == np.take(P[:, :, 1], link[rows], axis=0))
        side[rows] = np.where(at[:, ii] | at[:, jj], 0.0, side[rows])
    return side


def _min_cost_triangulations(poly: np.ndarray, chord: np.ndarray, trip: np.ndarray,
                             tcost: np.ndarray) -> list:
    """Dynamic programme over sub-polygons ``i..j`` for ``L`` polygons at once: the
    triangulation of each polygon ``poly`` (L, m) with the least total triangle cost ``tcost``
    (L, C) over the triples ``trip`` (inf: not allowed), as a list of knot-index triples, or
    None where no allowed triangulation exists. O(m^3) array steps, each over all polygons."""
    L, m = poly.shape
    index = {tuple(t): n for n, t in enumerate(trip.tolist())}
    best = np.full((L, m, m), np.inf)
    arg = np.full((L, m, m), -1, dtype=np.int64)
    for i in range(m - 1):
        best[:, i, i + 1] = 0.0
    rows = np.arange(L)
    for span in range(2, m):
        for i in range(0, m - span):
            j = i + span
            ks = np.arange(i + 1, j)
            cand = best[:, i, ks] + best[:, ks, j] + tcost[:, [index[(i, k, j)] for k in ks]]
            pick = cand.argmin(axis=1)
            arg[:, i, j] = ks[pick]
            best[:, i, j] = np.where(chord[:, i, j], cand[rows, pick], np.inf)
    out: list = [None] * L
    done = np.flatnonzero(np.isfinite(best[:, 0, m - 1]))
    args, polys = arg[done].tolist(), poly[done].tolist()
    for n, li in enumerate(done.tolist()):
        a, pl, tris, stack = args[n], polys[n], [], [(0, m - 1)]
        while stack:
            i, j = stack.pop()
            if j - i < 2:
                continue
            k = a[i][j]
            tris.append((pl[i], pl[k], pl[j]))
            stack.extend([(i, k), (k, j)])
        out[li] = tris
    return out


def constrained_delaunay_many(poly: np.ndarray, knots: np.ndarray) -> list:
    """Constrained Delaunay triangulations of ``L`` simple CCW polygons with ``m`` vertices each
    (``poly`` (L, m) knot indices), in one array pass: the triangulation minimizing the integral
    of the piecewise-linear interpolant of ``|x - x_0|^2`` (``x_0`` the mean of its vertices), i.e.
    ``sum_T area(T) (|a|^2 + |b|^2 + |c|^2) / 3``. Every Lawson flip to a locally Delaunay edge
    lowers that lifted volume, so its minimum is the constrained Delaunay triangulation (any
    one of them for co-circular knots). None where it fails (then use
    :func:`~core.configurations.constrained_delaunay`)."""
    P = knots[poly]
    P = P - P.mean(axis=1, keepdims=True)
    chord, trip, good = _candidate_triangles(P)
    tp = P[:, trip]  # (L, C, 3, 2)
    area = _orient(tp[..., 0, :], tp[..., 1, :], tp[..., 2, :])
    lift = (tp**2).sum(axis=(-1, -2)) / 3.0
    return _min_cost_triangulations(poly, chord, trip, np.where(good, area * lift, np.inf))


class FeatureLinkTriangulator:
    """Minimum-cost link triangulations (method.md section 2.4) for the link procedure.

    ``triangulator(polygon, knots, J, level)``: for ``level < degree`` the triangulation of the
    link polygon that minimizes the total fit residual of its triangles (with ``quadratic``, the
    default, of a local quadratic fit, otherwise of the affine :class:`PlaneFitCost`), by dynamic
    programming over admissible diagonals, among triangles ``T`` with no three (nearly)
    collinear knots in ``T u J``. A tiny shape term (sum of squared edges over area) breaks ties
    towards well-shaped triangles, so on planar data the choice is Delaunay-like. Other levels,
    links without data, links touching knots that are not ``movable`` (the border rings), or
    links with no admissible triangulation fall back to constrained Delaunay.

    The quadratic residual measures what a quadratic spline cannot follow locally. On 60 random
    knots with 6000 points (3 seeds each of a straight crease, a curved crease and Franke's
    function; least squares, error on a 90x90 grid of the true function;
    ``benchmarks/same_knots.py``) it was within 1% of the affine one on the straight crease,
    0.2-2% better on the curved one and 7-17% better on Franke's function, where the affine
    choice had been 2-7% worse than Delaunay links.

    :meth:`triangulate_many` does all the links of one level at once (the link procedure uses
    it): links with the same number of vertices share one array pass for their admissible
    diagonals, candidate triangles, collinearity tests and costs (one grouped moment sum over
    all (triangle, point) pairs), and the dynamic programme runs over the sub-polygon spans
    with every link of the group in one array. Groups are cut into batches of at most
    ``OPTIMAL_BATCH`` links that run on parallel threads (:mod:`core.parallel`); each link's
    choice does not depend on the batch it is in.
    """

    OPTIMAL_BATCH = 400

    def __init__(self, cost: PlaneFitCost, degree: int, movable: np.ndarray | None = None,
                 quadratic: bool = True):
        self.cost = cost
        self.degree = degree
        self.movable = movable
        self.quadratic = quadratic
        self.calls = 0
        self.optimized = 0

    def __call__(self, polygon, knots, J=(), level=0):
        return self.triangulate_many([tuple(polygon)], knots, [tuple(J)], level)[0]

    def triangulate_many(self, polygons, knots, Js, level=0) -> list:
        """Triangulations (lists of knot-index triples) of the link ``polygons`` (CCW tuples)
        with centre sets ``Js`` at ``level``, in order."""
        self.calls += len(polygons)
        knots = np.asarray(knots, dtype=np.float64)
        out: list = [None] * len(polygons)
        if level < self.degree:
            by_size: dict = {}
            for li, (poly, J) in enumerate(zip(polygons, Js)):
                if len(poly) == 3:
                    out[li] = [tuple(poly)]
                elif self.movable is None or (
                    self.movable[list(poly)].all() and self.movable[list(J)].all()
                ):
                    by_size.setdefault((len(poly), len(J)), []).append(li)
                # links that touch the border rings keep their Delaunay choice: reaching into
                # the rings with long triangles would shrink the region where the basis sums
                # to one
            # batches of at most OPTIMAL_BATCH links of one shape, on parallel threads
            batches = [
                (m, nj, members[s : s + self.OPTIMAL_BATCH])
                for (m, nj), members in by_size.items()
                for s in range(0, len(members), self.OPTIMAL_BATCH)
            ]

            def solve(batch):
                m, nj, members = batch
                polys = np.array([polygons[li] for li in members], dtype=np.int64).reshape(-1, m)
                J = np.array([Js[li] for li in members], dtype=np.int64).reshape(-1, nj)
                return self._optimal(polys, J, knots)

            for (_, _, members), result in zip(batches, pmap(solve, batches)):
                for li, tris in zip(members, result):
                    out[li] = tris
                self.optimized += sum(t is not None for t in result)
        # the rest (the last level, which does not change a TCB basis, links at the border
        # rings, links without data): constrained Delaunay, batched by polygon size
        rest: dict = {}
        for li, tris in enumerate(out):
            if tris is None and len(polygons[li]) == 3:
                out[li] = [tuple(polygons[li])]
            elif tris is None:
                rest.setdefault(len(polygons[li]), []).append(li)
        batches = [members[s : s + self.OPTIMAL_BATCH] for members in rest.values()
                   for s in range(0, len(members), self.OPTIMAL_BATCH)]

        def delaunay(members):
            polys = np.array([polygons[li] for li in members], dtype=np.int64)
            return constrained_delaunay_many(polys, knots)

        for members, result in zip(batches, pmap(delaunay, batches)):
            for li, tris in zip(members, result):
                out[li] = tris if tris is not None else constrained_delaunay(
                    polygons[li], knots, Js[li], level
                )
        return out

    def _optimal(self, poly: np.ndarray, J: np.ndarray, knots: np.ndarray) -> list:
        """Minimum-cost triangulations of ``L`` links with ``m`` vertices each (``poly`` (L, m),
        ``J`` (L, level)); None for a link without data or without an admissible one."""
        L, m = poly.shape
        P = knots[poly]  # (L, m, 2)
        out: list = [None] * L
        # the data near each link: the ball around its vertex mean through its farthest vertex
        # (it holds the vertices, so their convex hull and the polygon; 0.55x the candidates
        # of the ball around the bounding box on a hexagon)
        centre = P.mean(axis=1)
        radius = np.sqrt(((P - centre[:, None]) ** 2).sum(axis=2).max(axis=1)) * (1 + 1e-9)
        near = self.cost.tree.query_ball_point(centre, radius)
        counts = np.array([len(x) for x in near], dtype=np.int64)
        if counts.sum() == 0:
            return out
        flat = np.concatenate([np.asarray(x, dtype=np.int64) for x in near])
        link = np.repeat(np.arange(L), counts)
        x = np.take(self.cost.uv, flat, axis=0)
        chord, trip, valid = _candidate_triangles(P)
        # the side of every point against the line through every vertex pair (i < j) of its
        # link, once; the closed candidate triangle (i, k, j), i < k < j, CCW when admissible,
        # holds the points left of i -> k and k -> j and right of i -> j
        ii, jj = np.triu_indices(m, 1)
        pair = np.full((m, m), -1)
        pair[ii, jj] = np.arange(len(ii))
        e01, e12, e02 = (pair[trip[:, a], trip[:, b]] for a, b in ((0, 1), (1, 2), (0, 2)))
        forms = _line_forms(P, ii, jj)
        member = np.empty((len(flat), len(trip)), dtype=bool)
        step = max(1, (1 << 20) // len(ii))  # about 1e6 side tests per chunk (bounded memory)
        for s in range(0, len(flat), step):
            side = _link_sides(P, forms, ii, jj, link[s : s + step], x[s : s + step])
            left, right = side >= 0, side <= 0
            member[s : s + step] = left[:, e01] & left[:, e12] & right[:, e02]
        # the points of the closed link polygon: those in one of its admissible triangles
        # (they cover it); only those can count for a triangle
        keep = (member & np.take(valid, link, axis=0)).any(axis=1)
        if not keep.any():
            return out
        flat, link, x, member = flat[keep], link[keep], x[keep], member[keep]
        counts = np.bincount(link, minlength=L)
        C = len(trip)
        valid &= (counts > 3)[:, None]
        lt, ct = np.nonzero(valid)
        withJ = np.concatenate([P[lt[:, None], trip[ct]], knots[J[lt]]], axis=1)
        valid[lt, ct] = _collinear_free(withJ)
        lt, ct = np.nonzero(valid)
        V = len(lt)
        ssr = np.zeros(V)
        corners = P[lt[:, None], trip[ct]]  # (V, 3, 2)
        if V:
            vid = np.full((L, C), -1)
            vid[lt, ct] = np.arange(V)
            # (point, triangle) pairs; one grouped moment sum per triangle
            pi, ci = np.nonzero(member & np.take(valid, link, axis=0))
            ssr = grouped_plane_costs(np.take(x, pi, axis=0),
                                      np.take(self.cost.points, flat[pi], axis=0), vid[link[pi], ci], V,
                                      quadratic=self.quadratic)
        # tie-break towards well-shaped triangles, scaled by each link's data spread
        pts = np.take(self.cost.points, flat, axis=0)
        mean = np.stack([np.bincount(link, pts[:, j], L) for j in range(3)], 1)
        mean /= np.maximum(counts, 1)[:, None]
        q = np.bincount(link, ((pts - mean[link]) ** 2).sum(axis=1), L)
        edges2 = sum(((corners[:, (j + 1) % 3] - corners[:, j]) ** 2).sum(-1) for j in range(3))
        area = np.abs(_orient(corners[:, 0], corners[:, 1], corners[:, 2]))
        tcost = np.full((L, C), np.inf)
        tcost[lt, ct] = ssr + (1e-9 * q[lt] + 1e-15) * edges2 / np.maximum(area, 1e-300)
        return _min_cost_triangulations(poly, chord, trip, tcost)
