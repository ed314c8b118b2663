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
from scipy.spatial import Delaunay, cKDTree

from .configurations import constrained_delaunay, delaunay_triangulation
from .simplex import orient2d

__all__ = ["PlaneFitCost", "feature_triangulation", "FeatureLinkTriangulator", "min_angle_sine"]

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


def grouped_plane_costs(x: np.ndarray, p: np.ndarray, group: np.ndarray, n_groups: int) -> np.ndarray:
    """Plane-fit residual of every point group at once, (G,): ``Q - tr(R^T M^-1 R)`` from
    per-group moment sums (``bincount``) in coordinates centred on each group's mean; groups
    with at most 3 points cost 0. Points may appear in several groups (pass them repeated)."""
    cnt = np.bincount(group, minlength=n_groups).astype(np.float64)
    safe = np.maximum(cnt, 1.0)
    mx = np.stack([np.bincount(group, x[:, j], n_groups) for j in range(2)], 1) / safe[:, None]
    mp = np.stack([np.bincount(group, p[:, j], n_groups) for j in range(3)], 1) / safe[:, None]
    x = x - mx[group]
    p = p - mp[group]
    phi = np.c_[x, np.ones(len(x))]
    M = np.stack([np.bincount(group, phi[:, i] * phi[:, j], n_groups)
                  for i in range(3) for j in range(3)], 1).reshape(-1, 3, 3)
    R = np.stack([np.bincount(group, phi[:, i] * p[:, j], n_groups)
                  for i in range(3) for j in range(3)], 1).reshape(-1, 3, 3)
    Q = np.bincount(group, (p * p).sum(axis=1), n_groups)
    scale = np.trace(M, axis1=1, axis2=2)[:, None, None] + 1e-300
    sol = np.linalg.solve(M + 1e-12 * scale * np.eye(3), R)
    ssr = Q - np.einsum("tij,tij->t", R, sol)
    return np.where(cnt > 3, np.maximum(ssr, 0.0), 0.0)


class PlaneFitCost:
    """Sum of squared residuals of the affine fit ``(u, v) -> p`` over the points of a triangle.

    With ``phi = (u, v, 1)``, moment sums ``M = sum phi phi^T``, ``R = sum phi p^T`` and
    ``Q = sum |p|^2`` over the triangle's points, the residual is ``Q - tr(R^T M^-1 R)``
    (normal equations; method.md section 2.4). Sums are taken in coordinates centred on the
    region being triangulated, which avoids cancellation.
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
        is harmless for a cost).
        """
        T = len(tri_pts)
        if T == 0:
            return np.zeros(0), np.zeros(0, dtype=np.int64)
        if len(idx) == 0:
            return np.zeros(T), np.zeros(T, dtype=np.int64)
        x = self.uv[idx]
        p = self.points[idx]
        c_uv, c_p = x.mean(axis=0), p.mean(axis=0)
        x = x - c_uv
        p = p - c_p
        a, b, c = (tri_pts[:, j] - c_uv for j in range(3))
        sgn = np.sign(_orient(a, b, c))[:, None]
        inside = (
            (sgn * _orient(a[:, None], b[:, None], x[None]) >= 0)
            & (sgn * _orient(b[:, None], c[:, None], x[None]) >= 0)
            & (sgn * _orient(c[:, None], a[:, None], x[None]) >= 0)
        ).astype(np.float64)  # (T, n)
        phi = np.c_[x, np.ones(len(x))]
        M = (inside @ (phi[:, :, None] * phi[:, None, :]).reshape(-1, 9)).reshape(T, 3, 3)
        R = (inside @ (phi[:, :, None] * p[:, None, :]).reshape(-1, 9)).reshape(T, 3, 3)
        Q = inside @ (p * p).sum(axis=1)
        count = inside.sum(axis=1).astype(np.int64)
        scale = np.trace(M, axis1=1, axis2=2)[:, None, None] + 1e-300
        reg = 1e-12 * scale * np.eye(3)
        sol = np.linalg.solve(M + reg, R)
        ssr = Q - np.einsum("tij,tij->t", R, sol)
        ssr = np.where(count > 3, np.maximum(ssr, 0.0), 0.0)
        return ssr, count


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
    d = Delaunay(knots, qhull_options="Qbb Qc Qz Qt")
    key_of = {tuple(sorted(t)): i for i, t in enumerate(tri.tolist())}
    remap = np.array([key_of.get(tuple(sorted(s)), -1) for s in d.simplices.tolist()] + [-1])
    owner = remap[d.find_simplex(cost.uv)]  # -1 outside / degenerate
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


