"""The default surface mesh is faithful to the spline: a long or ragged domain gets as many grid
cells as a half-filled square (core.surface.tessellation_step), a square or disk domain as
before; a fine tessellation reports its progress and can be stopped."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from core import fit_surface
from core.surface import TESSELLATION_FULL_SHARE, grid_frame, tessellation_fill


def crescent():
    """A half ring of quads 0.4 wide and 3.8 long, waved along it (benchmarks/
    tessellation_fidelity.py's half_ring): its map keeps its own boundary, which fills 0.15 of
    the square on its longer side (a Suzanne brow patch: 0.26)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from tessellation_fidelity import half_ring

    return half_ring()


def mesh_at(uv, tri, verts, x):
    """The piecewise-linear mesh (``verts`` over the parameter triangles ``uv[tri]``) at the
    parameters ``x`` (m, 2): NaN rows where no triangle holds one."""
    out = np.full((len(x), 3), np.nan)
    a, b, c = (uv[tri[:, k]] for k in range(3))
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    for i, p in enumerate(x):
        l1 = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (p[1] - a[:, 1]) * (c[:, 0] - a[:, 0])) / det
        l2 = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[0] - a[:, 0])) / det
        hit = np.flatnonzero((l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9))
        if len(hit):
            k = hit[0]
            out[i] = ((1 - l1[k] - l2[k]) * verts[tri[k, 0]] + l1[k] * verts[tri[k, 1]]
                      + l2[k] * verts[tri[k, 2]])
    return out


@pytest.fixture(scope="module")
def long_patch():
    points, faces = crescent()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (a swing at one place)
        return fit_surface(points, faces)


def test_a_long_curved_patch_is_displayed_within_a_fraction_of_the_fit_error(long_patch):
    """At the default resolution 64 the grid's steps spanned the half ring's 2.8-long box, and
    its 0.4 width held 773 vertices: the displayed mesh was 0.24 of the fit's largest error
    from the spline at the data's parameters (a Suzanne brow patch, user test: 6.5e-3 of the
    diagonal for a fit of 3.3e-3). Now the patch holds about half of 64^2 grid cells (2290
    vertices) and the mesh stays within 0.15 of the fit error."""
    surf = long_patch
    fill = tessellation_fill(surf.parameterization)
    assert fill < 0.7  # (the case: the domain fills well under half its square)
    uv, tri = surf.tessellation_uv(64)
    assert 0.4 * 64**2 <= len(uv) <= 0.8 * 64**2, len(uv)
    x = surf.parameterization.uv
    gap = np.linalg.norm(mesh_at(uv, tri, surf(uv), x) - surf(x), axis=1)
    assert np.isfinite(gap).all()
    assert gap.max() < 0.15 * np.nanmax(surf.errors), (gap.max(), np.nanmax(surf.errors))


def test_square_and_disk_domains_keep_their_vertex_counts(nefertiti_fit):
    """The finer step is for domains filling under TESSELLATION_FULL_SHARE of their square: a
    square cloud (0.88 of its square) and nefertiti's map (0.71) keep ``side / resolution`` and
    their vertex counts (3838 and 3070 at resolution 64; a guard: as before this change)."""
    g = np.linspace(0, 1, 40)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    square = fit_surface(np.c_[x, y, 0.2 * np.sin(3 * x) * np.cos(2 * y)])
    for surf, low, high in ((square, 3700, 4300), (nefertiti_fit, 2900, 3300)):
        assert tessellation_fill(surf.parameterization) == 1.0
        _, lo, hi = grid_frame(surf.parameterization)
        poly = surf.parameterization.domain_polygon
        area = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1))
                         - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
        assert area >= TESSELLATION_FULL_SHARE * np.max(hi - lo) ** 2
        assert low <= len(surf.tessellation_uv(64)[0]) <= high


@pytest.fixture(scope="module")
def nefertiti_fit():
    from core.meshio import read_geometry

    points, faces = read_geometry(Path(__file__).parents[2] / "data" / "nefertiti.off")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (a swing at one place)
        return fit_surface(points, faces)


