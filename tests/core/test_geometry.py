"""Point-to-triangle and point-to-mesh distances (used by the deviation map)."""

import numpy as np

from core.geometry import (
    closest_point_on_triangles,
    coordinate_order,
    distances_at_vertices,
    point_mesh_distance,
    polygon_triangles,
    quad_triangles,
    simple_polygon,
)
from core.meshio import read_geometry
from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "data"


def test_closest_point_is_on_the_triangle_and_beats_dense_sampling():
    rng = np.random.default_rng(0)
    a, b, c = rng.random((3, 300, 3))
    p = rng.random((300, 3)) * 2 - 0.5
    q = closest_point_on_triangles(p, a, b, c)
    d = np.linalg.norm(q - p, axis=1)
    g = np.linspace(0, 1, 121)
    U, W = np.meshgrid(g, g)
    keep = (U + W) <= 1
    U, W = U[keep], W[keep]
    pts = a[:, None] + U[None, :, None] * (b - a)[:, None] + W[None, :, None] * (c - a)[:, None]
    sampled = np.linalg.norm(pts - p[:, None], axis=2).min(axis=1)
    assert np.all(d <= sampled + 1e-12)  # never worse than any sample of the triangle
    assert np.all(d >= sampled - 1e-2)  # and within the sampling resolution of the best one


def test_point_mesh_distance_equals_an_exhaustive_search():
    V, F = read_geometry(DATA / "nefertiti.off")
    rng = np.random.default_rng(1)
    pts = V[F].mean(axis=1) + rng.normal(0, 0.5, (len(F), 3))
    fast = point_mesh_distance(pts[:150], V, F)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    exhaustive = np.array([
        np.linalg.norm(closest_point_on_triangles(np.repeat(p[None], len(F), 0), A, B, C) - p, axis=1).min()
        for p in pts[:150]
    ])
    np.testing.assert_allclose(fast, exhaustive, rtol=0, atol=1e-12)
    # points on the mesh are at distance zero
    assert point_mesh_distance(V, V, F).max() < 1e-12


def test_distances_at_vertices_carry_the_data_distances_not_the_gaps():
    """Feet on the plane z=0 with distance 2x + 1 (data at height 2x + 1): a vertex gets the
    weighted mean of the nearest feet's distances (linear data: about its own 2x + 1), a vertex
    on a foot takes that foot's distance, and vertices beyond the radius get 0 / no data."""
    rng = np.random.default_rng(0)
    feet = np.c_[rng.random((5000, 2)), np.zeros(5000)]
    dist = 2 * feet[:, 0] + 1
    t = np.linspace(0.1, 0.9, 9)
    grid = np.c_[np.repeat(t, 9), np.tile(t, 9), np.zeros(81)]
    far = np.array([[0.5, 3.0, 0.0], [np.nan, 0.0, 0.0]])
    verts = np.vstack([grid, feet[:3], far])
    values, has = distances_at_vertices(verts, feet, dist)
    assert has[:84].all() and not has[84:].any() and np.all(values[84:] == 0)
    assert np.allclose(values[:81], 2 * grid[:, 0] + 1, atol=0.03)  # not the ~0.01 gaps
    assert np.allclose(values[81:84], dist[:3])
    # an explicit radius; feet that are NaN (no closest point) are left out
    feet[0] = np.nan
    values, has = distances_at_vertices(verts[:81], feet, dist, radius=1e-4)
    assert not has.any() and np.all(values == 0)
    values, has = distances_at_vertices(np.zeros((0, 3)), feet, dist)
    assert values.shape == (0,) and has.shape == (0,)


