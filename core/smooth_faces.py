"""A C^1 surface through a parameterized mesh's vertices: Clough-Tocher elements on its faces.

A mesh is fitted through its vertices and points sampled on its faces (``core.surface.
mesh_samples``; not in method.md: section 5 fits the data points as given). The fit sees the
mesh as the map ``x(u, v)`` from the parameters to space. On the flat faces, and on
point-normal triangles (``core.surface.curved_points``), that map is only C^0 across the
faces' edges, and a C^1 spline chases its kinks with knots. Sampled on the C^1 interpolant
of this module a sphere cap meshed with 55 vertices ends 3.7e-4 of its diagonal from the
sphere (RMS) instead of 1.0e-3, and tori and saddles of 50-100 vertices meet a tolerance of
1e-4 with 40-80% of the control points (benchmarks/coarse_meshes.py, docs/benchmarks.md).

The interpolant is Clough and Tocher's macro-element (reduced form; Farin, "Triangular
Bernstein-Bezier patches", CAGD 3, 1986, section 4.3; Lai and Schumaker, "Spline functions on
triangulations", 2007, section 6.1): each face, in the parameter plane, is split at its
centroid into three triangles carrying one cubic each, joined C^1 inside the face; along the
face's edges the cubic is fixed by the values and gradients at the edge's ends, and the
derivative across the edge is the linear interpolant of the ends' ones, so that two faces that
share an edge and its ends' gradients join C^1 there. It reproduces quadratics: with exact
gradients of a quadratic map it is that map.

The gradients ``dx/du, dx/dv`` (3 x 2) at each vertex are fitted: the quadratic through the
vertex in the parameters that is nearest, in least squares, to its neighbours within two
edges (:func:`vertex_gradients`). At a vertex on a crease or in a flat region
(``core.surface.flat_corners``: the point-normal triangles' rules) each face takes its own
linear gradient instead, so creases stay creases and planes stay flat
(``core.surface.smooth_points``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

# relative size of the smallest eigenvalue of a vertex's (scaled) normal matrix under which
# its quadratic fit is not trusted and mean_gradients is taken
QUADRATIC_CONDITION = 1e-6


def face_gradients(points, uv, faces) -> np.ndarray:
    """The gradient (f, 3, 2) of each face's linear map from its parameter triangle to its
    space triangle: ``[p_1 - p_0, p_2 - p_0] [x_1 - x_0, x_2 - x_0]^-1`` (zero for a face
    of no parameter area)."""
    x, p = uv[faces], points[faces]
    E = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]], axis=2)  # (f, 2, 2): columns
    D = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=2)  # (f, 3, 2)
    det = E[:, 0, 0] * E[:, 1, 1] - E[:, 0, 1] * E[:, 1, 0]
    ok = np.abs(det) > 1e-300
    inv = np.zeros_like(E)
    inv[ok, 0, 0], inv[ok, 1, 1] = E[ok, 1, 1] / det[ok], E[ok, 0, 0] / det[ok]
    inv[ok, 0, 1], inv[ok, 1, 0] = -E[ok, 0, 1] / det[ok], -E[ok, 1, 0] / det[ok]
    return D @ inv


def vertex_adjacency(faces, n: int) -> sp.csr_matrix:
    """The symmetric (n, n) matrix with 1 where two vertices share an edge of ``faces``."""
    e = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return ((A + A.T) > 0).astype(np.float64)


def vertex_gradients(points, uv, faces, mean=None) -> np.ndarray:
    """The gradient (n, 3, 2) of the map at each vertex ``i``: ``J`` of the quadratic
    ``x_i + J d + Q(d)`` (``d = u_j - u_i``) nearest, weighted least squares with weights
    ``h_i^2 / (h_i^2 + |d|^2)`` (``h_i`` the RMS of the vertex's ``|d|``), to the vertices
    ``j`` within two edges of ``i``: exact for a quadratic map, second order on a smooth one.
    Where those neighbours do not fix a quadratic (fewer than 5, or their normal matrix, scaled
    by ``h_i``, has an eigenvalue under :data:`QUADRATIC_CONDITION` times its largest):
    :func:`mean_gradients` (``mean``, if the caller has it). Vertices of no face get zero."""
    n = len(points)
    A = vertex_adjacency(faces, n)
    ring = (A + A @ A).tocoo()
    keep = ring.row != ring.col
    i, j = ring.row[keep], ring.col[keep]
    d = uv[j] - uv[i]
    r2 = np.einsum("ij,ij->i", d, d)
    count = np.bincount(i, minlength=n)
    h2 = np.bincount(i, weights=r2, minlength=n) / np.maximum(count, 1)
    h = np.sqrt(np.maximum(h2, 1e-300))
    s = d / h[i, None]
    w = 1.0 / (1.0 + r2 / np.maximum(h2[i], 1e-300))
    basis = np.stack([s[:, 0], s[:, 1], 0.5 * s[:, 0] ** 2, s[:, 0] * s[:, 1],
                      0.5 * s[:, 1] ** 2], axis=1)
    y = points[j] - points[i]
    M = np.empty((n, 5, 5))
    for a in range(5):
        for b in range(a, 5):
            M[:, a, b] = M[:, b, a] = np.bincount(i, weights=w * basis[:, a] * basis[:, b],
                                                  minlength=n)
    R = np.empty((n, 5, 3))
    for a in range(5):
        for c in range(3):
            R[:, a, c] = np.bincount(i, weights=w * basis[:, a] * y[:, c], minlength=n)
    eig = np.linalg.eigvalsh(M)
    good = (count >= 5) & (eig[:, 0] > QUADRATIC_CONDITION * np.maximum(eig[:, -1], 1e-300))
    G = np.zeros((n, 3, 2))
    if good.any():
        coef = np.linalg.solve(M[good], R[good])  # (g, 5, 3): rows d_u, d_v, ...
        G[good] = np.swapaxes(coef[:, :2, :], 1, 2) / h[good, None, None]
    rest = ~good
    if rest.any():
        G[rest] = (mean_gradients(points, uv, faces) if mean is None else mean)[rest]
    return G


def clough_tocher_points(points, uv, faces, face, bary, gradients, straight=None) -> np.ndarray:
    """Points (n, 3) of the Clough-Tocher interpolant (module docstring) at barycentric
    coordinates ``bary`` (n, 3) in the faces ``face`` (n,), from the vertices' ``points``,
    their parameters ``uv`` and the gradients ``gradients`` (f, 3 corners, 3, 2) of each
    face's corners (a vertex's may differ between its faces, where a crease passes).

    In the micro-triangle ``(V_i, V_j, C)`` of the face's edge ``V_i V_j`` (``C`` its
    centroid; the one of the corner ``k`` of least ``b_k``, at ``(b_i - b_k, b_j - b_k,
    3 b_k)``) the cubic's Bezier ordinates are ``p_i``, ``p_i + G_i (V_j - V_i) / 3``,
    ``q_i = p_i + G_i (C - V_i) / 3`` at the corners; ``e_ij`` at its middle, from the
    derivative across the edge along its normal ``n`` (barycentric direction ``(a, b, c)``):
    ``3 (a b_210 + b b_120 + c e_ij) = (G_i n + G_j n) / 2``; ``r_i = (e_ij + e_ik + q_i) / 3``
    on the inner edge ``V_i C`` (its C^1 conditions), and ``(r_0 + r_1 + r_2) / 3`` at ``C``.
    A face of no parameter area gives its flat point ``sum b_k p_k``. ``straight`` (f, 3, 3)
    bool: where ``straight[f, k, m]``, the edge from corner ``k`` toward corner ``m`` starts
    along the chord, ``p_k + (p_m - p_k) / 3``, whatever ``G_k`` (two faces whose gradients at
    a vertex differ still share the edge's curve when both start it so)."""
    V = uv[faces[face]]  # (n, 3, 2)
    P = points[faces[face]]  # (n, 3, 3)
    G = gradients[face]  # (n, 3, 3, 2)
    C = V.mean(axis=1)
    q = P + np.einsum("nkdt,nkt->nkd", G, C[:, None, :] - V) / 3.0  # toward C
    nxt, prv = [1, 2, 0], [2, 0, 1]

    chord = None if straight is None else straight[face]

    def toward(k, m, rows=slice(None)):  # p_k + G_k (V_m - V_k) / 3 for corners k and m
        step = np.einsum("ndt,nt->nd", G[rows, k], V[rows, m] - V[rows, k])
        if chord is not None:
            step = np.where(chord[rows, k, m][:, None], P[rows, m] - P[rows, k], step)
        return P[rows, k] + step / 3.0

    # e[:, k]: the ordinate e_ij at the middle of micro-triangle k (edge i = k+1, j = k+2)
    e = np.empty((len(face), 3, 3))
    ok = np.ones(len(face), dtype=bool)
    for k in range(3):
        i, j = nxt[k], prv[k]
        t = V[:, j] - V[:, i]
        nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        # barycentric direction of nrm in (V_i, V_j, C): [V_i - C, V_j - C] (a, b) = nrm
        a1, b1 = V[:, i] - C, V[:, j] - C
        det = a1[:, 0] * b1[:, 1] - a1[:, 1] * b1[:, 0]
        ok &= np.abs(det) > 1e-12 * np.maximum(np.einsum("ij,ij->i", t, t), 1e-300)
        det = np.where(ok, det, 1.0)
        a = (nrm[:, 0] * b1[:, 1] - nrm[:, 1] * b1[:, 0]) / det
        b = (a1[:, 0] * nrm[:, 1] - a1[:, 1] * nrm[:, 0]) / det
        c = -a - b
        c = np.where(np.abs(c) > 1e-300, c, 1.0)
        across = (np.einsum("ndt,nt->nd", G[:, i], nrm) + np.einsum("ndt,nt->nd", G[:, j], nrm))
        e[:, k] = ((across / 6.0 - a[:, None] * toward(i, j) - b[:, None] * toward(j, i))
                   / c[:, None])
    # r[:, i]: on the inner edge V_i C, between the micro-triangles of the edges at V_i
    # (micro-triangle prv[i] has edge (i, i+1), nxt[i] has edge (i-1, i))
    r = (e[:, prv] + e[:, nxt] + q) / 3.0
    centre = r.mean(axis=1)

    k = np.argmin(bary, axis=1)
    rows = np.arange(len(face))
    i, j = np.array(nxt)[k], np.array(prv)[k]
    bk = bary[rows, k]
    s, t, w = bary[rows, i] - bk, bary[rows, j] - bk, 3.0 * bk
    pi, pj = P[rows, i], P[rows, j]
    b210, b120 = toward(i, j, rows), toward(j, i, rows)
    b201, b021 = q[rows, i], q[rows, j]
    b102, b012 = r[rows, i], r[rows, j]
    b111 = e[rows, k]
    out = (pi * (s**3)[:, None] + pj * (t**3)[:, None] + centre * (w**3)[:, None]
           + 3.0 * (b210 * (s * s * t)[:, None] + b120 * (s * t * t)[:, None]
                    + b201 * (s * s * w)[:, None] + b021 * (t * t * w)[:, None]
                    + b102 * (s * w * w)[:, None] + b012 * (t * w * w)[:, None])
           + 6.0 * b111 * (s * t * w)[:, None])
    flat = np.einsum("nk,nkj->nj", bary, P)
    return np.where(ok[:, None], out, flat)


def mean_gradients(points, uv, faces) -> np.ndarray:
    """The mean (n, 3, 2) of the faces' linear gradients (:func:`face_gradients`) at each
    vertex, weighted by the faces' areas in the parameter plane (zero at vertices of no face).
    First order only, but it stays within the gradients of the vertex's own faces, and a
    sliver of the parameters, whose gradient is the least reliable, weighs least (weighted by
    the corner angles, a sliver's corner of nearly 180 degrees weighed most: samples 1.7
    diagonals off a mesh with a uv sliver of 1e-2, 2e7 at 1e-9: review)."""
    n = len(points)
    x = uv[faces]
    area = 0.5 * np.abs((x[:, 1, 0] - x[:, 0, 0]) * (x[:, 2, 1] - x[:, 0, 1])
                        - (x[:, 1, 1] - x[:, 0, 1]) * (x[:, 2, 0] - x[:, 0, 0]))
    weighted = area[:, None, None] * face_gradients(points, uv, faces)
    total = np.zeros((n, 3, 2))
    for k in range(3):
        np.add.at(total, faces[:, k], weighted)
    weight = np.bincount(faces.ravel(), weights=np.repeat(area, 3), minlength=n)
    return total / np.maximum(weight, 1e-300)[:, None, None]
