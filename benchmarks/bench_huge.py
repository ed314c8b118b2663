"""Huge-input benchmark (issue 6): 1e7 scattered points of Franke's function.

Above ``core.surface.MAX_FIT_POINTS`` (2e6) the fit runs on a seeded random subset (a
RuntimeWarning says so) while the errors are reported for every point. Prints seconds, peak
memory (``ru_maxrss``), control points, relative RMS, and whether all errors are finite.

    .venv/bin/python benchmarks/bench_huge.py [--points 10000000]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from core import fit_surface  # noqa: E402
from datasets import f1_franke  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--iterations", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    xy = rng.random((args.points, 2))
    points = np.c_[xy, f1_franke(*xy.T)]
    del xy
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        surf = fit_surface(points, max_iterations=args.iterations, max_control_points=5000)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{'points':>10} {'seconds':>8} {'peak MiB':>9} {'ctrl':>6} {'rms/diag':>9} "
          f"{'subsampled':>10} {'errors finite':>13}")
    print(f"{args.points:>10} {seconds:>8.1f} {peak:>9.0f} {surf.report['control_points']:>6} "
          f"{surf.report['rms_rel']:>9.2e} {str(surf.report['subsampled']):>10} "
          f"{str(bool(np.isfinite(surf.errors).all())):>13}")
    for w in caught:
        print("warning:", w.message)


if __name__ == "__main__":
    main()
