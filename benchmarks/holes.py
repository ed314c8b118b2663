"""Meshes with holes (``fit_surface(..., fill_holes=True)``): how the surface fits around and
across holes of several shapes, with every hole closed by a fan around its border's mean
("fan": the rule before the twenty-third session, forced here by making every hole count as
star-shaped and no fan bulge) against the rule shipped (fans for holes their mean sees, ear
clipping of the border for the others and where the fan bulges away from the hole:
``core.parameterize._clipped_hole``, HOLE_BACKWARD, HOLE_BULGE), in the same run.

Cases: holes cut into an ``m x m`` grid mesh of ``0.3 sin 3x cos 2y`` over the unit square
(a round one, C-, L- and S-shaped ones, a crescent; and large round ones), and a slot along
the bend of a strip bent by 30, 90, 180 and 240 degrees (the fan bulges away from it; the
last two's border crosses itself seen across the slot: clipped in the map). Columns: control points, RMS and max error at the
vertices over the diagonal, and for the grid the largest distance, over the diagonal, between
the surface and the function at the centres of the removed cells ("in hole"; for the strip,
the distance of the removed vertices to the surface). Default settings otherwise.

With ``--clouds``: point clouds with round gaps inside them (occlusions); the share of each
gap (over the xy plane) that the surface mesh at resolution 128 covers without and with
``fill_holes`` (the fit is the same), and the largest and RMS vertical distance between the
mesh and the function over the gap (at its vertices there), against the fit's RMS.

    .venv/bin/python benchmarks/holes.py [--quick] [--clouds]
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

import core.parameterize as parameterize_module  # noqa: E402
from core import TCBError, fit_surface  # noqa: E402


def f(x, y):
    return 0.3 * np.sin(3 * x) * np.cos(2 * y)


def grid(m: int):
    """Vertices and quad cells of an m x m grid mesh of f; each cell's row and column."""
    g = np.linspace(0, 1, m)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    i = np.arange(m * m).reshape(m, m)
    cells = np.c_[i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()]
    r, q = np.divmod(np.arange(len(cells)), m - 1)
    return np.c_[x, y, f(x, y)], cells, r, q


def grid_cases(quick: bool):
    P, cells, r, q = grid(41)
    c = 19.5
    ring = np.hypot(r - c, q - c)
    shapes = {
        "round (41 grid)": ring < 4.4,
        "C": (ring >= 4.5) & (ring <= 6.0) & ~((q > c) & (np.abs(r - c) < 2.5)),
        "L": ((q >= 14) & (q < 17) & (r >= 12) & (r < 28))
        | ((r >= 25) & (r < 28) & (q >= 14) & (q < 27)),
        "crescent": (ring < 6) & (np.hypot(r - c, q - 22.5) >= 5),
        "S": ((np.hypot(r - 15.5, q - c) >= 3) & (np.hypot(r - 15.5, q - c) <= 4.5) & (q <= c))
        | ((np.hypot(r - 24.5, q - c) >= 3) & (np.hypot(r - 24.5, q - c) <= 4.5) & (q >= c)),
    }
    if quick:
        shapes = {k: shapes[k] for k in ("round (41 grid)", "C")}
    for name, cut in shapes.items():
        yield name, P, cells[~cut], np.c_[(q[cut] + 0.5) / 40, (r[cut] + 0.5) / 40]
    if quick:
        return
    P, cells, r, q = grid(81)
    ring = np.hypot(r - 39.5, q - 39.5)
    for radius in (12, 17):
        cut = ring < radius
        yield (f"round r={radius} (81 grid)", P, cells[~cut],
               np.c_[(q[cut] + 0.5) / 80, (r[cut] + 0.5) / 80])


def bent_strip(degrees: float, ns: int = 121, nz: int = 21):
    """A strip of ``ns x nz`` vertices bent by ``degrees`` over s in [1.6, 2.4] of its length
    4, with a slot two cells wide along the bend (s in [1.5, 2.5]) at mid-height; its
    vertices, faces and removed vertices (tests/core/test_reconstruction.py uses it too)."""
    s = np.linspace(0, 4, ns)
    phi = np.radians(degrees) * np.clip((s - 1.6) / 0.8, 0, 1)
    x = np.r_[0, np.cumsum(np.cos(phi[:-1]) * (s[1] - s[0]))]
    y = np.r_[0, np.cumsum(np.sin(phi[:-1]) * (s[1] - s[0]))]
    P = np.c_[np.tile(x, nz), np.tile(y, nz), np.repeat(np.linspace(0, 1, nz), ns)]
    i = np.arange(ns * nz).reshape(nz, ns)
    cells = np.c_[i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()]
    r, q = np.divmod(np.arange(len(cells)), ns - 1)
    row = (nz - 1) // 2 - 1
    cut = (r >= row) & (r < row + 2) & (s[q] >= 1.5) & (s[q + 1] <= 2.5)
    F = cells[~cut]
    return P, F, np.setdiff1d(np.arange(len(P)), F)


