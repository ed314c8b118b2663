"""Noisy height fields against FITPACK: the error against the noise-free truth.

    .venv/bin/python benchmarks/noisy_peers.py [--quick] [--n 5000] [--noise 0.003]
                                               [--methods ours-d2 ours-1e-5]

``N`` uniform random points in the unit square, ``z = f(x, y) + e``, ``e`` Gaussian with standard
deviation ``sigma = frac * (max f - min f)`` (``frac`` = 0.01 and 0.003; the z-range is taken on a
401 x 401 grid of the unit square), for three test functions of ``benchmarks/datasets.py``:
``F1-franke`` (smooth), ``crease`` (a C^0 ridge along a curve) and ``F2-cliff`` (a steep tanh step
along the diagonal). ``N`` = 5000 and 15000, seeds 0 and 1 (the seed draws the points, the noise
and our fit's random choices). ``--quick``: N = 2000, seed 0, frac 0.01, Franke and the
crease, ``ours-d2`` and ``ours-1e-5`` (about 12 s of CPU).

Methods, on the same points in the same process:

* ``ours-d2``: ``fit_surface(P, seed=seed)``, every default (degree 2, tolerance 1e-3);
* ``ours-d3``: the same with ``degree=3``;
* ``ours-1e-5``: the same with ``tolerance=1e-5``, below any noise here: the run stops when the
  error stops falling and returns the net of the lowest estimated error at new points (what a
  user asking for the closest fit gets; the default tolerance stops before the noise where the
  noise is below it);
* ``smooth-oracle``: ``SmoothBivariateSpline(x, y, z, s=N sigma^2)`` (bicubic; it is told the
  true noise level);
* ``smooth-est``: the same with ``sigma`` estimated from the data: the residual RMS of the
  18-knot ``LSQBivariateSpline`` below, ``sqrt(SSR / (N - coefficients))`` (overestimates the
  noise where that spline cannot follow a feature);
* ``lsq-best``: ``LSQBivariateSpline`` (bicubic), 10, 14 and 18 uniform interior knots per axis;
  the row is the one of the lowest true RMS (``knots`` column: its count; the oracle choice).

Columns: control points (FITPACK: coefficients), the true RMS and max error on a 120 x 120 grid
of [0.02, 0.98]^2 against the noise-free ``f`` (ours: ``surf.heights``; NaN counted, nanmean and
nanmax over the rest), seconds. The summary per function class gives the median (over cases) of
our true RMS over the best peer's (the lowest true RMS of the three FITPACK rows) and of our
control points over that peer's coefficients.
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
from scipy.interpolate import LSQBivariateSpline, SmoothBivariateSpline  # noqa: E402

FUNCS = [("F1-franke", "smooth"), ("crease", "feature"), ("F2-cliff", "feature")]
LSQ_KNOTS = (10, 14, 18)
PEERS = ("smooth-oracle", "smooth-est", "lsq-best")
# our fits: every default; degree 3; a tolerance below any noise here, where the run stops
# when the error stops falling and picks the net by its estimate of the error at new points
# (core.refine STALL_DOF, BEST_BY_NEW_POINTS: benchmarks/noise.py)
OURS = {"ours-d2": {}, "ours-d3": {"degree": 3}, "ours-1e-5": {"tolerance": 1e-5}}


def z_range(f) -> float:
    g = np.linspace(0.0, 1.0, 401)
    X, Y = np.meshgrid(g, g)
    z = f(X, Y)
    return float(z.max() - z.min())


def errors(zhat, ztrue):
    e = zhat - ztrue
    nan = int(np.isnan(e).sum())
    return float(np.sqrt(np.nanmean(e * e))), float(np.nanmax(np.abs(e))), nan


def lsq(x, y, z, k):
    t = np.linspace(0.0, 1.0, k + 2)[1:-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return LSQBivariateSpline(x, y, z, t, t, kx=3, ky=3, bbox=[0, 1, 0, 1])


def smooth(x, y, z, s):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        spl = SmoothBivariateSpline(x, y, z, kx=3, ky=3, s=s, bbox=[0, 1, 0, 1])
    return spl, bool(w)


def run_case(name, n, frac, seed, grid, out, methods=None):
    methods = methods or tuple(OURS)
    f = D.FUNCTIONS[name]
    sigma = frac * z_range(f)
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    x, y = xy.T
    z = f(x, y) + sigma * rng.standard_normal(n)
    P = np.c_[xy, z]
    X, Y = grid
    ztrue = f(X, Y)
    rows = []

    for label, kw in OURS.items():
        if label not in methods:
            continue
        t0 = time.perf_counter()
        surf = fit_surface(P, seed=seed, **kw)
        sec = time.perf_counter() - t0
        rms, mx, nan = errors(surf.heights(np.c_[X, Y]), ztrue)
        r = surf.report
        rows.append((label, r["control_points"], "", rms, mx, nan, sec, r["stop_reason"]))

    t0 = time.perf_counter()
    spl, warned = smooth(x, y, z, n * sigma**2)
    sec = time.perf_counter() - t0
    rms, mx, nan = errors(spl.ev(X, Y), ztrue)
    rows.append(("smooth-oracle", spl.get_coeffs().size, "", rms, mx, nan, sec,
                 "warned" if warned else ""))

    best = None
    lsq_sec = 0.0
    for k in LSQ_KNOTS:
        t0 = time.perf_counter()
        s = lsq(x, y, z, k)
        dt = time.perf_counter() - t0
        lsq_sec += dt
        rms, mx, nan = errors(s.ev(X, Y), ztrue)
        if k == max(LSQ_KNOTS):
            nc = s.get_coeffs().size
            sig_hat = float(np.sqrt(np.sum((s.ev(x, y) - z) ** 2) / (n - nc)))
        if best is None or rms < best[3]:
            best = ("lsq-best", s.get_coeffs().size, k, rms, mx, nan, dt, "")

    t0 = time.perf_counter()
    spl, warned = smooth(x, y, z, n * sig_hat**2)
    sec = time.perf_counter() - t0
    rms, mx, nan = errors(spl.ev(X, Y), ztrue)
    rows.append(("smooth-est", spl.get_coeffs().size, "", rms, mx, nan, sec,
                 f"sigma^ {sig_hat / sigma:.2f}x" + (", warned" if warned else "")))
    rows.append(best[:-1] + (f"3 fits {lsq_sec:.1f} s",))

    for label, cp, knots, rms, mx, nan, sec, note in rows:
        print(f"| {name} | {n} | {sigma:.4g} ({frac:g}) | {seed} | {label} | {cp} | {knots} | "
              f"{rms:.2e} | {mx:.2e} | {nan} | {sec:.1f} | {note} |", flush=True)
    out.append({"class": dict(FUNCS)[name], "sigma": sigma, "frac": frac,
                **{r[0]: {"cp": r[1], "rms": r[3], "max": r[4], "nan": r[5]} for r in rows}})


def summary(results):
    ours = [m for m in OURS if results and all(m in r for r in results)]
    print("\n| class | sigma (of z-range) | cases | "
          + " | ".join(f"{m} / best peer: true RMS | cp" for m in ours) + " | best peer (times) |")
    print("|---|---|---:|" + "---:|---:|" * len(ours) + "---|")
    for cls in ("smooth", "feature"):
        for frac in sorted({r["frac"] for r in results}, reverse=True):
            rs = [r for r in results if r["class"] == cls and r["frac"] == frac]
            if not rs:
                continue
            peer = [min(PEERS, key=lambda p: r[p]["rms"]) for r in rs]
            cells = []
            for m in ours:
                cells.append(np.median([r[m]["rms"] / r[p]["rms"] for r, p in zip(rs, peer)]))
                cells.append(np.median([r[m]["cp"] / r[p]["cp"] for r, p in zip(rs, peer)]))
            wins = {p: peer.count(p) for p in PEERS if peer.count(p)}
            print(f"| {cls} | {frac:g} | {len(rs)} | " + " | ".join(f"{c:.2f}" for c in cells)
                  + " | " + ", ".join(f"{p} {c}" for p, c in wins.items()) + " |")


def parse(text: str) -> list:
    """The cases of a table this script printed, for :func:`summary` (complete cases only)."""
    cases = {}
    for line in text.splitlines():
        c = [x.strip() for x in line.split("|")[1:-1]]
        if len(c) != 12 or c[0] not in dict(FUNCS):
            continue
        frac = float(c[2].split("(")[1].rstrip(")"))
        case = cases.setdefault((c[0], c[1], c[2], c[3]), {"class": dict(FUNCS)[c[0]],
                                                         "frac": frac})
        case[c[4]] = {"cp": int(c[5]), "rms": float(c[7]), "max": float(c[8]), "nan": int(c[9])}
    return [r for r in cases.values() if all(p in r for p in PEERS) and any(m in r for m in OURS)]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true",
                    help="N = 2000, seed 0, frac 0.01, Franke and the crease, ours-d2 and "
                    "ours-1e-5")
    ap.add_argument("--n", type=int, nargs="*", help="point counts (default 5000 15000)")
    ap.add_argument("--noise", type=float, nargs="*",
                    help="noise as fractions of the z-range (default 0.01 0.003)")
    ap.add_argument("--methods", nargs="*", choices=tuple(OURS),
                    help="our fits to run (default all; the peers always run)")
    ap.add_argument("--summarize", metavar="TABLE",
                    help="only print the summary of a table printed before (a partial run)")
    args = ap.parse_args()
    if args.summarize:
        summary(parse(Path(args.summarize).read_text()))
        return
    ns = [2000] if args.quick else (args.n or [5000, 15000])
    fracs = [0.01] if args.quick else (args.noise or [0.01, 0.003])
    seeds = [0] if args.quick else [0, 1]
    funcs = [n for n, _ in FUNCS][:2] if args.quick else [n for n, _ in FUNCS]
    methods = ("ours-d2", "ours-1e-5") if args.quick else tuple(args.methods or OURS)
    g = np.linspace(0.02, 0.98, 120)
    grid = [a.ravel() for a in np.meshgrid(g, g)]
    print("| function | N | sigma (of z-range) | seed | method | cp | knots | true RMS | true max "
          "| NaN | s | note |")
    print("|---|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---|")
    results = []
    for n in ns:
        for frac in fracs:
            for seed in seeds:
                for name in funcs:
                    run_case(name, n, frac, seed, grid, results, methods)
    summary(results)


if __name__ == "__main__":
    main()