def test_tessellate_reports_its_chunks_and_stops_when_asked(long_patch, monkeypatch):
    """``tessellate(resolution, callback)`` evaluates the vertices by chunks, telling the
    callback of each (Re-tessellate's progress: 2048 is 3 million vertices), with the values
    of ``surf(uv)`` to rounding; a callback returning True stops it (Esc)."""
    import core.surface
    from core import CancelledError

    monkeypatch.setattr(core.surface, "CLOSEST_CHUNK", 500)
    heard = []
    verts, tris = long_patch.tessellate(64, callback=lambda r: heard.append(dict(r)) and False)
    uv, tri = long_patch.tessellation_uv(64)
    # first the grid's steps (when it is not cached), then the vertices' chunks
    grid = [r for r in heard if "grid_step" in r]
    if grid:
        assert heard[: len(grid)] == grid
        assert [r["grid_step"] for r in grid] == list(range(1, len(grid) + 1))
        assert 3 <= len(grid) <= grid[0]["grid_steps"] == core.surface.TESSELLATION_SPLITS + 3
        heard = heard[len(grid):]
    assert [r["points_done"] for r in heard] == list(range(500, len(uv), 500)) + [len(uv)]
    assert all(r["points"] == len(uv) for r in heard)
    np.testing.assert_array_equal(tris, tri)
    np.testing.assert_allclose(verts, long_patch(uv), rtol=0, atol=1e-12)
    # outside where the basis sums to 1: NaN rows, as surf(uv) gives
    far = np.vstack([uv[:3], uv.max(axis=0) + 10.0])
    np.testing.assert_array_equal(np.isnan(long_patch._points(far)[0]),
                                  np.isnan(long_patch(far)))
    # with the evaluation matrix of the vertices (a live net's weights), from the same chunks
    heard.clear()
    v2, t2, M = long_patch.tessellate_with_matrix(64, callback=lambda r: heard.append(r) and False)
    assert len(heard) == -(-len(uv) // 500)
    np.testing.assert_allclose(v2, verts, rtol=0, atol=1e-12)  # (the same NaN rows)
    np.testing.assert_array_equal(t2, tri)
    assert (M != long_patch.evaluation_matrix(uv)).nnz == 0
    inside = ~np.isnan(verts).any(axis=1)
    np.testing.assert_allclose(M[inside] @ long_patch.control_points, verts[inside], atol=1e-12)
    calls = []
    with pytest.raises(CancelledError):
        long_patch.tessellate(64, callback=lambda r: calls.append(r) or len(calls) == 2)
    assert len(calls) == 2


def test_a_tessellation_can_be_stopped_while_its_grid_is_laid_out(long_patch):
    """Resolution 2048 takes 6-8 s to lay out its grid before the first vertex is evaluated
    (user test: Esc in Re-tessellate was not heard for 8 s): the callback hears each of the
    grid's steps and True stops it there, leaving nothing half made (the next call lays the
    grid out in full); a callback answering neither True nor False is refused."""
    from core import CancelledError, InvalidInputError

    for stop_at in (1, 2, 3):
        calls = []
        with pytest.raises(CancelledError):
            long_patch.tessellate(57, callback=lambda r: calls.append(r) or len(calls) == stop_at)
        assert [r["grid_step"] for r in calls] == list(range(1, stop_at + 1))
    heard = []
    uv, tri = long_patch.tessellation_uv(57, callback=lambda r: heard.append(r))
    assert [r["grid_step"] for r in heard][:3] == [1, 2, 3]
    # the same grid as a copy of the surface that was never stopped lays out
    fresh = type(long_patch).from_bytes(long_patch.to_bytes()).tessellation_uv(57)
    np.testing.assert_array_equal(uv, fresh[0])
    np.testing.assert_array_equal(tri, fresh[1])
    with pytest.raises(InvalidInputError, match="callback must return"):
        long_patch.tessellation_uv(59, callback=lambda r: "no")


def test_the_tessellation_sag_falls_with_the_resolution_and_auto_resolution_meets_the_fit():
    """TCBSurface.tessellation_sag: the distance between the spline and the flat triangles at
    their edges' midpoints; 0 (to rounding) for a plane, falling with the
    resolution (quadratic pieces: 4x per doubling where the grid resolves the net). A tight fit
    strays from its mesh at the default 64 by more than from its data (user test): Auto
    Resolution takes the coarsest of AUTO_RESOLUTIONS within the fit's max error."""
    from core.surface import AUTO_RESOLUTIONS

    q = np.random.default_rng(0).random((6000, 2))
    plane = fit_surface(np.c_[q, 0.3 * q[:, 0] - 0.2 * q[:, 1]], tolerance=1e-3)
    assert plane.tessellation_sag(64) < 1e-12 and plane.auto_resolution()[0] == 64
    waves = fit_surface(np.c_[q, 0.25 * np.sin(10 * q[:, 0]) * np.cos(8 * q[:, 1])],
                        tolerance=2e-4, max_control_points=1500)
    sags = [waves.tessellation_sag(r) for r in (64, 512)]
    # (not 4x per doubling throughout: 2.6e-3, 9.7e-4, 1.07e-3, 3.8e-4 of all triangles, the
    # largest near the domain's border)
    assert sags[0] > 4 * sags[1]
    assert sags[0] > waves.report["max"]  # (the user test's case: the mesh the worse)
    resolution, sag = waves.auto_resolution()
    k = AUTO_RESOLUTIONS.index(resolution)
    assert k > 0 and sag <= waves.report["max"] < waves.tessellation_sag(AUTO_RESOLUTIONS[k - 1])
    # the midpoint sag measures the mesh: a dense probe of its triangles finds about as much,
    # and no more than 1.4x of it (the largest gap of a quadratic over a triangle is at most
    # 4/3 of its largest at the edges' midpoints)
    uv, tri = waves.tessellation_uv(64)
    w = np.random.default_rng(1).dirichlet(np.ones(3), size=(len(tri), 8))  # (t, 8, 3)
    at = np.einsum("tsk,tkj->tsj", w, uv[tri]).reshape(-1, 2)
    flat = np.einsum("tsk,tkj->tsj", w, waves(uv)[tri]).reshape(-1, 3)
    probe = np.nanmax(np.linalg.norm(waves(at) - flat, axis=1))
    assert 0.7 * sags[0] <= probe <= 1.4 * sags[0]


def test_auto_resolution_rejects_on_a_sample_and_hands_its_vertices_to_tessellate(nefertiti_fit,
                                                                                   monkeypatch):
    """auto_resolution passes over a candidate as soon as the edges of every
    SAG_SAMPLE_STRIDE-th triangle stray by more than the target, measures the rest only when
    none does, and keeps the spline at the chosen mesh's vertices for the next tessellate: the
    same resolution, the same sag (bits), the same mesh as a fresh copy of the surface that
    measures every candidate's whole sag in one pass and evaluates its mesh anew; a candidate
    passed over has its whole sag when asked for. When the finest strays, the sag at half of
    it (the advice's) is measured too, from the finest's values where the parameters are the
    same (nefertiti: all but a few percent of 128's)."""
    import core.surface
    from core.surface import AUTO_RESOLUTIONS

    data = nefertiti_fit.to_bytes()

    def fresh():
        return type(nefertiti_fit).from_bytes(data)

    ref = fresh()
    full = {r: ref.tessellation_sag(r) for r in AUTO_RESOLUTIONS}  # (one pass each)
    assert full[64] > full[128] > full[256] > 0
    # 64 within; 64 out by a few edges (the sample misses them: the rest measured too); 64 and
    # 128 out by many (rejected on their samples); all out (the finest, whole)
    mesh = {}  # resolution -> a fresh copy's tessellate
    targets = {1.01 * full[64]: {64}, 0.99 * full[64]: {64, 128}, 0.5 * full[128]: {256},
               0.5 * full[256]: {128, 256}}  # -> the resolutions whose whole sag was measured
    assert full[256] < 0.5 * full[128]  # (the third: 256 within)
    for target, whole in targets.items():
        surf = fresh()
        evaluated = []
        points = surf._points
        surf._points = lambda *a, **k: evaluated.append(len(a[0])) or points(*a, **k)
        resolution, sag = surf.auto_resolution(target)
        if 128 in whole and 64 not in whole:  # (128 after 256, from its values)
            vertices = len(surf.tessellation_uv(128)[0])  # (about 4x as many points: + edges)
            assert evaluated[-1] < 0.1 * 4 * vertices, evaluated
            assert sag == full[256] and surf._sag_cache[128] == full[128]
        assert resolution == next((r for r in AUTO_RESOLUTIONS if not full[r] > target),
                                  AUTO_RESOLUTIONS[-1])
        assert sag == full[resolution]  # (bit for bit)
        assert set(surf._sag_cache) == whole
        evaluated.clear()
        verts, faces = surf.tessellate(resolution)
        assert evaluated == [] and verts.flags.writeable  # (handed over: not evaluated again)
        if resolution not in mesh:
            mesh[resolution] = fresh().tessellate(resolution)
        again, faces2 = mesh[resolution]
        np.testing.assert_array_equal(verts, again)
        np.testing.assert_array_equal(faces, faces2)
        verts2, _ = surf.tessellate(resolution)  # (once: then evaluated as before)
        assert evaluated == [len(verts)] and verts2 is not verts
        np.testing.assert_array_equal(verts2, again)
        for r in AUTO_RESOLUTIONS:  # (passed over on a sample: measured whole when asked)
            assert surf.tessellation_sag(r) == full[r]
    # a sample and then the rest give the one pass's sag and vertices, bit for bit; above a
    # target the sample's largest gap, at most the sag
    sag, vertex, _ = fresh()._sag(256, above=np.inf)
    assert sag == full[256]
    np.testing.assert_array_equal(vertex, mesh[256][0])
    bound, none, _ = fresh()._sag(128, above=0.0)
    assert none is None and 0.0 < bound <= full[128]
    surf = fresh()
    for stride in (1, 2, 3):  # (samples of all, half and a third of the triangles)
        monkeypatch.setattr(core.surface, "SAG_SAMPLE_STRIDE", stride)
        assert surf._sag(64, above=np.inf)[0] == full[64]
    # the parameters looked up by their bits: found wherever they are, -0.0 is not 0.0
    known = np.random.default_rng(2).random((1000, 2))
    known[7] = (0.0, 0.5)
    # (and a row of the same hash as known[0], u one bit up and v down by the multiplier)
    bits = known[:1].view(np.int64) + np.array([[1, 7046029254386353131]])
    x = np.vstack([known[::-3], [[-0.0, 0.5], [0.25, 2.0]], np.nextafter(known[:1], 2.0),
                   bits.view(np.float64)])
    np.testing.assert_array_equal(core.surface._same_rows(known, x),
                                  np.r_[np.arange(999, -1, -3), -1, -1, -1, -1])


def test_finer_resolution_follows_the_measured_fall_of_the_sag():
    """core.surface.finer_resolution: doublings until the sag meets the target when it falls
    by the measured ratio per doubling (the sag at half the resolution over the sag), taken
    between 2x and 4x, 4x without it. A crease makes it fall about 2x (patch-01's fit: 0.996
    at 128, 0.481 at 256, 0.225 at 512, 0.103 at 1024), where 4x per doubling advised one
    doubling too few."""
    from core.surface import MAX_RESOLUTION, finer_resolution

    assert finer_resolution(256, 0.4, 0.12) == 512  # (4x assumed: 0.1 predicted at 512)
    assert finer_resolution(256, 0.481, 0.12, 0.996) == 1024  # 2.07x: 0.232 at 512
    assert finer_resolution(256, 0.481, 0.1, 0.996) == 2048  # (0.108 at 1024)
    assert finer_resolution(256, 0.4, 0.1, 1.6) == 512  # 4x measured: one doubling
    assert finer_resolution(256, 0.4, 0.1, 100.0) == 512  # (taken as 4x at most)
    assert finer_resolution(256, 0.4, 0.1, 0.5) == 1024  # (taken as 2x at least)
    assert finer_resolution(256, 0.4, 0.1, float("nan")) == 512
    assert finer_resolution(256, 0.05, 0.1, 0.2) == 256  # (already within)
    assert finer_resolution(2048, 10.0, 0.1, 20.0) == MAX_RESOLUTION


def test_texture_coordinates_map_the_domain_to_the_unit_square_unmirrored():
    """TCBSurface.texture_coordinates of the tessellation's parameters: the domain's box goes
    to [0, 1] on its longer side (the aspect kept); every triangle of tessellate() runs
    counter-clockwise in them as seen from its normal's side, for a mesh, for its copy wound
    the other way (its normals reversed, its map mirrored back) and for a cloud, so that an
    image on the surface is not shown mirrored."""
    m = 13
    g = np.linspace(0.0, 2.0, m)
    x, y = (a.ravel() for a in np.meshgrid(g, 0.5 * g))  # a 2 x 1 patch
    P = np.c_[x, y, 0.1 * np.sin(2 * x) * y]
    i = np.arange(m * m).reshape(m, m)
    a, b, c = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel()
    d = i[1:, :-1].ravel()
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fits = [fit_surface(P, F, max_iterations=1), fit_surface(P, F[:, ::-1], max_iterations=1),
                fit_surface(P, max_iterations=1)]
    assert not fits[0].parameterization.flipped and fits[1].parameterization.flipped
    for k, surf in enumerate(fits):
        uv, tri = surf.tessellation_uv(24)
        verts, faces = surf.tessellate(24)
        t = surf.texture_coordinates(uv)
        assert t.min(axis=0) == pytest.approx([0, 0], abs=1e-12), k
        assert t.max() == pytest.approx(1.0) and np.ptp(t, axis=0).min() < 0.9, k
        e1, e2 = t[faces[:, 1]] - t[faces[:, 0]], t[faces[:, 2]] - t[faces[:, 0]]
        assert (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0).all(), k
        v0 = verts[faces[:, 0]]
        n = np.cross(verts[faces[:, 1]] - v0, verts[faces[:, 2]] - v0)
        up = np.sign(n[:, 2].sum())  # the way the faces face: the given winding's
        assert up == (-1 if k == 1 else 1) or k == 2, k
    with pytest.raises(Exception, match=r"uv must be an \(M, 2\) array"):
        fits[0].texture_coordinates(np.zeros((3, 3)))
    # one pair, as surf(uv) takes it (it had been refused: user test)
    one = fits[0].texture_coordinates(uv[5])
    assert one.shape == (1, 2) and np.array_equal(one, fits[0].texture_coordinates(uv[5:6]))


def test_the_reach_of_a_cloud_s_mesh_ignores_the_order_and_doubles_of_its_points():
    """core.parameterize.trim_distance (how far from the data a cloud's tessellation reaches)
    of 8000 points is the same for the points in another order (its sample was taken by
    place in the array: a gap had been a hole in some orders and not in others) and for every
    point doubled (the spacing was 0 and the mesh fell apart into hundreds of pieces)."""
    from core.parameterize import parameterize, trim_distance

    xy = np.random.default_rng(4).random((8000, 2))
    P = np.c_[xy, 0.1 * np.sin(3 * xy[:, 0])]
    base = trim_distance(parameterize(P))
    perm = np.random.default_rng(5).permutation(len(P))
    assert trim_distance(parameterize(P[perm])) == pytest.approx(base, rel=1e-9)
    doubled = parameterize(np.r_[P, P])
    assert trim_distance(doubled) == pytest.approx(base, rel=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        surf = fit_surface(np.r_[P, P], max_iterations=1)
    uv, tri = surf.tessellation_uv(128)
    edges = np.sort(np.r_[tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    border = np.count_nonzero(count == 1)  # one loop around the square: about 4 x 128 edges
    assert border < 4 * 128 * 1.5, border


def test_the_sag_target_is_at_least_the_tolerance_asked_for():
    """Auto Resolution's target (core.surface.sag_target) was the fit's max error only: an
    exact quadratic fitted 20x below its tolerance was given the finest mesh and told to
    Re-tessellate finer for a mesh well within what was asked (user test). The tolerance
    (relative: of the diagonal) counts too; without one, or without options, as before."""
    from core.refine import RefineOptions
    from core.surface import AUTO_RESOLUTION_FLOOR, sag_target, sag_target_words

    report = {"max": 1e-3, "diagonal": 4.0}
    assert sag_target(report) == 1e-3
    assert sag_target(report, RefineOptions(tolerance=1e-3)) == 4e-3
    assert sag_target(report, RefineOptions(tolerance=2e-3, relative=False)) == 2e-3
    assert sag_target(report, RefineOptions(tolerance=1e-4, relative=False)) == 1e-3
    assert sag_target(report, RefineOptions(tolerance=0.0)) == 1e-3
    assert sag_target({"max": 0.0, "diagonal": 4.0}) == 4 * AUTO_RESOLUTION_FLOOR
    assert np.isnan(sag_target({}))
    # the notes name what the target is (review: "more than the fit's max error" for a mesh
    # held to the tolerance)
    assert sag_target_words(report) == "the fit's max error 0.001"
    assert sag_target_words(report, RefineOptions(tolerance=1e-3)) == (
        "the tolerance asked for, 0.004")
    assert sag_target_words({"max": 0.0, "diagonal": 4.0}) == "1e-06 of the diagonal"
