"""Simplex splines (method.md section 1): the batched evaluator against the direct recurrence,
integral, derivatives against finite differences, and the half-open rule."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.configurations import delaunay_triangulation
from core.simplex import SimplexBatch, simplex_spline

from knotsets import interior_knots


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), degree=st.integers(0, 3))
def test_batch_equals_reference_recurrence(seed, degree):
    rng = np.random.default_rng(seed)
    knots = rng.random((degree + 3, 2))
    x = rng.uniform(-0.1, 1.1, (500, 2))
    batch = SimplexBatch(knots, np.arange(degree + 3)[None, :])
    zero = np.zeros(len(x), dtype=int)
    ref = simplex_spline(x, knots)
    assert np.allclose(batch.evaluate(x, zero), ref, rtol=0, atol=1e-12 * max(ref.max(), 1))
    for der, dirs in [((1, 0), [(1, 0)]), ((0, 1), [(0, 1)]), ((1, 1), [(1, 0), (0, 1)])]:
        if sum(der) <= degree:
            r = simplex_spline(x, knots, dirs)
            g = batch.evaluate(x, zero, der)
            assert np.abs(g - r).max() <= 1e-10 * max(np.abs(r).max(), 1)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_integral_is_k_factorial_over_k_plus_2_factorial(degree):
    # int M(x | V) dx = k! / (k + 2)!  (method.md section 1), by the midpoint rule on a fine grid
    rng = np.random.default_rng(degree)
    knots = rng.random((degree + 3, 2))
    g = (np.arange(800) + 0.5) / 800
    x = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    batch = SimplexBatch(knots, np.arange(degree + 3)[None, :])
    integral = batch.evaluate(x, np.zeros(len(x), dtype=int)).mean()
    exact = 1.0 / ((degree + 1) * (degree + 2))
    assert integral == pytest.approx(exact, rel=2e-2 if degree == 0 else 5e-3)


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_reference_derivative_matches_central_differences(degree):
    rng = np.random.default_rng(10 + degree)
    knots = rng.random((degree + 3, 2))
    x = rng.random((400, 2))
    h = 1e-7
    for w in [(1.0, 0.0), (0.0, 1.0), (0.6, -0.8)]:
        w = np.array(w)
        fd = (simplex_spline(x + h * w, knots) - simplex_spline(x - h * w, knots)) / (2 * h)
        d = simplex_spline(x, knots, [w])
        err = np.abs(fd - d)
        # a stencil that straddles a knot line of a C^0 (degree 1) spline sees a kink: drop
        # those few points, keep the property everywhere else
        tol = 1e-6 * np.abs(d).max()
        assert np.mean(err > tol) < (0.02 if degree == 1 else 0.002)


def test_half_open_degree0_partition_is_exact_on_vertices_and_edges():
    """Degree-0 splines of a triangulation sum to exactly 1 at vertices and on edges."""
    for kind, seed in [("square", 0), ("hex", 1), ("random", 2), ("random", 3)]:
        knots = interior_knots(kind, 64, seed)
        if kind == "square":  # integer lattice: edge midpoints are exactly on the edges
            knots = np.round(knots * 8 - 0.5)
        tri = delaunay_triangulation(knots)
        # area-weighted: |det T| * M(x | T) is the indicator of [T)
        p, q, r = knots[tri[:, 0]], knots[tri[:, 1]], knots[tri[:, 2]]
        weights = np.abs((q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0]))
        batch = SimplexBatch(knots, tri, weights)
        edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        e, cnt = np.unique(edges, axis=0, return_counts=True)
        interior_edges = e[cnt == 2]
        boundary_vertices = np.unique(e[cnt == 1])
        inner_vertices = np.setdiff1d(np.arange(len(knots)), boundary_vertices)
        mids = 0.5 * (knots[interior_edges[:, 0]] + knots[interior_edges[:, 1]])
        t = np.random.default_rng(seed).random((len(interior_edges), 1))
        along = knots[interior_edges[:, 0]] + t * (knots[interior_edges[:, 1]] - knots[interior_edges[:, 0]])
        pts = np.concatenate([knots[inner_vertices], mids, along])
        pi = np.repeat(np.arange(len(pts)), len(tri))
        ci = np.tile(np.arange(len(tri)), len(pts))
        vals = batch.evaluate(pts[pi], ci).reshape(len(pts), len(tri))
        total = vals.sum(axis=1)
        # each point lies in exactly one half-open triangle (the exact statement); the value
        # there is |det T| * (1 / |det T|), computed in two orders, so 1 up to one rounding
        assert np.all((vals > 0).sum(axis=1) == 1), kind
        np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-15)


def test_degenerate_knot_sets_give_zero():
    x = np.random.default_rng(0).random((100, 2))
    collinear = np.array([[0, 0], [1, 1], [2, 2], [3, 3], [0.5, 0.5]], dtype=float)
    assert not simplex_spline(x, collinear).any()
    b = SimplexBatch(collinear, np.arange(5)[None, :])
    assert not b.evaluate(x, np.zeros(100, dtype=int)).any()
    coincident = np.array([[0, 0], [0, 0], [0, 0]], dtype=float)
    assert not simplex_spline(x, coincident).any()
