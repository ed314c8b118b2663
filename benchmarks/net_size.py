"""Net size against the tolerance: the sized start of the adaptive loop against a fixed start.

    .venv/bin/python benchmarks/net_size.py [--quick]

Per dataset and relative RMS tolerance, ``fit_surface(points, faces, tolerance=t)`` with the
defaults otherwise (budget 2000 control points, 20 iterations) in two ways:

* ``fixed``: ``initial_knots`` set to the automatic start (``core.refine.automatic_start``,
  166 interior knots for the default budget): the first fit has about a quarter of the budget
  whatever the tolerance (the behaviour before sizing);
* ``sized``: the default: a probe with a quarter of those knots, then fresh starts with the knot
  count the measured convergence predicts (``core.refine.next_start``), then knot insertion;
  a fresh start that meets the tolerance with room to spare is followed by coarser ones while
  they meet it (``SHRINK_FRACTION``, at least ``MIN_START_KNOTS`` interior knots).

Columns: control points of the result, its RMS relative to the bounding-box diagonal (``*`` when
it misses the tolerance), fits made (iterations), seconds. Both variants run in the same process,
alternating, so their time ratio is comparable on a noisy machine.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import datasets as D  # noqa: E402
from core import fit_surface  # noqa: E402
from core.refine import automatic_start  # noqa: E402

TOLERANCES = (1e-2, 3e-3, 1e-3, 3e-4)


def run(d: dict, tol: float, fixed: bool) -> dict:
    extra = {"initial_knots": automatic_start("tcb", 2000)} if fixed else {}
    t0 = time.perf_counter()
    s = fit_surface(d["points"], d["faces"], tolerance=tol, **extra)
    r = s.report
    return {"cp": r["control_points"], "rms": r["rms_rel"], "its": len(r["history"]),
            "s": time.perf_counter() - t0}


def cell(x: dict, tol: float) -> str:
    miss = "*" if x["rms"] > tol else ""
    return f"{x['cp']} | {x['rms']:.2e}{miss} | {x['its']} | {x['s']:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="two datasets, two tolerances")
    args = ap.parse_args()
    sets = [D.height_field("F1-franke", 20000), D.height_field("F2-cliff", 20000),
            D.height_field("crease", 20000), D.height_field("F6-sphere", 20000), D.dem(3),
            D.mesh("nefertiti"),
            D.mesh("patch-01"), D.mesh("three_peaks")]
    tols = TOLERANCES
    if args.quick:
        sets, tols = sets[:1] + sets[5:6], TOLERANCES[1:3]
    print("| data | tolerance | fixed: cp | RMS | fits | s | sized: cp | RMS | fits | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    total = {True: 0.0, False: 0.0}
    for d in sets:
        for tol in tols:
            res = {}
            for fixed in (True, False):
                res[fixed] = run(d, tol, fixed)
                total[fixed] += res[fixed]["s"]
            print(f"| {d['name']} | {tol:g} | {cell(res[True], tol)} | {cell(res[False], tol)} |",
                  flush=True)
    print(f"\ntotal seconds: fixed {total[True]:.1f}, sized {total[False]:.1f} "
          f"(ratio {total[False] / total[True]:.2f})")


if __name__ == "__main__":
    main()
