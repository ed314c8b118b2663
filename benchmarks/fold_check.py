"""Fold check of point clouds: which clouds are refused, and how folded the accepted ones are.

    .venv/bin/python benchmarks/fold_check.py [--noisy]

Every case has a ground truth: the triangles of the surface before it was turned (the Delaunay
triangulation of the height field's (x, y), a mesh's own faces). A parameterization folds where
those triangles flip in the parameter plane, so for an accepted cloud the column "flipped" is
the share of triangles of the minority orientation (0 for a projection without layers), with
the noise-free points projected the way the cloud was (noisy variants: noise alone would flip
many small triangles of the noisy points). A refused cloud got
``ParameterizationError`` ("folds over its best-fit plane").

Cases: the test functions of ``benchmarks/datasets.py`` on 1000, 5000 and 30 000 points,
scattered and on a grid, heights x1 and x3; sphere caps of 20-85 degrees; the Jacksboro DEM
(all of it and every 7th point); scan lines; the vertices of the bundled meshes; each as given
and turned at random (``--noisy``: also with noise of 0.5% of the extent); and a spiral sheet
rolled 1.5 turns in 64 and 32 bits. The last lines count the clouds refused, accepted with more
than 1% flipped triangles (a folded parameterization: a wrong surface), and accepted without.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import Delaunay

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import datasets as D  # noqa: E402
from core.errors import TCBError  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from core.parameterize import parameterize_points  # noqa: E402


def turn(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def cap(n: int, degrees: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z = rng.uniform(np.cos(np.radians(degrees)), 1, n)
    t = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    return np.c_[r * np.cos(t), r * np.sin(t), z]


def cases():
    for name in D.FUNCTIONS:
        for n in (1000, 5000, 30000):
            for sampling in ("scattered", "grid"):
                for scale in (1.0, 3.0):
                    pts = D.height_field(name, n, sampling, scale=scale)["points"]
                    yield f"{name} {n} {sampling} x{scale:g}", pts, None
    for degrees in (20, 45, 60, 75, 85):
        yield f"cap {degrees} deg", cap(4000, degrees, degrees), None
    dem = read_geometry(ROOT / "data" / "jacksboro_fault_dem.npz")[0]
    yield "DEM", dem, None
    yield "DEM every 7th", dem[::7], None
    x, y = np.meshgrid(np.linspace(0, 1, 800), np.linspace(0, 1, 25))
    yield "25 scan lines", np.c_[x.ravel(), y.ravel(), 0.2 * np.sin(3 * x.ravel()) * y.ravel()], None
    for mesh in ("nefertiti", "patch-01", "three_peaks"):
        pts, faces = read_geometry(ROOT / "data" / f"{mesh}.off")
        yield f"{mesh} vertices", pts, faces


def flipped(uv: np.ndarray, tri: np.ndarray) -> float:
    a = uv[tri]
    det = ((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
           - (a[:, 1, 1] - a[:, 0, 1]) * (a[:, 2, 0] - a[:, 0, 0]))
    return float(min(np.mean(det < 0), np.mean(det > 0)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--noisy", action="store_true", help="also the noisy turned variants")
    args = ap.parse_args()
    variants = ("", "turned", "noisy turned") if args.noisy else ("", "turned")
    print("| cloud | variant | result | flipped |")
    print("|---|---|---|---:|")
    count = {"refused": 0, "folded": 0, "ok": 0}
    t, s = np.meshgrid(np.linspace(0, 3 * np.pi, 60), np.linspace(0, 1, 20))
    r = 1 + 0.3 * t.ravel()
    spiral = np.column_stack([np.cos(t.ravel()) * r, 3 * s.ravel(), np.sin(t.ravel()) * r])
    for dtype in (np.float64, np.float32):
        try:
            parameterize_points(spiral.astype(dtype).astype(np.float64))
            print(f"| spiral sheet | {np.dtype(dtype).name} | ACCEPTED | |")
        except TCBError:
            print(f"| spiral sheet | {np.dtype(dtype).name} | refused | |")
    for i, (name, pts, faces) in enumerate(cases()):
        tri = faces if faces is not None else Delaunay(pts[:, :2]).simplices
        for variant in variants:
            clean = np.asarray(pts, dtype=np.float64)
            if variant:
                clean = clean @ turn(i).T
            q = clean
            if variant.startswith("noisy"):
                q = clean + (0.005 * np.ptp(clean, axis=0).max()
                             * np.random.default_rng(i).normal(size=clean.shape))
            try:
                share = flipped(parameterize_points(q, None).project(clean), tri)
            except TCBError:
                count["refused"] += 1
                print(f"| {name} | {variant or 'as given'} | refused | |", flush=True)
                continue
            count["folded" if share > 0.01 else "ok"] += 1
            print(f"| {name} | {variant or 'as given'} | accepted | {share:.4f} |", flush=True)
    print(f"\nrefused {count['refused']}, accepted with > 1% flipped triangles {count['folded']}, "
          f"accepted without {count['ok']}")


if __name__ == "__main__":
    main()