def run(P, F, rule: str):
    saved = parameterize_module.HOLE_BACKWARD, parameterize_module.HOLE_BULGE
    if rule == "fan":
        parameterize_module.HOLE_BACKWARD, parameterize_module.HOLE_BULGE = np.inf, 0.0
    try:
        t = time.perf_counter()
        surf = fit_surface(P, F, fill_holes=True)
        return surf, time.perf_counter() - t
    finally:
        parameterize_module.HOLE_BACKWARD, parameterize_module.HOLE_BULGE = saved


def smooth(x, y):
    return 0.3 * np.sin(2.0 * x) * np.cos(1.5 * y) + 0.1 * x * y


def cloud_table() -> None:
    """The ``--clouds`` table (module docstring): three round gaps in 30 000 random points of
    ``smooth`` over [-1, 1]^2, and the same gaps in 3000 points."""
    gaps = [((-0.4, 0.3), 0.08), ((0.35, -0.25), 0.15), ((0.3, 0.5), 0.25)]
    print("| points | gap radius | fit RMS | covered without | covered with | max in gap | "
          "RMS in gap | holes counted |")
    print("|---|---|---|---|---|---|---|---|")
    for n in (30_000, 3000):
        xy = np.random.default_rng(1).uniform(-1, 1, (n, 2))
        keep = np.ones(len(xy), dtype=bool)
        for c, r in gaps:
            keep &= np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) > r
        P = np.c_[xy[keep], smooth(*xy[keep].T)]
        rows = {}
        for fill in (False, True):
            surf = fit_surface(P, fill_holes=fill)
            v, t = surf.tessellate(128)
            cen = v[t].mean(axis=1)
            a, b = v[t[:, 1], :2] - v[t[:, 0], :2], v[t[:, 2], :2] - v[t[:, 0], :2]
            area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])  # (over the xy plane)
            err = np.abs(v[:, 2] - smooth(v[:, 0], v[:, 1]))
            for c, r in gaps:
                inside = np.hypot(cen[:, 0] - c[0], cen[:, 1] - c[1]) < r
                on = np.hypot(v[:, 0] - c[0], v[:, 1] - c[1]) < r
                rows.setdefault(r, []).append((area[inside].sum() / (np.pi * r * r),
                                               err[on], surf.report))
        for r, ((without, _, _), (with_, e, rep)) in rows.items():
            big = f"{e.max():.2e} | {np.sqrt(np.mean(e ** 2)):.2e}" if len(e) else " | "
            print(f"| {len(P)} | {r} | {rep['rms']:.2e} | {100 * without:.0f}% | "
                  f"{100 * with_:.0f}% | {big} | {rep['holes_filled']} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two grid holes only (smoke test)")
    ap.add_argument("--clouds", action="store_true", help="gaps in point clouds instead")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # (the removed cells' inner vertices: in no face)
    if args.clouds:
        cloud_table()
        return
    cases = [(name, P, F, ("grid", at)) for name, P, F, at in grid_cases(args.quick)]
    if not args.quick:
        for deg in (30, 90, 180, 240):
            P, F, lost = bent_strip(deg)
            cases.append((f"slot in a {deg} deg bend", P, F, ("strip", lost)))
    print("| hole | rule | control points | RMS | max | in hole | seconds |")
    print("|---|---|---|---|---|---|---|")
    for name, P, F, (kind, at) in cases:
        for rule in ("fan", "shipped"):
            try:
                surf, sec = run(P, F, rule)
            except TCBError as exc:
                print(f"| {name} | {rule} | refused: {str(exc)[:60]} | | | | |")
                continue
            rep = surf.report
            if kind == "grid":
                near = surf.closest_points(np.c_[at, f(*at.T)])
                off = np.abs(near[:, 2] - f(near[:, 0], near[:, 1])).max() / rep["diagonal"]
            else:
                off = surf.distances(P[at]).max() / rep["diagonal"]
            print(f"| {name} | {rule} | {rep['control_points']} | {rep['rms_rel']:.2e} | "
                  f"{rep['max_rel']:.2e} | {off:.2e} | {sec:.1f} |", flush=True)


if __name__ == "__main__":
    main()