def test_ear_clipping_triangulates_simple_polygons_and_refuses_crossing_ones():
    """Ear clipping of simple counter-clockwise polygons (a star of 5 lobes, a C, one with
    collinear runs along its sides) gives m - 2 counter-clockwise triangles of the
    polygon's own vertices that cover its area exactly; a clockwise or self-crossing
    polygon gives None, and simple_polygon tells them apart (crossings, a zero-length edge,
    an edge folding back onto its neighbour)."""
    from core.geometry import ear_clipping, simple_polygon
    from core.simplex import orient2d

    def shoelace(xy):
        return 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])

    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    star = np.c_[(1 + 0.5 * np.sin(5 * t)) * np.cos(t), (1 + 0.5 * np.sin(5 * t)) * np.sin(t)]
    a = np.linspace(0.3, 2 * np.pi - 0.3, 30)
    c_shape = np.r_[np.c_[np.cos(a), np.sin(a)], 0.6 * np.c_[np.cos(a), np.sin(a)][::-1]]
    g = np.arange(5.0)
    steps = np.r_[np.c_[g, 0 * g], np.c_[4 + 0 * g[1:], g[1:]], np.c_[g[::-1][1:], 4 + 0 * g[1:]],
                  np.c_[0 * g[1:-1], g[::-1][1:-1]]]  # a 4 x 4 square, 16 vertices on its sides
    for xy in (star, c_shape, steps):
        assert simple_polygon(xy)
        tri = ear_clipping(xy)
        assert tri.shape == (len(xy) - 2, 3) and len(np.unique(tri)) == len(xy)
        area = orient2d(xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]])
        assert area.min() > 0 and np.isclose(area.sum() / 2, shoelace(xy), rtol=1e-12)
        assert ear_clipping(xy[::-1]) is None  # clockwise
    bowtie = np.array([[0, 0], [1, 1], [1, 0], [0, 1.0]])
    assert not simple_polygon(bowtie) and ear_clipping(bowtie) is None
    assert not simple_polygon(np.r_[star[:10], star[9:]])  # a zero-length edge
    assert not simple_polygon(np.array([[0, 0], [2, 0], [1, 0], [1, 1.0]]))  # folds back
    assert not simple_polygon(np.r_[star, [[0.1, 0.0]], [[2.0, 0.0]]])  # crosses its start


def test_ear_clipping_survives_the_rounding_of_straight_runs_and_long_edges():
    """Review: a C-shaped lattice polygon (straight runs of collinear vertices) turned by an
    arbitrary rotation carries rounding of ~1e-17 along its runs; it is still clipped (each
    ear's triangle holds no other vertex, by the same tolerance that makes a straight vertex
    no ear tip), with the 3D shapes given. simple_polygon agrees with a test of all edge
    pairs on random lattice polygons, some with one far vertex (two long edges, which made
    the KD-tree's candidate pairs quadratic)."""
    from core.configurations import _segments_cross
    from core.geometry import ear_clipping, simple_polygon
    from core.simplex import orient2d

    steps = [(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (2, 1), (1, 1), (1, 2), (1, 3), (2, 3),
             (3, 3), (3, 4), (2, 4), (1, 4), (0, 4), (0, 3), (0, 2), (0, 1)]
    xy = np.array(steps, dtype=float)
    for angle in np.linspace(0.1, 3.0, 15):
        rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        turned = xy @ rot.T  # rounded: the runs are straight only within ~1e-16
        assert simple_polygon(turned)
        tri = ear_clipping(turned, np.c_[xy, np.zeros(len(xy))])
        assert tri is not None and tri.shape == (len(xy) - 2, 3)
        area = orient2d(xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]])  # in the exact lattice
        assert area.min() > 0 and np.isclose(area.sum() / 2, 8.0)
    rng = np.random.default_rng(0)
    for _ in range(300):
        poly = rng.integers(0, 6, (int(rng.integers(4, 30)), 2)).astype(float)
        if rng.random() < 0.3:
            poly[0] = [100.0, 100.0]
        m = len(poly)
        nxt = np.roll(poly, -1, axis=0)
        ii, jj = np.triu_indices(m, 2)
        keep = ~((ii == 0) & (jj == m - 1))
        crossing = _segments_cross(poly[ii[keep]], nxt[ii[keep]], poly[jj[keep]], nxt[jj[keep]])
        prv = np.roll(poly, 1, axis=0)
        degenerate = np.all(nxt == poly, axis=1).any() or (
            (orient2d(prv, poly, nxt) == 0) & (np.einsum("ij,ij->i", prv - poly, nxt - poly) > 0)
        ).any()
        assert simple_polygon(poly) == (not crossing.any() and not degenerate)


