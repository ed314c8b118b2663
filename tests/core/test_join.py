"""Joining a patch's surface to its neighbours' along their shared border (core.join;
fit_surface(join=...)), and the pins of core.fit.fit_control_points."""

from __future__ import annotations

import numpy as np
import pytest

from core import InvalidInputError, fit_surface
from core.fit import fit_control_points
from core.geometry import point_mesh_distance
from core.join import (border_edges, inward_directions, seam_folds, seam_samples, seams,
                       shared_border_edges, shared_vertices)
from core.refine import border_rings
from core.spline_space import build_space
from meshes import noisy_grid, split_mesh, terrain_tiles, uv_sphere, wavy_halves


def test_pins_draw_the_fit_to_their_targets_and_are_not_counted_as_data():
    rng = np.random.default_rng(0)
    interior = rng.uniform(0.05, 0.95, (30, 2))
    knots = np.vstack([interior, border_rings(np.zeros(2), np.ones(2), 0.2, rings=2, seed=0)])
    space = build_space(knots, 2)
    uv = rng.uniform(0, 1, (2000, 2))
    flat = np.column_stack([uv, np.zeros(len(uv))])  # the plane z = 0
    plain = fit_control_points(space, uv, flat, smoothness=1e-4)
    at = np.array([[0.5, 0.5]])
    target = np.array([[0.5, 0.5, 0.1]])
    # a pin of weight 0 changes nothing (the fairing is scaled by the data alone)
    none = fit_control_points(space, uv, flat, smoothness=1e-4, pins=(at, target, 0.0))
    assert np.allclose(none.control_points, plain.control_points, atol=1e-12)
    heights = []
    for weight in (10.0, 1e3, 1e5):
        fit = fit_control_points(space, uv, flat, smoothness=1e-4, pins=(at, target, weight))
        assert fit.errors.shape == (len(uv),)  # the pin is not among the errors
        heights.append(float((space.evaluate(at) @ fit.control_points)[0, 2]))
    assert 0 < heights[0] < heights[1] < heights[2] <= 0.1 + 1e-9
    assert heights[2] > 0.09  # worth 1e5 points: the surface goes (almost) through it
    with pytest.raises(ValueError, match="auto"):
        fit_control_points(space, uv, flat, smoothness="auto", pins=(at, target, 1.0))


def test_shared_vertices_pairs_identical_coordinates():
    (pa, fa), (pb, fb) = wavy_halves(20)
    pairs = shared_vertices(pb, pa)
    assert len(pairs) > 10
    assert np.array_equal(pb[pairs[:, 0]], pa[pairs[:, 1]])
    # every shared vertex is on both patches' borders, and every border vertex of one patch
    # inside the square is shared
    on_b = np.unique(border_edges(fb))
    assert np.isin(pairs[:, 0], on_b).all() and np.isin(pairs[:, 1], np.unique(border_edges(fa))).all()
    inner = on_b[(pb[on_b, 0] > 0) & (pb[on_b, 0] < 1) & (pb[on_b, 1] > 0) & (pb[on_b, 1] < 1)]
    assert np.isin(inner, pairs[:, 0]).all()
    assert len(shared_vertices(pb, pa + 1.0)) == 0


def _seam_mesh_gap(a, b, diagonal):
    """Largest distance from the border vertices of b's tessellation along the seam (inside
    the square, away from its sides) to a's tessellation, over the diagonal: the gap as the
    meshes show it, measured without core.join."""
    va, fa = a.tessellate(256)
    vb, fb = b.tessellate(256)
    edge = np.unique(border_edges(fb))
    p = vb[edge]
    near = ((np.abs(p[:, 0] - (0.5 + 0.1 * np.sin(9 * p[:, 1]))) < 0.01)
            & (p[:, 1] > 0.05) & (p[:, 1] < 0.95))
    assert near.sum() > 50
    return float(point_mesh_distance(p[near], va, fa).max()) / diagonal


