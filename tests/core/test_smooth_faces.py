"""The C^1 interpolant a mesh's face samples lie on (core.smooth_faces, core.surface.smooth_points)
and the order-free draw of the samples (core.surface._area_samples)."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

import core.surface as surface
from core.parameterize import parameterize
from core.smooth_faces import (mean_gradients, clough_tocher_points, face_gradients,
                               vertex_gradients)


def _quadratic(x):
    u, v = x.T
    return np.c_[u + 0.3 * u * v, v - 0.2 * u * u, 0.5 * u * u - v * v + 0.7 * u * v]


def _random_mesh(n=60, seed=1):
    uv = np.random.default_rng(seed).random((n, 2))
    return uv, Delaunay(uv).simplices


def _inside(faces, count, seed=2):
    rng = np.random.default_rng(seed)
    return rng.integers(0, len(faces), count), rng.dirichlet([1, 1, 1], count)


def test_a_quadratic_map_is_reproduced_from_its_fitted_gradients():
    """The quadratic through two rings of neighbours is the map itself, and Clough-Tocher
    elements reproduce quadratics: the samples lie on the map to rounding."""
    uv, faces = _random_mesh()
    points = _quadratic(uv)
    G = vertex_gradients(points, uv, faces)
    u, v = uv.T
    exact = np.stack([np.c_[1 + 0.3 * v, 0.3 * u], np.c_[-0.4 * u, np.ones_like(u)],
                      np.c_[u + 0.7 * v, -2 * v + 0.7 * u]], axis=1)
    np.testing.assert_allclose(G, exact, atol=1e-10)
    face, bary = _inside(faces, 4000)
    x = np.einsum("nk,nkj->nj", bary, uv[faces[face]])
    got = clough_tocher_points(points, uv, faces, face, bary, G[faces])
    np.testing.assert_allclose(got, _quadratic(x), atol=1e-12)
    # at the corners: the vertices themselves
    corners = np.repeat(np.eye(3)[None], len(faces), axis=0).reshape(-1, 3)
    at = clough_tocher_points(points, uv, faces, np.repeat(np.arange(len(faces)), 3), corners,
                              G[faces])
    np.testing.assert_allclose(at, points[faces.ravel()], atol=1e-13)


def test_the_interpolant_is_c1_across_the_edges_of_the_faces():
    """Value and derivative across every interior edge agree from both sides (Richardson
    differences of steps 1e-6 and 2e-6: a kink of the flat faces' size would show as 1e-1)."""
    uv, faces = _random_mesh()
    points = np.c_[np.sin(3 * uv[:, 0]) * np.cos(2 * uv[:, 1]), uv]
    G = vertex_gradients(points, uv, faces)[faces]
    edges = {}
    for f, tri in enumerate(faces):
        for k in range(3):
            edges.setdefault(tuple(sorted((tri[k], tri[(k + 1) % 3]))), []).append(f)
    worst_value = worst_slope = 0.0
    for (a, b), owners in edges.items():
        if len(owners) != 2:
            continue
        m = 0.37 * uv[a] + 0.63 * uv[b]
        t = uv[b] - uv[a]
        n = np.array([-t[1], t[0]]) / np.linalg.norm(t)
        sides = []
        for f in owners:
            T = uv[faces[f]]
            inward = np.sign((T.mean(axis=0) - m) @ n)

            def value(p, f=f, T=T):
                lam = np.linalg.solve(np.c_[T[1] - T[0], T[2] - T[0]], p - T[0])
                bary = np.array([[1 - lam.sum(), *lam]])
                return clough_tocher_points(points, uv, faces, np.array([f]), bary, G)[0, 0]

            h = 1e-6
            d1 = (value(m + inward * h * n) - value(m)) / h
            d2 = (value(m + 2 * inward * h * n) - value(m)) / (2 * h)
            sides.append((value(m), inward * (2 * d1 - d2)))
        worst_value = max(worst_value, abs(sides[0][0] - sides[1][0]))
        worst_slope = max(worst_slope, abs(sides[0][1] - sides[1][1]))
    assert worst_value < 1e-12 and worst_slope < 1e-5


def test_face_and_mean_gradients_of_a_linear_map_are_the_map():
    uv, faces = _random_mesh(20)
    A = np.array([[1.0, 2.0], [-0.5, 0.3], [0.7, -1.1]])
    points = uv @ A.T
    np.testing.assert_allclose(face_gradients(points, uv, faces),
                               np.broadcast_to(A, (len(faces), 3, 2)), atol=1e-12)
    np.testing.assert_allclose(mean_gradients(points, uv, faces),
                               np.broadcast_to(A, (len(uv), 3, 2)), atol=1e-12)


def test_few_neighbours_fall_back_to_the_faces_gradients():
    """Two triangles (4 vertices, 3 neighbours each): no quadratic; a planar pair stays flat."""
    uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.c_[uv, 0.2 * uv[:, 0] - 0.1 * uv[:, 1]]
    G = vertex_gradients(points, uv, faces)
    np.testing.assert_allclose(G, mean_gradients(points, uv, faces))
    face, bary = _inside(faces, 200)
    got = clough_tocher_points(points, uv, faces, face, bary, G[faces])
    np.testing.assert_allclose(got[:, 2], 0.2 * got[:, 0] - 0.1 * got[:, 1], atol=1e-14)


def _sphere_cap():
    """A cap of the unit sphere, z > 0.3, cut from an icosphere split twice (55 vertices)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from coarse_meshes import sphere_cap
    return sphere_cap(2)[0]


def test_a_coarse_sphere_cap_is_sampled_closer_to_the_sphere_than_its_facets():
    """55 vertices: the samples on the C^1 interpolant are 1.1e-3 from the sphere (RMS), the
    flat faces' 1.2e-2 and the point-normal triangles' (surface.curved_points) 2.4e-3."""
    points, faces = _sphere_cap()
    assert len(points) == 55
    par = parameterize(points, faces)
    face, bary = surface._area_samples(points, par.faces, 20000, 0)

    def off(q):
        return np.sqrt(np.mean((np.linalg.norm(q, axis=1) - 1) ** 2))

    flat = off(np.einsum("nk,nkj->nj", bary, points[par.faces[face]]))
    pn = off(surface.curved_points(points, par.faces, face, bary))
    c1 = off(surface.smooth_points(points, par.uv, par.faces, face, bary))
    assert c1 < 0.2 * flat and c1 < 0.6 * pn, (flat, pn, c1)


def test_a_crease_between_planes_keeps_its_facets():
    """z = |y| on a grid: every face is in a flat region (core.surface.flat_corners), so the
    samples are the flat faces' own points: the crease stays sharp."""
    g = np.linspace(-1, 1, 11)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    points = np.c_[x, y, np.abs(y)]
    i, j = np.meshgrid(np.arange(10), np.arange(10))
    a = (j * 11 + i).ravel()
    faces = np.r_[np.c_[a, a + 1, a + 12], np.c_[a, a + 12, a + 11]]
    par = parameterize(points, faces)
    assert surface.flat_corners(points, par.faces).all()
    face, bary = surface._area_samples(points, par.faces, 5000, 0)
    got = surface.smooth_points(points, par.uv, par.faces, face, bary)
    np.testing.assert_allclose(got[:, 2], np.abs(got[:, 1]), atol=1e-12)


@pytest.mark.parametrize("what", ["faces", "vertices", "corners"])
def test_the_face_samples_do_not_depend_on_the_order_of_the_mesh(what):
    rng = np.random.default_rng(0)
    points = rng.random((40, 3))
    faces = Delaunay(points[:, :2]).simplices

    def drawn(p, f):
        face, bary = surface._area_samples(p, f, 500, 3)
        return np.einsum("nk,nkj->nj", bary, p[f[face]])

    base = drawn(points, faces)
    p, f = points, faces
    if what == "faces":
        f = faces[rng.permutation(len(faces))]
    elif what == "vertices":
        perm = rng.permutation(len(points))
        p, f = points[perm], np.argsort(perm)[faces]
    else:
        f = np.roll(faces, 1, axis=1)
    np.testing.assert_allclose(drawn(p, f), base, atol=1e-15)


def test_a_dense_mesh_is_sampled_on_point_normal_triangles():
    """Under SMOOTH_SAMPLES_PER_FACE samples per face the gradients' cost (2 s at 1e5 vertices)
    buys nothing: the samples are the point-normal triangles' (core.surface.curved_points);
    at or above it, the C^1 surface's."""
    points, faces = _sphere_cap()
    par = parameterize(points, faces)
    few = surface.SMOOTH_SAMPLES_PER_FACE * len(par.faces) - 1
    for count, expected in ((few, surface.curved_points), (few + 1, None)):
        got, _ = surface.mesh_samples(points, par.uv, par.faces, count)
        face, bary = surface._area_samples(points, par.faces, count, 0)
        want = (expected(points, par.faces, face, bary) if expected is not None else
                surface.smooth_points(points, par.uv, par.faces, face, bary))
        np.testing.assert_array_equal(got, want)


def test_faces_around_a_crease_vertex_meet_along_their_edges():
    """An edge with a flagged corner (flat_corners) at an end, in either face, starts along its
    chord there in both faces, so the faces share its curve: with the flagged corners' own
    gradients alone, the faces around such vertices parted, up to 1.1e-3 of the diagonal on
    patch-01.off (review). Each interior edge's point at 0.3 of its length, from both of its
    faces: the same point."""
    from pathlib import Path
    from core.meshio import read_geometry

    points, faces = read_geometry(Path(__file__).resolve().parents[2] / "data" / "patch-01.off")
    par = parameterize(points, faces)
    f = par.faces
    assert surface.flat_corners(points, f).any(axis=1).mean() > 0.05  # it has such faces
    key = {}
    for n, tri in enumerate(f):
        for k in range(3):
            key.setdefault((tri[k], tri[(k + 1) % 3]), (n, k))
    face, bary = [], []
    for (a, b), (n, k) in key.items():
        if (b, a) not in key:
            continue
        m, j = key[(b, a)]
        for g, c, at_a in ((n, k, 0.7), (m, j, 0.3)):  # corner c is the edge's first end
            w = np.zeros(3)
            w[c], w[(c + 1) % 3] = at_a, 1 - at_a
            face.append(g)
            bary.append(w)
    got = surface.smooth_points(points, par.uv, f, np.array(face), np.array(bary))
    diagonal = np.linalg.norm(np.ptp(points, axis=0))
    assert np.abs(got[0::2] - got[1::2]).max() < 1e-12 * diagonal


def test_a_sliver_of_the_parameters_next_to_a_flat_region_stays_on_the_mesh():
    """A 7 x 7 grid, flat for x < 0.3 and curved beyond, with one vertex moved in the
    parameters to 1e-6 of its face's opposite edge: the vertices near the flat region take
    the mean of their faces' gradients, in which the sliver weighs by its area. Weighted by
    corner angles, the sliver's corner of nearly 180 degrees weighed most and the samples went
    up to 217 diagonals off the mesh at 1e-4 (review); now they stay within 3.5% of the
    diagonal of the flat faces' points (the sliver's own map is distorted) for moves from
    1e-1 to 1e-6, the gradients under 1.5."""
    g = np.linspace(0, 1, 7)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    points = np.c_[x, y, np.where(x < 0.3, 0.0, (x - 0.3) ** 2)]
    i, j = np.meshgrid(np.arange(6), np.arange(6))
    a = (j * 7 + i).ravel()
    faces = np.r_[np.c_[a, a + 1, a + 8], np.c_[a, a + 8, a + 7]]
    uv = points[:, :2].copy()
    v = 3 * 7 + 3
    tri = faces[np.flatnonzero((faces == v).any(axis=1))[0]]
    k = list(tri).index(v)
    p, q = uv[tri[(k + 1) % 3]], uv[tri[(k + 2) % 3]]
    inward = uv[v] - (p + q) / 2
    uv[v] = (p + q) / 2 + 1e-6 * np.linalg.norm(q - p) * inward / np.linalg.norm(inward)
    assert surface.flat_corners(points, faces).any()
    face, bary = _inside(faces, 20000)
    got = surface.smooth_points(points, uv, faces, face, bary)
    flat = np.einsum("nk,nkj->nj", bary, points[faces[face]])
    assert np.isfinite(got).all()
    assert np.linalg.norm(got - flat, axis=1).max() < 0.04 * np.sqrt(3)
