"""Knot sets shared by the core tests: random, square-lattice and hex-lattice interiors in the
unit square, surrounded by border rings (method.md section 3)."""

from __future__ import annotations

import numpy as np

from core import border_rings

KINDS = ("random", "square", "hex")


def interior_knots(kind: str, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "random":
        return rng.random((n, 2))
    m = max(int(round(np.sqrt(n))), 3)
    if kind == "square":  # co-circular and collinear: Delaunay ties everywhere
        g = (np.arange(m) + 0.5) / m
        return np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    if kind == "hex":  # six co-circular neighbours around every knot
        j, i = np.divmod(np.arange(m * m), m)
        return np.stack([(i + 0.5 * (j % 2) + 0.25) / m, (j + 0.5) / m], axis=1)
    raise ValueError(kind)


def knot_set(kind: str, n: int, degree: int, seed: int, rings: int | None = None) -> np.ndarray:
    """Interior knots in [0, 1]^2 plus ``degree + 1`` jittered rings outside it."""
    inner = interior_knots(kind, n, seed)
    h = 1.0 / np.sqrt(len(inner))
    ring = border_rings([0, 0], [1, 1], h, rings=degree + 1 if rings is None else rings, seed=seed)
    return np.vstack([inner, ring])


def polar_form(f: str, I: np.ndarray) -> np.ndarray:
    """Blossom ``F(I)`` (one value per row of knot points ``I`` (n, k, 2)) of u, v, u*v, u^2.

    For degree k the polar forms are ``mean(u_i)`` and ``sum_{i != j} a_i b_j / (k (k - 1))``.
    """
    u, v = I[..., 0], I[..., 1]
    k = I.shape[1]
    if f == "u":
        return u.mean(axis=1)
    if f == "v":
        return v.mean(axis=1)
    if f == "uv":
        return (u.sum(1) * v.sum(1) - (u * v).sum(1)) / (k * (k - 1))
    if f == "uu":
        return (u.sum(1) ** 2 - (u * u).sum(1)) / (k * (k - 1))
    raise ValueError(f)


FUNCTIONS = {
    "u": lambda x: x[:, 0],
    "v": lambda x: x[:, 1],
    "uv": lambda x: x[:, 0] * x[:, 1],
    "uu": lambda x: x[:, 0] ** 2,
}
