"""Tensor-product B-spline fitting with adaptive knot placement by dominant columns and rows.

The baseline of the seed paper's comparison (method.md section 8), after

    H. Park, "B-spline surface fitting based on adaptive knot placement using dominant columns",
    Computer-Aided Design 43(3), 2011, 258-264.

Data: parameters ``uv (N, 2)`` and points ``(N, 3)``. Grid data (the parameters take few distinct
values per axis, e.g. a DEM) has one *column* per distinct ``u`` and one *row* per distinct ``v``;
scattered parameters are binned into columns and rows by quantiles (about ``sqrt(N)`` each).

1. **Feature measure** of a column: how much the data bends across it. Every point gets the
   second derivatives ``|P_uu|``, ``|P_vv|`` of a local quadratic least-squares fit to its ``k``
   nearest neighbours in parameter space (batched 6x6 solves, no loop over points); a column's
   measure is the mean ``|P_uu|`` of its points times the column's width (so a crease inside one
   column counts as its jump in slope, whatever the sampling), a row's the same with ``|P_vv|``.
2. **Dominant columns**: the first and last columns, and interior columns equally spaced in the
   cumulative sum of ``feature + mean feature`` (half feature-driven, half uniform), so they
   crowd where the data bends. The same for rows.
3. **Knots by averaging** the parameters ``s_0 < ... < s_{d-1}`` of the ``d`` dominant columns
   (the averaging technique, one control point per dominant column): clamped ends and interior
   knots ``mean(s_j, ..., s_{j+p-1})``, ``j = 1 .. d-p-1``; likewise in ``v``.
4. **Least squares**: the design matrix ``B_u(u_j) (x) B_v(v_j)`` row by row from scipy's
   ``BSpline.design_matrix`` (sparse, ``(p+1)^2`` entries per row, built without loops),
   normal equations with a small second-difference fairing of the control net and a tiny ridge
   (so empty spans stay determined), one sparse LU for the three coordinates.
5. **Refinement**: the squared errors are summed per *strip* (the points between two consecutive
   dominant columns, or rows); in the worst strips (about 10% of the strips per iteration) the
   column (row) with the largest error sum becomes dominant; knots are re-averaged and the surface
   refitted, until the RMS (or max) error is at most the tolerance, the next step would exceed the
   control-point budget ``n_u * n_v``, or the iteration limit.

numpy/scipy only, never imports bpy.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

from ..errors import InvalidInputError, SingularSystemError

__all__ = ["TensorSurface", "fit_tensor", "averaged_knots", "design_matrix"]


# ---------------------------------------------------------------------------------------------
# B-spline pieces
# ---------------------------------------------------------------------------------------------
def averaged_knots(params: np.ndarray, degree: int) -> np.ndarray:
    """Clamped knot vector for ``d = len(params)`` control points by averaging.

    Ends of multiplicity ``degree + 1`` at ``params[0]`` and ``params[-1]``; interior knots
    ``mean(params[j : j + degree])`` for ``j = 1 .. d - degree - 1`` (strictly increasing params
    give strictly increasing knots).
    """
    s = np.asarray(params, dtype=np.float64)
    p = int(degree)
    d = len(s)
    if d < p + 1:
        raise InvalidInputError(f"need at least {p + 1} dominant parameters, got {d}")
    c = np.concatenate([[0.0], np.cumsum(s)])
    j = np.arange(1, d - p)
    interior = (c[j + p] - c[j]) / p
    return np.concatenate([np.full(p + 1, s[0]), interior, np.full(p + 1, s[-1])])


def _basis(x: np.ndarray, t: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Column indices and values ``(m, p+1)`` of the nonzero B-splines at ``x`` (clamped)."""
    x = np.clip(np.asarray(x, dtype=np.float64), t[p], t[-p - 1])
    B = BSpline.design_matrix(x, t, p)
    B = sp.csr_matrix(B)
    if not np.all(np.diff(B.indptr) == p + 1):  # scipy stores exactly p+1 per row; be safe
        B = B.tolil()
        idx = np.zeros((len(x), p + 1), dtype=np.int64)
        val = np.zeros((len(x), p + 1))
        for i, (r, v) in enumerate(zip(B.rows, B.data)):  # pragma: no cover - fallback only
            idx[i, : len(r)], val[i, : len(v)] = r, v
        return idx, val
    return B.indices.reshape(-1, p + 1).astype(np.int64), B.data.reshape(-1, p + 1)


