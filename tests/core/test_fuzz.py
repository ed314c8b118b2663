"""Property-based hardening (issue 6): generated inputs of every awkward kind either give a
valid surface (finite, with the errors it reports) or one of the project's exceptions.

The outcome of every generated case is tallied and printed at the end of the run
(``tests/conftest.py``)."""

from collections import Counter

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import TCBError, fit_surface

OUTCOMES: Counter = Counter()

KINDS = (
    "cloud", "lattice", "near_collinear", "duplicates", "nan", "inf", "tiny", "scale_small",
    "scale_large", "offset_large", "grid_mesh", "mesh_holes", "holes_filled", "non_manifold",
    "components", "closed", "bad_faces",
)


def grid_mesh(rng, n):
    g = np.linspace(0, 1, n)
    v = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    v = np.c_[v, 0.2 * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1])]
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    f = np.concatenate([np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]])
    return v + rng.normal(0, 1e-3, v.shape), f


def make_input(kind, seed, n):
    rng = np.random.default_rng(seed)
    faces = None
    xy = rng.random((n, 2))
    pts = np.c_[xy, 0.3 * np.sin(4 * xy[:, 0]) * xy[:, 1]]
    if kind == "lattice":
        m = max(int(np.sqrt(n)), 2)
        g = np.linspace(0, 1, m)
        xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        pts = np.c_[xy, np.abs(xy[:, 0] - 0.5)]
    elif kind == "near_collinear":
        t = rng.random(n)
        pts = np.c_[t, 2 * t, 3 * t] + rng.normal(0, 10.0 ** rng.integers(-12, -2), (n, 3))
    elif kind == "duplicates":
        pts = np.repeat(pts[: max(n // 4, 1)], 4, axis=0)
    elif kind == "nan":
        pts[rng.integers(n)] = np.nan
    elif kind == "inf":
        pts[rng.integers(n), rng.integers(3)] = np.inf * rng.choice([-1, 1])
    elif kind == "tiny":
        pts = pts[: rng.integers(0, 21)]
    elif kind == "scale_small":
        pts = pts * 1e-6
    elif kind == "scale_large":
        pts = pts * 1e6
    elif kind == "offset_large":
        pts = pts + 1e6
    elif kind in ("grid_mesh", "mesh_holes", "holes_filled", "non_manifold", "components",
                  "closed", "bad_faces"):
        pts, faces = grid_mesh(rng, int(np.clip(np.sqrt(n), 3, 14)))
        if kind in ("mesh_holes", "holes_filled"):  # (the second with fill_holes=True)
            keep = np.ones(len(faces), dtype=bool)
            keep[rng.choice(len(faces), size=max(1, len(faces) // 10), replace=False)] = False
            faces = faces[keep]
        elif kind == "non_manifold":
            a, b = faces[0][:2]
            pts = np.vstack([pts, [0.5, 0.5, 1.0]])
            faces = np.vstack([faces, [a, b, len(pts) - 1]])
        elif kind == "components":
            faces = np.vstack([faces, faces + len(pts)])
            pts = np.vstack([pts, pts + [2.0, 0, 0]])
        elif kind == "closed":
            from scipy.spatial import ConvexHull

            pts = rng.normal(size=(max(n, 8), 3))
            faces = ConvexHull(pts).simplices
        elif kind == "bad_faces":
            faces = faces.copy()
            faces[rng.integers(len(faces)), rng.integers(3)] = len(pts) + 5
    return pts, faces


@settings(max_examples=850, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(KINDS), seed=st.integers(0, 2**31 - 1), n=st.integers(10, 400))
def test_any_input_parameterizes_or_raises_a_specific_error(kind, seed, n):
    """The first stage on its own (fast, so many more cases): finite parameters for every used
    point, positively oriented mesh triangles in the plane, or a TCBError."""
    from core.parameterize import parameterize

    points, faces = make_input(kind, seed, n)
    try:
        param = parameterize(points, faces, fill_holes=kind == "holes_filled")
    except TCBError as exc:
        assert str(exc)
        OUTCOMES[f"parameterize {kind}: {type(exc).__name__}"] += 1
        return
    OUTCOMES[f"parameterize {kind}: ok"] += 1
    if faces is not None:  # the mesh's own vertices and faces (no fan of a filled hole)
        assert len(param.uv) == len(points) and param.faces.max() < len(points)
    uv = param.uv[param.used]
    assert np.all(np.isfinite(uv)) and len(uv) >= 3
    if param.faces is not None:
        a, b, c = (param.uv[param.faces[:, j]] for j in range(3))
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        assert np.all(det > 0)
    assert np.all(param.contains(uv, tol=1e-9))


@pytest.mark.filterwarnings("ignore:.*loosely determined:RuntimeWarning")  # tiny clouds
@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(KINDS), seed=st.integers(0, 2**31 - 1), n=st.integers(10, 250))
def test_any_input_gives_a_valid_surface_or_a_specific_error(kind, seed, n):
    points, faces = make_input(kind, seed, n)
    try:
        surf = fit_surface(points, faces, max_iterations=1, max_control_points=400, tolerance=1e-3,
                           fill_holes=kind == "holes_filled")
    except TCBError as exc:
        assert str(exc), "an error must say what is wrong"
        OUTCOMES[f"fit {kind}: {type(exc).__name__}"] += 1
        return
    OUTCOMES[f"fit {kind}: surface"] += 1
    C = surf.control_points
    assert np.all(np.isfinite(C))
    verts, tris = surf.tessellate(16)
    assert len(tris) > 0 and np.all(np.isfinite(verts))
    # the reported errors are the true ones
    used = surf.parameterization.used
    uv = surf.parameterization.uv[used]
    true = np.linalg.norm(surf(uv) - np.asarray(points, dtype=float)[used], axis=1)
    # in world coordinates a far-off origin (1e6) costs ~1e-16 of the coordinates per term
    magnitude = np.abs(np.asarray(points, dtype=float)[used]).max()
    atol = 1e-9 * surf.report["diagonal"] + 1e-13 * magnitude
    np.testing.assert_allclose(surf.errors[used], true, rtol=1e-6, atol=atol)
    assert np.isclose(surf.report["rms"], np.sqrt(np.mean(true**2)), rtol=1e-6, atol=atol)
