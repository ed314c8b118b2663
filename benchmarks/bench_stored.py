"""What a fitted surface costs to store: bytes per input point and seconds to write and read it,
full (``TCBSurface.to_bytes()``, float64, bit-exact) against compact (``to_bytes(compact=True)``,
the data's parameters and errors in float32: what Blender keeps in the .blend, as base64 text).

Data: Franke's function on a scattered cloud (coordinates rounded to float32, as Blender's) and
on a grid mesh of about the same number of vertices; one fit of ``--iterations`` each. Prints a
markdown table; the ratio column is full over compact, measured in the same run.

    .venv/bin/python benchmarks/bench_stored.py [--sizes 100000 1000000] [--quick]
"""

from __future__ import annotations

import argparse
import base64
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from core import TCBSurface, fit_surface  # noqa: E402
from datasets import f1_franke  # noqa: E402


def cloud(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    pts = np.c_[xy, f1_franke(*xy.T) + 1e-3 * rng.standard_normal(n)]
    return pts.astype(np.float32).astype(np.float64), None


def grid_mesh(n: int):
    m = max(int(round(np.sqrt(n))), 3)
    u, v = np.meshgrid(np.linspace(0, 1, m), np.linspace(0, 1, m))
    pts = np.c_[u.ravel(), v.ravel(), f1_franke(u.ravel(), v.ravel())]
    i = np.arange(m * m).reshape(m, m)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return pts.astype(np.float32).astype(np.float64), np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def best_of(fn, repeat: int = 3):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", nargs="*", type=int, default=[100_000, 1_000_000])
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="2e4 points only")
    args = ap.parse_args()
    sizes = [20_000] if args.quick else args.sizes
    print("| data | points | control points | full B/point | compact B/point | ratio "
          "| write full / compact (s) | read full / compact (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for n in sizes:
        for name, make in (("cloud", cloud), ("grid mesh", grid_mesh)):
            pts, faces = make(n)
            surf = fit_surface(pts, faces, max_iterations=args.iterations)
            row = {}
            for compact in (False, True):
                wt, blob = best_of(lambda: base64.b64encode(surf.to_bytes(compact=compact)))
                rt, back = best_of(lambda: TCBSurface.from_bytes(base64.b64decode(blob)))
                assert np.isfinite(back(back.tessellation_uv(16)[0])).all()
                row[compact] = (len(blob) / len(pts), wt, rt)
            (fb, fw, fr), (cb, cw, cr) = row[False], row[True]
            print(f"| {name} | {len(pts)} | {len(surf.control_points)} | {fb:.1f} | {cb:.1f} "
                  f"| {fb / cb:.2f} | {fw:.2f} / {cw:.2f} | {fr:.2f} / {cr:.2f} |", flush=True)


if __name__ == "__main__":
    main()
