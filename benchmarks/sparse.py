"""Sparse clouds: 12-1000 random points of a height field, fitted with the defaults.

    .venv/bin/python benchmarks/sparse.py [--seeds 3]

With fewer than 2 points per control point only the fairing holds the surface between the
points, and the engine replaces the default smoothness by the cross-validated one
(``core.refine.adaptive_fit``). Per function and cloud size, over ``--seeds`` random clouds:
the error of the surface against the function itself, vertically at the vertices of its
tessellation (RMS and worst, divided by the data's height range), for

* ``given``: ``smoothness=1e-4`` passed explicitly (the behaviour before the sparse rule),
* ``default``: ``fit_surface(points)``,
* ``TPS``: scipy's thin-plate-spline interpolant of the same points (``RBFInterpolator``), the
  tool a user would pick for scattered heights, at the same positions as ``default``.

``s`` lists the smoothness ``default`` used per seed, ``cp`` the control points. Every fit
is given ``projection="z"``: these clouds are as tall as they are wide (Franke's function
on the unit square), and below a few dozen points the fold check cannot tell such a cloud
from a folded one, so without the direction it is refused with a message that asks for it.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.interpolate import RBFInterpolator

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from core import fit_surface  # noqa: E402


def franke(x, y):
    return (0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
            + 0.75 * np.exp(-((9 * x + 1) ** 2) / 49 - (9 * y + 1) / 10)
            + 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
            - 0.2 * np.exp(-((9 * x - 4) ** 2) - (9 * y - 7) ** 2))


def two_peaks(x, y):
    return (np.exp(-20 * ((x - 0.3) ** 2 + (y - 0.3) ** 2))
            - 0.5 * np.exp(-10 * ((x - 0.7) ** 2 + (y - 0.6) ** 2)))


def gentle(x, y):
    return 0.3 * x + 0.2 * y + 0.1 * np.sin(3 * x)


FUNCTIONS = {"franke": franke, "two_peaks": two_peaks, "gentle": gentle}
SIZES = (12, 20, 30, 60, 100, 200, 400, 1000)


def errors(surf, fn, zr):
    """(RMS, max) of the surface's vertical error at its tessellation vertices, and the
    vertices."""
    V, _ = surf.tessellate(48)
    e = np.abs(V[:, 2] - fn(V[:, 0], V[:, 1])) / zr
    return float(np.sqrt(np.mean(e**2))), float(e.max()), V


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)  # the sparse warning of `given`
    t0 = time.perf_counter()
    head = (f"{'function':10s} {'points':>6s} | {'given rms':>9s} {'max':>6s} | {'default rms':>11s} "
            f"{'max':>6s} | {'TPS rms':>8s} {'max':>6s} | {'def/TPS':>7s} | s, cp")
    print(head)
    print("-" * len(head))
    ratios = []
    for name, fn in FUNCTIONS.items():
        for n in SIZES:
            rows = []
            for seed in range(args.seeds):
                xy = np.random.default_rng(seed).random((n, 2))
                P = np.c_[xy, fn(*xy.T)]
                zr = float(np.ptp(P[:, 2]))
                g_rms, g_max, _ = errors(fit_surface(P, smoothness=1e-4, projection="z"), fn, zr)
                surf = fit_surface(P, projection="z")
                d_rms, d_max, V = errors(surf, fn, zr)
                tps = np.abs(RBFInterpolator(xy, P[:, 2], kernel="thin_plate_spline")(V[:, :2])
                             - fn(V[:, 0], V[:, 1])) / zr
                rows.append((g_rms, g_max, d_rms, d_max, float(np.sqrt(np.mean(tps**2))),
                             float(tps.max()), surf.report["smoothness"],
                             surf.report["control_points"]))
            r = np.array([row[:6] for row in rows])
            ratio = r[:, 2].mean() / r[:, 4].mean()
            ratios.append(ratio)
            print(f"{name:10s} {n:6d} | {r[:, 0].mean():9.4f} {r[:, 1].max():6.2f} | "
                  f"{r[:, 2].mean():11.4f} {r[:, 3].max():6.2f} | {r[:, 4].mean():8.4f} "
                  f"{r[:, 5].max():6.2f} | {ratio:7.2f} | "
                  f"{' '.join(f'{row[6]:g}' for row in rows)}, {' '.join(str(row[7]) for row in rows)}",
                  flush=True)
    print(f"\ndefault / TPS RMS, geometric mean: {np.exp(np.mean(np.log(ratios))):.2f}; "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
