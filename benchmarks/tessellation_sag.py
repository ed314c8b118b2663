"""How far the surface mesh strays from the spline, per resolution, and what Auto Resolution takes.

    .venv/bin/python benchmarks/tessellation_sag.py [--quick]    # (--quick: the saddle at 3e-4)

Blender users measure the mesh, not the spline: at the fixed default of 64 grid steps a tight
fit's mesh strayed several times the fit's own max error from it (user test of the
thirty-fourth session). Per dataset and tolerance (defaults otherwise): the fit's control points
and max error at the data, ``TCBSurface.tessellation_sag`` at 64 / 128 / 256 / 512 (the largest
distance between the spline and the flat triangles at the midpoints of all the mesh's edges),
all over the bounding-box diagonal, and the resolution ``auto_resolution`` picks (the coarsest
of 64 / 128 / 256 whose sag is within the fit's max error, else 256), with its seconds (the
sags it measured and the grids it laid out).
"""

from __future__ import annotations

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

RESOLUTIONS = (64, 128, 256, 512)


def cases(quick: bool):
    g = np.linspace(-1, 1, 5)
    x, y = np.meshgrid(g, g, indexing="ij")
    saddle = np.c_[x.ravel(), y.ravel(), 0.5 * (x * x - y * y).ravel()]
    i = np.arange(25).reshape(5, 5)
    quads = np.c_[i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()]
    if quick:  # (at 1e-4 its fit alone takes 20-30 s: stalled at 1022 control points)
        yield "saddle, 5 x 5 quads", saddle, quads, 3e-4
        return
    yield "saddle, 5 x 5 quads", saddle, quads, 1e-4
    for name in ("nefertiti", "three_peaks"):
        d = D.mesh(name)
        for tol in (1e-3, 1e-4):
            yield f"{name}.off", d["points"], d["faces"], tol
    d = D.height_field("F7-trig", 20000)
    yield "F7-trig scattered 20 000", d["points"], None, 1e-4


def main(argv=None) -> None:
    quick = "--quick" in (argv if argv is not None else sys.argv[1:])
    warnings.simplefilter("ignore", RuntimeWarning)  # (large-net notes of coarse meshes)
    print("| data | tolerance | cp | max | " + " | ".join(f"sag {r}" for r in RESOLUTIONS)
          + " | auto | s |")
    print("|---" * (6 + len(RESOLUTIONS)) + "|")
    for name, points, faces, tol in cases(quick):
        surf = fit_surface(points, faces, tolerance=tol)
        diag = float(np.linalg.norm(np.ptp(points, axis=0)))
        sags = [surf.tessellation_sag(r) / diag for r in RESOLUTIONS]
        fresh = type(surf).from_bytes(surf.to_bytes())  # (no grids cached)
        t = time.perf_counter()
        auto, _ = fresh.auto_resolution()
        seconds = time.perf_counter() - t
        print(f"| {name} | {tol:g} | {surf.report['control_points']} | "
              f"{surf.report['max_rel']:.2e} | " + " | ".join(f"{s:.2e}" for s in sags)
              + f" | {auto} | {seconds:.2f} |", flush=True)


if __name__ == "__main__":
    main()
