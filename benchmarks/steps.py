"""Terrain with a step (a cliff, a wall): does the surface stay within the data's heights?

    .venv/bin/python benchmarks/steps.py [--quick]

A smooth surface fitted to a discontinuity must cross it somewhere; the question is what it
does around it. Where more knots crowd at the step than the data hold, the surface swings
between the data points (spikes and fins far beyond any data), which the errors at the data
do not show. ``core.refine.swing_places`` looks for such swings and ``adaptive_fit`` takes
the fits that have them back (not in method.md). Clouds, fitted along z:

* ``tile 1e4``: 1e4 uniform points of a 200 m tile, ``z = 0.05 x + 5 sin(y / 30)`` plus a
  20 m step where ``x + 0.3 y > 120`` (the step crosses the tile), 5 cm noise; tolerance
  0.1 m (absolute), at most 1000 control points (the test suite's ``step_tile``);
* ``cliff 5e4``: the same with 5e4 points;
* ``lattice 32``: a 32 x 32 lattice (6.5 m) of ``5 sin(x / 40) + 3 cos(y / 30)`` plus 20 m
  where ``x > 100`` and ``y > 80`` (the step ends inside the tile), default settings;
* ``random 1000``: 1000 uniform points of that, 0.1 m noise, default settings;
* ``cliff 1e5`` (not with ``--quick``): 1e5 uniform points of that, 5 cm noise, defaults.

Columns: the data's and the surface's height range (the surface evaluated on a 256 x 256
tessellation), "over": how far the surface leaves the band between the terrain without and
with the step (its largest excursion below the lower or above the upper level), "off": RMS
and largest height error off the true shape beyond 3 m of the step (and 5 m of the tile's
border), control points, the stop reason and seconds. Compare the code before a change by
running this file with another checkout's ``core`` first on ``sys.path``:
``PYTHONPATH=/path/to/other/checkout .venv/bin/python benchmarks/steps.py``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

if not os.environ.get("PYTHONPATH"):  # (with it: that checkout's core, to compare)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core import fit_surface  # noqa: E402


def _crossing(xy):  # (the step of the tiles: a line across them)
    return xy[:, 0] + 0.3 * xy[:, 1] - 120.0


def _corner(xy):  # (the step of the lattice: x > 100 and y > 80, ending inside the tile)
    return np.minimum(xy[:, 0] - 100.0, xy[:, 1] - 80.0)


def tile_terrain(xy):
    return 0.05 * xy[:, 0] + 5.0 * np.sin(xy[:, 1] / 30.0)


def corner_terrain(xy):
    return 5.0 * np.sin(xy[:, 0] / 40.0) + 3.0 * np.cos(xy[:, 1] / 30.0)


def datasets(quick: bool) -> list[dict]:
    """The clouds (seeded), each with its terrain, step function and fit settings."""
    out = []
    tile = dict(terrain=tile_terrain, side=_crossing,
                fit=dict(tolerance=0.1, relative=False, max_control_points=1000))
    for name, n in (("tile 1e4", 10_000), ("cliff 5e4", 50_000)):
        rng = np.random.default_rng(0)
        xy = rng.uniform(0, 200, (n, 2))
        z = tile_terrain(xy) + 20.0 * (_crossing(xy) > 0) + rng.normal(0, 0.05, n)
        out.append(dict(name=name, points=np.c_[xy, z], **tile))
    corner = dict(terrain=corner_terrain, side=_corner, fit={})
    g = np.linspace(0, 200, 32)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    out.append(dict(name="lattice 32", points=np.c_[xy, corner_terrain(xy) + 20.0 * (
        _corner(xy) > 0)], **corner))
    sizes = (("random 1000", 1000, 0.1, 3),)
    if not quick:
        sizes += (("cliff 1e5", 100_000, 0.05, 21),)
    for name, n, noise, seed in sizes:
        rng = np.random.default_rng(seed)
        xy = rng.random((n, 2)) * 200
        z = corner_terrain(xy) + 20.0 * (_corner(xy) > 0) + rng.normal(0, noise, n)
        out.append(dict(name=name, points=np.c_[xy, z], **corner))
    return out


def measure(d: dict) -> dict:
    """Fit ``d`` along z and measure the surface against the true shape."""
    p = d["points"]
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        surf = fit_surface(p, projection="z", **d["fit"])
    seconds = time.perf_counter() - t0
    v, _ = surf.tessellate(256)
    low = d["terrain"](v[:, :2])
    over = float(np.maximum(v[:, 2] - (low + 20.0), low - v[:, 2]).max(initial=0.0))
    side = d["side"](v[:, :2])
    truth = low + 20.0 * (side > 0)
    lo, hi = p[:, :2].min(axis=0) + 5.0, p[:, :2].max(axis=0) - 5.0
    far = (np.abs(side) > 3.0) & (v[:, :2] > lo).all(axis=1) & (v[:, :2] < hi).all(axis=1)
    off = np.abs(v[far, 2] - truth[far])
    return {"data": (p[:, 2].min(), p[:, 2].max()), "surface": (v[:, 2].min(), v[:, 2].max()),
            "over": max(over, 0.0), "off_rms": float(np.sqrt(np.mean(off**2))),
            "off_max": float(off.max()), "cp": surf.report["control_points"],
            "stop": surf.report["stop_reason"], "seconds": seconds}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="without the 1e5-point cliff")
    args = ap.parse_args()
    import core

    print(f"core: {Path(core.__file__).resolve().parent}")
    print("| cloud | data z | surface z | over (m) | off RMS / max (m) | control points | "
          "stop | s |")
    print("|---|---|---|---|---|---|---|---|")
    for d in datasets(args.quick):
        r = measure(d)
        print(f"| {d['name']} | {r['data'][0]:.1f} to {r['data'][1]:.1f} | "
              f"{r['surface'][0]:.1f} to {r['surface'][1]:.1f} | {r['over']:.1f} | "
              f"{r['off_rms']:.3f} / {r['off_max']:.1f} | {r['cp']} | {r['stop']} | "
              f"{r['seconds']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