def test_a_joined_patch_meets_its_neighbour_along_their_shared_border():
    (pa, fa), (pb, fb) = wavy_halves(40)
    a = fit_surface(pa, fa, tolerance=1e-3)
    a_control = a.control_points.copy()
    pairs = shared_vertices(pb, pa)
    free = fit_surface(pb, fb, tolerance=1e-3)
    joined = fit_surface(pb, fb, tolerance=1e-3, join=(a, pairs))
    j = joined.report["join"]
    assert j["surfaces"] == 1 and j["shared_vertices"] == len(pairs)
    assert j["shared_edges"] == len(pairs) - 1  # one open seam across the square
    # the borders meet to a share of the tolerance (about twice it apart without joining)
    assert j["gap_max_unjoined_rel"] > 1.5e-3
    assert j["gap_max_rel"] < 0.25 * j["gap_max_unjoined_rel"]
    assert j["gap_max_rel"] < 5e-4
    diagonal = joined.report["diagonal"]
    assert j["gap_max"] == pytest.approx(j["gap_max_rel"] * diagonal)
    # ... and so do the meshes, measured on the tessellations
    before, after = _seam_mesh_gap(a, free, diagonal), _seam_mesh_gap(a, joined, diagonal)
    assert after < 0.25 * before and after < 5e-4
    # the patch still fits its own data; the neighbour is not changed
    assert joined.report["rms_rel"] < 1.5e-3
    assert np.isfinite(joined.control_points).all()
    assert np.array_equal(a.control_points, a_control)
    assert "join" not in free.report
    # refine() joins again when asked
    again = joined.refine(pb, fb, join=(a, pairs), max_iterations=2)
    assert again.report["join"]["gap_max_rel"] < 5e-4


def test_a_joined_sphere_turns_over_nowhere_at_its_seam():
    """The rest of a 64 x 32 UV sphere joined to its cap's surface: its normals on a fine
    tessellation all point outward (the joined fits had turned over in thin lips along the
    seam, at 23 of its 2.1e5 vertices at 512, where the patch's border was drawn in over its
    own data to the cap's border; the mesh's fold check, 1e4 points drawn by area, had said 0).
    The pins no longer draw a border in across itself, and a fit that turns over on the
    seam's triangles is not returned; the borders are still 3x closer than unjoined."""
    pts, faces = uv_sphere(64, 32)
    (pa, fa), (pb, fb) = split_mesh(pts, faces, pts[faces].mean(axis=1)[:, 2] > 0.2)
    cap = fit_surface(pa, fa, tolerance=1e-3)
    pairs = shared_vertices(pb, pa)
    rest = fit_surface(pb, fb, tolerance=1e-3, join=(cap, pairs))
    j = rest.report["join"]
    assert not j["kept_unjoined"] and j["seam_folds"] == 0 and j["seam_samples"] > 5000
    assert 3 * j["gap_max"] < j["gap_max_unjoined"]
    uv, _ = rest.tessellation_uv(512)
    x = rest(uv)
    outward = np.einsum("ij,ij->i", rest.normals(uv), x / np.linalg.norm(x, axis=1)[:, None])
    assert outward.min() > 0.5, (np.count_nonzero(outward < 0), len(outward))
    # the seam's check itself: against the triangles' reversed normals the surface turns over
    # at every point; the directions into the patch are across the shared edges, downward
    samples = seam_samples(seams(rest.parameterization, (cap, pairs)), rest.parameterization.faces,
                           rest.parameterization.uv, pb)
    assert seam_folds(samples, rest.space, rest.coefficients) == 0
    reversed_ = (samples[0], -samples[1])
    assert seam_folds(reversed_, rest.space, rest.coefficients) == len(samples[0])
    seam = seams(rest.parameterization, (cap, pairs))
    edges = inward_directions(seam, rest.parameterization.faces, pb)[0]
    along = pb[seam[0].own[:, 1]] - pb[seam[0].own[:, 0]]
    assert np.allclose(np.linalg.norm(edges, axis=1), 1.0)
    assert np.abs(np.einsum("ij,ij->i", edges, along)).max() < 1e-9
    assert (edges[:, 2] < 0).all() and edges.shape == (len(seam[0].own), 3)


