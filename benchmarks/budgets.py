"""Does a budget the fit does not reach change the net? The sizing's start against the budget.

    .venv/bin/python benchmarks/budgets.py [--quick]

Per dataset and relative RMS tolerance, ``fit_surface(points, faces, tolerance=t,
max_control_points=b)`` for budgets ``b`` of 300, 1000, 2000, 5000 and 20 000, in two ways,
alternating in one process:

* ``own``: the sizing's probe and largest fresh start are those of the budget given (a quarter
  of ``core.refine.automatic_start(mode, b)``, and that start): the behaviour before
  ``core.refine.PROBE_BUDGET`` (set to ``b`` for the run);
* ``default``: the default budget's (``PROBE_BUDGET = 2000``) for larger budgets; smaller ones
  their own, as before (so ``own`` and ``default`` agree below 2000).

Cells: control points of the result / its RMS relative to the bounding-box diagonal (``*`` when
it misses the tolerance) / fits made. The last column says whether the cells of the budgets of
2000 and up agree (``same``) or how far apart their control points are (largest / smallest).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import datasets as D  # noqa: E402
from core import fit_surface, refine  # noqa: E402

BUDGETS = (300, 1000, 2000, 5000, 20_000)


def run(d: dict, tol: float, budget: int, own: bool) -> dict:
    keep = refine.PROBE_BUDGET
    refine.PROBE_BUDGET = budget if own else keep
    try:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = fit_surface(d["points"], d["faces"], tolerance=tol,
                            max_control_points=budget).report
    finally:
        refine.PROBE_BUDGET = keep
    return {"cp": r["control_points"], "rms": r["rms_rel"], "its": len(r["history"]),
            "s": time.perf_counter() - t0}


def cell(x: dict, tol: float) -> str:
    miss = "*" if x["rms"] > tol else ""
    return f"{x['cp']} / {x['rms']:.2e}{miss} / {x['its']}"


def spread(cells: list[dict]) -> str:
    big = [c for b, c in zip(BUDGETS, cells) if b >= refine.PROBE_BUDGET]
    cps = [c["cp"] for c in big]
    if all((c["cp"], c["rms"]) == (big[0]["cp"], big[0]["rms"]) for c in big):
        return "same"
    return f"{max(cps) / min(cps):.2f}x"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="two datasets, one tolerance")
    args = ap.parse_args()
    if args.quick:
        sets, tols = [D.height_field("F1-franke", 20000), D.mesh("three_peaks")], (1e-3,)
    else:
        sets = [D.height_field("F1-franke", 20000), D.height_field("crease", 20000),
                D.height_field("F6-sphere", 20000), D.mesh("nefertiti"), D.mesh("three_peaks")]
        tols = (1e-2, 3e-3, 1e-3)
    head = " | ".join(f"b={b}" for b in BUDGETS)
    print(f"| data | tol | start | {head} | b >= {refine.PROBE_BUDGET} | seconds |")
    print("|---|---|---|" + "---|" * len(BUDGETS) + "---|---|")
    for d in sets:
        for tol in tols:
            got = {True: [], False: []}
            for b in BUDGETS:
                for own in (True, False):
                    got[own].append(run(d, tol, b, own))
            for own in (True, False):
                cells = " | ".join(cell(x, tol) for x in got[own])
                secs = sum(x["s"] for x in got[own])
                print(f"| {d['name']} | {tol:g} | {'own' if own else 'default'} | {cells} | "
                      f"{spread(got[own])} | {secs:.1f} |", flush=True)


if __name__ == "__main__":
    main()
