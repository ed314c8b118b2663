"""Benchmark datasets (issue 5): Renka's test functions, a synthetic crease, the Jacksboro DEM
and the disk meshes of ``data/``.

Test functions over ``[0, 1]^2`` (values and names as in R. J. Renka's ``TSTFN2``):

    R. J. Renka and R. Brown, "Algorithm 792: accuracy tests of ACM algorithms for
    interpolation of scattered data in the plane", ACM Trans. Math. Software 25(1), 1999,
    78-94 (test functions F1..F10; F1..F6 are from R. Franke, "A critical comparison of some
    methods for interpolation of scattered data", Naval Postgraduate School report
    NPS-53-79-003, 1979).

Every dataset is a dict: ``name``, ``points (N, 3)``, ``faces`` (None for clouds),
``kind`` (``"height"`` for height fields ``z = f(x, y)``, ``"mesh"``), ``sampling``
(``"scattered"``, ``"grid"``, ``"dem"``, ``"mesh"``) and ``note``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data"


# ---------------------------------------------------------------------------------------------
# Renka's test functions
# ---------------------------------------------------------------------------------------------
def f1_franke(x, y):
    """F1, Franke's exponential (Renka-Brown 1999, Franke 1979):
    ``.75 exp(-((9x-2)^2 + (9y-2)^2)/4) + .75 exp(-(9x+1)^2/49 - (9y+1)/10)
    + .5 exp(-((9x-7)^2 + (9y-3)^2)/4) - .2 exp(-(9x-4)^2 - (9y-7)^2)``."""
    return (0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
            + 0.75 * np.exp(-((9 * x + 1) ** 2) / 49 - (9 * y + 1) / 10)
            + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
            - 0.2 * np.exp(-(9 * x - 4) ** 2 - (9 * y - 7) ** 2))


def f2_cliff(x, y):
    """F2, cliff (Renka-Brown 1999): ``(tanh(9 (y - x)) + 1) / 9`` (a steep step along the
    diagonal)."""
    return (np.tanh(9.0 * (y - x)) + 1.0) / 9.0


def f6_sphere(x, y):
    """F6, sphere (Renka-Brown 1999): ``sqrt(64 - 81 ((x-.5)^2 + (y-.5)^2)) / 9 - .5`` (part of
    a sphere of radius 8/9 over the whole unit square; 0 outside that circle)."""
    t = 64.0 - 81.0 * ((x - 0.5) ** 2 + (y - 0.5) ** 2)
    return np.where(t >= 0, np.sqrt(np.maximum(t, 0.0)) / 9.0 - 0.5, 0.0)


def f7_trig(x, y):
    """F7, trig (Renka-Brown 1999): ``2 cos(10 x) sin(10 y) + sin(10 x y)``."""
    return 2.0 * np.cos(10.0 * x) * np.sin(10.0 * y) + np.sin(10.0 * x * y)


def f10_cosine_peak(x, y):
    """F10, cosine peak (Renka-Brown 1999): ``exp(-.04 r) cos(.15 r)`` with
    ``r = sqrt((80x - 40)^2 + (90y - 45)^2)`` (a cone point at the centre)."""
    r = np.sqrt((80.0 * x - 40.0) ** 2 + (90.0 * y - 45.0) ** 2)
    return np.exp(-0.04 * r) * np.cos(0.15 * r)


def crease(x, y):
    """Synthetic crease along a curve: ``0.25 |y - 0.5 - 0.15 sin(4 x)|`` (C^0 ridge line)."""
    return 0.25 * np.abs(y - 0.5 - 0.15 * np.sin(4.0 * x))


FUNCTIONS = {
    "F1-franke": f1_franke,
    "F2-cliff": f2_cliff,
    "F6-sphere": f6_sphere,
    "F7-trig": f7_trig,
    "F10-cospeak": f10_cosine_peak,
    "crease": crease,
}


def height_field(name: str, n: int, sampling: str = "scattered", seed: int = 0,
                 scale: float = 1.0) -> dict:
    """``n`` samples (scattered: uniform random; grid: ``round(sqrt(n))^2`` lattice points) of
    one of :data:`FUNCTIONS` over the unit square, heights multiplied by ``scale``."""
    f = FUNCTIONS[name]
    if sampling == "scattered":
        xy = np.random.default_rng(seed).random((n, 2))
    elif sampling == "grid":
        m = int(round(np.sqrt(n)))
        g = np.linspace(0.0, 1.0, m)
        xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    else:
        raise ValueError(sampling)
    label = name if scale == 1.0 else f"{name} x{scale:g}"
    return {"name": f"{label} {sampling}", "points": np.c_[xy, scale * f(xy[:, 0], xy[:, 1])],
            "faces": None, "kind": "height", "sampling": sampling,
            "note": (f.__doc__ or "").split("\n")[0]}


def dem(step: int = 3) -> dict:
    """The Jacksboro fault DEM (``data/jacksboro_fault_dem.npz``, 344 x 403 grid, metres after
    :func:`core.meshio.read_geometry`), every ``step``-th row and column (keeps it a grid)."""
    from core.meshio import read_geometry

    pts, _ = read_geometry(DATA / "jacksboro_fault_dem.npz")
    grid = pts.reshape(344, 403, 3)[::step, ::step].reshape(-1, 3)
    return {"name": f"jacksboro DEM /{step}", "points": grid, "faces": None, "kind": "height",
            "sampling": "dem", "note": f"real terrain, every {step}th sample, {len(grid)} points"}


def mesh(name: str) -> dict:
    """A disk-topology mesh of ``data/`` (``nefertiti``, ``three_peaks``, ``patch-01``)."""
    from core.meshio import read_geometry

    pts, faces = read_geometry(DATA / f"{name}.off")
    return {"name": f"{name}.off", "points": pts, "faces": faces, "kind": "mesh",
            "sampling": "mesh", "note": f"{len(pts)} vertices, {len(faces)} faces"}
