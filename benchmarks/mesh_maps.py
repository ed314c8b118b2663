"""Meshes: the boundary on the circle or rectangle (method.md section 4) against the boundary's
own shape flattened (``core.parameterize._flattened_map``, the default when it distorts the
triangles less), in the same run.

Cases: the three bundled meshes; a 21 x 21 grid mesh of ``0.3 sin 3x cos 2y`` whole and
without one boundary triangle (a notch); a 41 x 41 grid patch of a smooth function cut by a
wavy, ragged border (a scan's edge: a staircase of grid edges); 60-, 90- and 120-degree spherical
caps cut from a grid (staircase borders); half a cylinder; the scanned face without 15 of its
faces along the border (faces deleted in Blender: each leaves a notch); a comb of fingers 0.2
wide cut from a 40 x 40 grid of ``0.3 sin 3x cos 2y`` over [-1, 1]^2, of ``0.8 sin 3x cos 2y``
and of ``1.2 sin 3x cos 2y`` (their developments overlap themselves). Columns: the map the
default takes ("circle", "rectangle", "flattened", or "projected": the flattened loop refused,
``core.parameterize._projected_map``), the distortion of each map (``_map_energy``: 1 for an
isometry), then for the fixed boundary ("fixed") and the default ("now") the control points,
RMS and max error at the vertices over the diagonal, and seconds of ``fit_surface``.
Default settings otherwise.

    .venv/bin/python benchmarks/mesh_maps.py [--quick] [--tolerances 1e-2 1e-3 1e-4]
        [--only NAME ...]
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

import core.parameterize as pz  # noqa: E402
from core import fit_surface  # noqa: E402
from core.meshio import read_geometry  # noqa: E402
from holes import f, grid as quad_grid  # noqa: E402


def grid(n: int, height=f):
    """An n x n grid mesh over the unit square (benchmarks/holes.py's), its cells split into
    triangles, lifted by ``height``."""
    pts, cells, _, _ = quad_grid(n)
    pts[:, 2] = height(pts[:, 0], pts[:, 1])
    return pts, np.r_[cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]]


def ragged(n: int = 41):
    """A smooth patch cut by a wavy border through the grid (a staircase of its edges)."""
    pts, faces = grid(n, lambda x, y: 0.2 * np.sin(4 * x) * np.cos(3 * y) + 0.1 * x * y)
    c = pts[faces].mean(axis=1)[:, :2] - 0.5
    a = np.arctan2(c[:, 1], c[:, 0])
    return pts, faces[np.hypot(*c.T) < 0.42 + 0.05 * np.sin(5 * a) + 0.03 * np.sin(13 * a + 1)]


def cap(degrees: float, n: int = 31):
    """A spherical cap of the given opening, cut from a grid (the faces inside the disk)."""
    pts, faces = grid(n, lambda x, y: 0 * x)
    x, y = 2 * pts[:, 0] - 1, 2 * pts[:, 1] - 1
    faces = faces[(np.hypot(x, y)[faces] <= 1.0).all(axis=1)]
    theta, phi = np.radians(degrees) * np.hypot(x, y), np.arctan2(y, x)
    return np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], faces


def half_cylinder(n: int = 31):
    pts, faces = grid(n, lambda x, y: 0 * x)
    a = np.pi * pts[:, 0]
    return np.c_[np.cos(a), 2 * pts[:, 1], np.sin(a)], faces


def face_frayed():
    """The scanned face without some of its faces along its border (seeded): faces with one
    edge on the border, no two sharing a vertex (each leaves a notch; the patch stays a disk),
    up to 5% of the faces (15 of the 562 are taken)."""
    pts, faces = read_geometry(ROOT / "data" / "nefertiti.off")
    rim = np.zeros(len(pts), dtype=bool)
    rim[pz.parameterize(pts, faces).boundary] = True
    edge = np.flatnonzero(rim[faces].sum(axis=1) == 2)
    taken = np.zeros(len(pts), dtype=bool)
    drop = []
    for f in np.random.default_rng(0).permutation(edge):
        if len(drop) < 0.05 * len(faces) and not taken[faces[f]].any():
            drop.append(f)
            taken[faces[f]] = True
    return pts, np.delete(faces, drop, axis=0)


def comb(height, n: int = 40, finger: float = 0.2):
    """An n x n grid mesh over [-1, 1]^2 lifted by ``height``, without every other strip of
    cells ``finger`` wide above y = -0.3: a comb."""
    pts, cells, _, _ = quad_grid(n)
    pts = 2 * pts - 1
    pts[:, 2] = height(pts[:, 0], pts[:, 1])
    c = pts[cells].mean(axis=1)
    cells = cells[~((c[:, 1] > -0.3) & (((c[:, 0] + 1) / finger).astype(int) % 2 == 1))]
    faces = np.r_[cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]]
    used = np.unique(faces)
    index = np.full(len(pts), -1)
    index[used] = np.arange(len(used))
    return pts[used], index[faces]


def cases(quick: bool) -> dict:
    out = {name: read_geometry(ROOT / "data" / f"{name}.off")
           for name in ("nefertiti", "patch-01", "three_peaks")}
    out["grid 21"] = grid(21)
    notch = grid(21)
    out["grid 21, notch"] = (notch[0], notch[1][1:])
    out["ragged 41"] = ragged()
    if quick:
        return {k: out[k] for k in ("nefertiti", "grid 21, notch", "ragged 41")}
    out["cap 60"] = cap(60)
    out["cap 90"] = cap(90)
    out["cap 120"] = cap(120)
    out["half cylinder"] = half_cylinder()
    out["face, frayed"] = face_frayed()
    out["comb, wavy"] = comb(lambda x, y: 0.3 * np.sin(3 * x) * np.cos(2 * y))
    out["comb, steep"] = comb(lambda x, y: 0.8 * np.sin(3 * x) * np.cos(2 * y))
    out["comb, steeper"] = comb(lambda x, y: 1.2 * np.sin(3 * x) * np.cos(2 * y))
    return out


def fit(pts, faces, tol, flat: bool):
    pz.FLAT_BOUNDARY = flat
    try:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            surf = fit_surface(pts, faces, tolerance=tol)
        return surf, time.perf_counter() - t0
    finally:
        pz.FLAT_BOUNDARY = True


def which(par, fixed, pts, faces) -> str:
    """The map ``par`` took: the circle, the rectangle (both: as ``fixed``), flattened or
    projected (what it takes without ``PROJECTED_BOUNDARY`` is ``fixed``)."""
    if not np.array_equal(np.asarray(par.uv), np.asarray(fixed.uv), equal_nan=True):
        pz.PROJECTED_BOUNDARY = False
        try:
            alone = pz.parameterize(pts, faces)
        finally:
            pz.PROJECTED_BOUNDARY = True
        same = np.array_equal(np.asarray(alone.uv), np.asarray(fixed.uv), equal_nan=True)
        return "projected" if same else "flattened"
    poly = np.asarray(par.domain_polygon)
    return "circle" if np.allclose(np.hypot(poly[:, 0], poly[:, 1]), 1.0) else "rectangle"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--tolerances", type=float, nargs="+", default=None)
    ap.add_argument("--only", nargs="+", default=None,
                    help="the cases of these names only (of all of them, --quick or not)")
    args = ap.parse_args()
    tols = args.tolerances or ([1e-3] if args.quick else [1e-2, 1e-3, 1e-4])
    print("| mesh | vertices | map | energy fixed | energy now | tol | fixed: cp | RMS | max "
          "| s | now: cp | RMS | max | s |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, (pts, faces) in cases(args.quick and not args.only).items():
        if args.only and name not in args.only:
            continue
        pz.FLAT_BOUNDARY = False
        fixed = pz.parameterize(pts, faces)
        pz.FLAT_BOUNDARY = True
        par = pz.parameterize(pts, faces)
        p = np.asarray(pts, dtype=np.float64)
        energy = [pz._map_energy(p, np.asarray(m.faces), np.asarray(m.uv)) for m in (fixed, par)]
        for tol in tols:
            row = [name, str(int(np.asarray(par.used).sum())), which(par, fixed, pts, faces),
                   f"{energy[0]:.3f}", f"{energy[1]:.3f}", f"{tol:g}"]
            for flat_on in (False, True):
                surf, sec = fit(pts, faces, tol, flat_on)
                r = surf.report
                row += [str(r["control_points"]), f"{r['rms_rel']:.2e}", f"{r['max_rel']:.2e}",
                        f"{sec:.1f}"]
            print("| " + " | ".join(row) + " |", flush=True)


if __name__ == "__main__":
    main()