def test_quads_are_cut_along_their_shorter_diagonal_whatever_corner_they_start_at():
    """core.geometry.quad_triangles: the shorter diagonal of those whose triangles face the
    quad's way (a concave quad's only one), ties by the corner of least coordinates; the
    same triangles for every rotation of a quad's corners, in the quad's winding."""
    rng = np.random.default_rng(0)
    P = rng.random((400, 3))
    quads = rng.permutation(400).reshape(-1, 4)
    P[quads[:, 2], 2] += 0.5  # (some bent, some convex, some concave in projection)
    cut = quad_triangles(P, quads).reshape(-1, 2, 3)

    def canon(t):  # a face's corners from its least index, the faces sorted
        t = np.array([np.roll(f, -int(np.argmin(f))) for f in t])
        return t[np.lexsort(t.T[::-1])]

    for k in (1, 2, 3):
        again = quad_triangles(P, np.roll(quads, k, axis=1)).reshape(-1, 2, 3)
        for a, b in zip(cut, again):
            np.testing.assert_array_equal(canon(a), canon(b))
    # the winding is the quad's: both triangles face the quad's way (Newell normal) wherever
    # one of the two cuts does (not in a bow tie)
    Q = P[quads]
    newell = np.cross(Q, np.roll(Q, -1, axis=1)).sum(axis=1)

    def facing(tris):
        T = P[tris.reshape(-1, 3)]
        n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]).reshape(-1, 2, 3)
        return (np.einsum("qtj,qj->qt", n, newell) > 0).all(axis=1)

    either = facing(quads[:, [0, 1, 2, 0, 2, 3]]) | facing(quads[:, [1, 2, 3, 1, 3, 0]])
    assert 0.5 < either.mean() < 1 and facing(cut)[either].all()
    # the shorter diagonal: a flat rhombus, longer along x
    rh = np.array([[0, 0, 0], [2, -1, 0], [4, 0, 0], [2, 1, 0.0]])
    for k in range(4):
        t = quad_triangles(rh, np.roll([0, 1, 2, 3], k)[None])
        assert set(np.intersect1d(t[0], t[1]).tolist()) == {1, 3}
    # a concave quad (a dart): only the diagonal through its reflex corner stays inside
    dart = np.array([[0, 0, 0], [4, 2, 0], [1, 1, 0], [0, 4, 0.0]])  # reflex at 2
    for k in range(4):
        t = quad_triangles(dart, np.roll([0, 1, 2, 3], k)[None])
        assert set(np.intersect1d(t[0], t[1]).tolist()) == {0, 2}
    # a square: the diagonal through the corner of least coordinates (0, 0, 0)
    sq = np.array([[1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0.0]])
    for k in range(4):
        t = quad_triangles(sq, np.roll([0, 1, 2, 3], k)[None])
        assert set(np.intersect1d(t[0], t[1]).tolist()) == {1, 3}


def _canon_faces(t):
    """Triangles as a set: each from its least index (its winding kept), the list sorted."""
    t = np.array([np.roll(f, -int(np.argmin(f))) for f in t])
    return t[np.lexsort(t.T[::-1])]