def test_join_refuses_what_it_cannot_join():
    (pa, fa), (pb, fb) = wavy_halves(20)
    a = fit_surface(pa, fa, tolerance=1e-2)
    pairs = shared_vertices(pb, pa)
    with pytest.raises(InvalidInputError, match="fitted to a mesh; a point cloud's surface"):
        fit_surface(pb, join=(a, pairs))  # (a cloud joins clouds: test_dem_tiles_...)
    cloud = fit_surface(pa, tolerance=1e-2)
    with pytest.raises(InvalidInputError, match="fitted to a point cloud"):
        fit_surface(pb, fb, join=(cloud, pairs))
    with pytest.raises(InvalidInputError, match="out of range"):
        fit_surface(pb, fb, join=(a, pairs + len(pa)))
    with pytest.raises(InvalidInputError, match=r"\(k, 2\) array of whole numbers"):
        fit_surface(pb, fb, join=(a, pairs.astype(float)))
    with pytest.raises(InvalidInputError, match="must be a pair"):
        fit_surface(pb, fb, join=[a])
    with pytest.raises(InvalidInputError, match="for a mesh takes pairs"):
        fit_surface(pb, fb, join=a)  # (a cloud's neighbour may be given so: review)
    # vertices that are not on both borders (B's own interior ones paired with A's)
    whole, faces = noisy_grid(20, noise=0.0)
    inside = np.setdiff1d(np.arange(len(pb)), np.unique(border_edges(fb)))[:20]
    with pytest.raises(InvalidInputError, match="share no border edge"):
        fit_surface(pb, fb, join=(a, np.column_stack([inside, np.arange(20)])))
    # a mesh that is not a neighbour: no border edge in common
    with pytest.raises(InvalidInputError, match="share no border edge"):
        fit_surface(whole, faces, join=(a, shared_vertices(whole, pa)[:1]))


