"""TCB and DCB spline spaces (method.md sections 2, 3, 7): the identities that make them spline
spaces, checked on random and lattice knot sets with Delaunay and random triangulations."""

import copy
from itertools import combinations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core import (
    BorderError,
    InvalidKnotsError,
    RandomTriangulator,
    build_space,
    check_partition_of_unity,
    constrained_delaunay,
)
from core.configurations import delaunay_triangulation
from core.spatial import BoxIndex, support_bands
from knotsets import FUNCTIONS, KINDS, knot_set, polar_form


def random_flips(knots, tri, seed, movable, n_flips=200):
    """A random triangulation: Delaunay followed by random flips of strictly convex quads.

    Only quads whose four knots are ``movable`` (the interior knots) are flipped: the border
    rings keep their triangles, so the region where every link closes still covers the domain.
    """
    rng = np.random.default_rng(seed)
    tri = [list(t) for t in tri]

    def orient(a, b, c):
        (ax, ay), (bx, by), (cx, cy) = knots[a], knots[b], knots[c]
        return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)

    for _ in range(n_flips):
        owner = {}
        for ti, t in enumerate(tri):
            for e in range(3):
                owner[(t[e], t[(e + 1) % 3])] = (ti, e)
        inner = [(k, v) for k, v in owner.items() if (k[1], k[0]) in owner]
        (a, b), (ti, e) = inner[rng.integers(len(inner))]
        tj, f = owner[(b, a)]
        c, d = tri[ti][(e + 2) % 3], tri[tj][(f + 2) % 3]
        if not movable[[a, b, c, d]].all():
            continue
        if orient(c, a, d) > 0 and orient(d, b, c) > 0:  # strictly convex: flip ab -> cd
            tri[ti], tri[tj] = [c, a, d], [d, b, c]
    return np.array(tri)


@settings(max_examples=36, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(16, 70),
    kind=st.sampled_from(KINDS),
    degree=st.sampled_from([1, 2, 3]),
    gamma0=st.sampled_from(["delaunay", "random"]),
    links=st.sampled_from(["cdt", "random"]),
)
def test_partition_of_unity_and_blossom_reproduction(seed, n, kind, degree, gamma0, links):
    knots = knot_set(kind, n, degree, seed)
    tri = None
    if gamma0 == "random":
        inner = ((knots >= 0) & (knots <= 1)).all(axis=1)
        tri = random_flips(knots, delaunay_triangulation(knots), seed, inner)
    lt = RandomTriangulator(seed) if links == "random" else None
    space = build_space(knots, degree, triangulation=tri, link_triangulator=lt)
    x = np.random.default_rng(seed + 1).random((3000, 2))
    A = space.evaluate(x)
    assert A.shape == (3000, space.n_basis)
    assert A.min() >= -1e-14  # nonnegative
    np.testing.assert_allclose(np.asarray(A.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-12)
    I = knots[space.interior_sets]
    for name in ["u", "v"] + (["uv", "uu"] if degree >= 2 else []):
        got = A @ polar_form(name, I)
        np.testing.assert_allclose(got, FUNCTIONS[name](x), rtol=0, atol=1e-12, err_msg=name)
    np.testing.assert_allclose(A @ space.greville, x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", ["tcb", "dcb"])
@pytest.mark.parametrize("degree", [2, 3])
def test_derivatives_match_central_differences(mode, degree):
    knots = knot_set("random", 60, degree, seed=degree)
    space = build_space(knots, degree, mode=mode)
    x = np.random.default_rng(7).uniform(0.05, 0.95, (400, 2))
    steps = {0: np.array([1.0, 0.0]), 1: np.array([0.0, 1.0])}

    def check(der, fd):
        D = space.evaluate(x, der).toarray()
        err = np.abs(D - fd).max(axis=1)
        scale = np.abs(D).max()
        assert scale > 0
        # a stencil that straddles a knot line sees the jump of a higher derivative; those
        # rows are rare (measure ~ h), every other row must agree to 1e-6 relative
        frac_bad = np.mean(err > 1e-6 * scale)
        assert frac_bad <= 0.01, (der, frac_bad, err.max() / scale)

    h = 1e-7
    for axis, der in [(0, (1, 0)), (1, (0, 1))]:
        w = steps[axis] * h
        fd = (space.evaluate(x + w).toarray() - space.evaluate(x - w).toarray()) / (2 * h)
        check(der, fd)
    h = 1e-6
    for first, axis, der in [((1, 0), 0, (2, 0)), ((1, 0), 1, (1, 1)), ((0, 1), 1, (0, 2))]:
        w = steps[axis] * h
        fd = (space.evaluate(x + w, first).toarray() - space.evaluate(x - w, first).toarray()) / (2 * h)
        check(der, fd)


@pytest.mark.parametrize("mode", ["tcb", "dcb"])
def test_combine_is_the_product_of_the_basis_with_the_coefficients(mode):
    """``combine`` (the surface and its derivatives without the sparse matrices, for closest
    points) equals ``evaluate(x, d) @ c`` to rounding, for one or several columns and for
    points outside every support (0 there), in more blocks than one."""
    space = build_space(knot_set("random", 80, 2, seed=3), 2, mode=mode)
    rng = np.random.default_rng(8)
    x = np.vstack([rng.uniform(-0.1, 1.1, (9000, 2)), [[5.0, 5.0]]])
    ders = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1)]
    for c in (rng.normal(size=(space.n_basis, 3)), rng.normal(size=space.n_basis)):
        got = space.combine(x, c, ders)
        for d, g in zip(ders, got):
            want = space.evaluate(x, d) @ c
            assert g.shape == want.shape
            np.testing.assert_allclose(g, want, rtol=0, atol=1e-12 * np.abs(want).max())
        assert np.all(got[0][-1] == 0)  # (far outside: no function there)
    assert [g.shape for g in space.combine(np.zeros((0, 2)), c, ders[:2])] == [(0,), (0,)]
    with pytest.raises(ValueError, match="rows"):
        space.combine(x, c[:-1])


