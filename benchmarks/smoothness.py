"""The fairing weight: the default ``smoothness=1e-4`` against ``smoothness="auto"`` (5-fold
cross-validation, core.fit).

    .venv/bin/python benchmarks/smoothness.py [--quick] [--out docs/smoothness.md]

(``--quick``: the sphere and the crease, quadratic, sparse regime only; 10 s.)

Height fields of ``benchmarks/datasets.py`` (scattered, 10% of the points held out of every
fit) in a sparse regime (3000 points, 400 control points: 7 points per control point, the
setting of compare.py) and a dense one (20000 points, same budget: 50 per control point), for
quadratic and cubic TCB; then the DEM and the three meshes at the Blender default budget of
2000 control points (meshes: no hold-out, the RMS is at their vertices). The loop runs to the
budget (tolerance 0). Columns: training RMS and hold-out RMS / bounding-box diagonal for both
settings, their ratios (auto / default, < 1: auto better), the chosen value, the seconds of
the final auto refit (basis, cross-validation and fit) and of the whole default fit.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import datasets as ds  # noqa: E402
from core import fit_surface  # noqa: E402


def run(points, faces, hold, budget, degree, smoothness):
    t = time.perf_counter()
    s = fit_surface(points, faces, degree=degree, smoothness=smoothness, tolerance=0.0,
                    max_control_points=budget, max_iterations=40)
    sec = time.perf_counter() - t
    diag = s.report["diagonal"]
    h = np.nan
    if hold is not None and len(hold):
        e = np.linalg.norm(s(s.parameterization.project(hold)) - hold, axis=1)
        h = float(np.sqrt(np.mean(e**2))) / diag
    sel = s.report.get("smoothness_selection") or {}
    return {"rms": s.report["rms_rel"], "hold": h, "sec": sec, "chosen": s.report["smoothness"],
            "select": sel.get("seconds", 0.0), "kept": "kept" in sel}


def cases(quick: bool):
    names = ("F6-sphere", "crease") if quick else (
        "F1-franke", "F2-cliff", "F6-sphere", "F7-trig", "F10-cospeak", "crease")
    sizes = (3000,) if quick else (3000, 20000)
    degrees = (2,) if quick else (2, 3)
    for n in sizes:
        for name in names:
            rng = np.random.default_rng(0)
            xy = rng.random((n + n // 9, 2))
            P = np.c_[xy, ds.FUNCTIONS[name](*xy.T)]
            for degree in degrees:
                yield f"{name} {n}", P[:n], None, P[n:], 400, degree
    if quick:
        return
    d = ds.dem(2)
    yield f"{d['name']}", d["points"], None, None, 2000, 2
    for m in ("nefertiti", "three_peaks", "patch-01"):
        d = ds.mesh(m)
        yield d["name"], d["points"], d["faces"], None, 2000, 2


def fmt(v, spec=".2e"):
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", help="write the table as markdown here")
    args = ap.parse_args(argv)
    head = ["dataset", "deg", "budget", "RMS 1e-4", "RMS auto", "ratio", "hold 1e-4",
            "hold auto", "ratio", "chosen", "auto refit s", "fit s (1e-4)"]
    rows = []
    t0 = time.perf_counter()
    for name, P, F, H, budget, degree in cases(args.quick):
        a = run(P, F, H, budget, degree, 1e-4)
        b = run(P, F, H, budget, degree, "auto")
        rows.append([name, str(degree), str(budget), fmt(a["rms"]), fmt(b["rms"]),
                     fmt(b["rms"] / a["rms"], ".2f"), fmt(a["hold"]), fmt(b["hold"]),
                     fmt(b["hold"] / a["hold"], ".2f"),
                     f"{b['chosen']:g}" + (" (kept)" if b["kept"] else ""),
                     fmt(b["select"], ".2f"), fmt(a["sec"], ".1f")])
        print("  ".join(rows[-1]), flush=True)

    def regime(name):
        last = name.split()[-1]
        return f"{last} points, 400 control points" if last.isdigit() else "DEM and meshes, 2000"

    summary = []
    for group in dict.fromkeys(regime(r[0]) for r in rows):
        for col, what in ((5, "training RMS"), (8, "hold-out RMS")):
            v = np.array([float(r[col]) for r in rows if regime(r[0]) == group and r[col] != "-"])
            if len(v):
                summary.append(
                    f"{group}: {what} auto/default geometric mean "
                    f"{np.exp(np.mean(np.log(v))):.2f}, range {v.min():.2f}-{v.max():.2f}, "
                    f"lower in {(v < 0.995).sum()}, higher in {(v > 1.005).sum()} of {len(v)}")
    for line in summary:
        print(line)
    if args.out:
        md = ["# Fairing weight: default 1e-4 against smoothness=\"auto\"\n",
              f"Produced by `.venv/bin/python benchmarks/smoothness.py` in "
              f"{time.perf_counter() - t0:.0f} s. "
              + " ".join(line.strip() for line in (__doc__ or "").split("\n\n")[3].split("\n"))
              .replace("``", "`") + "\n",
              "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        md += ["| " + " | ".join(r) + " |" for r in rows]
        md += [""] + [f"- {line}" for line in summary] + [""]
        Path(args.out).write_text("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
