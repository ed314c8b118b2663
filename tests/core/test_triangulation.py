"""Feature-sensitive configurations (core/triangulation.py, method.md section 2.4)."""

import numpy as np
import pytest

from core.border import border_rings
from core.configurations import constrained_delaunay, delaunay_triangulation
from core.refine import make_space
from core.simplex import orient2d
from core.triangulation import (
    FeatureLinkTriangulator,
    PlaneFitCost,
    constrained_delaunay_many,
    feature_triangulation,
    _line_forms,
    _link_sides,
    grouped_plane_costs,
)
from knotsets import FUNCTIONS, polar_form


def star_polygons(count, m, seed):
    """Random simple CCW polygons, star-shaped around the origin, non-convex in general."""
    rng = np.random.default_rng(seed)
    # jittered even angles: every gap is below pi, so the origin sees the whole polygon
    ang = (np.arange(m) + 0.8 * rng.random((count, m))) * (2 * np.pi / m)
    rad = 0.3 + rng.random((count, m))
    return np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=-1)


def tri_set(tris):
    return sorted(tuple(sorted(t)) for t in tris)


@pytest.mark.parametrize("m", [4, 5, 7, 10])
def test_batched_constrained_delaunay_equals_the_per_polygon_one(m):
    P = star_polygons(60, m, seed=m)
    knots = P.reshape(-1, 2)
    poly = np.arange(len(knots)).reshape(-1, m)
    got = constrained_delaunay_many(poly, knots)
    for row, tris in zip(poly, got):
        assert tris is not None
        assert tri_set(tris) == tri_set(constrained_delaunay(tuple(row), knots))


@pytest.mark.parametrize("quadratic", [False, True])
def test_grouped_fit_residuals_match_a_least_squares_solve_per_group(quadratic):
    rng = np.random.default_rng(0)
    x = rng.random((4000, 2)) * 3 + 5  # off-centre, so centring matters
    p = np.c_[x, np.sin(3 * x[:, 0]) + x[:, 1] ** 2] + 0.01 * rng.standard_normal((4000, 3))
    g = rng.integers(0, 40, 4000)
    g[g == 7] = 8  # an empty group costs 0
    g[np.flatnonzero(g == 9)[3:]] = 10  # 3 points: 0
    g[np.flatnonzero(g == 11)[5:]] = 12  # 5 points: the affine residual even when quadratic
    got = grouped_plane_costs(x, p, g, 40, quadratic=quadratic)
    for k in range(40):
        xx = x[g == k]
        A = np.c_[xx, np.ones(len(xx))]
        if quadratic and len(xx) > 6:
            A = np.c_[A, xx[:, 0] ** 2, xx[:, 0] * xx[:, 1], xx[:, 1] ** 2]
        ref = 0.0
        if len(xx) > 3:
            c = np.linalg.lstsq(A, p[g == k], rcond=None)[0]
            ref = ((A @ c - p[g == k]) ** 2).sum()
        assert abs(got[k] - ref) <= 1e-8 * max(ref, 1.0)
    assert got[7] == got[9] == 0 and got[11] > 0


@pytest.mark.parametrize("apex", [(2.0, 3.0), (2.0, 1.6)])
def test_a_diagonal_on_the_line_of_a_distant_edge_is_admissible(apex):
    """A crown whose diagonal (1,1)-(3,1) lies on the line of the edge (6,1)-(5,1) it does not
    touch: the diagonal is inside the polygon, so the batched CDT must find the same
    triangulation as the per-polygon one (it used to treat the two as crossing)."""
    knots = np.array([(0, 0), (7, 0), (7, 3), (6, 1), (5, 1), (4, 3), (3, 1), apex, (1, 1), (0, 3)],
                     dtype=float)
    poly = np.arange(10)[None]
    got = constrained_delaunay_many(poly, knots)[0]
    assert got is not None
    assert tri_set(got) == tri_set(constrained_delaunay(tuple(range(10)), knots))


@pytest.mark.parametrize("quadratic", [False, True])
def test_fit_residuals_do_not_depend_on_the_units_of_the_parameters(quadratic):
    """Scaling u, v by s changes no residual (the columns are scaled per group): small groups
    of a smooth function, where a ridge on unscaled columns had biased the quadratic fit."""
    rng = np.random.default_rng(1)
    g = np.repeat(np.arange(200), 20)
    x = rng.random((200, 2))[g] + 0.03 * rng.random((4000, 2))
    p = np.c_[x, np.sin(3 * x[:, 0]) * np.cos(2 * x[:, 1])]
    ref = grouped_plane_costs(x, p, g, 200, quadratic)
    for s in (0.01, 100.0):
        got = grouped_plane_costs(s * x, p, g, 200, quadratic)
        np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-12 * ref.max())


def test_link_procedure_refuses_a_batch_with_missing_links():
    from core.configurations import link_triangulation_procedure

    class Short:
        def __call__(self, polygon, knots, J=(), level=0):
            return constrained_delaunay(polygon, knots, J, level)

        def triangulate_many(self, polygons, knots, Js, level=0):
            return [self(p, knots, J, level) for p, J in zip(polygons, Js)][:-1]

    knots = np.random.default_rng(3).random((30, 2))
    with pytest.raises(ValueError, match="triangulations for"):
        link_triangulation_procedure(knots, 2, link_triangulator=Short())


def crease_data(n=6000, seed=0):
    rng = np.random.default_rng(seed)
    uv = rng.random((n, 2))
    return uv, np.c_[uv, 0.25 * np.abs(uv[:, 1] - 0.3 - 0.4 * uv[:, 0])]


