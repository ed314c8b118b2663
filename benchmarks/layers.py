"""The final layers check (``core.surface.data_layers``): false alarms and what it finds.

    .venv/bin/python benchmarks/layers.py            # compare.py's 16 datasets x 3 settings
    .venv/bin/python benchmarks/layers.py --quick    # its 4 quick datasets, 1 setting

Part 1 fits compare.py's datasets (seed 0) at its own settings (tolerance 0 to its budget),
at the default tolerance 1e-3 and at 1e-4 with 2000 control points, and prints the control
points, the RMS / diagonal and ``report["layers"]`` (0: no two layers): every nonzero value is
a false alarm. Part 2 fits two copies of a 4 x 4 terrain scan (3000 points each, 5 mm noise)
one lifted by an offset, and the same scan with noise only: ``layers`` should be about the
offset once it is a few noise sigmas, and 0 for noise; offsets the fold check sees (0.2 and
more here) are refused before the fit ("two or more layers about ... apart").
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import compare as C  # noqa: E402
from core import fit_surface  # noqa: E402
from core.errors import ParameterizationError  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    cfg = C.settings(args.quick)
    runs = [("budget", dict(tolerance=0.0, max_control_points=cfg["budget"],
                            initial_knots=cfg["initial"], knots_per_iteration=cfg["per_iteration"],
                            max_iterations=cfg["iterations"]))]
    if not args.quick:
        runs += [("1e-3", dict(tolerance=1e-3)),
                 ("1e-4", dict(tolerance=1e-4, max_control_points=2000))]
    print(f"{'dataset':24} " + " | ".join(f"{name}: cp, rms/diag, layers" for name, _ in runs))
    alarms = 0
    for d in C.dataset_list(args.quick, cfg, 0):
        P, _ = C.split(d, 0)
        row = []
        for _, kw in runs:
            s = fit_surface(P, d["faces"], seed=0, **kw)
            alarms += s.report["layers"] > 0
            row.append(f"{s.report['control_points']}, {s.report['rms_rel']:.2e}, "
                       f"{s.report['layers']:.3g}")
        print(f"{d['name'][:24]:24} " + " | ".join(row), flush=True)
    print(f"false alarms: {alarms}")
    rng = np.random.default_rng(3)
    xy = rng.random((3000, 2)) * 4
    scan = np.c_[xy, 0.3 * np.sin(xy[:, 0])]
    print("\noffset  layers   rms      (two copies, 5 mm noise)")
    for off in (0.0, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2):
        cloud = (np.vstack([scan, scan + [0.0, 0.0, off]]) if off else np.vstack([scan, scan]))
        cloud = cloud + rng.normal(0.0, 0.005, cloud.shape)
        try:
            s = fit_surface(cloud)
            print(f"{off:<7g} {s.report['layers']:<8.3g} {s.report['rms']:.3g}")
        except ParameterizationError as exc:
            print(f"{off:<7g} refused: {str(exc)[:70]}")


if __name__ == "__main__":
    main()
