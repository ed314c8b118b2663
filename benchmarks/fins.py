"""Fins: a fit of a coarse creased mesh swinging off the mesh between the points it fitted, with
and without the face check (``core.surface.FaceCheck``), in the same run.

A mesh is fitted to its vertices and to points sampled on its faces (``mesh_sample_count``: 20
per vertex, at least 5000), whatever the net's size. At a tight tolerance a creased CAD mesh
gets a net of ~1000 control points, crowded at the crease, with fewer than 3 fitted points
each there, and between them the surface swung off the mesh as a fin that no error reported
(user test of the forty-first session: a bent sheet 2.6 off at 1e-4, reported 0.074). The face
check evaluates each fit of the loop at samples drawn apart from the fitted ones; where it
strays, it fits the samples of those faces as well.

Rows: each case (and seed, ``--seeds``) with the check ``off`` (``FACE_CHECK = False``: the loop
before it), ``faces`` (``BORDER_SAMPLES = False``: samples inside the faces only, the check
before the forty-fifth session) and ``on`` (as shipped: the border edges sampled too). Columns:
control points; the reported max error at the vertices and on the faces (``faces_max``: the
fitted samples, and with the check its samples not fitted too); the distance from the surface
tessellated at 256 steps to the mesh's faces (``off mesh``: max and 99th percentile; the truth a
user sees); the check's samples the surface was fitted to (``report["stray_samples"]``);
seconds. Over the bounding box's diagonal where it says so. The grids are
benchmarks/coarse_meshes.py's: the folded one ``z = |y|``, the smooth ones ``0.3 sin 2x cos y``,
over [-1, 1]^2.

    .venv/bin/python benchmarks/fins.py [--quick] [--seeds N]
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
sys.path.insert(0, str(ROOT / "tests"))

import core.surface as surface_module  # noqa: E402
from core import fit_surface  # noqa: E402
from core.geometry import point_mesh_distance  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from coarse_meshes import crease, grid, smooth  # noqa: E402
from meshes import bent_sheet  # noqa: E402


def cases(quick: bool):
    """(name, (points, faces), fit_surface keywords)."""
    sheet = bent_sheet()
    out = [("bent sheet, 231 vertices, 1e-4", sheet,
            dict(tolerance=1e-4, max_control_points=3000))]
    if quick:
        return out
    patch = read_geometry(ROOT / "data" / "patch-01.off")[:2]
    out += [("bent sheet, 231 vertices, 1e-3", sheet,
             dict(tolerance=1e-3, max_control_points=3000)),
            ("folded grid 21 x 21, 1e-4", grid(21, crease)[0], dict(tolerance=1e-4)),
            ("patch-01.off, 0.05 absolute", patch, dict(tolerance=0.05, relative=False)),
            ("patch-01.off, 1e-3", patch, {}),
            # (no crease: what the check costs; 121 x 121: 14 641 vertices, 50 000 samples)
            ("smooth grid 41 x 41, 1e-4", grid(41, smooth)[0], dict(tolerance=1e-4)),
            ("smooth grid 121 x 121, 1e-4", grid(121, smooth)[0], dict(tolerance=1e-4))]
    for name in ("nefertiti", "three_peaks"):
        out.append((f"{name}.off, 1e-3", read_geometry(ROOT / "data" / f"{name}.off")[:2], {}))
    return out


def run(mesh, kwargs: dict, check: str) -> dict:
    points, faces = (np.asarray(a) for a in mesh)
    surface_module.FACE_CHECK = check != "off"
    surface_module.BORDER_SAMPLES = check == "on"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            surf = fit_surface(points, faces, **kwargs)
            seconds = time.perf_counter() - t0
    finally:
        surface_module.FACE_CHECK = surface_module.BORDER_SAMPLES = True
    r = surf.report
    v, _ = surf.tessellate(256)
    d = point_mesh_distance(v, points, faces, k=24)
    return {"cp": r["control_points"], "max": r["max"], "faces": r["faces_max"],
            "off": d.max(), "p99": np.percentile(d, 99), "diag": r["diagonal"],
            "added": r.get("stray_samples", 0),
            "seconds": seconds}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="the bent sheet at 1e-4 only")
    ap.add_argument("--seeds", type=int, default=1, help="fit each case with seeds 0 .. N-1")
    args = ap.parse_args()
    print("| case | seed | check | control points | max at vertices | faces max (reported) | "
          "off mesh max | off mesh p99 | off mesh max / diagonal | samples added | seconds |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for name, mesh, kwargs in cases(args.quick):
        for seed in range(args.seeds):
            for check in ("off", "faces", "on"):
                x = run(mesh, dict(kwargs, seed=seed), check)
                rows.append((name, check, x))
                print(f"| {name} | {seed} | {check} | {x['cp']} | {x['max']:.3g} | "
                      f"{x['faces']:.3g} | {x['off']:.3g} | {x['p99']:.3g} | "
                      f"{x['off'] / x['diag']:.2e} | {x['added']} | {x['seconds']:.1f} |",
                      flush=True)
    off = sum(x["seconds"] for _, c, x in rows if c == "off")
    on = sum(x["seconds"] for _, c, x in rows if c == "on")
    print(f"\ntime with the check / without: {on / off:.2f} ({on:.1f} s / {off:.1f} s)")


if __name__ == "__main__":
    main()
