"""How much the net of a sized fit depends on the draw of its knots (``seed``): the start rule
of ``core.refine.next_start`` now and before the forty-fourth session.

    .venv/bin/python benchmarks/seed_spread.py [--quick]

A fit with a tolerance first fits a probe, then a fresh start with the knot count the probe's
error predicts (method.md section 7's loop, sized: docs/benchmarks.md "Net size against the
tolerance"). Before, a prediction of 0.7 of the automatic start (166 interior knots for the
default budget) or more was rounded up to that start, so two draws whose probes differed a
little could get nets 1.5x apart (a user test: 318-479 control points over six seeds of one
cloud, those rounded up meeting the tolerance at half of it). ``before`` puts that rule back
(``core.refine.next_start`` swapped in this process); ``now`` is the default.

Per dataset and tolerance, over ``SEEDS``: control points (min-max, and the median), the
spread max/min, the median RMS over the tolerance, misses of the tolerance (of the seeds),
seconds (sum). Both rules run in the same process, alternating per seed, so their time ratio
is comparable on a noisy machine.
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

import datasets as D  # noqa: E402
from core import fit_surface  # noqa: E402
from core import refine  # noqa: E402

SEEDS = (0, 1, 2, 3, 4, 5)
TOLERANCES = (3e-3, 1e-3)
NOW = refine.next_start


def before(n, error, tol, previous, degree, n_start):
    """``next_start`` as it was: a prediction of 0.7 of ``n_start`` or more is ``n_start``."""
    want = refine.predicted_knots(n, error, tol, previous, degree)
    if want >= 0.7 * n_start:
        return n_start
    if want <= 1.15 * n:
        return None
    return int(np.ceil(want))


def user_cloud() -> dict:
    """The user test's cloud: 5000 points of a 200 m tile (a wave and a bump), fitted to an
    absolute tolerance of 0.05 (given as relative to its diagonal here)."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (5000, 2))
    z = (0.3 * np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1])
         + 0.2 * np.exp(-((xy[:, 0] - 0.3) ** 2 + (xy[:, 1] + 0.2) ** 2) * 8))
    p = np.c_[xy, z] * 100.0
    return {"name": "user tile (0.05 abs)", "points": p, "faces": None,
            "tolerances": (0.05 / float(np.linalg.norm(np.ptp(p, axis=0))),)}


def run(d: dict, tol: float, seed: int, rule) -> dict:
    refine.next_start = rule
    try:
        t0 = time.perf_counter()
        r = fit_surface(d["points"], d["faces"], tolerance=tol, seed=seed).report
        return {"cp": r["control_points"], "rms": r["rms_rel"], "s": time.perf_counter() - t0}
    finally:
        refine.next_start = NOW


def cell(rows: list, tol: float) -> str:
    cp = [x["cp"] for x in rows]
    miss = sum(x["rms"] > tol for x in rows)
    return (f"{min(cp)}-{max(cp)} ({int(np.median(cp))}) | {max(cp) / min(cp):.2f} | "
            f"{np.median([x['rms'] for x in rows]) / tol:.2f} | {miss} | "
            f"{sum(x['s'] for x in rows):.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="the user's cloud and Franke, 3 seeds")
    args = ap.parse_args()
    sets = [user_cloud(), D.height_field("F1-franke", 5000), D.height_field("crease", 5000),
            D.dem(6), D.mesh("nefertiti"), D.mesh("patch-01"), D.mesh("three_peaks")]
    seeds = SEEDS
    if args.quick:
        sets, seeds = sets[:2], SEEDS[:3]
    print("| data | tolerance | before: cp | spread | RMS/tol | misses | s "
          "| now: cp | spread | RMS/tol | misses | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    total = {"before": 0.0, "now": 0.0}
    for d in sets:
        for tol in d.get("tolerances", TOLERANCES):
            res = {"before": [], "now": []}
            for seed in seeds:
                for name, rule in (("before", before), ("now", NOW)):
                    res[name].append(run(d, tol, seed, rule))
                    total[name] += res[name][-1]["s"]
            print(f"| {d['name']} | {tol:.3g} | {cell(res['before'], tol)} | "
                  f"{cell(res['now'], tol)} |", flush=True)
    print(f"\ntotal seconds: before {total['before']:.1f}, now {total['now']:.1f} "
          f"(ratio {total['now'] / total['before']:.2f})")


if __name__ == "__main__":
    main()