@pytest.mark.parametrize("degree", [2, 3])
@pytest.mark.parametrize("kind", ["random", "hex"])
def test_last_level_link_triangulation_does_not_change_tcb_basis(degree, kind):
    knots = knot_set(kind, 50, degree, seed=11)
    ref = build_space(knots, degree)
    other = build_space(
        knots, degree, link_triangulator=RandomTriangulator(5, levels={degree}, fallback=constrained_delaunay)
    )
    # the configurations differ, the functions do not
    T_ref = {tuple(sorted(t)) for t in ref.config_triangles.tolist()}
    T_other = {tuple(sorted(t)) for t in other.config_triangles.tolist()}
    assert T_ref != T_other
    np.testing.assert_array_equal(ref.interior_sets, other.interior_sets)
    x = np.random.default_rng(3).random((3000, 2))
    diff = (ref.evaluate(x) - other.evaluate(x)).toarray()
    assert np.abs(diff).max() < 1e-12


def brute_force_delaunay_configurations(knots, degree):
    """All (T, I): open circumdisk of T holds exactly the knots I, |I| = degree (Neamtu)."""
    out = set()
    for t in combinations(range(len(knots)), 3):
        a, b, c = knots[list(t)]
        d = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if abs(d) < 1e-14:
            continue
        # circumcenter
        A = 2 * np.array([b - a, c - a])
        rhs = np.array([b @ b - a @ a, c @ c - a @ a])
        center = np.linalg.solve(A, rhs)
        r2 = (a - center) @ (a - center)
        dist = ((knots - center) ** 2).sum(axis=1)
        inside = [i for i in np.flatnonzero(dist < r2 * (1 - 1e-12)) if i not in t]
        if len(inside) == degree:
            out.add((t, tuple(sorted(int(i) for i in inside))))
    return out