def test_shared_vertices_pair_every_row_of_a_repeated_coordinate():
    (pa, fa), (pb, fb) = wavy_halves(20)
    pairs = shared_vertices(pb, pa)
    edges = shared_border_edges(fb, fa, pairs)[0]
    # a loose vertex at a seam vertex's coordinates, listed first (an unwelded copy): the
    # seam's edges are all still found through the vertex in faces
    seam_vertex = pairs[len(pairs) // 2, 0]
    pb2, fb2 = np.vstack([pb[seam_vertex], pb]), fb + 1
    pairs2 = shared_vertices(pb2, pa)
    assert len(pairs2) == len(pairs) + 1
    mine, theirs = shared_border_edges(fb2, fa, pairs2)
    assert len(mine) == len(edges) and np.array_equal(pb2[mine], pb[edges])
    assert np.array_equal(pb2[mine], pa[theirs])
    # -0.0 and 0.0 are the same coordinate (two files' writers)
    zero = np.array([[0.0, 1.0, 2.0], [-0.0, 1.0, 2.0], [0.0, -0.0, 1.0]])
    assert shared_vertices(zero, np.array([[-0.0, 1.0, 2.0]])).tolist() == [[0, 0], [1, 0]]


def test_join_keeps_to_the_tolerance_and_the_budget_or_says_so():
    (pa, fa), (pb, fb) = wavy_halves(20)
    pairs = shared_vertices(pb, pa)
    # joined to itself (or to an overlapping patch): refused
    b = fit_surface(pb, fb, tolerance=1e-2)
    with pytest.raises(InvalidInputError, match="triangles in common"):
        fit_surface(pb, fb, tolerance=1e-2, join=(b, shared_vertices(pb, pb)))
    # a budget that holds only some of the knots the seam asks for: those are added
    free = fit_surface(pb, fb, tolerance=1e-3)
    a = fit_surface(pa, fa, tolerance=1e-3)
    budget = free.report["control_points"] + 12
    tight = fit_surface(pb, fb, tolerance=1e-3, max_control_points=budget, join=(a, pairs))
    assert 0 < tight.report["join"]["knots_added"]
    assert tight.report["control_points"] <= budget
    # a neighbour fitted 20x looser: the joined patch misses its tolerance, and says so
    coarse = fit_surface(pa, fa, tolerance=2e-2)
    with pytest.warns(RuntimeWarning, match="misses the tolerance at its data"):
        loose = fit_surface(pb, fb, tolerance=1e-3, join=(coarse, pairs))
    assert loose.report["join"]["tolerance_missed"]
    assert not fit_surface(pb, fb, tolerance=1e-3, join=(a, pairs)).report["join"][
        "tolerance_missed"]


def test_dem_tiles_fitted_along_z_are_joined_where_they_share_a_row_of_nodes():
    """Two DEM tiles sharing a column of nodes, fitted along z one after the other: alone,
    the second's surface is up to 2.2 m off the first's along that column (each within its
    tolerance of its own data, 0.25 m RMS); joined (``join=first``: core.join.CloudSeam, its
    border pinned where it lies on the first's fitted surface) the two meet there to a small
    share of the tolerance, seen by TCBSurface.heights at points between the nodes, and the
    second still meets its tolerance at its data."""
    west, east, x_shared = terrain_tiles()
    a = fit_surface(west, projection="z")
    b = fit_surface(east, projection="z", join=a)
    tol = 1e-3 * b.report["diagonal"]
    j = b.report["join"]
    assert j["surfaces"] == 1 and j["shared_edges"] == 0 and j["pins"] >= 80
    assert abs(j["shared_length"] - 200.0) < 1e-6  # (the column is 200 m long)
    assert j["gap_max_unjoined"] > 4 * tol and j["gap_max"] < 0.5 * tol
    assert not j["tolerance_missed"] and b.report["rms"] <= tol
    ys = np.linspace(east[:, 1].min(), east[:, 1].max(), 301)  # (between the nodes too)
    column = np.c_[np.full_like(ys, x_shared), ys]
    dz = a.heights(column) - b.heights(column)
    assert np.isfinite(dz).all() and np.abs(dz).max() < 0.5 * tol
    # the data's z is met as before away from the seam: the east half of the east tile
    far = east[:, 0] > x_shared + 50
    assert np.abs(b.heights(east[far, :2]) - east[far, 2]).max() < 8 * tol


def test_cloud_joins_refuse_what_they_cannot_join():
    """A point cloud joins the surface of a neighbouring cloud fitted along the same
    direction that reaches a part of its border: anything else is refused in words."""
    west, east, _ = terrain_tiles(n=21, spacing=10.0)
    a = fit_surface(west, projection="z", tolerance=1e-2)
    with pytest.raises(InvalidInputError, match="reaches all of this cloud's border"):
        fit_surface(west, projection="z", tolerance=1e-2, join=a)
    with pytest.raises(InvalidInputError,
                       match="reaches no part of this cloud's border.*fitted together"):
        fit_surface(east + [30.0, 0, 0], projection="z", tolerance=1e-2, join=a)
    with pytest.raises(InvalidInputError, match="projected along different directions"):
        fit_surface(east, projection=(0.3, 0.0, 1.0), tolerance=1e-2, join=a)
    with pytest.raises(InvalidInputError, match="must be the TCBSurface of a neighbouring"):
        fit_surface(east, projection="z", tolerance=1e-2, join=[np.zeros((3, 2))])
    # a pair as for meshes is taken, its vertex pairs unused: the same fit
    b = fit_surface(east, projection="z", tolerance=1e-2, join=(a, None))
    c = fit_surface(east, projection="z", tolerance=1e-2, join=[a])
    assert np.array_equal(b.control_points, c.control_points)
    # two surfaces in a tuple are two neighbours, not a pair (the second had been dropped)
    two = fit_surface(east, projection="z", tolerance=1e-2, join=(a, a))
    assert two.report["join"]["surfaces"] == 2
    assert two.report["join"]["pins"] == 2 * c.report["join"]["pins"]
    with pytest.raises(InvalidInputError, match="as a list of surfaces"):
        fit_surface(east, projection="z", tolerance=1e-2, join=[(a, a)])
