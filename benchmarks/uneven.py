"""Clouds of uneven density: does the fit meet the tolerance where the points are few?

    .venv/bin/python benchmarks/uneven.py [--quick]

A scan's density follows the scanner, not the surface: a terrestrial scanner that dwelt in one
place, or one whose density falls as 1/r^2. The RMS over points then measures mostly the dense
part. Clouds, fitted with ``fit_surface(points, tolerance=T)`` (relative) and the defaults:

* ``dwell n``: ``n`` points N(50, 0.5) in x and y plus ``n/20`` uniform over [0, 100]^2, on
  ``z = 3 sin(x / 8)``; "sparse" is the uniform points; ``dwell n noisy``: the same with
  Gaussian noise of twice the tolerance (of the diagonal) on the sparse points' heights;
* ``lidar``: 50 000 points from a scanner at the origin, radius log-uniform in [2, 40] (density
  ~1/r^2) over a quarter disk, on ``z = 0.5 sin(x/3) cos(y/4) + 0.02 x``; "sparse" is r > 20
  (23% of the points, 76% of the area);
* ``step``: 4000 + 16 000 uniform points on the two halves of [0, 1]^2 (density 1:4) on
  Franke's function; "sparse" is the left half;
* ``even``: 20 000 uniform points of Franke's function (a control: nothing changes).

Variants, in the same process: ``points`` (``core.refine.UNEVEN_DENSITY`` set to infinity: the
RMS over points alone, as before) and ``area`` (the default: an uneven cloud must also meet the
tolerance by the RMS over its area, ``core.refine.area_weights``). Columns: control points,
fits, RMS over points, RMS over the area and RMS of the sparse part (errors at the data), the
RMS height error off the true shape at 5000 random places of the domain ("off": what a fit
that chases noise gets wrong), each over the tolerance (1.00 = just met), seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import core.refine as refine  # noqa: E402
from core import fit_surface  # noqa: E402
from datasets import f1_franke as franke  # noqa: E402


# each case: (points, sparse mask, true height z(x, y), places of the domain to compare at)
def dwell_shape(x, y):
    return 3 * np.sin(x / 8)


def dwell(n: int, seed: int, noise: float = 0.0):
    rng = np.random.default_rng(seed)
    xy = np.vstack([rng.normal(50, 0.5, (n, 2)), rng.uniform(0, 100, (n // 20, 2))])
    sparse = np.arange(len(xy)) >= n
    points = np.c_[xy, dwell_shape(*xy.T)]
    if noise:  # noise * the diagonal on the sparse points' heights
        diagonal = np.linalg.norm(np.ptp(points, axis=0))
        rng = np.random.default_rng(seed + 7)
        points[sparse, 2] += rng.normal(0, noise * diagonal, sparse.sum())
    places = np.random.default_rng(3).uniform(5, 95, (5000, 2))
    return points, sparse, dwell_shape, places


def lidar_shape(x, y):
    return 0.5 * np.sin(x / 3) * np.cos(y / 4) + 0.02 * x


def lidar(seed: int):
    rng = np.random.default_rng(seed)
    r = np.exp(rng.uniform(np.log(2), np.log(40), 50_000))
    a = rng.uniform(0, np.pi / 2, 50_000)
    x, y = r * np.cos(a), r * np.sin(a)
    g = np.random.default_rng(3)
    rr, aa = np.sqrt(g.uniform(2.5**2, 39.5**2, 5000)), g.uniform(0.02, np.pi / 2 - 0.02, 5000)
    places = np.c_[rr * np.cos(aa), rr * np.sin(aa)]
    return np.c_[x, y, lidar_shape(x, y)], r > 20, lidar_shape, places


def step(seed: int):
    rng = np.random.default_rng(seed)
    xy = np.vstack([rng.random((4000, 2)) * [0.5, 1], rng.random((16_000, 2)) * [0.5, 1] + [0.5, 0]])
    places = np.random.default_rng(3).uniform(0.02, 0.98, (5000, 2))
    return np.c_[xy, franke(*xy.T)], xy[:, 0] < 0.5, franke, places


def even(seed: int):
    xy = np.random.default_rng(seed).random((20_000, 2))
    places = np.random.default_rng(3).uniform(0.02, 0.98, (5000, 2))
    return np.c_[xy, franke(*xy.T)], xy[:, 0] < 0.5, franke, places


def run(case, tol, uneven):
    points, sparse, shape, places = case
    refine.UNEVEN_DENSITY = uneven
    t = time.perf_counter()
    surf = fit_surface(points, tolerance=tol)
    dt = time.perf_counter() - t
    r, e = surf.report, surf.errors
    unit = tol * r["diagonal"]
    w = refine.area_weights(surf.parameterization.uv)
    # off the true shape: the surface at the parameters of the true points, against the
    # true height where the surface point is
    s = surf(surf.parameterization.project(np.c_[places, shape(*places.T)]))
    off = float(np.sqrt(np.mean((s[:, 2] - shape(s[:, 0], s[:, 1])) ** 2)))
    return (r["control_points"], r["iterations"], r["rms"] / unit,
            float(np.sqrt(np.mean(w * e * e))) / unit,
            float(np.sqrt(np.mean(e[sparse] ** 2))) / unit, off / unit, dt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed, the smaller cases")
    args = ap.parse_args()
    default = refine.UNEVEN_DENSITY
    seeds = [0] if args.quick else [0, 1, 2]
    cases = [("dwell 20000", lambda s: dwell(20_000, s), 1e-3),
             ("dwell 20k noisy", lambda s: dwell(20_000, s, 2e-3), 1e-3)]
    if not args.quick:
        cases += [("dwell 100000", lambda s: dwell(100_000, s), 1e-3),
                  ("dwell 100k noisy", lambda s: dwell(100_000, s, 2e-3), 1e-3),
                  ("lidar", lidar, 3e-4), ("lidar", lidar, 1e-4)]
    cases += [("step 1:4", step, 1e-3), ("even", even, 1e-3)]
    head = f"{'case':<16} {'tol':>6} {'seed':>4} | " + " | ".join(
        f"{v:<6} {'cp':>5} {'fits':>4} {'pts':>5} {'area':>5} {'sparse':>6} {'off':>5} {'s':>5}"
        for v in ("points", "area"))
    print(head)
    print("-" * len(head))
    for name, make, tol in cases:
        for seed in seeds:
            case = make(seed)
            cols = []
            for variant, uneven in (("points", np.inf), ("area", default)):
                cp, fits, rp, ra, rs, off, dt = run(case, tol, uneven)
                cols.append(f"{variant:<6} {cp:5d} {fits:4d} {rp:5.2f} {ra:5.2f} {rs:6.2f} "
                            f"{off:5.2f} {dt:5.1f}")
            print(f"{name:<16} {tol:6.0e} {seed:4d} | " + " | ".join(cols), flush=True)
    refine.UNEVEN_DENSITY = default


if __name__ == "__main__":
    main()
