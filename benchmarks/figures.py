"""Figures for docs/benchmarks.md (issue 5); needs matplotlib (requirements-bench.txt).

    .venv/bin/python benchmarks/figures.py            # writes docs/fig_*.png

* ``fig_configurations.png``: the knot triangulation Gamma_0 and the level-1 configurations
  (link triangulations) over the parameter domain for TCB and DCB on the crease data, with the
  crease drawn in.
* ``fig_error_maps.png``: the errors of TCB, DCB and the Park tensor fit at equal control
  points, side by side (points coloured by error, one shared log scale).
* ``fig_error_vs_cp.png``: RMS/diag against control points along each method's refinement
  (``report['history']``) on the crease, the DEM and Franke's F1 (quadratic and cubic TCB).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

import datasets as ds  # noqa: E402
from core import fit_surface  # noqa: E402
from core.baselines import fit_tensor  # noqa: E402

DOCS = ROOT / "docs"
N = 3000
BUDGET = 300


def crease_curve(surf, m=200):
    """The crease line y = 0.5 + 0.15 sin(4x) mapped to the surface's parameter plane."""
    x = np.linspace(0, 1, m)
    pts = np.c_[x, 0.5 + 0.15 * np.sin(4 * x), np.zeros(m)]
    return surf.parameterization.project(pts)


def draw_triangles(ax, knots, tris, **kw):
    t = np.asarray(tris)
    if len(t) == 0:
        return
    seg = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    seg = np.unique(np.sort(seg, axis=1), axis=0)
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(knots[seg], **kw))


def fig_configurations(P):
    settings = dict(tolerance=0.0, initial_knots=40, knots_per_iteration=12, max_iterations=4,
                    max_control_points=100_000)
    fits = {"TCB (feature-sensitive)": fit_surface(P, mode="tcb", **settings),
            "DCB (Delaunay)": fit_surface(P, mode="dcb", **settings)}
    fig, axes = plt.subplots(2, 2, figsize=(11, 10.5), constrained_layout=True)
    for col, (name, s) in enumerate(fits.items()):
        K = s.knots
        n_int = s.n_interior
        lo, hi = s.parameterization.uv.min(axis=0), s.parameterization.uv.max(axis=0)
        pad = 0.08 * (hi - lo)
        cur = crease_curve(s)
        for row in range(2):
            ax = axes[row, col]
            tris = s.configurations.triangles[row]
            draw_triangles(ax, K, tris, colors="0.35" if row == 0 else "tab:blue",
                           linewidths=0.7 if row == 0 else 0.35, alpha=1.0 if row == 0 else 0.6)
            ax.plot(cur[:, 0], cur[:, 1], color="tab:red", lw=2.2, alpha=0.8, label="crease")
            ax.plot(K[:n_int, 0], K[:n_int, 1], "o", ms=3.5, color="k", label="interior knots")
            ax.plot(K[n_int:, 0], K[n_int:, 1], "s", ms=2.5, color="0.6", label="border rings")
            ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
            ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
            ax.set_aspect("equal")
            r = s.report
            what = "knot triangulation $\\Gamma_0$" if row == 0 else (
                f"level-1 configurations ({len(tris)} triangles)")
            ax.set_title(f"{name}: {what}\n{r['interior_knots']} interior knots, "
                         f"{r['control_points']} control points, RMS/diag {r['rms_rel']:.2e}",
                         fontsize=10)
            if row == 0 and col == 0:
                ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    fig.suptitle("Crease z = 0.25 |y - 0.5 - 0.15 sin 4x|, same initial knots and "
                 "iterations (4): parameter domain", fontsize=12)
    out = DOCS / "fig_configurations.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def fig_error_maps(P):
    tcb = fit_surface(P, mode="tcb", tolerance=0.0, max_control_points=BUDGET, initial_knots=25,
                      knots_per_iteration=10, max_iterations=40)
    dcb = fit_surface(P, mode="dcb", tolerance=0.0, max_control_points=BUDGET, initial_knots=10,
                      knots_per_iteration=10, max_iterations=40)
    ten = fit_tensor(P[:, :2], P, max_control_points=tcb.report["control_points"], tolerance=0.0)
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    errs = {
        f"TCB, {tcb.report['control_points']} cp": tcb.errors / diag,
        f"DCB, {dcb.report['control_points']} cp": dcb.errors / diag,
        f"Park tensor (bicubic), {ten.n_control_points} cp": ten.errors / diag,
    }
    vmax = max(e.max() for e in errs.values())
    vmin = vmax * 1e-3
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.3), constrained_layout=True)
    for ax, (name, e) in zip(axes, errs.items()):
        order = np.argsort(e)
        sc = ax.scatter(P[order, 0], P[order, 1], c=np.clip(e[order], vmin, vmax), s=7,
                        cmap="inferno", norm=LogNorm(vmin=vmin, vmax=vmax))
        x = np.linspace(0, 1, 200)
        ax.plot(x, 0.5 + 0.15 * np.sin(4 * x), color="c", lw=0.8, ls="--")
        ax.set_title(f"{name}\nRMS/diag {np.sqrt(np.mean(e ** 2)):.2e}, max/diag {e.max():.2e}",
                     fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    fig.colorbar(sc, ax=axes, shrink=0.85, label="|S(x_j) - p_j| / diagonal")
    fig.suptitle(f"Error at the data, crease, {len(P)} scattered points, equal control-point "
                 f"budget ({BUDGET}); dashed: the crease", fontsize=12)
    out = DOCS / "fig_error_maps.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def fig_error_vs_cp(data):
    fig, axes = plt.subplots(1, len(data), figsize=(5.2 * len(data), 4.6), constrained_layout=True)
    for ax, (title, P) in zip(np.atleast_1d(axes), data):
        common = dict(tolerance=0.0, max_control_points=500, knots_per_iteration=12,
                      max_iterations=30)
        runs = {
            "TCB": fit_surface(P, mode="tcb", initial_knots=25, **common),
            "TCB Delaunay": fit_surface(P, mode="tcb", feature_sensitive=False,
                                        initial_knots=25, **common),
            "DCB": fit_surface(P, mode="dcb", initial_knots=10, **common),
            "TCB cubic": fit_surface(P, mode="tcb", degree=3, initial_knots=25, **common),
        }
        for (name, s), st in zip(runs.items(), ("o-", "s--", "^-", "v:")):
            h = s.report["history"]
            ax.plot([x["control_points"] for x in h], [x["rms_rel"] for x in h], st, ms=3,
                    label=name)
        ten = fit_tensor(P[:, :2], P, max_control_points=500, tolerance=0.0)
        h = ten.report["history"]
        ax.plot([x["control_points"] for x in h], [x["rms_rel"] for x in h], "d-", ms=3,
                label="Park tensor (bicubic)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("control points")
        ax.set_ylabel("RMS / diagonal")
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Error along the refinement (each point one iteration)", fontsize=12)
    out = DOCS / "fig_error_vs_cp.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main() -> int:
    DOCS.mkdir(exist_ok=True)
    crease = ds.height_field("crease", N)["points"]
    which = sys.argv[1:] or ["configurations", "error_maps", "error_vs_cp"]
    if "configurations" in which:
        print(fig_configurations(crease))
    if "error_maps" in which:
        print(fig_error_maps(crease))
    if "error_vs_cp" in which:
        data = [(f"crease, {N} scattered points", crease),
                ("Jacksboro DEM (every 6th sample)", ds.dem(6)["points"]),
                (f"Franke F1, {N} scattered points", ds.height_field("F1-franke", N)["points"])]
        print(fig_error_vs_cp(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