def design_matrix(uv: np.ndarray, tu: np.ndarray, tv: np.ndarray, p: int) -> sp.csr_matrix:
    """Sparse ``(m, n_u * n_v)`` matrix of the tensor B-splines at ``uv`` (row-wise Kronecker)."""
    nv = len(tv) - p - 1
    iu, vu = _basis(uv[:, 0], tu, p)
    iv, vv = _basis(uv[:, 1], tv, p)
    m = len(uv)
    w = (p + 1) ** 2
    cols = (iu[:, :, None] * nv + iv[:, None, :]).reshape(m, w)
    vals = (vu[:, :, None] * vv[:, None, :]).reshape(m, w)
    nu = len(tu) - p - 1
    return sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, m * w + 1, w)),
                         shape=(m, nu * nv))


def _second_differences(n: int) -> sp.csr_matrix:
    if n < 3:
        return sp.csr_matrix((0, n))
    return sp.diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2],
                    shape=(n - 2, n), format="csr")


# ---------------------------------------------------------------------------------------------
# Columns, rows and their feature measure
# ---------------------------------------------------------------------------------------------
@dataclass
class _Axis:
    """Columns (or rows) of one parameter axis."""

    label: np.ndarray  # (N,) column of every point
    params: np.ndarray  # (c,) mean parameter of each column (ends: the data's min / max)
    feature: np.ndarray = field(default=None)  # (c,) feature measure


def _columns(values: np.ndarray, gridded: bool, n_bins: int) -> _Axis:
    if gridded:
        params, label = np.unique(values, return_inverse=True)
    else:
        edges = np.quantile(values, np.linspace(0.0, 1.0, n_bins + 1))
        label = np.clip(np.searchsorted(edges[1:-1], values, side="right"), 0, n_bins - 1)
        used, label = np.unique(label, return_inverse=True)
        cnt = np.bincount(label)
        params = np.bincount(label, weights=values) / cnt
        # equal values in neighbouring bins would give equal column parameters: merge them
        params, inv = np.unique(params, return_inverse=True)
        label = inv[label]
    params = params.astype(np.float64).copy()
    params[0], params[-1] = float(values.min()), float(values.max())
    return _Axis(label=label.astype(np.int64), params=params)


def local_second_derivatives(uv: np.ndarray, points: np.ndarray, k: int = 12,
                             max_points: int = 50_000, seed: int = 0):
    """``|P_uu|`` and ``|P_vv|`` (s,) of a quadratic least-squares fit to each point's ``k``
    nearest neighbours in parameter space, on a subsample (indices (s,) returned first)."""
    N = len(uv)
    rng = np.random.default_rng(seed)
    sample = np.sort(rng.choice(N, max_points, replace=False)) if N > max_points else np.arange(N)
    k = int(min(k, N))
    if k < 6:
        return sample, np.zeros(len(sample)), np.zeros(len(sample))
    _, nb = cKDTree(uv).query(uv[sample], k=k)
    d = uv[nb] - uv[sample][:, None, :]  # (s, k, 2)
    r = np.maximum(np.abs(d).max(axis=(1, 2)), 1e-300)[:, None]
    du, dv = d[..., 0] / r, d[..., 1] / r
    X = np.stack([np.ones_like(du), du, dv, du * du, du * dv, dv * dv], axis=-1)  # (s, k, 6)
    G = np.einsum("ski,skj->sij", X, X) + 1e-9 * np.eye(6)
    rhs = np.einsum("ski,skc->sic", X, points[nb])  # (s, 6, 3)
    coef = np.linalg.solve(G, rhs)
    r2 = r[:, 0] ** 2
    puu = 2.0 * np.linalg.norm(coef[:, 3, :], axis=1) / r2
    pvv = 2.0 * np.linalg.norm(coef[:, 5, :], axis=1) / r2
    return sample, puu, pvv


