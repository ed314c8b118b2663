"""Noisy borders: a scanned sheet's four corners, read from its border's turns alone (``before``,
as through the thirty-eighth session: ``core.parameterize._turn_corners``) or also at coarser
scales where the border is ragged (``now``, ``core.parameterize.boundary_corners``), in the same
run. Noise on the border's vertices turns them by tens of degrees and hid the corners: such a
mesh went to the circle, which squeezes a square's corners.

    .venv/bin/python benchmarks/noisy_borders.py [--quick]

Cases: grid meshes of ``0.2 sin 4x cos 3y + 0.1 xy`` over the unit square (tests/meshes.py's
``noisy_grid``) of 100 x 100 to 317 x 317 vertices with Gaussian noise of the given share of the
diagonal on every coordinate of every vertex (seeded), a strip of 300 x 30 vertices of the same
function over [0, 3] x [0, 0.3], a grid without noise (nothing may change), and the noisy cap of
a 64 x 32 UV sphere (tests/meshes.py's ``noisy_sphere_cap``: a round border, the circle either
way). Columns: the map the fit took (``circle``; ``rectangle``; ``own``: the border's own shape
flattened or projected, ``core.parameterize.FLAT_BOUNDARY``), the control points, the largest
error at the vertices over the diagonal, *surface to true*: the RMS and largest distance from the
noise-free shape (the grid without noise; the sphere) of the surface at 20 000 random points of
the faces' parameters (benchmarks/noisy_meshes.py's ``off_clean``), *true to surface*: the
largest distance of the noise-free vertices from the surface (``TCBSurface.distances``: where
the surface does not reach the corners), and seconds. Default settings otherwise.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import core.parameterize as pz  # noqa: E402
from core import fit_surface  # noqa: E402
from meshes import noisy_grid, noisy_sphere_cap, wavy  # noqa: E402
from noisy_meshes import off_clean  # noqa: E402


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
        noisy, faces = noisy_sphere_cap(noise=0.002, segments=64, rings=32)
        out.append(("cap 64 x 32", 0.002, 1e-3, noisy, None, faces))
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
    ap.add_argument("--quick", action="store_true", help="one noisy 100 x 100 grid")
    args = ap.parse_args()
    print("| mesh | vertices | noise | tolerance | variant | map | cp | max | surface to true: "
          "RMS | max | true to surface: max | s |")
    print("|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|")
    shipped = pz.boundary_corners
    for name, noise, tol, noisy, clean, faces in cases(args.quick):
        for variant in ("before", "now"):
            pz.boundary_corners = (shipped if variant == "now"
                                   else lambda b, ears=None: pz._turn_corners(b))
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    surf = fit_surface(noisy, faces, tolerance=tol)
                    seconds = time.perf_counter() - t0
            finally:
                pz.boundary_corners = shipped
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
