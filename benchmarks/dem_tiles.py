"""DEM tiles fitted on their best-fit plane and along z: do neighbouring tiles meet?

    .venv/bin/python benchmarks/dem_tiles.py [--quick] [--step K]

The Jacksboro DEM (``data/jacksboro_fault_dem.npz``, 344 x 403 nodes, metres; every ``K``-th
row and column, default 1; ``--quick``: every 3rd) cut into 2 x 2 tiles that share the middle
row and column of nodes, each tile fitted with every default (tolerance 1e-3 of its diagonal)
on its best-fit plane (``projection=None``, what ``fit_surface`` chooses for a cloud) and along z
(``projection="z"``, what the command line and Blender's Import Points give a DEM raster since
the forty-sixth session: ``core.meshio.is_raster``), and along z joined (*z, joined*: each tile
fitted with ``join=`` the tiles before it that share a side with it, forty-seventh session).
Per projection, over the four tiles:

* *tilt*: the largest angle between a tile's projection direction and z (degrees);
* *cp*: the control points of the four fits, summed; *s*: their seconds, summed;
* *past edges*: how far the tiles' tessellations (``tessellate(128)``) reach past their own
  rectangles of nodes in x or y (m; the largest): where neighbouring tiles' meshes overlap;
* *seam dz*: on the shared row and column (500 points along each, inside both tiles), the RMS
  and largest difference of the two tiles' heights (``TCBSurface.heights``), in m: how far
  the surfaces are apart where they should meet; *seam NaN*: the share of those points where
  a tile's surface has no height (beyond its fitted part: a gap between the tiles).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import datasets as D  # noqa: E402
from core import fit_surface  # noqa: E402

RESOLUTION = 128
SEAM_POINTS = 500
# "z, joined": the tiles fitted in turn, each joined to those before it that share a side
# with it (core.join.CloudSeam): 1 to 0, 2 to 0, 3 to 1 and 2
JOINS = ((), (0,), (0,), (1, 2))


def tiles(step: int):
    """The four tiles' points (nodes of the DEM every ``step``-th row and column), their
    rectangles ``(lo, hi)`` of x and y, and the shared row and column (x of the column, y of
    the row) and the grid's bounds."""
    g = D.dem(step)["points"]
    rows, cols = len(np.unique(g[:, 1])), len(np.unique(g[:, 0]))
    grid = g.reshape(rows, cols, 3) if np.unique(g[:cols, 1]).size == 1 else None
    assert grid is not None, "the DEM's nodes are not in rows"
    r, c = rows // 2, cols // 2
    parts = [grid[:r + 1, :c + 1], grid[:r + 1, c:], grid[r:, :c + 1], grid[r:, c:]]
    out = []
    for p in parts:
        pts = p.reshape(-1, 3)
        out.append((pts, pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)))
    return out, float(grid[0, c, 0]), float(grid[r, 0, 1]), g[:, :2].min(axis=0), g[:, :2].max(axis=0)


def run(step: int) -> None:
    parts, xc, yr, glo, ghi = tiles(step)
    # the shared column (x = xc) and row (y = yr), inside the grid (a node's step in from its ends)
    ys = np.linspace(glo[1], ghi[1], SEAM_POINTS + 2)[1:-1]
    xs = np.linspace(glo[0], ghi[0], SEAM_POINTS + 2)[1:-1]
    col = np.c_[np.full_like(ys, xc), ys]
    row = np.c_[xs, np.full_like(xs, yr)]
    print(f"Jacksboro DEM every {step}: {sum(len(p) for p, _, _ in parts)} points in 4 tiles of "
          f"{', '.join(str(len(p)) for p, _, _ in parts)}")
    print("| projection | tilt (deg) | cp | past edges (m) | seam dz RMS / max (m) | seam NaN | s |")
    print("|---|---|---|---|---|---|---|")
    for label, projection, joins in (("best-fit plane", None, False), ("z", "z", False),
                                     ("z, joined", "z", True)):
        surfs, cp, secs, tilt, past = [], 0, 0.0, 0.0, 0.0
        for k, (pts, lo, hi) in enumerate(parts):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                join = [surfs[i] for i in JOINS[k]] if joins and JOINS[k] else None
                s = fit_surface(pts, projection=projection, join=join)
            secs += time.perf_counter() - t0
            surfs.append(s)
            cp += len(s.control_points)
            ax = np.asarray(s.parameterization.axes)[2]
            tilt = max(tilt, float(np.degrees(np.arccos(min(1.0, abs(ax[2]))))))
            v = s.tessellate(RESOLUTION)[0]
            past = max(past, float(max((lo - v[:, :2]).max(), (v[:, :2] - hi).max())))
        # tiles 0 | 1 and 2 | 3 share the column; 0 / 2 and 1 / 3 the row
        dz, nan, total = [], 0, 0
        for a, b, where in ((0, 1, col), (2, 3, col), (0, 2, row), (1, 3, row)):
            lo = np.maximum(parts[a][1], parts[b][1])
            hi = np.minimum(parts[a][2], parts[b][2])
            inside = np.all((where >= lo) & (where <= hi), axis=1)
            ha, hb = surfs[a].heights(where[inside]), surfs[b].heights(where[inside])
            ok = np.isfinite(ha) & np.isfinite(hb)
            dz.append(ha[ok] - hb[ok])
            nan += int((~ok).sum())
            total += int(inside.sum())
        dz = np.concatenate(dz)
        print(f"| {label} | {tilt:.2f} | {cp} | {past:.3g} | "
              f"{np.sqrt(np.mean(dz ** 2)):.3g} / {np.abs(dz).max():.3g} | {nan / total:.1%} | "
              f"{secs:.1f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="every 3rd node")
    ap.add_argument("--step", type=int, default=None, help="every K-th node (default 1)")
    args = ap.parse_args()
    run(args.step or (3 if args.quick else 1))


if __name__ == "__main__":
    main()
