"""A tolerance below the noise: how far from the true shape the adaptive loop ends up.

    .venv/bin/python benchmarks/noise.py [--quick]

A smooth height field ``0.3 exp(-4 r^2) + 0.1 sin 3x cos 2y`` on [-1, 1]^2, ``n`` uniform random
points with Gaussian noise ``sigma`` on the heights, fitted with ``fit_surface(points,
tolerance=1e-4)`` (relative; far below every noise level here) and the other defaults, then
``refine(points, tolerance=rms_rel / 2)`` as Blender's Refine does by default. Columns per
variant: control points, fits, RMS on the data, the true error (vertical RMS against the
function at a 150 x 150 grid of [-0.95, 0.95]^2, where the surface covers it), seconds.

Variants, in the same process:

* ``before``: the stall rule on the RMS of the data, the lowest-RMS fit returned, the default
  smoothness kept (``core.refine`` switches ``STALL_DOF``, ``BEST_BY_NEW_POINTS`` and
  ``CROSS_VALIDATE_STALLED`` off);
* ``now``: the defaults: the stall test on the estimate of the error at new points, a stalled
  run returns the fit of the lowest estimate, and its default smoothness is cross-validated.

The window that insertions doubling the knots fill, and the stall test's baseline at the start
of the insertion chain, are the same in both variants.

A second table: clean test functions (``benchmarks/datasets.py``) on 1500-3000 points with a
tolerance they cannot reach, where the run stops with few points per control point; the true
error is against the function on a 120 x 120 grid of [0.02, 0.98]^2.
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

import core.refine as R  # noqa: E402
import datasets as D  # noqa: E402
from core import fit_surface  # noqa: E402

SWITCHES = ("STALL_DOF", "BEST_BY_NEW_POINTS", "CROSS_VALIDATE_STALLED")
CLEAN = [("F6-sphere", 3000, 1e-7), ("F10-cospeak", 1500, 1e-5), ("F10-cospeak", 3000, 1e-5),
         ("crease", 3000, 1e-5), ("F2-cliff", 3000, 1e-6), ("F1-franke", 3000, 1e-5)]
CASES = [(1000, 0.01), (2000, 0.01), (4000, 0.01), (10000, 0.01), (40000, 0.01),
         (4000, 0.003), (20000, 0.001), (100000, 0.003)]


def shape(x, y):
    return 0.3 * np.exp(-4 * (x * x + y * y)) + 0.1 * np.sin(3 * x) * np.cos(2 * y)


def true_error(surf, truth) -> float:
    uv = surf.parameterization.project(truth)
    ok = surf.covers(uv)
    return float(np.sqrt(np.mean((surf(uv[ok])[:, 2] - truth[ok, 2]) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="the first four cases")
    args = ap.parse_args()
    g = np.linspace(-0.95, 0.95, 150)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    truth = np.c_[grid, shape(*grid.T)]
    print("| points | noise | variant | fit: cp | fits | RMS | true | s | refine: cp | fits | RMS "
          "| true | s |")
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    totals = {"before": [0.0, 0.0], "now": [0.0, 0.0]}
    for n, sigma in CASES[:4] if args.quick else CASES:
        rng = np.random.default_rng(n)
        xy = rng.uniform(-1, 1, (n, 2))
        points = np.c_[xy, shape(*xy.T) + sigma * rng.standard_normal(n)]
        for variant in ("before", "now"):
            for name in SWITCHES:
                setattr(R, name, variant == "now")
            t0 = time.perf_counter()
            surf = fit_surface(points, tolerance=1e-4)
            t1 = time.perf_counter()
            more = surf.refine(points, tolerance=surf.report["rms_rel"] / 2)
            t2 = time.perf_counter()
            cells = []
            for s, dt in ((surf, t1 - t0), (more, t2 - t1)):
                r = s.report
                fits = len(r["history"]) - (len(surf.report["history"]) if s is more else 0)
                cells += [r["control_points"], fits, f"{r['rms']:.4f}",
                          f"{true_error(s, truth):.5f}", f"{dt:.1f}"]
            totals[variant][0] += t1 - t0
            totals[variant][1] += t2 - t1
            print(f"| {n} | {sigma} | {variant} | " + " | ".join(map(str, cells)) + " |",
                  flush=True)
    print("\n| function | points | tolerance | variant | cp | fits | RMS/diag | true | smoothness "
          "| stop |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---|")
    g = np.linspace(0.02, 0.98, 120)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    for name, n, tol in CLEAN[:2] if args.quick else CLEAN:
        points = D.height_field(name, n)["points"]
        clean_truth = np.c_[grid, D.FUNCTIONS[name](*grid.T)]
        for variant in ("before", "now"):
            for switch in SWITCHES:
                setattr(R, switch, variant == "now")
            r = (surf := fit_surface(points, tolerance=tol)).report
            print(f"| {name} | {n} | {tol:g} | {variant} | {r['control_points']} | "
                  f"{r['iterations']} | {r['rms_rel']:.2e} | {true_error(surf, clean_truth):.2e} | "
                  f"{r['smoothness']:.3g} | {r['stop_reason']} |", flush=True)
    for name in SWITCHES:
        setattr(R, name, True)
    print(f"\ntotal seconds: fit {totals['before'][0]:.1f} before, {totals['now'][0]:.1f} now; "
          f"refine {totals['before'][1]:.1f} before, {totals['now'][1]:.1f} now")


if __name__ == "__main__":
    main()
