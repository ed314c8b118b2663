"""TCB against DCB with literally the same knots (issue 5: the paper's first claim).

    .venv/bin/python benchmarks/same_knots.py [--seeds 3] [--knots 60] [--points 6000]

For each case (a straight crease ``0.25 |y - 0.3 - 0.4 x|``, a curved crease
``0.25 |y - 0.5 - 0.15 sin 4x|`` and Franke's F1 on uniform random points of the unit square,
several seeds) the same random interior knots plus two jittered border rings define four
quadratic spaces, each fitted by plain least squares (smoothness 0; the data-free functions are
held by the fairing term only, see ``core.fit``):

* ``TCB``: feature-sensitive configurations (``Gamma_0`` flips and link DP by the local
  quadratic-fit residual; the default of ``fit_surface``),
* ``TCB-affine``: the same with the affine (plane-fit) residual in the link DP,
* ``TCB-del``: Delaunay ``Gamma_0`` and constrained-Delaunay links,
* ``DCB``: Neamtu's Delaunay configuration splines, one function per configuration.

Errors: RMS of ``|S(x_j) - p_j|`` at the data and RMS against the true surface on a 90 x 90 grid
of the unit square (what the fit does between the data). One table row per case; the last rows
give the geometric mean, the median and the number of cases below 1 of the ratios to DCB and to
TCB-del (a geometric mean alone hides that a few DCB fits overshoot between the data).
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
from core.border import border_rings  # noqa: E402
from core.configurations import link_triangulation_procedure  # noqa: E402
from core.fit import fit_control_points  # noqa: E402
from core.refine import make_space  # noqa: E402
from core.spline_space import SplineSpace  # noqa: E402
from core.triangulation import FeatureLinkTriangulator, PlaneFitCost, feature_triangulation  # noqa: E402

CASES = {
    "line": lambda x, y: 0.25 * np.abs(y - 0.3 - 0.4 * x),
    "curve": ds.crease,
    "franke": ds.f1_franke,
}


def spaces(K: np.ndarray, n_interior: int, cost: PlaneFitCost) -> dict:
    movable = np.arange(len(K)) < n_interior

    def affine():
        tri0 = feature_triangulation(K, cost, movable=movable)
        lt = FeatureLinkTriangulator(cost, 2, movable, quadratic=False)
        return SplineSpace(K, 2, "tcb", link_triangulation_procedure(K, 2, tri0, lt))

    return {
        "TCB": lambda: make_space(K, 2, "tcb", cost, n_interior),
        "TCB-affine": affine,
        "TCB-del": lambda: make_space(K, 2, "tcb", None, n_interior),
        "DCB": lambda: make_space(K, 2, "dcb", None, n_interior),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--knots", type=int, default=60)
    ap.add_argument("--points", type=int, default=6000)
    ap.add_argument("--smoothness", type=float, default=0.0,
                    help="fairing weight (0: plain least squares; fit_surface uses 1e-4)")
    args = ap.parse_args()
    g = np.stack(np.meshgrid(np.linspace(0.01, 0.99, 90), np.linspace(0.01, 0.99, 90)), -1)
    g = g.reshape(-1, 2)
    methods = ["TCB", "TCB-affine", "TCB-del", "DCB"]
    head = f"{'case':<9}" + "".join(f"{m + ' fns':>15}{m + ' data':>15}{m + ' grid':>15}" for m in methods)
    print(head)
    ratios = {m: [] for m in methods}
    t0 = time.perf_counter()
    for name, f in CASES.items():
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            uv = rng.random((args.points, 2))
            P = np.c_[uv, f(*uv.T)]
            inner = rng.random((args.knots, 2)) * 0.96 + 0.02
            rings = border_rings([0, 0], [1, 1], 1 / np.sqrt(args.knots), rings=2, seed=seed)
            K = np.r_[inner, rings]
            row, res = f"{name + str(seed):<9}", {}
            for m, build in spaces(K, args.knots, PlaneFitCost(uv, P)).items():
                sp = build()
                fit = fit_control_points(sp, uv, P, smoothness=args.smoothness)
                eg = np.linalg.norm(sp.evaluate(g) @ fit.control_points - np.c_[g, f(*g.T)], axis=1)
                res[m] = (fit.rms, float(np.sqrt(np.mean(eg**2))))
                row += f"{sp.n_basis:>15}{fit.rms:>15.3e}{res[m][1]:>15.3e}"
            print(row, flush=True)
            for m in methods:
                ratios[m].append((res[m][0] / res["DCB"][0], res[m][1] / res["DCB"][1],
                                  res[m][0] / res["TCB-del"][0], res[m][1] / res["TCB-del"][1]))
    print(f"\nratios over the cases, geometric mean / median / cases below 1 "
          f"(smoothness {args.smoothness:g}, {time.perf_counter() - t0:.0f} s):")
    names = ["data/DCB", "grid/DCB", "data/TCB-del", "grid/TCB-del"]
    print(f"{'method':<12}" + "".join(f"{n:>22}" for n in names))
    for m in methods:
        r = np.array(ratios[m])
        cells = [f"{np.exp(np.log(c).mean()):.2f} / {np.median(c):.2f} / {int((c < 1).sum())}"
                 for c in r.T]
        print(f"{m:<12}" + "".join(f"{c:>22}" for c in cells))


if __name__ == "__main__":
    main()