class FeatureLinkTriangulator:
    """Minimum-cost link triangulations (method.md section 2.4) for the link procedure.

    ``triangulator(polygon, knots, J, level)``: for ``level < degree`` the triangulation of the
    link polygon that minimizes the total :class:`PlaneFitCost` of its triangles, by dynamic
    programming over admissible diagonals, among triangles ``T`` with no three (nearly)
    collinear knots in ``T u J``. A tiny shape term (sum of squared edges over area) breaks ties
    towards well-shaped triangles, so on planar data the choice is Delaunay-like. Other levels,
    links without data, links touching knots that are not ``movable`` (the border rings), or
    links with no admissible triangulation fall back to constrained Delaunay.
    """

    def __init__(self, cost: PlaneFitCost, degree: int, movable: np.ndarray | None = None):
        self.cost = cost
        self.degree = degree
        self.movable = movable
        self.calls = 0
        self.optimized = 0

    def __call__(self, polygon, knots, J=(), level=0):
        self.calls += 1
        if level >= self.degree:
            return constrained_delaunay(polygon, knots, J, level)
        poly = np.asarray(polygon, dtype=np.int64)
        if self.movable is not None and not (self.movable[poly].all() and self.movable[list(J)].all()):
            # links that touch the border rings keep their Delaunay choice: reaching into the
            # rings with long triangles would shrink the region where the basis sums to one
            return constrained_delaunay(polygon, knots, J, level)
        P = knots[poly]
        m = len(poly)
        if m == 3:
            return [tuple(polygon)]
        lo, hi = P.min(axis=0), P.max(axis=0)
        idx = self.cost.near(0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo)) * 1.0001)
        if len(idx) <= 3:
            return constrained_delaunay(polygon, knots, J, level)
        # admissible chords (i, j), i < j: polygon edges or diagonals inside the polygon
        ii, jj = np.triu_indices(m, 1)
        adjacent = (jj - ii == 1) | ((ii == 0) & (jj == m - 1))
        ok = adjacent.copy()
        diag = np.flatnonzero(~adjacent)
        if len(diag):
            di, dj = ii[diag], jj[diag]
            A, B = P[di], P[dj]
            e0 = np.arange(m)
            E0, E1 = P[e0], P[(e0 + 1) % m]
            o1 = _orient(A[:, None], B[:, None], E0[None])
            o2 = _orient(A[:, None], B[:, None], E1[None])
            o3 = _orient(E0[None], E1[None], A[:, None])
            o4 = _orient(E0[None], E1[None], B[:, None])
            touches_end = (e0[None] == di[:, None]) | (e0[None] == dj[:, None])
            touches_end |= ((e0[None] + 1) % m == di[:, None]) | ((e0[None] + 1) % m == dj[:, None])
            crosses = (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~touches_end
            # locally inside at vertex i: between the edges (i-1 -> i) and (i -> i+1)
            prev, nxt = P[(di - 1) % m], P[(di + 1) % m]
            convex = _orient(prev, A, nxt) > 0
            left_next = _orient(A, nxt, B) > 0
            left_prev = _orient(prev, A, B) > 0
            inside_cone = np.where(convex, left_next & left_prev, left_next | left_prev)
            ok[diag] = ~crosses.any(axis=1) & inside_cone
        chord = np.zeros((m, m), dtype=bool)
        chord[ii[ok], jj[ok]] = True
        # candidate triangles (i < k < j) with all three sides admissible
        trip = np.array(list(combinations(range(m), 3)))
        good = chord[trip[:, 0], trip[:, 1]] & chord[trip[:, 1], trip[:, 2]] & chord[trip[:, 0], trip[:, 2]]
        trip = trip[good]
        if len(trip) == 0:
            return constrained_delaunay(polygon, knots, J, level)
        tp = P[trip]  # (T, 3, 2), CCW since the polygon is CCW and i < k < j
        if len(J):
            withJ = np.concatenate([tp, np.broadcast_to(knots[list(J)], (len(tp), len(J), 2))], 1)
        else:
            withJ = tp
        valid = _collinear_free(withJ) & (_orient(tp[:, 0], tp[:, 1], tp[:, 2]) > 0)
        ssr, _ = self.cost.costs(tp, idx)
        edges2 = sum(((tp[:, (j + 1) % 3] - tp[:, j]) ** 2).sum(-1) for j in range(3))
        area = np.abs(_orient(tp[:, 0], tp[:, 1], tp[:, 2]))
        shape = edges2 / np.maximum(area, 1e-300)
        loc = self.cost.points[idx]
        q = float(((loc - loc.mean(axis=0)) ** 2).sum())
        tcost = np.where(valid, ssr + (1e-9 * q + 1e-15) * shape, np.inf)
        cost_of = {tuple(t): c for t, c in zip(trip.tolist(), tcost.tolist())}
        # DP over sub-polygons i..j
        INF = float("inf")
        best = [[INF] * m for _ in range(m)]
        arg = [[-1] * m for _ in range(m)]
        for i in range(m - 1):
            best[i][i + 1] = 0.0
        for span in range(2, m):
            for i in range(0, m - span):
                j = i + span
                if not chord[i, j]:
                    continue
                bi = INF
                for k in range(i + 1, j):
                    c = cost_of.get((i, k, j))
                    if c is None:
                        continue
                    v = best[i][k] + best[k][j] + c
                    if v < bi:
                        bi, arg[i][j] = v, k
                best[i][j] = bi
        if not np.isfinite(best[0][m - 1]):
            return constrained_delaunay(polygon, knots, J, level)
        out, stack = [], [(0, m - 1)]
        while stack:
            i, j = stack.pop()
            if j - i < 2:
                continue
            k = arg[i][j]
            out.append((int(poly[i]), int(poly[k]), int(poly[j])))
            stack.extend([(i, k), (k, j)])
        self.optimized += 1
        return out