def _feature(axis: _Axis, sample: np.ndarray, second: np.ndarray) -> np.ndarray:
    c = len(axis.params)
    lab = axis.label[sample]
    cnt = np.bincount(lab, minlength=c)
    mean = np.bincount(lab, weights=second, minlength=c) / np.maximum(cnt, 1)
    # empty columns (subsampling) borrow their neighbours' value
    if np.any(cnt == 0) and np.any(cnt > 0):
        have = np.flatnonzero(cnt > 0)
        mean = np.interp(np.arange(c), have, mean[have])
    p = axis.params
    width = np.gradient(p) if c > 1 else np.ones(1)
    return mean * np.abs(width)


def _initial_dominant(feature: np.ndarray, count: int) -> np.ndarray:
    """``count`` column indices (sorted, unique, ends included), equally spaced in the
    cumulative ``feature + mean(feature)``."""
    c = len(feature)
    count = int(min(max(count, 2), c))
    w = feature + max(float(feature.mean()), 1e-300)
    W = np.concatenate([[0.0], np.cumsum(w[1:-1])]) if c > 2 else np.zeros(c)
    if c > 2:
        W = W / max(W[-1], 1e-300)
        targets = np.arange(1, count - 1) / (count - 1)
        idx = 1 + np.searchsorted(W[1:], targets, side="left")
        idx = np.clip(idx, 1, c - 2)
    else:
        idx = np.zeros(0, dtype=np.int64)
    idx = np.concatenate([[0], idx, [c - 1]]).astype(np.int64)
    # make strictly increasing (a crease asks for the same column several times: use its
    # neighbours), forward then backward
    for i in range(1, len(idx)):
        idx[i] = max(idx[i], idx[i - 1] + 1)
    idx[-1] = c - 1
    for i in range(len(idx) - 2, -1, -1):
        idx[i] = min(idx[i], idx[i + 1] - 1)
    return idx


# ---------------------------------------------------------------------------------------------
# The surface
# ---------------------------------------------------------------------------------------------
class TensorSurface:
    """A tensor-product B-spline surface ``S(u, v) = sum_ij c_ij N_i(u) M_j(v)``.

    Attributes: ``degree``, ``knots_u``, ``knots_v``, ``control_points`` ``(n_u, n_v, 3)``,
    ``n_control_points``, ``errors`` (N,) at the data it was fitted to, ``report`` (dict:
    control_points, shape, rms, max, rms_rel, max_rel, iterations, stop_reason, seconds,
    history), ``dominant_u`` / ``dominant_v`` (parameters of the dominant columns / rows).
    """

    def __init__(self, degree, knots_u, knots_v, control_points, errors=None, report=None,
                 dominant_u=None, dominant_v=None):
        self.degree = int(degree)
        self.knots_u = np.asarray(knots_u, dtype=np.float64)
        self.knots_v = np.asarray(knots_v, dtype=np.float64)
        nu = len(self.knots_u) - self.degree - 1
        nv = len(self.knots_v) - self.degree - 1
        self.control_points = np.asarray(control_points, dtype=np.float64).reshape(nu, nv, -1)
        self.errors = None if errors is None else np.asarray(errors)
        self.report = dict(report or {})
        self.dominant_u = dominant_u
        self.dominant_v = dominant_v

    @property
    def shape(self) -> tuple[int, int]:
        return self.control_points.shape[:2]

    @property
    def n_control_points(self) -> int:
        return int(self.shape[0] * self.shape[1])

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        p = self.degree
        return ((self.knots_u[p], self.knots_u[-p - 1]), (self.knots_v[p], self.knots_v[-p - 1]))

    def evaluation_matrix(self, uv) -> sp.csr_matrix:
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        return design_matrix(uv, self.knots_u, self.knots_v, self.degree)

    def __call__(self, uv) -> np.ndarray:
        """Surface points ``(m, dim)`` at ``uv (m, 2)`` (clamped to the domain box)."""
        C = self.control_points.reshape(self.n_control_points, -1)
        return self.evaluation_matrix(uv) @ C

    def __repr__(self) -> str:
        return (f"TensorSurface(degree={self.degree}, shape={self.shape}, "
                f"rms_rel={self.report.get('rms_rel', float('nan')):.3g})")


