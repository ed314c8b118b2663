"""The Park (2011) tensor-product baseline (core/baselines/tensor.py, issue 5)."""

import numpy as np
import pytest

from core import InvalidInputError
from core.baselines import TensorSurface, averaged_knots, fit_tensor


def bicubic(x, y):
    return 1 + x ** 3 - 2 * x * y ** 2 + 0.5 * x ** 3 * y ** 3 - y ** 3


@pytest.fixture(scope="module")
def scattered():
    return np.random.default_rng(1).random((3000, 2))


def parameters(scattered, grid: bool, side: int) -> np.ndarray:
    """The scattered sample, or a ``side x side`` lattice of the unit square."""
    if not grid:
        return scattered
    g = np.linspace(0, 1, side)
    return np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)


def test_averaged_knots():
    t = averaged_knots(np.array([0.0, 0.1, 0.2, 0.6, 0.7, 1.0]), 3)
    assert len(t) == 6 + 3 + 1
    np.testing.assert_allclose(t[:4], 0.0)
    np.testing.assert_allclose(t[-4:], 1.0)
    np.testing.assert_allclose(t[4:6], [(0.1 + 0.2 + 0.6) / 3, (0.2 + 0.6 + 0.7) / 3])


@pytest.mark.parametrize("grid", [False, True])
def test_reproduces_bicubic_polynomial(scattered, grid):
    uv = parameters(scattered, grid, 40)
    P = np.c_[uv, bicubic(uv[:, 0], uv[:, 1])]
    surf = fit_tensor(uv, P, max_control_points=64, tolerance=0, max_iterations=3, smoothness=0)
    assert isinstance(surf, TensorSurface)
    assert surf.report["rms_rel"] < 1e-10
    x = 0.05 + 0.9 * np.random.default_rng(5).random((200, 2))  # inside the data box
    np.testing.assert_allclose(surf(x), np.c_[x, bicubic(x[:, 0], x[:, 1])], atol=1e-9)
    # the default (tiny) fairing only perturbs it slightly
    surf = fit_tensor(uv, P, max_control_points=64, tolerance=0, max_iterations=2)
    assert surf.report["rms_rel"] < 1e-4


def test_error_decreases_with_refinement(scattered):
    x, y = scattered.T
    P = np.c_[scattered, np.sin(6 * x) * np.cos(5 * y)]
    surf = fit_tensor(scattered, P, max_control_points=400, tolerance=0)
    rms = [h["rms"] for h in surf.report["history"]]
    cps = [h["control_points"] for h in surf.report["history"]]
    assert len(rms) >= 4
    assert np.all(np.diff(cps) > 0)
    assert rms[-1] < 0.2 * rms[0]
    # mostly monotone (knot averaging does not nest the spaces, allow small bumps)
    assert np.all(np.diff(rms) < 0.05 * rms[0])


@pytest.mark.parametrize("budget", [30, 100, 257])
def test_respects_control_point_budget(scattered, budget):
    x, y = scattered.T
    P = np.c_[scattered, np.abs(x - 0.3) + np.sin(7 * y)]
    surf = fit_tensor(scattered, P, max_control_points=budget, tolerance=0)
    assert surf.n_control_points <= budget
    assert all(h["control_points"] <= budget for h in surf.report["history"])
    assert surf.report["stop_reason"] in ("control-point budget reached", "no strip can be refined")
    assert surf.n_control_points >= 0.7 * budget


def test_tolerance_stops_early(scattered):
    x, y = scattered.T
    P = np.c_[scattered, np.sin(3 * x) + y ** 2]
    surf = fit_tensor(scattered, P, max_control_points=2000, tolerance=1e-3)
    assert surf.report["stop_reason"] == "tolerance reached"
    assert surf.report["rms_rel"] <= 1e-3
    assert surf.n_control_points < 2000


@pytest.mark.parametrize("grid", [False, True])
def test_knots_concentrate_at_crease(scattered, grid):
    """Dominant columns crowd at a crease along u = 0.37: knots follow them."""
    uv = parameters(scattered, grid, 70)
    P = np.c_[uv, 0.25 * np.abs(uv[:, 0] - 0.37) + 0.05 * uv[:, 1]]
    surf = fit_tensor(uv, P, max_control_points=150, tolerance=0)
    p = surf.degree
    ku = surf.knots_u[p + 1: -p - 1]
    kv = surf.knots_v[p + 1: -p - 1]
    assert len(ku) >= 3
    near = np.mean(np.abs(ku - 0.37) < 0.1)  # a uniform spread would put ~20% there
    assert near >= 0.6, ku
    # the rows do not crowd anywhere in particular (the crease runs along v)
    assert np.mean(np.abs(kv - 0.37) < 0.1) < 0.6
    # and the crease is resolved far better than by a uniform tensor fit of the same size
    from scipy.interpolate import LSQBivariateSpline

    n_int = int(np.sqrt(surf.n_control_points)) - 4
    t = np.linspace(0, 1, n_int + 2)[1:-1]
    fp = LSQBivariateSpline(uv[:, 0], uv[:, 1], P[:, 2], t, t, kx=3, ky=3)
    rms_fp = np.sqrt(np.mean((fp.ev(uv[:, 0], uv[:, 1]) - P[:, 2]) ** 2))
    assert surf.report["rms"] < 0.5 * rms_fp


def test_bad_input():
    with pytest.raises(InvalidInputError):
        fit_tensor(np.zeros((10, 3)), np.zeros((10, 3)))
    with pytest.raises(InvalidInputError):
        fit_tensor(np.random.rand(100, 2), np.random.rand(100, 3), max_control_points=5)
    uv = np.random.rand(100, 2)
    uv[0, 0] = np.nan
    with pytest.raises(InvalidInputError):
        fit_tensor(uv, np.random.rand(100, 3))
