"""Meshes shared by the core tests."""

from __future__ import annotations

import numpy as np


def comb_mesh(height, n: int = 40, finger: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid mesh over [-1, 1]^2 lifted by ``height``, its quads split into triangles
    (counter-clockwise from +z), with every other strip of quads ``finger`` wide cut away
    above y = -0.3: a comb of fingers. Only the vertices in faces are kept."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    pts = np.column_stack([u.ravel(), v.ravel(), height(u.ravel(), v.ravel())])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    quads = np.column_stack([a, a + 1, a + n + 1, a + n])
    c = pts[quads].mean(axis=1)
    quads = quads[~((c[:, 1] > -0.3) & (((c[:, 0] + 1) / finger).astype(int) % 2 == 1))]
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    used = np.unique(faces)
    index = np.full(len(pts), -1)
    index[used] = np.arange(len(used))
    return pts[used], index[faces]


def wavy(x, y):
    """The height field of :func:`noisy_grid`."""
    return 0.2 * np.sin(4 * x) * np.cos(3 * y) + 0.1 * x * y


def noisy_grid(n: int = 41, noise: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid mesh over [0, 1]^2 of :func:`wavy` (0.2 sin 4x cos 3y + 0.1 xy) with
    Gaussian noise of ``noise`` times its diagonal on every coordinate of every vertex
    (seeded): a noisy scan."""
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n)))
    pts = np.column_stack([u, v, wavy(u, v)])
    pts += noise * np.linalg.norm(np.ptp(pts, axis=0)) * np.random.default_rng(0).standard_normal(
        pts.shape)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    return pts, np.concatenate([np.column_stack([a, a + 1, a + n + 1]),
                                np.column_stack([a, a + n + 1, a + n])])


def spiky_grid(raise_by=(), nx: int = 40, ny: int = 30):
    """A quad grid mesh of ``0.3 sin 2x cos y`` over [-1, 1] x [-0.74, 0.74] (spacing 0.051),
    with the vertices ``raise_by`` ({row: dz}) raised: spikes (the user test's 2-unit grid)."""
    x, y = np.meshgrid(np.linspace(-1, 1, nx), np.linspace(-1, 1, ny) * (ny - 1) / (nx - 1))
    points = np.c_[x.ravel(), y.ravel(), 0.3 * np.sin(2 * x.ravel()) * np.cos(y.ravel())]
    for row, dz in dict(raise_by).items():
        points[row, 2] += dz
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    return points, np.c_[a, a + 1, a + nx + 1, a + nx]