def _solve(A: sp.csr_matrix, P: np.ndarray, nu: int, nv: int, smoothness: float) -> np.ndarray:
    AtA = (A.T @ A).tocsc()
    rhs = A.T @ P
    n = nu * nv
    D = sp.vstack([sp.kron(_second_differences(nu), sp.identity(nv)),
                   sp.kron(sp.identity(nu), _second_differences(nv))]).tocsr()
    R = (D.T @ D).tocsc()
    scale = AtA.diagonal().sum() / n
    lam = smoothness * AtA.diagonal().sum() / max(R.diagonal().sum(), 1e-300)
    for ridge in (1e-12, 1e-9, 1e-6):
        M = (AtA + lam * R + ridge * scale * sp.identity(n)).tocsc()
        try:
            C = spla.splu(M).solve(np.ascontiguousarray(rhs))
        except RuntimeError:
            continue
        if np.all(np.isfinite(C)):
            return C
    raise SingularSystemError("the tensor-product least-squares system is singular")


def fit_tensor(
    uv,
    points,
    max_control_points: int = 400,
    tolerance: float = 1e-3,
    degree: int = 3,
    *,
    relative: bool = True,
    criterion: str = "rms",
    max_iterations: int = 60,
    smoothness: float = 1e-4,
    initial: int | None = None,
    per_iteration: float = 0.1,
    n_columns: int | None = None,
    seed: int = 0,
) -> TensorSurface:
    """Park (2011) tensor-product B-spline fit of ``points (N, 3)`` at parameters ``uv (N, 2)``.

    Parameters
    ----------
    max_control_points : budget on ``n_u * n_v``; refinement stops before exceeding it.
    tolerance : stop when the RMS (``criterion="max"``: max) error is at most this; relative to
        the bounding-box diagonal of ``points`` when ``relative``.
    degree : B-spline degree (3: bicubic, the paper's setting).
    smoothness : weight of the second-difference fairing of the control net relative to the
        data term (keeps empty spans determined; 0 for plain least squares).
    initial : dominant columns (and rows) to start with (default ``~0.4 sqrt(budget)``).
    per_iteration : fraction of the strips refined per iteration (at least one).
    n_columns : columns (and rows) scattered parameters are binned into (default ``2 sqrt(N)``,
        at most 400); grid data uses its own columns.
    """
    t_start = time.perf_counter()
    uv = np.asarray(uv, dtype=np.float64)
    P = np.asarray(points, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2 or P.ndim != 2 or len(P) != len(uv):
        raise InvalidInputError("fit_tensor needs uv (N, 2) and points (N, dim) of equal length")
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(P))):
        raise InvalidInputError("uv and points must be finite")
    p = int(degree)
    if p < 1:
        raise InvalidInputError("degree must be at least 1")
    if max_control_points < (p + 1) ** 2:
        raise InvalidInputError(f"max_control_points must be at least {(p + 1) ** 2}")
    if criterion not in ("rms", "max"):
        raise InvalidInputError("criterion must be 'rms' or 'max'")
    N = len(uv)
    diagonal = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    tol = tolerance * (diagonal if relative else 1.0)

    # columns and rows: grid data keeps its own, scattered data is binned by quantiles
    nuniq = [len(np.unique(uv[:, 0])), len(np.unique(uv[:, 1]))]
    gridded = nuniq[0] * nuniq[1] <= 2 * N and max(nuniq) <= 4000
    nb = int(n_columns or np.clip(2 * np.sqrt(N), 8, 400))
    axes = [_columns(uv[:, a], gridded, nb) for a in (0, 1)]
    if min(len(ax.params) for ax in axes) < p + 1:
        raise InvalidInputError(f"the data has fewer than {p + 1} distinct columns or rows")
    sample, puu, pvv = local_second_derivatives(uv, P, seed=seed)
    axes[0].feature = _feature(axes[0], sample, puu)
    axes[1].feature = _feature(axes[1], sample, pvv)

    n0 = initial or max(p + 1, int(round(0.4 * np.sqrt(max_control_points))))
    dom = [_initial_dominant(ax.feature, n0) for ax in axes]
    while len(dom[0]) * len(dom[1]) > max_control_points:
        big = 0 if len(dom[0]) >= len(dom[1]) else 1
        dom[big] = _initial_dominant(axes[big].feature, len(dom[big]) - 1)

    history: list[dict] = []
    best = None
    reason = "iteration limit"
    for it in range(int(max_iterations)):
        t0 = time.perf_counter()
        knots = [averaged_knots(axes[a].params[dom[a]], p) for a in (0, 1)]
        nu, nv = len(dom[0]), len(dom[1])
        A = design_matrix(uv, knots[0], knots[1], p)
        C = _solve(A, P, nu, nv, smoothness)
        err = np.linalg.norm(A @ C - P, axis=1)
        rms, mx = float(np.sqrt(np.mean(err ** 2))), float(err.max())
        history.append({
            "iteration": it + 1, "control_points": nu * nv, "shape": [nu, nv],
            "rms": rms, "max": mx, "rms_rel": rms / diagonal, "max_rel": mx / diagonal,
            "seconds": time.perf_counter() - t0,
        })
        if best is None or rms < best[0]:
            best = (rms, mx, knots, C, err, [d.copy() for d in dom])
        if (rms if criterion == "rms" else mx) <= tol:
            reason = "tolerance reached"
            break
        if it == max_iterations - 1:
            break
        # strips: points between consecutive dominant columns (rows)
        e2 = err * err
        cands = []  # (score, axis, column)
        for a in (0, 1):
            d = dom[a]
            lab = axes[a].label
            col_err = np.bincount(lab, weights=e2, minlength=len(axes[a].params))
            strip = np.searchsorted(d, lab, side="right") - 1  # strip i: columns d[i] .. d[i+1]-1
            strip = np.clip(strip, 0, len(d) - 2)
            strip_err = np.bincount(strip, weights=e2, minlength=len(d) - 1)
            for i in np.argsort(-strip_err):
                lo, hi = d[i] + 1, d[i + 1]
                if hi <= lo or strip_err[i] <= 0:
                    continue
                free = np.arange(lo, hi)
                ce = col_err[free]
                j = free[np.argmax(ce)] if ce.max() > 0 else free[len(free) // 2]
                cands.append((float(strip_err[i]), a, int(j)))
        if not cands:
            reason = "no strip can be refined"
            break
        cands.sort(key=lambda c: -c[0])
        want = max(1, int(np.ceil(per_iteration * (nu + nv))))
        new = [list(dom[0]), list(dom[1])]
        added = 0
        for _, a, j in cands:
            size = [len(new[0]), len(new[1])]
            size[a] += 1
            if size[0] * size[1] > max_control_points:
                continue
            new[a].append(j)
            added += 1
            if added >= want:
                break
        if added == 0:
            reason = "control-point budget reached"
            break
        dom = [np.array(sorted(new[0]), dtype=np.int64), np.array(sorted(new[1]), dtype=np.int64)]

    rms, mx, knots, C, err, dom_best = best
    report = {
        "control_points": int(len(dom_best[0]) * len(dom_best[1])),
        "shape": [len(dom_best[0]), len(dom_best[1])],
        "rms": rms, "max": mx, "rms_rel": rms / diagonal, "max_rel": mx / diagonal,
        "diagonal": diagonal, "iterations": len(history), "stop_reason": reason,
        "gridded": bool(gridded), "columns": [len(axes[0].params), len(axes[1].params)],
        "seconds": time.perf_counter() - t_start, "history": history,
    }
    return TensorSurface(p, knots[0], knots[1], C, err, report,
                         dominant_u=axes[0].params[dom_best[0]],
                         dominant_v=axes[1].params[dom_best[1]])
