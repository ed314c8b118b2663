"""Fitting benchmark (issue 3): seconds per phase and peak memory for 1e4, 1e5, 1e6 points.

Each case runs in its own subprocess so that peak memory (``ru_maxrss``) is its own. Cases:
Franke's function on scattered points and the Jacksboro DEM (138k points; smaller sizes are
subsamples), each as (a) one fit with a fixed knot count (``max_iterations=1``) and (b) a full
adaptive reconstruction: the loop with no tolerance, refining until the budget of 5000 control
points (above 2e5 points its iterations fit a 2e5 subset and the result is refitted to all
points; that refit is in the phase columns). Columns: seconds of the parameterization
(a separate call before the fit; the fit makes its own, inside "total"), the initial knot
placement, the configurations (spaces), basis evaluation, assembly, fairing, solve and the knot
insertion (all summed over the iterations), peak RSS. Peer in the same run: scipy's
``LSQBivariateSpline`` (FITPACK, cubic) with about as many coefficients on the same points.

    python benchmarks/bench_fit.py [--quick] [--sizes 10000 100000 1000000]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from datasets import f1_franke as franke  # noqa: E402


def dataset(name: str, n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    if name == "franke":
        xy = rng.random((n, 2))
        return np.c_[xy, franke(*xy.T)]
    from core.meshio import read_geometry

    pts, _ = read_geometry(ROOT / "data" / "jacksboro_fault_dem.npz")
    if n < len(pts):
        pts = pts[np.sort(rng.choice(len(pts), n, replace=False))]
    return pts


def one(name: str, n: int, kind: str) -> dict:
    from core import fit_surface, refine
    from core.parameterize import parameterize
    from timing import report_phases, time_calls

    pts = dataset(name, n)
    t0 = time.perf_counter()
    parameterize(pts)
    t_param = time.perf_counter() - t0
    # initial knot placement and knot insertion are not in the per-iteration report: time them
    extra = {"knots": 0.0, "insertion": 0.0}
    time_calls(refine, "initial_knots", "knots", extra)
    time_calls(refine, "feature_measure", "knots", extra)  # computed once, before the knots
    time_calls(refine, "insertion_points", "insertion", extra)
    t0 = time.perf_counter()
    if kind == "single":
        surf = fit_surface(pts, max_iterations=1, initial_knots=1500, max_control_points=5000)
    else:
        # the whole refinement path: no tolerance stops it before the budget
        surf = fit_surface(pts, tolerance=0.0, max_control_points=5000, max_iterations=20)
    total = time.perf_counter() - t0
    phases: dict = dict(extra)
    for ph in report_phases(surf.report):
        for k, v in ph.items():
            phases[k] = phases.get(k, 0.0) + v
    peer = None
    if kind == "single":
        from scipy.interpolate import LSQBivariateSpline

        m = max(int(np.sqrt(surf.report["control_points"])) - 3, 1)
        tx = np.quantile(pts[:, 0], np.linspace(0, 1, m + 2)[1:-1])
        ty = np.quantile(pts[:, 1], np.linspace(0, 1, m + 2)[1:-1])
        t0 = time.perf_counter()
        try:
            sp = LSQBivariateSpline(pts[:, 0], pts[:, 1], pts[:, 2], tx, ty, kx=3, ky=3)
            res = sp.ev(pts[:, 0], pts[:, 1]) - pts[:, 2]
            diag = float(np.linalg.norm(np.ptp(pts, axis=0)))
            peer = {"seconds": time.perf_counter() - t0,
                    "rms_rel": float(np.sqrt(np.mean(res**2)) / diag),
                    "coefficients": int((m + 4) ** 2)}
        except Exception as exc:  # FITPACK refuses some knot sets
            peer = {"error": str(exc)[:60]}
    return {
        "dataset": name, "points": len(pts), "kind": kind, "seconds": total,
        "parameterize": t_param, "phases": phases,
        "iterations": surf.report["iterations"], "control_points": surf.report["control_points"],
        "rms_rel": surf.report["rms_rel"], "max_rel": surf.report["max_rel"],
        "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "peer": peer,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sizes", type=int, nargs="*")
    ap.add_argument("--one", nargs=3, metavar=("DATASET", "N", "KIND"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(args.one[0], int(args.one[1]), args.one[2])))
        return
    sizes = args.sizes or ([10_000] if args.quick else [10_000, 100_000, 1_000_000])
    cases = [(d, n, k) for n in sizes for d in ("franke", "dem") for k in ("single", "adaptive")
             if not (d == "dem" and n > 138_000 and n != sizes[-1]) and not (d == "dem" and n > 200_000)]
    cols = ("dataset", "points", "kind", "it", "ctrl", "rms/diag", "total s", "param", "knots",
            "config", "basis", "assem", "fair", "solve", "insert", "peak MiB", "FITPACK s",
            "FITPACK rms", "ratio s")
    print(" ".join(f"{c:>10}" for c in cols))
    rows = []
    for d, n, k in cases:
        out = subprocess.run([sys.executable, __file__, "--one", d, str(n), k],
                             capture_output=True, text=True)
        if out.returncode != 0:
            print(f"{d:>10} {n:>10} {k:>10}  failed: {out.stderr.strip().splitlines()[-1]}")
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append(r)
        p, peer = r["phases"], r["peer"] or {}
        ratio = r["seconds"] / peer["seconds"] if peer.get("seconds") else float("nan")
        vals = (r["dataset"], r["points"], r["kind"], r["iterations"], r["control_points"],
                f"{r['rms_rel']:.2e}", f"{r['seconds']:.2f}", f"{r['parameterize']:.2f}",
                f"{p.get('knots', 0):.2f}", f"{p.get('configurations', 0):.2f}",
                f"{p.get('basis', 0):.2f}", f"{p.get('assembly', 0):.2f}",
                f"{p.get('fairing', 0):.2f}", f"{p.get('solve', 0):.2f}",
                f"{p.get('insertion', 0):.2f}", f"{r['peak_mib']:.0f}",
                f"{peer.get('seconds', float('nan')):.2f}", f"{peer.get('rms_rel', float('nan')):.2e}",
                f"{ratio:.1f}")
        print(" ".join(f"{str(v):>10}" for v in vals), flush=True)
    for d in ("franke", "dem"):
        pts = [(r["points"], r["seconds"]) for r in rows if r["dataset"] == d and r["kind"] == "adaptive"]
        if len(pts) >= 2:
            x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            print(f"growth exponent ({d}, adaptive): {np.polyfit(x, y, 1)[0]:.2f}")


if __name__ == "__main__":
    main()
