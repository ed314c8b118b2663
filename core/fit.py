"""Least-squares fitting of control points with fairing (method.md section 5).

Minimizes, over the control points ``C`` (n_basis, 3),

    sum_j w_j |S(x_j) - p_j|^2
      + alpha sum_q a_q (|S_u|^2 + |S_v|^2)
      + beta  sum_q a_q (|S_uu|^2 + 2 |S_uv|^2 + |S_vv|^2)

through the sparse normal equations
``(A^T W A + alpha G1 + beta G2) C = A^T W P`` with ``G1 = Du^T Q Du + Dv^T Q Dv`` and
``G2 = Duu^T Q Duu + 2 Duv^T Q Duv + Dvv^T Q Dvv`` (``Q`` the quadrature weights ``a_q``). ``A^T W A``
and ``A^T W P`` are accumulated over chunks of points, so memory does not grow with the number of
points. ``alpha`` and ``beta`` are given relative to ``trace(A^T W A) / trace(G)``, so one
``smoothness`` works at any scale and knot density. One sparse LU factorization serves the three
coordinates.

Quadrature: three points per triangle of ``Gamma_0`` (the rule exact for quadratics, weights
``area / 3``). ``Gamma_0`` covers the convex hull of all knots, including the border rings, so every
basis function meets quadrature points and functions with little or no data are held by the
fairing term.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import BorderError, InvalidInputError, SingularSystemError

__all__ = ["FitResult", "fit_control_points", "fairing_quadrature", "PARTITION_TOL"]

PARTITION_TOL = 1e-9
CHUNK = 200_000
# beta = smoothness, alpha = FIRST_ORDER_SHARE * smoothness (both relative to the data term)
FIRST_ORDER_SHARE = 0.1


@dataclass
class FitResult:
    """Control points and per-point errors of one least-squares fit."""

    control_points: np.ndarray  # (n_basis, 3)
    errors: np.ndarray  # (N,) |S(x_j) - p_j|
    rms: float
    max: float
    timings: dict = field(default_factory=dict)


def fairing_quadrature(space) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points (Q, 2) and weights (Q,) over ``Gamma_0`` of ``space``.

    Three points per triangle at barycentric ``(2/3, 1/6, 1/6)`` and permutations, each with
    weight ``area / 3``: exact for polynomials of degree 2 on every triangle.
    """
    T = space.configurations.triangles[0]
    K = space.knots
    a, b, c = K[T[:, 0]], K[T[:, 1]], K[T[:, 2]]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    pts = [(4 * a + b + c) / 6, (a + 4 * b + c) / 6, (a + b + 4 * c) / 6]
    q = np.stack(pts, axis=1).reshape(-1, 2)
    w = np.repeat(area / 3, 3)
    return q, w


def _gram(space, q, w, derivatives, factors) -> sp.csr_matrix:
    G = None
    W = sp.diags(w)
    for der, f in zip(derivatives, factors):
        D = space.evaluate(q, der)
        term = (D.T @ W @ D) * f
        G = term if G is None else G + term
    return G.tocsr()


