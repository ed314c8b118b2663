"""How the TCB fit scales with the number of points (issue 5).

    .venv/bin/python benchmarks/bench_scaling.py                 # 1e4, 1e5, 1e6 points
    .venv/bin/python benchmarks/bench_scaling.py --sizes 10000 100000 --out /tmp/s.md

Data: Franke's F1 on uniform random points of the unit square. Every size runs in its own
subprocess (fresh memory): ``fit_surface(points, tolerance=0, max_control_points=B,
max_iterations=K)`` with a fixed budget, so the spline space is about the same at every size and
the growth measures the cost per point. Per phase:

* seconds: ``parameterize`` (measured around ``core.parameterize.parameterize``), ``initial
  knots``, and the fit's own phases summed over the iterations (``report['history'][i]
  ['phases']``: configurations, basis, assembly, fairing, solve, errors), ``insertion`` (new
  knots), and the wall time of the whole call;
* memory: the peak of ``tracemalloc`` (numpy reports its buffers to it) during each phase,
  and the process's peak resident set size (``ru_maxrss``).

Phases are wrapped by replacing module attributes in the child process only (no change to
``core``). ``tracemalloc`` adds some overhead to the Python-heavy phases (configurations); the
seconds include it. The exponent is the least-squares slope of ``log(seconds)`` against
``log(points)``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

FIT_PHASES = ("configurations", "basis", "assembly", "fairing", "solve", "errors")


def child(n: int, budget: int, iterations: int) -> dict:
    import resource

    import core.refine as refine
    import core.surface as surface
    import datasets as ds
    from core import fit_surface
    from timing import report_phases, time_calls

    P = ds.height_field("F1-franke", n, "scattered")["points"]
    mem: dict = {}
    sec: dict = {}

    def peak(label):
        mem[label] = max(mem.get(label, 0), tracemalloc.get_traced_memory()[1])

    def wrap(module, attr, label):
        time_calls(module, attr, label, sec, before=tracemalloc.reset_peak, after=peak)

    wrap(surface, "parameterize", "parameterize")
    wrap(refine, "initial_knots", "initial knots")
    wrap(refine, "make_space", "configurations")
    wrap(refine, "fit_control_points", "fit")
    wrap(refine, "insertion_points", "insertion")
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    s = fit_surface(P, tolerance=0.0, max_control_points=budget, max_iterations=iterations)
    wall = time.perf_counter() - t0
    peak_total = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    r = s.report
    # above 2e5 points the iterations fit a subset and the chosen space is refitted to all
    for ph in report_phases(r):
        for k in FIT_PHASES:
            sec["fit:" + k] = sec.get("fit:" + k, 0.0) + float(ph.get(k, 0.0))
    return {
        "points": n, "control_points": r["control_points"], "knots": r["interior_knots"],
        "iterations": r["iterations"], "rms_rel": r["rms_rel"], "wall": wall, "seconds": sec,
        "mem_mb": {k: (v - base) / 2 ** 20 for k, v in mem.items()},
        "traced_peak_mb": (peak_total - base) / 2 ** 20,
        "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "data_mb": P.nbytes / 2 ** 20,
    }


def slope(x, y) -> float:
    x, y = np.log(np.asarray(x, float)), np.log(np.maximum(np.asarray(y, float), 1e-9))
    return float(np.polyfit(x, y, 1)[0]) if len(x) >= 2 else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--budget", type=int, default=1000)
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--timeout", type=float, default=3600)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "scaling.md")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.budget, args.iterations)))
        return 0
    runs = []
    for n in args.sizes:
        print(f"{n} points ...", file=sys.stderr, flush=True)
        cmd = [sys.executable, __file__, "--child", str(n), "--budget", str(args.budget),
               "--iterations", str(args.iterations)]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
        if res.returncode != 0:
            print(res.stderr, file=sys.stderr)
            continue
        runs.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print(f"   {runs[-1]['wall']:.1f} s, maxrss {runs[-1]['maxrss_mb']:.0f} MB",
              file=sys.stderr, flush=True)
    phases = ["parameterize", "initial knots", "configurations"] + [
        "fit:" + k for k in FIT_PHASES if k != "configurations"] + ["insertion"]
    head = ["points", "ctrl pts", "iters", "RMS/diag", "wall s"] + [
        p.replace("fit:", "") + " s" for p in phases] + ["maxrss MB"]
    rows = [head]
    for r in runs:
        rows.append([f"{r['points']:.0e}", str(r["control_points"]), str(r["iterations"]),
                     f"{r['rms_rel']:.2e}", f"{r['wall']:.1f}"]
                    + [f"{r['seconds'].get(p, 0.0):.2f}" for p in phases]
                    + [f"{r['maxrss_mb']:.0f}"])
    ns = [r["points"] for r in runs]
    rows.append(["exponent", "", "", "", f"{slope(ns, [r['wall'] for r in runs]):.2f}"]
                + [f"{slope(ns, [r['seconds'].get(p, 0.0) for r in runs]):.2f}" for p in phases]
                + [f"{slope(ns, [r['maxrss_mb'] for r in runs]):.2f}"])
    mphases = ["parameterize", "initial knots", "configurations", "fit", "insertion"]
    mhead = ["points", "data MB"] + [p + " MB" for p in mphases] + ["traced peak MB",
                                                                     "maxrss MB"]
    mrows = [mhead]
    for r in runs:
        mrows.append([f"{r['points']:.0e}", f"{r['data_mb']:.1f}"]
                     + [f"{r['mem_mb'].get(p, 0.0):.1f}" for p in mphases]
                     + [f"{r['traced_peak_mb']:.1f}", f"{r['maxrss_mb']:.0f}"])
    mrows.append(["exponent", ""] + [f"{slope(ns, [r['mem_mb'].get(p, 0.0) for r in runs]):.2f}"
                                     for p in mphases]
                 + [f"{slope(ns, [r['traced_peak_mb'] for r in runs]):.2f}",
                    f"{slope(ns, [r['maxrss_mb'] for r in runs]):.2f}"])

    def md(lines):
        return "\n".join(["| " + " | ".join(lines[0]) + " |", "|" + "---|" * len(lines[0])]
                         + ["| " + " | ".join(x) + " |" for x in lines[1:]])

    text = "\n".join([
        "# Scaling with the number of points",
        "",
        f"`.venv/bin/python benchmarks/bench_scaling.py --sizes {' '.join(map(str, args.sizes))}"
        f" --budget {args.budget} --iterations {args.iterations}`: Franke F1 on uniform random "
        f"points, `fit_surface(tolerance=0, max_control_points={args.budget}, "
        f"max_iterations={args.iterations})`, one subprocess per size, under tracemalloc.",
        "",
        "Seconds per phase (summed over the iterations; above 2e5 points the iterations fit a "
        "2e5 random subset and the chosen space is fitted once more to all points, which is "
        "included):",
        "",
        md(rows),
        "",
        "Peak memory per phase (tracemalloc peak during the phase, above the data already "
        "loaded) and the process's peak RSS:",
        "",
        md(mrows),
        "",
    ])
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
