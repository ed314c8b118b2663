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


def noisy_sphere_cap(seed=0, noise=0.002, segments=32, rings=16):
    """The faces (triangles) with centroid z > 0.4 of a UV sphere of radius 1 (``segments``
    x ``rings``, poles, as Blender's), its vertices moved along their normals by Gaussian
    noise, rounded to 32-bit floats as Blender keeps them: (points, faces)."""
    th = np.pi * np.arange(1, rings) / rings
    ph = 2 * np.pi * np.arange(segments) / segments
    T, H = np.meshgrid(th, ph, indexing="ij")
    V = np.vstack([[0, 0, 1], np.c_[(np.sin(T) * np.cos(H)).ravel(),
                                    (np.sin(T) * np.sin(H)).ravel(), np.cos(T).ravel()],
                   [0, 0, -1]])
    V = V + V * np.random.default_rng(seed).normal(0, noise, (len(V), 1))
    V = V.astype(np.float32).astype(np.float64)
    at = lambda i, j: 1 + (i - 1) * segments + j % segments  # noqa: E731
    tris = [[0, at(1, j), at(1, j + 1)] for j in range(segments)]
    for i in range(1, rings - 1):
        for j in range(segments):
            a, b, c, d = at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)
            tris += [[a, b, c], [a, c, d]]
    tris = np.array(tris)
    keep = np.zeros(len(tris), bool)
    keep[:segments] = V[tris[:segments]].mean(axis=1)[:, 2] > 0.4
    body = tris[segments:].reshape(-1, 2, 3)
    centre = V[body.reshape(len(body), 6)].mean(axis=1)  # (a quad's 4 corners: a, c twice)
    keep[segments:] = np.repeat(centre[:, 2] > 0.4, 2)  # (each quad's centroid decides)
    used, faces = np.unique(tris[keep], return_inverse=True)
    return V[used], faces.reshape(-1, 3)


def split_mesh(points, faces, mask) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two patches of a mesh, the faces ``mask`` selects and the others, each with its
    own vertices only: ``[(points, faces), (points, faces)]`` (they share the vertices of the
    border between them, at identical coordinates)."""
    out = []
    for pick in (mask, ~mask):
        used, f = np.unique(np.asarray(faces)[pick], return_inverse=True)
        out.append((np.asarray(points)[used], f.reshape(-1, 3)))
    return out


def wavy_halves(n: int = 40) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`noisy_grid` without noise, cut into two patches along the wavy line
    ``x = 0.5 + 0.1 sin 9y`` (faces by their centroids): Edit Mode's two selections."""
    pts, faces = noisy_grid(n, noise=0.0)
    c = pts[faces].mean(axis=1)
    return split_mesh(pts, faces, c[:, 0] < 0.5 + 0.1 * np.sin(9 * c[:, 1]))


def uv_sphere(segments: int, rings: int):
    """A closed UV sphere of radius 1 (poles as vertices): points, triangles."""
    th = np.pi * np.arange(1, rings) / rings
    ph = 2 * np.pi * np.arange(segments) / segments
    t, h = np.meshgrid(th, ph, indexing="ij")
    ring = np.c_[(np.sin(t) * np.cos(h)).ravel(), (np.sin(t) * np.sin(h)).ravel(),
                 np.cos(t).ravel()]
    pts = np.vstack([[0, 0, 1], ring, [0, 0, -1]])
    i, j = np.meshgrid(np.arange(rings - 2), np.arange(segments), indexing="ij")
    a = 1 + i * segments + j
    b = 1 + (i + 1) * segments + j
    c = 1 + (i + 1) * segments + (j + 1) % segments
    d = 1 + i * segments + (j + 1) % segments
    top = np.c_[np.zeros(segments, int), 1 + np.arange(segments),
                1 + (np.arange(segments) + 1) % segments]
    last = 1 + (rings - 2) * segments
    bottom = np.c_[np.full(segments, len(pts) - 1), last + (np.arange(segments) + 1) % segments,
                   last + np.arange(segments)]
    faces = np.vstack([top, np.c_[a.ravel(), b.ravel(), c.ravel()],
                       np.c_[a.ravel(), c.ravel(), d.ravel()], bottom])
    return pts, faces


def bent_sheet(n: int = 11, size: float = 100.0):
    """A sheet of ``size`` x ``size`` bent up by 90 degrees along its middle, (2n - 1) x n
    vertices: a flat half and an upright half (a user test's 231-vertex sheet)."""
    s_ = np.linspace(0, 2, 2 * n - 1)
    t_ = np.linspace(0, 1, n)
    s, t = (a.ravel() for a in np.meshgrid(s_, t_))
    points = np.c_[np.minimum(s, 1.0), t, np.maximum(s - 1.0, 0.0)] * size
    m = len(s_)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n - 1), np.arange(m - 1), indexing="ij"))
    a, b, c, d = i * m + j, i * m + j + 1, (i + 1) * m + j + 1, (i + 1) * m + j
    return points, np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def terrain_tiles(n: int = 41, spacing: float = 5.0, origin=(5.0e5, 4.2e6)):
    """Two DEM tiles of a hilly terrain (heights in m over x and y in m, at UTM-like
    coordinates ``origin``) on one grid of ``n`` x ``n`` nodes ``spacing`` apart, side by
    side: the west tile the columns up to the middle one, the east tile from it on, so the
    two share the middle column of nodes (as tiles cut from one DEM do). Returns
    ``(west, east, x_of_the_shared_column)``."""
    g = np.arange(n) * spacing
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    z = (40 * np.sin(x / 37) * np.cos(y / 53) + 15 * np.tanh((x - 0.7 * y - 20) / 8)
         + 0.3 * x + 250)
    pts = np.c_[x + origin[0], y + origin[1], z]
    mid = g[n // 2]
    return pts[x <= mid], pts[x >= mid], mid + origin[0]
