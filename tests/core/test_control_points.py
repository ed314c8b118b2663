"""Control points are the basis functions whose support meets the data's domain.

The border rings (method.md section 3) carry functions that vanish on the domain; they are not
control points: the budget does not count them and the control net does not show them.
"""

import numpy as np
import pytest

from core import fit_surface
from core.errors import InvalidInputError
from core.parameterize import _points_in_polygon
from core.spline_space import _outer_polygon, build_space


def _polygon(n: int) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False) + 0.3
    return 0.5 + 0.6 * np.c_[np.cos(t), np.sin(t)]


def _rhombus(per_side: int) -> np.ndarray:
    """A tilted rhombus with ``per_side`` vertices on each slightly bulging side: the convex
    hull of a projected grid (a cliff sampled on a lattice gave 196 such vertices, and the
    circumscribed 128-gon then repeats each corner many times)."""
    corners = np.array([[1.0, -0.1], [0.1, 1.0], [-1.0, 0.1], [-0.1, -1.0]]) * 0.7 + 0.5
    out = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        t = np.linspace(0.0, 1.0, per_side, endpoint=False)
        edge = a + t[:, None] * (b - a)
        bulge = 1e-3 * np.sin(np.pi * t)[:, None] * np.array([(b - a)[1], -(b - a)[0]])
        out.append(edge + bulge)
    return np.vstack(out)


@pytest.mark.parametrize("degree, shape", [(2, "hexagon"), (3, "hexagon"), (2, "200-gon"),
                                           (2, "rhombus")])
def test_meets_finds_every_function_that_is_nonzero_in_the_polygon(degree, shape):
    rng = np.random.default_rng(degree)
    space = build_space(rng.random((150, 2)) * 3 - 1, degree)
    poly = {"hexagon": _polygon(6), "200-gon": _polygon(200), "rhombus": _rhombus(50)}[shape]
    met = space.meets(poly)
    sample = rng.random((300_000, 2)) * 1.4 - 0.2
    inside = sample[_points_in_polygon(sample, poly, 1e-12)]
    seen = np.diff(space.evaluate(inside).tocsc().indptr) > 0
    assert seen.sum() > 20 and (~met).sum() > 20
    assert not (seen & ~met).any()  # nothing that shapes the surface there is missed
    # and what is kept but not seen only grazes the polygon (the circumscribed 128-gon of
    # the 200-gon is 0.03% larger)
    assert (met & ~seen).sum() <= 0.02 * met.sum()


def test_outer_polygon_contains_the_polygon():
    poly = _polygon(1000)
    outer = _outer_polygon(poly, 128)
    assert len(outer) == 128 and _points_in_polygon(poly, outer, 1e-12).all()
    assert _outer_polygon(_polygon(50), 128).shape == (50, 2)


@pytest.fixture(scope="module")
def ridge():
    xy = np.random.default_rng(5).random((3000, 2))
    points = np.c_[xy, 0.3 * np.abs(xy[:, 0] - 0.45 - 0.1 * xy[:, 1]) + 0.1 * xy[:, 1] ** 2]
    return fit_surface(points, tolerance=0.0, max_control_points=300, max_iterations=4)


def test_the_budget_and_the_net_count_the_functions_that_meet_the_domain(ridge):
    surf = ridge
    n = len(surf.control_points)
    assert n == surf.report["control_points"] <= 300
    assert surf.report["functions"] == surf.space.n_basis > n
    assert all(h["control_points"] <= min(300, h["functions"]) for h in surf.report["history"])
    pts, faces = surf.control_net()
    np.testing.assert_array_equal(pts, surf.control_points)
    assert len(faces) > n and faces.min() >= 0 and faces.max() < n
    np.testing.assert_array_equal(surf.coefficients[surf.active], surf.control_points)


def test_the_other_functions_vanish_on_the_domain(ridge):
    surf = ridge
    uv = np.vstack([surf.tessellation_uv(64)[0], surf.parameterization.uv])
    A = surf.space.evaluate(uv).tocsc()
    border = np.setdiff1d(np.arange(surf.space.n_basis), surf.active)
    assert len(border) > 0 and A[:, border].nnz == 0
    # almost every control point is seen at these parameters (the rest graze the domain)
    assert (np.diff(A[:, surf.active].indptr) > 0).mean() > 0.9
    np.testing.assert_allclose(surf.evaluation_matrix(uv) @ surf.control_points, surf(uv),
                               rtol=0, atol=1e-12)


def test_editing_the_control_points(ridge):
    surf = ridge
    uv, _ = surf.tessellation_uv(48)
    lifted = surf.with_control_points(surf.control_points + [0.0, 0.0, 1.0])
    # partition of unity on the domain: moving every control point moves the whole surface
    np.testing.assert_allclose(lifted(uv) - surf(uv), np.tile([0.0, 0.0, 1.0], (len(uv), 1)),
                               rtol=0, atol=1e-9)
    same = surf.with_control_points(surf.coefficients)  # all coefficients are accepted too
    np.testing.assert_array_equal(same.control_points, surf.control_points)
    with pytest.raises(InvalidInputError, match="shape"):
        surf.with_control_points(np.zeros((len(surf.control_points) + 1, 3)))
