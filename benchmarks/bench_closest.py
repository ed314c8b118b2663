"""Closest points (``TCBSurface.distances``, what Blender's Deviation Map runs on every input
point): seconds and accuracy at a fit's own data and at points around it.

    .venv/bin/python benchmarks/bench_closest.py [--points 200000] [--quick]

Fits (made once per run): Franke's function on ``--points`` random points with noise 1e-3, and
the DEM (all 138 632 nodes; ``--quick``: 5000 points and every 16th node). Rows, each on the same points in the same process:

* ``now``: ``surf.distances(p)`` as shipped;
* ``every start``: the same search with both descents for every point of a cloud and no stop
  on a distance that no longer changes (``CLOSEST_SAME_BASIN = -1``,
  ``CLOSEST_DISTANCE_TOL = 0``): the search before the nineteenth session (with today's
  evaluation of the surface, 0.65-0.75x the time of the sparse matrices it used), the
  reference for the accuracy columns (``larger``: the largest amount by which ``now`` is farther, over the
  diagonal, and at how many points it is farther by more than 1e-9 of it);
* ``mesh vertices``: the peer a user would reach for, the distance to the nearest vertex of
  the surface tessellated at 256 steps (scipy's cKDTree; the tessellation's time included),
  which overestimates by up to about half a triangle.

``data``: the fitted points themselves (the Deviation Map's case); ``around``: 20 000 points
(``--quick``: 2000) uniform in the box grown by 20% on each side.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import core.surface  # noqa: E402
from core import fit_surface  # noqa: E402
from datasets import f1_franke  # noqa: E402


def cases(n: int, dem_step: int):
    from core.meshio import read_geometry

    xy = np.random.default_rng(0).random((n, 2))
    pts = np.c_[xy, f1_franke(*xy.T) + np.random.default_rng(1).normal(0, 1e-3, n)]
    yield "franke", pts
    dem, _ = read_geometry(ROOT / "data" / "jacksboro_fault_dem.npz")
    yield "dem", dem[::dem_step]


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=200_000)
    ap.add_argument("--quick", action="store_true",
                    help="5000 points, every 16th DEM node, 2000 around")
    args = ap.parse_args()
    n, dem_step, n_around = (5000, 16, 2000) if args.quick else (args.points, 1, 20_000)
    warnings.simplefilter("ignore", RuntimeWarning)
    print(f"{'dataset':8s} {'where':7s} {'points':>7s} | {'now s':>6s} {'every start s':>13s} "
          f"{'ratio':>6s} | {'larger':>8s} {'at':>5s} | {'mesh vertices s':>15s} {'its max over':>12s}")
    for name, pts in cases(n, dem_step):
        surf = fit_surface(pts, tolerance=1e-3)
        surf.distances(pts[:10])  # (the starting tessellation, cached)
        diag = surf.report["diagonal"]
        v, _ = surf.tessellate(96)
        lo, hi = v.min(axis=0), v.max(axis=0)
        around = np.random.default_rng(4).uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo),
                                                  (n_around, 3))
        for where, p in (("data", pts), ("around", around)):
            now, t_now = timed(lambda: surf.distances(p))
            basin, tol = core.surface.CLOSEST_SAME_BASIN, core.surface.CLOSEST_DISTANCE_TOL
            core.surface.CLOSEST_SAME_BASIN, core.surface.CLOSEST_DISTANCE_TOL = -1.0, 0.0
            try:
                ref, t_ref = timed(lambda: surf.distances(p))
            finally:
                core.surface.CLOSEST_SAME_BASIN, core.surface.CLOSEST_DISTANCE_TOL = basin, tol

            def peer():
                V, _ = surf.tessellate(256)
                return cKDTree(V).query(p, workers=-1)[0]

            near, t_peer = timed(peer)
            over = (now - ref) / diag
            print(f"{name:8s} {where:7s} {len(p):7d} | {t_now:6.2f} {t_ref:13.2f} "
                  f"{t_ref / t_now:6.2f} | {over.max():8.1e} {int((over > 1e-9).sum()):5d} | "
                  f"{t_peer:15.2f} {((near - ref) / diag).max():12.1e}", flush=True)


if __name__ == "__main__":
    main()