def fit_control_points(
    space,
    uv: np.ndarray,
    points: np.ndarray,
    weights: np.ndarray | None = None,
    smoothness: float = 1e-4,
    check_partition: bool = True,
) -> FitResult:
    """Fit the control points of ``space`` to ``points`` (N, 3) at parameters ``uv`` (N, 2).

    Parameters
    ----------
    space : SplineSpace
    uv : (N, 2) float64
    points : (N, 3) float64
    weights : (N,) float64, optional
        Nonnegative per-point weights ``w_j`` (default 1).
    smoothness : float
        ``beta`` relative to the data term; ``alpha = 0.1 * smoothness`` likewise.
    check_partition : bool
        Assert ``|sum_I B_I(x_j) - 1| < 1e-9`` at every parameter (method.md section 3).

    Raises
    ------
    BorderError
        The basis does not sum to one at some data parameters.
    SingularSystemError
        The normal equations are singular or the solution is not trustworthy.
    """
    t0 = time.perf_counter()
    uv = np.asarray(uv, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    N, n = len(uv), space.n_basis
    if weights is None:
        weights = np.ones(N)
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape != (N,) or not np.all(np.isfinite(weights)) or (weights < 0).any():
        raise InvalidInputError("weights must be N finite nonnegative numbers, one per point")
    if not (np.isfinite(smoothness) and smoothness >= 0):
        raise InvalidInputError(f"smoothness must be a nonnegative number, got {smoothness}")

    AtA = sp.csr_matrix((n, n))
    AtP = np.zeros((n, 3))
    chunks = []
    worst, n_bad = 0.0, 0
    t_eval = 0.0
    for s in range(0, N, CHUNK):
        te = time.perf_counter()
        A = space.evaluate(uv[s : s + CHUNK])
        t_eval += time.perf_counter() - te
        if check_partition:
            dev = np.abs(np.asarray(A.sum(axis=1)).ravel() - 1.0)
            worst = max(worst, float(dev.max(initial=0.0)))
            n_bad += int((~(dev < PARTITION_TOL)).sum())
        WA = sp.diags(weights[s : s + CHUNK]) @ A
        AtA = AtA + A.T @ WA
        AtP += WA.T @ points[s : s + CHUNK]
        if N <= 2 * CHUNK:
            chunks.append(A)
    if n_bad:
        raise BorderError(
            f"the spline basis does not sum to one at {n_bad} of {N} data parameters (worst "
            f"deviation {worst:.3g}); more auxiliary border rings are needed"
        )
    t_assemble = time.perf_counter() - t0 - t_eval

    t1 = time.perf_counter()
    data_trace = AtA.diagonal().sum()
    if not data_trace > 0:
        raise SingularSystemError("no data point lies in the support of any basis function")
    K = AtA
    if smoothness > 0:
        q, qw = fairing_quadrature(space)
        G1 = _gram(space, q, qw, [(1, 0), (0, 1)], [1.0, 1.0])
        K = K + (FIRST_ORDER_SHARE * smoothness * data_trace / max(G1.diagonal().sum(), 1e-300)) * G1
        if space.degree >= 2:
            G2 = _gram(space, q, qw, [(2, 0), (1, 1), (0, 2)], [1.0, 2.0, 1.0])
            K = K + (smoothness * data_trace / max(G2.diagonal().sum(), 1e-300)) * G2
    t_fair = time.perf_counter() - t1

    t2 = time.perf_counter()
    C = _solve(K.tocsc(), AtP, ridge=smoothness > 0)
    t_solve = time.perf_counter() - t2

    t3 = time.perf_counter()
    errors = np.empty(N)
    for i, s in enumerate(range(0, N, CHUNK)):
        A = chunks[i] if chunks else space.evaluate(uv[s : s + CHUNK])
        errors[s : s + CHUNK] = np.linalg.norm(A @ C - points[s : s + CHUNK], axis=1)
    t_err = time.perf_counter() - t3
    timings = {
        "basis": t_eval,
        "assembly": t_assemble,
        "fairing": t_fair,
        "solve": t_solve,
        "errors": t_err,
    }
    return FitResult(
        control_points=C,
        errors=errors,
        rms=float(np.sqrt(np.mean(errors**2))) if N else 0.0,
        max=float(errors.max(initial=0.0)),
        timings=timings,
    )


def _solve(K: sp.csc_matrix, rhs: np.ndarray, ridge: bool = True) -> np.ndarray:
    """Solve the SPD normal equations; never a silent blow-up (method.md section 5).

    * A column without data and without fairing (a function nothing determines) is refused.
    * TCB bases can be linearly dependent (method.md section 2.2): when the fairing term is on
      (``ridge``), a ridge of ``1e-12 trace(K)/n`` picks a solution in the null-space directions,
      which do not change the surface anywhere.
    * The factorization is symmetric (no pivoting), so its pivots are bounded below by the
      smallest eigenvalue; a pivot ratio below ``1e-14``, a non-finite solution or a relative
      residual above ``1e-6`` is refused.
    """
    n = K.shape[0]
    diag = K.diagonal()
    dead = np.flatnonzero(~(diag > 1e-14 * diag.max(initial=0.0)))
    if len(dead):
        raise SingularSystemError(
            f"{len(dead)} of the {n} control points have no data and no fairing to determine "
            "them; use a positive smoothness or fewer control points"
        )
    if ridge:
        K = (K + sp.identity(n, format="csc") * (1e-12 * diag.sum() / n)).tocsc()
    try:
        lu = spla.splu(
            K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularSystemError(
            f"the fitting system ({n} control points) is singular: {exc}; use fewer control "
            "points or a larger smoothness"
        ) from None
    d = lu.U.diagonal()
    if not (d.min(initial=np.inf) > 1e-14 * np.abs(d).max(initial=0.0)):
        raise SingularSystemError(
            f"the fitting system ({n} control points) is numerically singular (pivot ratio "
            f"{d.min() / np.abs(d).max():.2e}); use fewer control points or a larger smoothness"
        )
    C = lu.solve(rhs)
    if not np.all(np.isfinite(C)):
        raise SingularSystemError("the fit produced non-finite control points")
    resid = np.linalg.norm(K @ C - rhs) / max(np.linalg.norm(rhs), 1e-300)
    if resid > 1e-6:
        raise SingularSystemError(
            f"the fitting system is too ill-conditioned (relative residual {resid:.1e}); use "
            "fewer control points or a larger smoothness"
        )
    return C