def total_cost(cost, knots, tris, quadratic=False):
    """Sum over triangles of the affine (or quadratic) fit residual of the data inside."""
    T = knots[np.asarray(tris)]
    t = np.repeat(np.arange(len(T)), len(cost.uv))
    j = np.tile(np.arange(len(cost.uv)), len(T))
    a, b, c, x = T[t, 0], T[t, 1], T[t, 2], cost.uv[j]
    inside = (orient2d(a, b, x) >= 0) & (orient2d(b, c, x) >= 0) & (orient2d(c, a, x) >= 0)
    return grouped_plane_costs(x[inside], cost.points[j[inside]], t[inside], len(T), quadratic).sum()


def test_gamma0_flips_lower_the_plane_fit_cost_and_keep_a_triangulation():
    uv, P = crease_data()
    rng = np.random.default_rng(1)
    knots = np.r_[rng.random((60, 2)) * 0.96 + 0.02, border_rings([0, 0], [1, 1], 0.13, rings=2)]
    movable = np.arange(len(knots)) < 60
    cost = PlaneFitCost(uv, P)
    dt = delaunay_triangulation(knots)
    ft = feature_triangulation(knots, cost, movable=movable)
    assert len(ft) == len(dt)
    a, b, c = (knots[ft[:, j]] for j in range(3))
    det = orient2d(a, b, c)
    assert (det > 0).all()
    # same area: still a triangulation of the convex hull
    assert np.isclose(det.sum(), orient2d(*(knots[dt[:, j]] for j in range(3))).sum())
    assert total_cost(cost, knots, ft) < 0.9 * total_cost(cost, knots, dt)


def test_link_dp_is_never_costlier_than_constrained_delaunay():
    uv, P = crease_data()
    rng = np.random.default_rng(2)
    knots = rng.random((80, 2))
    cost = PlaneFitCost(uv, P)
    tri = delaunay_triangulation(knots)
    lt = FeatureLinkTriangulator(cost, degree=2)
    # level-1 links: the one-rings of the interior knots
    polys, Js = [], []
    for v in range(len(knots)):
        star = tri[(tri == v).any(axis=1)]
        nxt = {}
        for t in star.tolist():
            i = t.index(v)
            nxt[t[(i + 1) % 3]] = t[(i + 2) % 3]
        start = next(iter(nxt))
        ring = [start]
        while nxt.get(ring[-1]) not in (None, start):
            ring.append(nxt[ring[-1]])
        if nxt.get(ring[-1]) == start and len(ring) >= 4:
            polys.append(tuple(ring))
            Js.append((v,))
    assert len(polys) > 30
    dp = lt.triangulate_many(polys, knots, Js, level=1)
    assert lt.optimized > 0
    worse = differ = 0
    for poly, J, tris in zip(polys, Js, dp):
        assert len(tris) == len(poly) - 2
        cdt = constrained_delaunay(poly, knots, J, 1)
        differ += tri_set(tris) != tri_set(cdt)
        worse += total_cost(cost, knots, tris, True) > total_cost(cost, knots, cdt, True) * (1 + 1e-9) + 1e-12
    assert worse == 0
    assert differ >= 5  # the data made real choices


@pytest.mark.parametrize("degree", [2, 3])
def test_feature_sensitive_space_is_a_partition_of_unity_and_reproduces_polynomials(degree):
    uv, P = crease_data(seed=degree)
    rng = np.random.default_rng(degree)
    inner = rng.random((50, 2)) * 0.96 + 0.02
    knots = np.r_[inner, border_rings([0, 0], [1, 1], 0.14, rings=degree, seed=degree)]
    space = make_space(knots, degree, "tcb", PlaneFitCost(uv, P), len(inner))
    x = np.random.default_rng(7).random((3000, 2))
    A = space.evaluate(x)
    assert A.min() >= -1e-14
    np.testing.assert_allclose(np.asarray(A.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-12)
    I = knots[space.interior_sets]
    for name in ["u", "v", "uv", "uu"]:
        np.testing.assert_allclose(A @ polar_form(name, I), FUNCTIONS[name](x), rtol=0, atol=1e-11)


def test_link_side_tests_agree_with_the_orientation_predicate():
    """The link DP's side tests from line forms have the sign of ``orient2d`` and are exactly 0
    at both ends of every line (a data point on a knot belongs to its closed triangles; the
    form alone is not exact at the second end: 35% of random segments)."""
    rng = np.random.default_rng(11)
    L, m = 300, 6
    P = rng.random((L, m, 2)) * 10 ** rng.uniform(-4, 2, (L, 1, 1)) + rng.normal(0, 100, (L, 1, 2))
    ii, jj = np.triu_indices(m, 1)
    forms = _line_forms(P, ii, jj)
    link = np.repeat(np.arange(L), m + 20)
    x = np.concatenate([np.concatenate([P[l], P[l].min(0) + rng.random((20, 2)) * np.ptp(P[l], 0)])
                        for l in range(L)])
    side = _link_sides(P, forms, ii, jj, link, x)
    ref = orient2d(P[link][:, ii], P[link][:, jj], x[:, None, :])
    at_vertex = np.tile(np.r_[np.ones(m, bool), np.zeros(20, bool)], L)
    vertex_pairs = np.zeros((len(x), len(ii)), bool)
    k = np.tile(np.r_[np.arange(m), np.full(20, -1)], L)
    vertex_pairs[at_vertex] = (ii[None] == k[at_vertex, None]) | (jj[None] == k[at_vertex, None])
    assert np.all(side[vertex_pairs] == 0.0) and np.all(ref[vertex_pairs] == 0.0)
    scale = np.abs(ref).max(axis=1, keepdims=True)
    clear = ~vertex_pairs & (np.abs(ref) > 1e-9 * scale)
    assert np.array_equal(np.sign(side[clear]), np.sign(ref[clear]))