def test_polygons_are_cut_by_their_best_ears_whatever_corner_they_start_at():
    """core.geometry.polygon_triangles: polygons of 5-9 corners (convex, bent out of their
    plane, concave) give the same triangles for every rotation of their corners, in their
    winding (none turned against the polygon's normal, unless the polygon crosses itself);
    quads are quad_triangles'; either winding gives the same triangles."""
    rng = np.random.default_rng(1)
    for k in range(5, 10):
        t = np.sort(rng.uniform(0, 2 * np.pi, (60, k)), axis=1)  # convex, in the xy plane
        r = rng.uniform(0.5, 1.5, (60, 1))
        P = np.stack([r * np.cos(t), r * np.sin(t), 0.1 * rng.normal(size=(60, k))], -1)
        P[:20, ::2, :2] *= 0.4  # concave stars
        P = P.reshape(-1, 3) + rng.normal(size=(60, 1, 3)).repeat(k, 1).reshape(-1, 3)
        polys = np.arange(60 * k).reshape(60, k)
        cut = polygon_triangles(P, polys).reshape(60, k - 2, 3)
        for turn in range(1, k):
            again = polygon_triangles(P, np.roll(polys, turn, axis=1)).reshape(60, k - 2, 3)
            for a, b in zip(cut, again):
                np.testing.assert_array_equal(_canon_faces(a), _canon_faces(b))
        # in the polygon's winding, none turned over: each triangle faces its Newell normal
        # (bent out of its plane, the stars' concave corners are those seen along it)
        T = P[cut]
        area = np.cross(T[:, :, 1] - T[:, :, 0], T[:, :, 2] - T[:, :, 0])  # (60, k - 2, 3)
        Q = P[polys]
        newell = np.cross(Q, np.roll(Q, -1, axis=1)).sum(axis=1)
        np.testing.assert_allclose(area.sum(axis=1), newell, atol=1e-9)  # (any triangulation)
        facing = (np.einsum("mtj,mj->mt", area, newell) > 0).all(axis=1)

        def simple(i):  # seen along its normal (a star whose gap passes pi crosses itself)
            n = newell[i] / np.linalg.norm(newell[i])
            e1 = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
            e1 /= np.linalg.norm(e1)
            return simple_polygon(np.c_[Q[i] @ e1, Q[i] @ np.cross(n, e1)])

        crossing = [i for i in range(60) if not simple(i)]
        assert len(crossing) <= 2 and facing[np.setdiff1d(np.arange(60), crossing)].all()
    # a regular octagon: its ears alike to rounding, the same cut whatever its first corner
    # (centred at its mean, summed in its corners' order, its ears had differed in their last
    # bits with the corner it started at, and so had its cut)
    a = np.arange(8) * np.pi / 4
    octagon = np.c_[np.cos(a), np.sin(a), np.zeros(8)] + [1e3, -2e3, 5.0]
    for turn in range(8):
        tris = polygon_triangles(octagon, np.roll(np.arange(8), turn)[None])
        np.testing.assert_array_equal(
            _canon_faces(tris), _canon_faces(polygon_triangles(octagon, np.arange(8)[None])))
    quads = np.arange(8).reshape(2, 4)
    np.testing.assert_array_equal(polygon_triangles(octagon, quads),
                                  quad_triangles(octagon, quads))
    # either winding, the same triangles (a 7-pointed star, concave; review: reversed, its
    # ears alike in quality had been taken in the other order)
    a7 = 2 * np.pi * np.arange(7) / 7
    star = np.c_[np.where(np.arange(7) % 2 == 0, 1.0, 0.45)[:, None]
                 * np.c_[np.cos(a7), np.sin(a7)], np.zeros(7)]
    for poly in (np.arange(7), np.arange(7)[::-1], np.r_[0, np.arange(6, 0, -1)]):
        np.testing.assert_array_equal(
            np.sort(_canon_faces(np.sort(polygon_triangles(star, poly[None]), axis=1)), axis=0),
            np.sort(_canon_faces(np.sort(polygon_triangles(star, np.arange(7)[None]), axis=1)),
                    axis=0))


def test_coordinate_order_is_the_lexicographic_order_and_takes_nan_rows_alike():
    """core.geometry.coordinate_order: the order of np.lexsort over the columns (x, then y,
    then z) for rows with and without ties in x, None for sorted rows; NaN rows go last in any
    order given (rows that looked sorted around a NaN had been taken as sorted: review)."""
    rng = np.random.default_rng(0)
    for p in (rng.random((500, 3)), rng.integers(0, 4, (500, 3)).astype(float)):
        order = coordinate_order(p)
        np.testing.assert_array_equal(p[order], p[np.lexsort(p.T[::-1])])
        assert coordinate_order(p[order]) is None
    a = np.array([[1.0, 0, 0], [np.nan, 0, 0], [0.0, 0, 0]])
    b = a[[2, 1, 0]]
    for x in (a, b):
        order = coordinate_order(x)
        assert order is not None
        np.testing.assert_array_equal(x[order][:2], [[0.0, 0, 0], [1.0, 0, 0]])


def test_coordinate_order_does_not_hang_on_the_last_bits_of_tied_coordinates():
    """A lattice's exact ties (a CAD mesh's vertices along grid lines) had been broken by the
    next column's last bits, so the same points translated by 64, scaled by 1e-3 or given
    noise of 1e-12 of their extent came in another order, and the fit drew other knots
    (patch-01.off: 636 to 731 control points; user test). On ORDER_QUANTUM's grid the order
    is the same; points farther apart than a cell keep their lexicographic order."""
    rng = np.random.default_rng(1)
    g = np.stack(np.meshgrid(np.arange(12.0), np.arange(9.0)), -1).reshape(-1, 2)
    p = np.c_[g * 0.37, np.sin(g[:, 0] * g[:, 1])][rng.permutation(len(g))]
    base = coordinate_order(p)
    moved = [p + [64.0, 0.0, 0.0], p * 1e-3, p + rng.normal(size=p.shape) * 1e-12 * 4.4]
    for q in moved:
        np.testing.assert_array_equal(coordinate_order(q), base)
    # (the tie in x, then y: the lexicographic order of the lattice)
    np.testing.assert_array_equal(p[base], p[np.lexsort(p.T[::-1])])
