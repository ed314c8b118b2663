"""Spline-space benchmark (issue 2): build and evaluation speed of TCB spaces.

Prints a table: degree, knots, points -> seconds to build the space (link-triangulation
procedure + per-configuration precomputation), seconds to evaluate the sparse basis matrix,
non-zeros per row, (point, function) pairs per second. Peer measured in the same run: scipy's
tensor-product B-spline design matrix (``BSpline.design_matrix`` per axis, row-wise Kronecker
product) of the same degree with about as many basis functions, on the same points.

    python benchmarks/bench_space.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core import border_rings, build_space  # noqa: E402


def tensor_design(uv: np.ndarray, n_basis: int, degree: int) -> sp.csr_matrix:
    """Peer: bivariate tensor-product B-spline design matrix with ~n_basis functions."""
    m = max(int(round(np.sqrt(n_basis))), degree + 1)
    inner = np.linspace(0, 1, m - degree + 1)
    t = np.r_[[0.0] * degree, inner, [1.0] * degree]
    Bu = BSpline.design_matrix(np.clip(uv[:, 0], 0, 1), t, degree).tocsr()
    Bv = BSpline.design_matrix(np.clip(uv[:, 1], 0, 1), t, degree).tocsr()
    # row-wise Kronecker product: (Bu[i] kron Bv[i])
    nu, nv = Bu.shape[1], Bv.shape[1]
    ku, kv = np.diff(Bu.indptr), np.diff(Bv.indptr)
    rows = np.repeat(np.arange(len(uv)), ku * kv)
    iu = np.repeat(np.arange(Bu.nnz), np.repeat(kv, ku))
    start_v = np.repeat(Bv.indptr[:-1], ku * kv)
    off = np.arange(len(rows)) - np.repeat(np.cumsum(ku * kv) - ku * kv, ku * kv)
    iv = start_v + off % np.repeat(kv, ku * kv)
    cols = Bu.indices[iu] * nv + Bv.indices[iv]
    vals = Bu.data[iu] * Bv.data[iv]
    return sp.csr_matrix((vals, (rows, cols)), shape=(len(uv), nu * nv))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller sizes (a smoke run)")
    args = ap.parse_args()
    knot_counts = (250, 1000) if args.quick else (250, 1000, 4000)
    point_counts = (10_000,) if args.quick else (10_000, 100_000)
    rng = np.random.default_rng(0)
    header = (f"{'deg':>3} {'knots':>6} {'points':>7} {'n_basis':>7} {'build s':>8} "
              f"{'eval s':>7} {'nnz/row':>7} {'pairs/s':>9} | {'peer s':>7} {'ratio':>6}")
    print(header)
    print("-" * len(header))
    for degree in (2, 3):
        for n in knot_counts:
            inner = rng.random((n, 2))
            knots = np.vstack([inner, border_rings([0, 0], [1, 1], 1 / np.sqrt(n),
                                                   rings=2 if degree == 2 else 3)])
            t0 = time.perf_counter()
            space = build_space(knots, degree)
            t_build = time.perf_counter() - t0
            for m in point_counts:
                uv = rng.random((m, 2))
                t0 = time.perf_counter()
                A = space.evaluate(uv)
                t_eval = time.perf_counter() - t0
                t0 = time.perf_counter()
                tensor_design(uv, space.n_basis, degree)
                t_peer = time.perf_counter() - t0
                print(f"{degree:>3} {len(knots):>6} {m:>7} {space.n_basis:>7} {t_build:>8.2f} "
                      f"{t_eval:>7.2f} {A.nnz / m:>7.1f} {A.nnz / t_eval:>9.2e} | "
                      f"{t_peer:>7.3f} {t_eval / t_peer:>6.1f}")
    print("\nratio = TCB evaluation seconds / tensor-product design-matrix seconds (same points)")


if __name__ == "__main__":
    main()