@pytest.mark.parametrize("degree", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dcb_from_link_procedure_equals_brute_force_delaunay_configurations(degree, seed):
    knots = np.random.default_rng(100 + seed).random((35, 2))
    space = build_space(knots, degree, mode="dcb")
    ltp = {
        (tuple(sorted(t)), tuple(i))
        for t, i in zip(space.config_triangles.tolist(), space.config_interior.tolist())
    }
    brute = brute_force_delaunay_configurations(knots, degree)
    assert ltp <= brute
    # away from the hull (where the LTP basis sums to one) every Delaunay configuration whose
    # support holds a sample point is found by the link procedure
    x = np.random.default_rng(seed).random((4000, 2))
    ok = check_partition_of_unity(space, x, tol=1e-12).bad == False  # noqa: E712
    assert ok.sum() > 100
    xs = x[ok]
    from core.simplex import SimplexBatch

    missing = sorted(brute - ltp)
    if missing:
        sets = np.array([list(t) + list(i) for t, i in missing])
        batch = SimplexBatch(knots, sets)
        pi = np.repeat(np.arange(len(xs)), len(sets))
        ci = np.tile(np.arange(len(sets)), len(xs))
        # (a cubic is ~1e-15 just inside the edge of its support: that is not a missing function)
        touched = batch.evaluate(xs[pi], ci) > 1e-10
        assert not touched.any(), "a Delaunay configuration is missing in the interior"


def test_quadratic_basis_is_c1_across_knot_lines():
    knots = knot_set("random", 40, 2, seed=4)
    space = build_space(knots, 2)
    rng = np.random.default_rng(4)
    # points on knot lines: segments between two knots of a configuration, inside the domain
    V = np.concatenate([space.config_triangles, space.config_interior], axis=1)
    pick = rng.integers(len(V), size=3000)
    ij = np.array([rng.choice(4, 2, replace=False) for _ in range(len(pick))])
    p, q = knots[V[pick, ij[:, 0]]], knots[V[pick, ij[:, 1]]]
    x = p + rng.uniform(0.05, 0.95, (len(pick), 1)) * (q - p)
    keep = ((x > 0.02) & (x < 0.98)).all(axis=1)
    x, p, q = x[keep], p[keep], q[keep]
    n = np.stack([-(q - p)[:, 1], (q - p)[:, 0]], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    delta = 1e-9
    jumps, scale = [], 0.0
    for der in [(1, 0), (0, 1)]:
        plus, minus = space.evaluate(x + delta * n, der), space.evaluate(x - delta * n, der)
        jumps.append(np.abs((plus - minus).toarray()).max())
        scale = max(scale, np.abs(plus.toarray()).max())
    # the second derivatives jump across these lines (piecewise quadratic) ...
    second = space.evaluate(x + delta * n, (2, 0)) - space.evaluate(x - delta * n, (2, 0))
    assert np.abs(second.toarray()).max() > 1e-3
    # ... but the gradient is continuous
    assert max(jumps) < 1e-6 * scale


@pytest.mark.parametrize("degree", [1, 2, 3])
@pytest.mark.parametrize("kind", KINDS)
def test_control_net_faces_are_positive_and_tile_the_interior_once(degree, kind):
    knots = knot_set(kind, 49, degree, seed=21)
    space = build_space(knots, degree)
    F = space.net_faces
    assert len(F) > 0 and F.min() >= 0 and F.max() < space.n_basis
    a, b, c = (space.greville[F[:, j]] for j in range(3))
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (area > 0).all()
    x = np.random.default_rng(degree).uniform(0.1, 0.9, (2000, 2))
    counts = np.zeros(len(x), dtype=int)
    for s in range(0, len(F), 500):
        aa, bb, cc = a[s : s + 500, None], b[s : s + 500, None], c[s : s + 500, None]

        def orient(p, q, r):
            return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

        inside = (orient(aa, bb, x) > 0) & (orient(bb, cc, x) > 0) & (orient(cc, aa, x) > 0)
        counts += inside.sum(axis=0)
    assert (counts == 1).all(), np.bincount(counts)


def test_dcb_has_one_function_per_configuration_and_more_than_tcb():
    knots = knot_set("random", 40, 2, seed=8)
    tcb, dcb = build_space(knots, 2), build_space(knots, 2, mode="dcb")
    assert dcb.n_basis == dcb.n_configurations
    assert tcb.n_basis < dcb.n_basis
    assert len(dcb.net_faces) == 0


@pytest.mark.parametrize(
    "knots, words",
    [
        (np.array([[0.0, 0.0], [1.0, 0.0]]), "at least 3"),
        (np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]), "collinear"),
        (np.array([[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0], [0.0, 1.0]]), "NaN"),
        (np.array([[0.0, 0.0], [1.0, 0.0], [np.inf, 1.0], [0.0, 1.0]]), "NaN or infinite"),
        (np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]), "coincide"),
        (np.zeros((5, 3)), "(n, 2)"),
    ],
)
def test_degenerate_knots_raise_a_clear_value_error(knots, words):
    with pytest.raises(InvalidKnotsError, match=words.replace("(", r"\(").replace(")", r"\)")) as info:
        build_space(knots, 2)
    assert isinstance(info.value, ValueError)


def test_bad_degree_and_mode_raise():
    knots = knot_set("random", 20, 2, seed=0)
    with pytest.raises(ValueError, match="degree"):
        build_space(knots, 5)
    with pytest.raises(ValueError, match="mode"):
        build_space(knots, 2, mode="nurbs")
    with pytest.raises(ValueError, match="dcb"):
        build_space(knots, 2, mode="dcb", link_triangulator=RandomTriangulator(0))


def test_border_check_reports_where_the_basis_fails_to_sum_to_one():
    # one ring is too thin for quadratics (method.md section 3): the check must say so
    thin = build_space(knot_set("random", 60, 2, seed=2, rings=1), 2)
    x = np.random.default_rng(0).random((4000, 2))
    report = check_partition_of_unity(thin, x)
    assert not report.ok and report.bad.sum() > 0 and report.max_deviation > 1e-3
    with pytest.raises(BorderError, match="border rings"):
        check_partition_of_unity(thin, x, raise_error=True)
    assert check_partition_of_unity(build_space(knot_set("random", 60, 2, seed=2), 2), x).ok


