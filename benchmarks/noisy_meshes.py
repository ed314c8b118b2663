"""Noisy meshes: how many control points a scan's noise costs, and how far from the noise-free
shape the fit ends, with the mesh's vertices counted alone against the net (the default where
the mesh's noise is at least ``core.surface.NOISE_COUNTS`` of the tolerance, with its errors
taken across the surface and its folds weighed against normals smooth over the noise) or as
before (``samples``: NOISE_COUNTS set to infinity, which turns all three off), and as through
the thirty-seventh session (``before``: the faces of every such mesh sampled flat,
``core.surface.FACET_SAG_OVER_NOISE`` set to infinity, instead of curved where the facets' sag
outweighs the noise, ``core.surface.facet_sag``; and its net not capped at one control point per
vertex, ``core.refine.NOISY_NET_PER_VERTEX`` set to infinity), in the same run.

    .venv/bin/python benchmarks/noisy_meshes.py [--quick] [--tolerances 1e-3 1e-4]

Cases: grid meshes of ``0.2 sin 4x cos 3y + 0.1 xy`` over the unit square (tests/meshes.py's
``noisy_grid``) of 41 x 41 and 81 x 81 vertices, and the bundled ``three_peaks.off`` (1907
vertices), with Gaussian noise of the given share of the diagonal on every coordinate of every
vertex (seeded); caps of UV spheres of radius 1 (tests/meshes.py's ``noisy_sphere_cap``, 32 x 16
and 64 x 32 segments: coarse meshes of a curved shape) with noise of the given share of the
radius along the normals; and clean meshes, where nothing may change (``three_peaks.off`` and a
41 x 41 grid, noise 0). Columns: the noise given and measured (``report["noise_rel"]``,
``core.parameterize.local_noise``, over the diagonal); then per variant the control points,
how the faces were sampled (``report["face_samples"]``), the stop reason, the RMS at the
vertices over the diagonal, *true*: the RMS distance over the diagonal from the noise-free shape
(the mesh without noise; the sphere for a cap) of the surface at 20 000 random points of the
faces' parameters (``core.geometry.point_mesh_distance``), the share of the mesh's area where the
surface folds over (``report["folded"]``), and seconds.
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

import core.refine as R  # noqa: E402
import core.surface as S  # noqa: E402
from core import fit_surface  # noqa: E402
from core.geometry import point_mesh_distance  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from meshes import noisy_grid, noisy_sphere_cap  # noqa: E402

STOPS = {"tolerance reached": "tolerance", "control-point budget reached": "budget",
         "the error stopped falling": "stalled"}


def cases(quick: bool) -> list:
    """(name, noise share, clean vertices (None: the unit sphere), noisy vertices, faces)."""
    out = []
    grids = [(41, 0.002), (41, 0.005)] if quick else [
        (41, 0.0), (41, 0.001), (41, 0.002), (41, 0.005), (81, 0.002), (81, 0.005)]
    for n, noise in grids:
        clean, faces = noisy_grid(n, 0.0)
        out.append((f"grid {n} x {n}", noise, clean, noisy_grid(n, noise)[0], faces))
    caps = [(32, 0.002)] if quick else [(32, 0.002), (32, 0.005), (64, 0.002), (64, 0.005)]
    for segments, noise in caps:
        noisy, faces = noisy_sphere_cap(noise=noise, segments=segments, rings=segments // 2)
        out.append((f"cap {segments} x {segments // 2}", noise, None, noisy, faces))
    if not quick:
        clean, faces = read_geometry(ROOT / "data" / "three_peaks.off")
        diagonal = np.linalg.norm(np.ptp(clean, axis=0))
        for noise in (0.0, 0.001, 0.003):
            shaken = clean + noise * diagonal * np.random.default_rng(0).standard_normal(
                clean.shape)
            out.append(("three_peaks.off", noise, clean, shaken, faces))
    return out


def off_clean(surf, clean, faces) -> np.ndarray:
    """Distances from the mesh ``clean`` (``faces``; None: the unit sphere) of ``surf`` at
    20 000 seeded random points of the faces in the parameters (the noise along the surface,
    which moves the vertices' parameters with them, is no error of the fit)."""
    uv = np.asarray(surf.parameterization.uv)
    rng = np.random.default_rng(5)
    corners = uv[faces[rng.integers(len(faces), size=20_000)]]
    at = surf((corners * rng.dirichlet([1, 1, 1], 20_000)[:, :, None]).sum(axis=1))
    if clean is None:
        return np.abs(np.linalg.norm(at, axis=1) - 1.0)
    return point_mesh_distance(at, clean, faces)


def timed_fit(points, faces, tolerance: float):
    """``fit_surface`` of a mesh at ``tolerance``, its warnings silenced: (surface, seconds)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        surf = fit_surface(points, faces, tolerance=tolerance)
        return surf, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="two noisy grids at 1e-3")
    ap.add_argument("--tolerances", type=float, nargs="*")
    args = ap.parse_args()
    tolerances = args.tolerances or ([1e-3] if args.quick else [1e-3, 1e-4])
    print("| mesh | vertices | noise | measured | tolerance | variant | cp | faces | stop | RMS "
          "| true | folded | s |")
    print("|---|---:|---:|---:|---:|---|---:|---|---|---:|---:|---:|---:|")
    counts, sag, cap = S.NOISE_COUNTS, S.FACET_SAG_OVER_NOISE, R.NOISY_NET_PER_VERTEX
    for name, noise, clean, noisy, faces in cases(args.quick):
        for tol in tolerances:
            for variant in ("samples", "before", "now"):
                S.NOISE_COUNTS = np.inf if variant == "samples" else counts
                S.FACET_SAG_OVER_NOISE = np.inf if variant == "before" else sag
                R.NOISY_NET_PER_VERTEX = np.inf if variant == "before" else cap
                try:
                    surf, seconds = timed_fit(noisy, faces, tol)
                finally:
                    S.NOISE_COUNTS, S.FACET_SAG_OVER_NOISE = counts, sag
                    R.NOISY_NET_PER_VERTEX = cap
                r = surf.report
                true = float(np.sqrt(np.mean(off_clean(surf, clean, faces) ** 2))) / r["diagonal"]
                print(f"| {name} | {len(noisy)} | {noise:g} | {r['noise_rel']:.2e} | {tol:g} | "
                      f"{variant} | {r['control_points']} | {r['face_samples']} | "
                      f"{STOPS.get(r['stop_reason'], r['stop_reason'])} | {r['rms_rel']:.2e} | "
                      f"{true:.2e} | {100 * r['folded']:.2f}% | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
