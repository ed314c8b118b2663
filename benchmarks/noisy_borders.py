"""Noisy borders: a scanned sheet's map as through the thirty-eighth session (``before``: its four
corners read from its border's turns alone, ``core.parameterize._turn_corners``, and its own
shape flattened from its noisy vertices) and now (``now``: the corners also read at coarser
scales where the border is ragged, ``core.parameterize.boundary_corners``, and a mesh left on
the circle trying its own shape again of its vertices smoothed,
``core.parameterize._denoised_own_map``), in the same run. Noise on the border's vertices turns
them by tens of degrees and hid the corners, and it made the flattened border overlap itself or
its map flip triangles: such a mesh went to the circle, which squeezes its corners.

    .venv/bin/python benchmarks/noisy_borders.py [--quick]

Cases: grid meshes of ``0.2 sin 4x cos 3y + 0.1 xy`` over the unit square (tests/meshes.py's
``noisy_grid``) of 100 x 100 to 317 x 317 vertices with Gaussian noise of the given share of the
diagonal on every coordinate of every vertex (seeded), a strip of 300 x 30 vertices of the same
function over [0, 3] x [0, 0.3], a grid without noise (nothing may change), the noisy cap of a
64 x 32 UV sphere (tests/meshes.py's ``noisy_sphere_cap``: a round border, the circle either
way), and parts of the noisy 100 x 100 grid: the faces outside its upper right quarter (an L),
below its diagonal (a triangle) and inside a wavy ragged border (benchmarks/mesh_maps.py's
``ragged``), and a 150 x 100 grid with bitten sides (``bitten``). Columns: the map the fit took
(``circle``; ``rectangle``; ``own``: the border's own shape flattened or projected,
``core.parameterize.FLAT_BOUNDARY``), the control points, the largest
error at the vertices over the diagonal, *surface to true*: the RMS and largest distance from the
noise-free shape (the grid without noise; the sphere) of the surface at 20 000 random points of
the faces' parameters (benchmarks/noisy_meshes.py's ``off_clean``), *true to surface*: the
largest distance of the noise-free vertices from the surface (``TCBSurface.distances``: where
the surface does not reach the corners), and seconds. Default settings otherwise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import core.parameterize as pz  # noqa: E402
from meshes import noisy_grid, noisy_sphere_cap, wavy  # noqa: E402
from noisy_meshes import off_clean, timed_fit  # noqa: E402


def strip(nx: int, ny: int, noise: float, length: float = 3.0, width: float = 0.3):
    """A grid mesh of nx x ny vertices of ``wavy`` over [0, length] x [0, width] with Gaussian
    noise of ``noise`` times its diagonal on every coordinate (seeded): (noisy, clean, faces)."""
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, length, nx),
                                           np.linspace(0, width, ny)))
    clean = np.column_stack([u, v, wavy(u, v)])
    noisy = clean + noise * np.linalg.norm(np.ptp(clean, axis=0)) * (
        np.random.default_rng(0).standard_normal(clean.shape))
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    faces = np.concatenate([np.column_stack([a, a + 1, a + nx + 1]),
                            np.column_stack([a, a + nx + 1, a + nx])])
    return noisy, clean, faces


def _bites(count: int, rng) -> np.ndarray:
    """How deep (0-3 cells) a side of ``count`` cells is bitten at each: runs of 3-10 cells at
    one depth, 0 with probability 1/2, none within 4 cells of its ends."""
    runs = rng.integers(3, 11, size=count)
    depth = np.where(rng.random(count) < 0.5, 0, rng.integers(1, 4, size=count))
    out = np.repeat(depth, runs)[:count]
    out[:4] = out[-4:] = 0
    return out


def bitten(noise: float, seed: int = 40, nx: int = 150, ny: int = 100):
    """A grid mesh of nx x ny vertices of ``wavy`` over [0, 1.5] x [0, 1] whose sides are bitten
    by up to 3 cells (:func:`_bites`, seeded: a scan's ragged edge, as the user test's), with
    Gaussian noise of ``noise`` times its diagonal on every coordinate: (noisy, clean,
    faces)."""
    rng = np.random.default_rng(seed)
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1.5, nx), np.linspace(0, 1, ny)))
    clean = np.column_stack([u, v, wavy(u, v)])
    i, j = (a.ravel() for a in np.meshgrid(np.arange(nx - 1), np.arange(ny - 1)))
    bottom, top = _bites(nx - 1, rng), _bites(nx - 1, rng)
    left, right = _bites(ny - 1, rng), _bites(ny - 1, rng)
    keep = ((j >= bottom[i]) & (ny - 2 - j >= top[i]) & (i >= left[j])
            & (nx - 2 - i >= right[j]))
    a = (j * nx + i)[keep]
    faces = np.concatenate([np.column_stack([a, a + 1, a + nx + 1]),
                            np.column_stack([a, a + nx + 1, a + nx])])
    used = np.unique(faces)
    index = np.full(len(clean), -1)
    index[used] = np.arange(len(used))
    clean = clean[used]
    noisy = clean + noise * np.linalg.norm(np.ptp(clean, axis=0)) * rng.standard_normal(
        clean.shape)
    return noisy, clean, index[faces]


def cases(quick: bool) -> list:
    """(name, noise, tolerance, noisy vertices, clean vertices (None: the unit sphere), faces)."""
    grids = [(100, 0.002, 3e-3)] if quick else [
        (100, 0.002, 3e-3), (200, 0.0, 1e-3), (200, 0.001, 1e-3), (200, 0.002, 1e-3),
        (317, 0.001, 1e-3)]
    out = []
    for n, noise, tol in grids:
        noisy, faces = noisy_grid(n, noise)
        out.append((f"grid {n} x {n}", noise, tol, noisy, noisy_grid(n, 0.0)[0], faces))
    if not quick:
        noisy, clean, faces = strip(300, 30, 0.001)
        out.append(("strip 300 x 30", 0.001, 1e-3, noisy, clean, faces))
        noisy, clean, faces = bitten(0.002)
        out.append(("bitten 150 x 100", 0.002, 1e-3, noisy, clean, faces))
        noisy, faces = noisy_sphere_cap(noise=0.002, segments=64, rings=32)
        out.append(("cap 64 x 32", 0.002, 1e-3, noisy, None, faces))
    clean, faces = noisy_grid(100, 0.0)
    x, y = clean[faces].mean(axis=1)[:, :2].T - 0.5
    angle = np.arctan2(y, x)
    parts = {"L": ~((x > 0) & (y > 0)), "triangle": y < x,
             "ragged": np.hypot(x, y) < 0.42 + 0.05 * np.sin(5 * angle) + 0.03 * np.sin(
                 13 * angle + 1)}
    for part, keep in parts.items() if not quick else [("L", parts["L"])]:
        for noise in (0.001, 0.002) if not quick else (0.002,):
            used = np.unique(faces[keep])
            index = np.full(len(clean), -1)
            index[used] = np.arange(len(used))
            out.append((f"{part} of grid 100 x 100", noise, 3e-3 if quick else 1e-3,
                        noisy_grid(100, noise)[0][used],
                        clean[used], index[faces[keep]]))
    return out


def which(surf) -> str:
    """The map a mesh's fit took: its border on the unit circle, on a rectangle, or its own."""
    par = surf.parameterization
    edge = np.asarray(par.uv)[np.asarray(par.boundary)]
    if np.allclose(np.hypot(edge[:, 0], edge[:, 1]), 1.0):
        return "circle"
    w, h = np.abs(edge).max(axis=0)
    on_side = np.isclose(np.abs(edge[:, 0]), w) | np.isclose(np.abs(edge[:, 1]), h)
    return "rectangle" if on_side.all() else "own"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="one noisy 100 x 100 grid and an L-shaped part of it, at 3e-3")
    args = ap.parse_args()
    print("| mesh | vertices | noise | tolerance | variant | map | cp | max | surface to true: "
          "RMS | max | true to surface: max | s |")
    print("|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|")
    shipped = pz.boundary_corners
    for name, noise, tol, noisy, clean, faces in cases(args.quick):
        for variant in ("before", "now"):
            if variant == "before":
                pz.boundary_corners = lambda b, ears=None: pz._turn_corners(b)
                pz.MAP_DENOISE = False
            try:
                surf, seconds = timed_fit(noisy, faces, tol)
            finally:
                pz.boundary_corners, pz.MAP_DENOISE = shipped, True
            r = surf.report
            d = r["diagonal"]
            there = off_clean(surf, clean, faces) / d
            true = (noisy / np.linalg.norm(noisy, axis=1)[:, None] if clean is None
                    else clean)  # (the sphere: the noisy vertices' directions on it)
            back = surf.distances(true) / d
            print(f"| {name} | {len(noisy)} | {noise:g} | {tol:g} | {variant} | {which(surf)} | "
                  f"{r['control_points']} | {r['max_rel']:.2e} | "
                  f"{np.sqrt(np.mean(there ** 2)):.2e} | {there.max():.2e} | {back.max():.2e} | "
                  f"{seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