def test_spatial_index_finds_exactly_the_points_in_each_box():
    rng = np.random.default_rng(0)
    lo = rng.random((300, 2))
    boxes = np.concatenate([lo, lo + rng.uniform(0.01, 0.2, (300, 2))], axis=1)
    pts = rng.uniform(-0.1, 1.3, (2000, 2))
    got = set()
    for p, b in BoxIndex(boxes).pairs(pts, max_pairs=1000):
        got.update(zip(p.tolist(), b.tolist()))
    inside = (
        (boxes[None, :, 0] <= pts[:, None, 0]) & (pts[:, None, 0] <= boxes[None, :, 2])
        & (boxes[None, :, 1] <= pts[:, None, 1]) & (pts[:, None, 1] <= boxes[None, :, 3])
    )
    assert got == set(zip(*np.nonzero(inside)))


@pytest.mark.parametrize("fraction", [0.1, 0.25, 0.5])
def test_spatial_index_with_diagonal_bands_finds_exactly_the_points_in_each_octagon(fraction):
    # the band registers a box only in the cells that meet its octagon: no pair inside box
    # and band may be lost, none outside returned
    rng = np.random.default_rng(1)
    sets = rng.random((300, 1, 2)) + rng.uniform(-0.1, 0.1, (300, 5, 2))
    boxes = np.concatenate([sets.min(axis=1), sets.max(axis=1)], axis=1)
    bands = support_bands(sets)
    pts = np.vstack([rng.uniform(-0.2, 1.2, (3000, 2)), sets.reshape(-1, 2)])  # and the corners
    got = set()
    for p, b in BoxIndex(boxes, diagonals=bands, cell_fraction=fraction).pairs(pts, max_pairs=999):
        got.update(zip(p.tolist(), b.tolist()))
    s, d = pts[:, 0] + pts[:, 1], pts[:, 0] - pts[:, 1]
    inside = (
        (boxes[None, :, 0] <= pts[:, None, 0]) & (pts[:, None, 0] <= boxes[None, :, 2])
        & (boxes[None, :, 1] <= pts[:, None, 1]) & (pts[:, None, 1] <= boxes[None, :, 3])
        & (bands[None, :, 0] <= s[:, None]) & (s[:, None] <= bands[None, :, 1])
        & (bands[None, :, 2] <= d[:, None]) & (d[:, None] <= bands[None, :, 3])
    )
    assert got == set(zip(*np.nonzero(inside)))
    # every set's own points are in its octagon
    own = np.arange(3000, len(pts)).reshape(300, 5)
    assert all((q, b) in got for b in range(300) for q in own[b])


@pytest.mark.parametrize("degree", [2, 3])
def test_the_support_index_gives_the_same_basis_bits_as_the_plain_box_index(degree):
    # the octagons only leave out pairs outside the supports (all zero): the basis and its
    # derivatives are the same bits, also on knot lines and at the knots
    space = build_space(knot_set("square", 40, degree, seed=3), degree)
    assert space._index._bands is not None  # (the octagons are in use)
    plain = copy.copy(space)
    plain._index = BoxIndex(space._batch.bbox)
    k = np.asarray(space.knots)
    rng = np.random.default_rng(4)
    i, j = rng.integers(0, len(k), (2, 4000))
    x = np.vstack([rng.uniform(k.min(axis=0), k.max(axis=0), (4000, 2)), k,
                   k[i] + rng.random((4000, 1)) * (k[j] - k[i])])
    for der in [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]:
        a, b = space.evaluate(x, der), plain.evaluate(x, der)
        assert a.nnz == b.nnz and a.nnz > 0
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert np.array_equal(a.data, b.data)


def test_point_boxes_with_bands_keep_their_cell():
    # every box a point: the grid step falls to 1e-300 (the bands' bounds had overflowed the
    # integer cast and the box got no cell; review)
    sets = np.array([[[1.0, 1.0]] * 5, [[2.0, 3.0]] * 5])
    boxes = np.concatenate([sets.min(axis=1), sets.max(axis=1)], axis=1)
    got = [(p.tolist(), b.tolist()) for p, b in
           BoxIndex(boxes, diagonals=support_bands(sets)).pairs(np.array([[1.0, 1.0], [2.0, 3.0]]))]
    assert sorted(zip(got[0][0], got[0][1])) == [(0, 0), (1, 1)]
    with pytest.raises(ValueError, match="2 diagonal bands for 1 boxes"):
        BoxIndex(boxes[:1], diagonals=support_bands(sets))
