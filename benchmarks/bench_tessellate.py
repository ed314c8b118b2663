"""Tessellation benchmark: seconds and peak memory of ``TCBSurface.tessellation_uv`` by resolution.

    .venv/bin/python benchmarks/bench_tessellate.py [--resolutions 64 128 256 512 1024]

For two disk meshes and the DEM cloud (fitted once, tolerance 3e-3, budget 500), per resolution:
vertices and triangles, the seconds of ``tessellation_uv`` (cache cleared before each call,
best of 2, not traced), the peak memory it allocates (tracemalloc, a separate call), and the
seconds to evaluate the surface at those vertices (``surf(uv)``: what a Blender
re-tessellation costs on top).

Peer in the same run: the same method with every triangle from qhull's Delaunay (the lattice
of grid cells deep inside the domain switched off, as before it existed, also in the edge-split
rounds). Both must cover the same area and give nearly the same vertices (at most 0.1% not
shared: a lattice cell keeps its diagonal through the rounds, qhull may pick the other one, so
an edge may be split in one and not the other); the ratio column is peer / lattice seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import datasets as D  # noqa: E402
import core.surface as S  # noqa: E402
from core import fit_surface  # noqa: E402
from core.simplex import orient2d  # noqa: E402


def no_lattice(deep, number, origin, d):
    """``core.surface._lattice`` with no cell split directly: every point goes to Delaunay."""
    return np.zeros((0, 3), dtype=np.intp), number[number >= 0].astype(np.intp), None


def timed(surf, resolution: int, repeats: int = 2):
    """(uv, triangles, best seconds of ``repeats`` untraced calls, peak MiB of a traced one)."""
    surf._tess_cache.clear()
    tracemalloc.start()
    surf.tessellation_uv(resolution)
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    best = np.inf
    for _ in range(repeats):
        surf._tess_cache.clear()
        t0 = time.perf_counter()
        uv, tri = surf.tessellation_uv(resolution)
        best = min(best, time.perf_counter() - t0)
    return uv, tri, best, peak


def area(uv, tri) -> float:
    return 0.5 * float(orient2d(uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]).sum())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", type=int, nargs="+", default=[64, 128, 256, 512, 1024])
    args = ap.parse_args()
    sets = [D.mesh("nefertiti"), D.mesh("patch-01"), D.dem(3)]
    print("| data | resolution | vertices | triangles | tessellation_uv s | peak MiB "
          "| Delaunay-only s | peak MiB | ratio | vertices not shared | evaluate s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for d in sets:
        surf = fit_surface(d["points"], d["faces"], tolerance=3e-3, max_control_points=500)
        for r in args.resolutions:
            uv, tri, t_new, m_new = timed(surf, r)
            with mock.patch.object(S, "_lattice", no_lattice):
                uv0, tri0, t_old, m_old = timed(surf, r, repeats=1 if r > 512 else 2)
            surf._tess_cache.clear()
            # nearly the same vertices (a lattice cell keeps its diagonal through the edge-split
            # rounds, qhull may pick the other one: an edge split or not) and the same area
            differ = len(set(map(tuple, uv)) ^ set(map(tuple, uv0)))
            assert differ <= 1e-3 * len(uv0)
            assert abs(area(uv, tri) - area(uv0, tri0)) <= 1e-9 * abs(area(uv0, tri0))
            t0 = time.perf_counter()
            surf(uv)
            t_eval = time.perf_counter() - t0
            print(f"| {d['name']} | {r} | {len(uv)} | {len(tri)} | {t_new:.2f} | {m_new:.0f} "
                  f"| {t_old:.2f} | {m_old:.0f} | {t_old / t_new:.1f}x | {differ} | {t_eval:.2f} |", flush=True)
    # a long thin strip (1000:1) is all boundary strip, no lattice cell: qhull on its regular
    # grid of co-circular points, as they are (the peer) and moved by 1e-7 of a grid step
    rng = np.random.default_rng(0)
    xy = np.c_[rng.uniform(0, 1000, 1600), rng.uniform(0, 1, 1600)]
    surf = fit_surface(np.c_[xy, 0.01 * np.sin(xy[:, 0] / 50)])
    uv, tri, t_new, _ = timed(surf, 64, repeats=1)
    with mock.patch.object(S, "TESSELLATION_JITTER", 0.0):
        uv0, tri0, t_old, _ = timed(surf, 64, repeats=1)
    print(f"\nstrip 1000:1: {len(uv)} vertices, {len(tri)} triangles, {t_new:.2f} s moved, "
          f"{t_old:.2f} s as they are ({t_old / t_new:.1f}x); areas {area(uv, tri):.6g} and "
          f"{area(uv0, tri0):.6g}")
    # a ring 10 m wide and 500 m across (3e4 points along z): most of its hull is the empty
    # middle, whose triangles the trim leaves out (a bounded nearest-data search since the
    # twenty-sixth session: the unbounded one took 11.3 s at 512); peer: a square tile of as
    # many points
    th, rr = rng.uniform(0, 2 * np.pi, 30000), 500 + rng.uniform(-5, 5, 30000)
    x, y = rr * np.cos(th), rr * np.sin(th)
    shapes = {"ring 10 m x 500 m": np.c_[x, y], "square 1000 m": rng.uniform(0, 1000, (30000, 2))}
    for name, xy in shapes.items():
        pts = np.c_[xy, 3 * np.sin(xy[:, 0] / 40) + 2 * np.cos(xy[:, 1] / 30)]
        surf = fit_surface(pts, tolerance=0.05, relative=False, projection="z", max_iterations=3)
        uv, tri, t_new, _ = timed(surf, 512, repeats=1)
        print(f"{name} at 512: {len(uv)} vertices, {len(tri)} triangles, {t_new:.2f} s")


if __name__ == "__main__":
    main()
