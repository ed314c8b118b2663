"""Least-squares fitting of control points with fairing (method.md section 5).

Minimizes, over the control points ``C`` (n_basis, 3),

    sum_j w_j |S(x_j) - p_j|^2
      + alpha sum_q a_q (|S_u|^2 + |S_v|^2)
      + beta  sum_q a_q (|S_uu|^2 + 2 |S_uv|^2 + |S_vv|^2)

through the sparse normal equations
``(A^T W A + alpha G1 + beta G2) C = A^T W P + (alpha G1 + beta G2) L`` with
``G1 = Du^T Q Du + Dv^T Q Dv`` and
``G2 = Duu^T Q Duu + 2 Duv^T Q Duv + Dvv^T Q Dvv`` (``Q`` the quadrature weights ``a_q``). ``A^T W A``
and ``A^T W P`` are accumulated over chunks of points; the sparse chunks of ``A`` are kept (up to
:data:`KEEP_BYTES`, more than the 2e6 points ``fit_surface`` fits) for iterative refinement and
the errors, so the basis is evaluated once per fit. ``alpha`` and ``beta`` are given relative to
``trace(A^T W A) / trace(G)``, so one ``smoothness`` works at any scale and knot density. One
sparse LU factorization serves the three coordinates.

The fairing measures the surface minus its reference ``L``: the control points of the weighted
least-squares quadratic map ``(u, v) -> p`` of the data (:func:`fairing_reference`: its polar
form at each function's interior knots, which reproduces it exactly, method.md section 2.2;
the affine map, ``L_I = M [xi_I, 1]`` at the Greville points ``xi_I``, at degree 1 or where the
quadratic is ill-determined), i.e. the energies above are those of ``S - (quadratic fit)``.
Without a reference the first-order energy pulled the surface towards a constant: a plane was
not reproduced (in-plane errors of 7e-4 of its size, edges drawn in), and a cloud's in-plane
coordinates, which are exactly affine in its parameters, were bent; against the affine one the
second-order energy pulled curved surfaces towards a plane (a saddle, which a quadratic spline
holds exactly, 0.23 mm off at its border over 100 mm: user test). (method.md section 5 has
the energies of ``S`` itself.)

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
from .geometry import column_bounds
from .parallel import background
from .simplex import orient2d

__all__ = ["FitResult", "fit_control_points", "fairing_quadrature", "check_smoothness",
           "affine_reference", "fairing_reference", "PARTITION_TOL", "AUTO_SMOOTHNESS",
           "SPARSE_SMOOTHNESS",
           "DEFAULT_SMOOTHNESS"]

PARTITION_TOL = 1e-9
CHUNK = 200_000
# the evaluated basis chunks are kept up to this size (CSR bytes) instead of evaluated again
# for the errors: at 1e6 points that second evaluation took as long as the first (10 s)
KEEP_BYTES = 768 * 2**20
# beta = smoothness, alpha = FIRST_ORDER_SHARE * smoothness (both relative to the data term)
FIRST_ORDER_SHARE = 0.1
# smoothness="auto": the candidates (largest first), the number of cross-validation folds, the
# fewest points that make a choice (below it: DEFAULT_SMOOTHNESS)
AUTO_SMOOTHNESS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
FOLDS = 5
MIN_AUTO_POINTS = 10
# sparse data: fewer fitted points than this per basis function that sees data. Between the
# points only the fairing holds the surface, and the choice also tries these larger weights
# (the limit of a large weight is the quadratic fit, fairing_reference): on 30-60 random
# points of Franke's function cross-validation chose 1-100
SPARSE_POINTS_PER_CONTROL = 2
SPARSE_SMOOTHNESS = (1e2, 1e1, 1.0, 1e-1)


class DefaultSmoothness(float):
    """The default fairing weight 1e-4 as a float that remembers it was not chosen by the
    user: on sparse clouds :func:`core.refine.adaptive_fit` then uses the cross-validated
    weight instead (``smoothness=1e-4`` passed explicitly is used as given). Arithmetic gives
    plain floats; saved surfaces keep the distinction (``smoothness_is_default``)."""


DEFAULT_SMOOTHNESS = DefaultSmoothness(1e-4)


@dataclass
class FitResult:
    """Control points and per-point errors of one least-squares fit."""

    control_points: np.ndarray  # (n_basis, 3)
    errors: np.ndarray  # (N,) |S(x_j) - p_j|
    rms: float
    max: float
    timings: dict = field(default_factory=dict)
    smoothness: float = DEFAULT_SMOOTHNESS  # the value used (the chosen one for "auto")
    # smoothness="auto": the cross-validated RMS of each candidate ({} when a value was given)
    validation: dict = field(default_factory=dict)
    # the evaluated basis, CSR chunks of CHUNK rows (None if it was too large to keep): a later
    # fit of the same space at the same parameters can take it (``basis=``)
    basis: list | None = field(default=None, repr=False, compare=False)
    # with ``normals``: |(S(x_j) - p_j) . n_j| at the first len(normals) points (None without)
    across: np.ndarray | None = field(default=None, repr=False, compare=False)


def fairing_quadrature(space) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points (Q, 2) and weights (Q,) over ``Gamma_0`` of ``space``.

    Three points per triangle at barycentric ``(2/3, 1/6, 1/6)`` and permutations, each with
    weight ``area / 3``: exact for polynomials of degree 2 on every triangle.
    """
    T = space.configurations.triangles[0]
    K = space.knots
    a, b, c = K[T[:, 0]], K[T[:, 1]], K[T[:, 2]]
    area = 0.5 * np.abs(orient2d(a, b, c))
    pts = [(4 * a + b + c) / 6, (a + 4 * b + c) / 6, (a + b + 4 * c) / 6]
    q = np.stack(pts, axis=1).reshape(-1, 2)
    w = np.repeat(area / 3, 3)
    return q, w


def _grams(space, q, w) -> tuple[sp.csr_matrix, sp.csr_matrix | None]:
    """``G1 = Du^T Q Du + Dv^T Q Dv`` and (degree >= 2) ``G2 = Duu^T Q Duu + 2 Duv^T Q Duv +
    Dvv^T Q Dvv`` from one evaluation pass over the quadrature points."""
    ders = [(1, 0), (0, 1)] + ([(2, 0), (1, 1), (0, 2)] if space.degree >= 2 else [])
    D = space.evaluate_many(q, ders)
    W = sp.diags(w)
    G1 = (D[0].T @ W @ D[0] + D[1].T @ W @ D[1]).tocsr()
    if space.degree < 2:
        return G1, None
    G2 = (D[2].T @ W @ D[2] + 2.0 * (D[3].T @ W @ D[3]) + D[4].T @ W @ D[4]).tocsr()
    return G1, G2


def fit_control_points(
    space,
    uv: np.ndarray,
    points: np.ndarray,
    weights: np.ndarray | None = None,
    smoothness: float | str = DEFAULT_SMOOTHNESS,
    check_partition: bool = True,
    scored: int | None = None,
    basis: list | None = None,
    sparse: bool | None = None,
    normals: np.ndarray | None = None,
    pins: tuple | None = None,
) -> FitResult:
    """Fit the control points of ``space`` to ``points`` (N, 3) at parameters ``uv`` (N, 2).

    Parameters
    ----------
    space : SplineSpace
    uv : (N, 2) float64
    points : (N, 3) float64
    weights : (N,) float64, optional
        Nonnegative per-point weights ``w_j`` (default 1).
    smoothness : float or "auto"
        ``beta`` relative to the data term; ``alpha = 0.1 * smoothness`` likewise. 0 means
        pure least squares for the functions that see data; the others then minimize the
        fairing energy with those held (exact reproduction of what the space reproduces).
        ``"auto"``: chosen among :data:`AUTO_SMOOTHNESS` by 5-fold cross-validation
        (:func:`_choose_smoothness`); ``FitResult.smoothness`` says which.
    check_partition : bool
        Assert ``|sum_I B_I(x_j) - 1| < 1e-9`` at every parameter (method.md section 3).
    scored : int, optional
        ``smoothness="auto"``: only the first ``scored`` points score the candidates (a mesh's
        vertices, not the points sampled on its faces; default: all).
    basis : list of CSR, optional
        ``FitResult.basis`` of an earlier fit of this space at these ``uv``: not evaluated again.
    sparse : bool, optional
        ``smoothness="auto"``: whether the data are sparse (the larger candidates
        :data:`SPARSE_SMOOTHNESS` too), as the caller decided it (:func:`core.refine.adaptive_fit`
        counts control points); None: fewer than :data:`SPARSE_POINTS_PER_CONTROL` fitted points
        per function that sees data.
    normals : (M, 3) float64, optional
        Unit normals at the first M points: ``FitResult.across`` gets the errors' components
        along them, ``|(S(x_j) - p_j) . n_j|`` (a noisy mesh's stall test:
        :func:`core.refine.adaptive_fit`).
    pins : (uv (M, 2), targets (M, 3), weight), optional
        Points the surface is drawn to besides the data (a neighbouring surface's border,
        :func:`core.join.join_pins`): the term ``rho sum_m |S(y_m) - t_m|^2`` is added to
        the data term, ``rho = weight * mean(w)``, so each pin counts as ``weight`` data points
        of the mean weight (method.md section 5's objective with extra data; not in
        method.md). The fairing is scaled by the data's trace alone, and the pins neither
        count in ``errors`` nor score an ``"auto"`` smoothness (refused with pins).

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
    smoothness = check_smoothness(smoothness)
    if pins is not None and smoothness == "auto":
        raise ValueError("pins= needs a smoothness value, not 'auto'")

    unit = bool((weights == 1.0).all())
    # the fairing's Gram matrices depend on the space only: made on a thread of their own
    # while the data's basis is evaluated and assembled
    grams = background(lambda: _grams(space, *fairing_quadrature(space)))
    AtA = sp.csr_matrix((n, n))
    AtP = np.zeros((n, 3))
    chunks, keep, kept_bytes = [], True, 0
    worst, n_bad = 0.0, 0
    t_eval = 0.0
    if basis is not None and (len(basis) != -(-N // CHUNK) or any(
            A.shape != (min(CHUNK, N - i * CHUNK), n) for i, A in enumerate(basis))):
        raise ValueError("basis= does not match these parameters and this space")
    for i, s in enumerate(range(0, N, CHUNK)):
        te = time.perf_counter()
        A = basis[i] if basis is not None else space.evaluate(uv[s : s + CHUNK])
        t_eval += time.perf_counter() - te
        if check_partition:
            dev = np.abs(np.asarray(A.sum(axis=1)).ravel() - 1.0)
            worst = max(worst, float(dev.max(initial=0.0)))
            n_bad += int((~(dev < PARTITION_TOL)).sum())
        # (equal weights of one: A itself, the same products without the diagonal's pass)
        WA = A if unit else sp.diags(weights[s : s + CHUNK]) @ A
        AtA = AtA + A.T @ WA
        AtP += WA.T @ points[s : s + CHUNK]
        if keep and kept_bytes + A.data.nbytes + A.indices.nbytes + A.indptr.nbytes <= KEEP_BYTES:
            chunks.append(A)
            kept_bytes += A.data.nbytes + A.indices.nbytes + A.indptr.nbytes
        else:
            keep = False
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
    pin_grad = None
    if pins is not None:  # (after the trace: the pins do not scale the fairing)
        pin_uv, pin_targets, pin_weight = pins
        Ap = space.evaluate(np.asarray(pin_uv, dtype=np.float64))
        rho = float(pin_weight) * float(weights.sum()) / max(N, 1)
        PtP = (rho * (Ap.T @ Ap)).tocsr()
        PtT = rho * (Ap.T @ np.asarray(pin_targets, dtype=np.float64))
        AtA, AtP = AtA + PtP, AtP + PtT

        def pin_grad(c, cols=slice(None)):  # the pins' part of the gradient at c
            return PtP[cols][:, cols] @ c - PtT[cols]
    has_data = AtA.diagonal() > 0
    G1, G2 = grams()
    G = (FIRST_ORDER_SHARE * data_trace / max(G1.diagonal().sum(), 1e-300)) * G1
    if G2 is not None:
        G = G + (data_trace / max(G2.diagonal().sum(), 1e-300)) * G2
    G = G.tocsr()
    quadratic = quadratic_reference_fits(space, uv, weights)  # (the folds' too)
    L = fairing_reference(space, uv, points, weights, quadratic)
    GL = G @ L
    if not (has_data | (G.diagonal() > 0)).all():
        raise SingularSystemError(
            f"{int((~(has_data | (G.diagonal() > 0))).sum())} of the {n} control points have no "
            "data and no fairing to determine them; use fewer control points"
        )
    t_fair = time.perf_counter() - t1

    validation: dict = {}
    t_select = 0.0
    if smoothness == "auto":
        ts = time.perf_counter()
        smoothness, validation = _choose_smoothness(space, uv, points, weights, AtA, AtP, G,
                                                    chunks if keep else None, scored, sparse,
                                                    quadratic=quadratic)
        t_select = time.perf_counter() - ts
    t2 = time.perf_counter()
    if smoothness > 0:
        C, solver = _solve((AtA + smoothness * G).tocsc(), AtP + smoothness * GL, ridge=True)
        if keep:
            C = _refine(C, solver, chunks, weights, points,
                        lambda c: smoothness * (G @ c - GL)
                        + (0.0 if pin_grad is None else pin_grad(c)))
    else:
        # no fairing: pure least squares for the functions that see data, then the functions
        # without data minimize the fairing energy of S - (reference) with the others held
        # (they do not touch the data, so the fit at the data is the exact least-squares one)
        d, u = np.flatnonzero(has_data), np.flatnonzero(~has_data)
        C = np.zeros((n, 3))
        C[d], solver = _solve(AtA[d][:, d].tocsc(), AtP[d], ridge=True)
        if keep:
            C[d] = _refine(C[d], solver, [A[:, d] for A in chunks], weights, points,
                           None if pin_grad is None else lambda c: pin_grad(c, d))
        if len(u):
            C[u], _ = _solve(G[u][:, u].tocsc(), GL[u] - G[u][:, d] @ C[d], ridge=True)
    t_solve = time.perf_counter() - t2

    t3 = time.perf_counter()
    errors = np.empty(N)
    across = None if normals is None else np.empty(len(normals))
    for i, s in enumerate(range(0, N, CHUNK)):
        A = chunks[i] if i < len(chunks) else space.evaluate(uv[s : s + CHUNK])
        r = A @ C - points[s : s + CHUNK]
        errors[s : s + CHUNK] = np.linalg.norm(r, axis=1)
        if across is not None and s < len(across):
            m = min(CHUNK, len(across) - s)
            across[s : s + m] = np.abs(np.einsum("ij,ij->i", r[:m], normals[s : s + m]))
    t_err = time.perf_counter() - t3
    timings = {
        "basis": t_eval,
        "assembly": t_assemble,
        "fairing": t_fair,
        "solve": t_solve,
        "errors": t_err,
    }
    if validation:
        timings["smoothness"] = t_select
    return FitResult(
        control_points=C,
        errors=errors,
        rms=float(np.sqrt(np.mean(errors**2))) if N else 0.0,
        max=float(errors.max(initial=0.0)),
        timings=timings,
        smoothness=float(smoothness),
        validation=validation,
        basis=chunks if keep else None,
        across=across,
    )


def affine_reference(space, uv: np.ndarray, points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Control points ``L`` (n_basis, 3) of the weighted least-squares affine map
    ``(u, v) -> p`` of the data: ``L_I = c_p + (xi_I - c_u) M`` with ``c_u``, ``c_p`` the
    weighted means, ``M`` (2, 3) minimizing ``sum_j w_j |(x_j - c_u) M - (p_j - c_p)|^2`` (its
    2x2 normal equations, accumulated in chunks of points) and ``xi_I`` the Greville points.
    The spline with these control points is that affine map where the basis is a partition of
    unity (linear reproduction, method.md section 2.2); the fairing pulls towards it (module
    docstring). Centring makes it exact for a plane."""
    w = np.asarray(weights, dtype=np.float64)
    total = float(w.sum())
    if not total > 0:
        return np.zeros((space.n_basis, 3))
    cu = (w @ uv) / total
    cp = (w @ points) / total
    XtWX, XtWP = np.zeros((2, 2)), np.zeros((2, 3))
    for s in range(0, len(uv), CHUNK):  # chunks: lstsq on all of 1e6 points took 120 MB
        X = uv[s : s + CHUNK] - cu
        wX = X * w[s : s + CHUNK, None]
        XtWX += wX.T @ X
        XtWP += wX.T @ (points[s : s + CHUNK] - cp)
    M, *_ = np.linalg.lstsq(XtWX, XtWP, rcond=None)  # (2, 3)
    return cp + (np.asarray(space.greville) - cu) @ M


# fairing_reference: the quadratic is taken where it is well determined over the data: its
# normal equations, in parameters whitened by the data's own covariance (a long strip is as
# good as a square), have a smallest eigenvalue of at least this share of the largest (a
# square or a disk 0.07-0.08, a square with a hole of 0.3 of its side 0.033, annuli of width
# 0.3 / 0.2 / 0.1 of the radius 9e-3 / 3.6e-3 / 8e-4: /tmp/s35/cond.py). A thin annulus's
# quadratic is set by its width, and the fairing carried it into the hole: 0.048 -> 0.107 off
# there (review) ...
QUADRATIC_REFERENCE_COND = 2e-3
# ... and where the data are dense: at least this many points per basis function. Between
# sparse points the fairing, not the data, shapes the surface, and a quadratic of the whole
# cloud is no guide to it: 500 points of Franke's function at degree 3 were 0.065 off
# against 0.055 with the affine reference, in DCB mode 0.097 against 0.083 (review); the
# CAD-like patches it is for have 100 and more
QUADRATIC_REFERENCE_POINTS = 5.0


def fairing_reference(space, uv: np.ndarray, points: np.ndarray, weights: np.ndarray,
                      quadratic: bool | None = None) -> np.ndarray:
    """Control points ``L`` (n_basis, 3) of the reference the fairing measures the surface
    against (module docstring): at degree 2 and 3, the weighted least-squares quadratic map
    ``(u, v) -> p`` of the data, whose control points are its polar form at each function's
    interior knots ``I`` (quadratic reproduction through the blossom, method.md section 2.2:
    ``F({a, b}) = c + g (a + b) / 2 + a^T H b`` for ``c + g x + x^T H x``, at three knots the
    means over their pairs and the knots); :func:`affine_reference` at degree 1, for sparse
    data or where the quadratic is ill-determined (:func:`quadratic_reference_fits`; given as
    ``quadratic``, else decided on these weights: a fit decides once, for its
    cross-validation folds too).

    Against the affine reference the second-order energy pulled every curved surface towards
    a plane, most at its border (the fairing's natural boundary condition, zero curvature at
    the edge of the border rings): a saddle z = 0.01 (x^2 - y^2) over 100 mm, which a
    quadratic spline holds exactly, took 141 control points for an RMS of 1e-2 with the
    surface 0.23 mm off at the border (37 and 7.7e-3 without fairing), and with the criterion
    "max" 1195 control points whose final, cross-validated smoothness left fins of 0.53 mm
    along the border (user test; /tmp/s35/fair/cmp.py). Against the quadratic: 37 control
    points and 7.7e-3, 41 and 8.4e-3; a 90-degree cylinder's border 0.11 -> 0.04 mm; Franke,
    F7, the crease, the DEM (quadratic TCB fits of 5000 points and more) and the bundled meshes
    as before to 3 digits."""
    if quadratic is None:
        quadratic = quadratic_reference_fits(space, uv, weights)
    moments = _quadratic_moments(uv, np.asarray(weights, dtype=np.float64),
                                 points) if quadratic else None
    if moments is None:
        return affine_reference(space, uv, points, weights)
    cu, white, XtWX, XtWP = moments
    coef = np.linalg.solve(XtWX, XtWP)  # (6, 3)
    K = (np.asarray(space.knots)[space.interior_sets] - cu) @ white  # (n_basis, k, 2)
    k = K.shape[1]
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
    xx = np.mean([K[:, a, 0] * K[:, b, 0] for a, b in pairs], axis=0)
    yy = np.mean([K[:, a, 1] * K[:, b, 1] for a, b in pairs], axis=0)
    xy = np.mean([0.5 * (K[:, a, 0] * K[:, b, 1] + K[:, b, 0] * K[:, a, 1])
                  for a, b in pairs], axis=0)
    return np.c_[np.ones(len(K)), K.mean(axis=1), xx, xy, yy] @ coef


def _monomials(x: np.ndarray) -> np.ndarray:
    """1, x, y, x^2, x y, y^2 at the (whitened) parameters ``x`` (m, 2)."""
    return np.c_[np.ones(len(x)), x, x[:, 0] ** 2, x[:, 0] * x[:, 1], x[:, 1] ** 2]


def _whitening(uv: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The weighted mean ``c`` of ``uv`` and a 2 x 2 ``W`` such that ``(uv - c) @ W`` has unit
    weighted covariance (None when the data are a point or a line)."""
    total = float(w.sum())
    cu = (w @ uv) / total
    d = uv - cu
    cov = (d * w[:, None]).T @ d / total
    ev, vec = np.linalg.eigh(cov)
    if not ev[0] > 1e-12 * max(ev[1], 1e-300):
        return cu, None
    return cu, vec / np.sqrt(ev)


def _quadratic_moments(uv: np.ndarray, w: np.ndarray, points: np.ndarray | None = None):
    """``(c, W, X^T w X, X^T w P)`` of the weighted least-squares quadratic in the whitened
    parameters ``(uv - c) @ W`` (:func:`_whitening`; ``X`` their :func:`_monomials`),
    accumulated in chunks of points (the last None without ``points``); None for data on a
    line."""
    cu, white = _whitening(uv, w)
    if white is None:
        return None
    XtWX = np.zeros((6, 6))
    XtWP = None if points is None else np.zeros((6, 3))
    for s in range(0, len(uv), CHUNK):
        X = _monomials((uv[s : s + CHUNK] - cu) @ white)
        wX = X * w[s : s + CHUNK, None]
        XtWX += wX.T @ X
        if points is not None:
            XtWP += wX.T @ points[s : s + CHUNK]
    return cu, white, XtWX, XtWP


def quadratic_reference_fits(space, uv: np.ndarray, weights: np.ndarray) -> bool:
    """Whether :func:`fairing_reference` takes the data's quadratic: degree 2 or more, at least
    QUADRATIC_REFERENCE_POINTS points of positive weight per basis function, and the quadratic
    well determined over the data (QUADRATIC_REFERENCE_COND, in whitened parameters)."""
    w = np.asarray(weights, dtype=np.float64)
    if (space.degree < 2 or space.n_basis == 0 or not float(w.sum()) > 0
            or np.count_nonzero(w > 0) < QUADRATIC_REFERENCE_POINTS * space.n_basis):
        return False
    moments = _quadratic_moments(uv, w)
    if moments is None:
        return False
    ev = np.linalg.eigvalsh(moments[2])
    return bool(ev[0] > QUADRATIC_REFERENCE_COND * ev[-1])


def check_smoothness(value):
    """A smoothness as given by a user: a nonnegative number, or ``"auto"``."""
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    v = np.nan
    if not isinstance(value, (str, bool, np.bool_)) and np.ndim(value) == 0:
        try:
            v = float(value)
        except (TypeError, ValueError):
            pass
    if not (np.isfinite(v) and v >= 0):
        raise InvalidInputError(f"smoothness must be a nonnegative number or 'auto', got {value!r}")
    return v


def _choose_smoothness(space, uv, points, weights, AtA, AtP, G, chunks, scored=None,
                       sparse=None, quadratic=None):
    """Cross-validated choice of the fairing weight (method.md section 5).

    The points are dealt into :data:`FOLDS` folds by :func:`_folds` (same input, same choice;
    points with (nearly) the same parameters share a fold). For fold
    ``f`` the normal equations of the other points are those of all points minus the fold's
    rows, ``K_f = A^T W A - A_f^T W_f A_f + s G_f`` and ``A^T W P - A_f^T W_f P_f + s G_f L_f``
    (``L_f`` the reference of the points kept, :func:`fairing_reference`, quadratic or not as
    ``quadratic`` says, the full fit's decision; ``G_f``
    scaled by the data term of the points kept, as in a fit with the fold's weights set to 0,
    without its final iterative refinement); every candidate ``s`` of :data:`AUTO_SMOOTHNESS`
    is solved on them (one sparse factorization each; the basis is not evaluated again) and
    predicts the fold's points. Each point is predicted once; the score of ``s`` is the
    weighted mean of ``|A_f C_s - P_f|^2`` over the first ``scored`` points (default all: for a
    mesh its vertices, while the points sampled on its faces are fitted and left out like the
    others but not scored). The choice is :func:`_one_standard_error`. Candidates whose system
    is singular are skipped. With fewer than :data:`MIN_AUTO_POINTS` scored points of positive
    weight there is nothing to cross-validate: :data:`DEFAULT_SMOOTHNESS`. On ``sparse`` data
    (see :func:`fit_control_points`) the candidates :data:`SPARSE_SMOOTHNESS` come first.

    Returns the chosen value and ``{candidate: cross-validated RMS}``.
    """
    N = len(uv)
    m = N if scored is None else int(min(max(scored, 0), N))
    if int((weights[:m] > 0).sum()) < MIN_AUTO_POINTS:
        return DEFAULT_SMOOTHNESS, {}
    if sparse is None:  # all fitted points count (a mesh's face samples make it dense)
        sparse = (int((weights > 0).sum())
                  < SPARSE_POINTS_PER_CONTROL * int(np.count_nonzero(AtA.diagonal() > 0)))
    candidates = SPARSE_SMOOTHNESS + AUTO_SMOOTHNESS if sparse else AUTO_SMOOTHNESS
    fold = _folds(uv)
    starts = np.cumsum([0] + [A.shape[0] for A in chunks or []])

    def fold_rows(f):  # one fold's rows of A at a time (memory: a fifth of A)
        rows = np.flatnonzero(fold == f)
        if chunks is None:  # the basis was too large to keep: evaluate it again, in chunks
            return rows, sp.vstack([space.evaluate(uv[rows[i : i + CHUNK]])
                                    for i in range(0, len(rows), CHUNK)]).tocsr()
        parts = [A[fold[starts[i] : starts[i + 1]] == f] for i, A in enumerate(chunks)]
        return rows, sp.vstack(parts).tocsr()

    sq = {s: np.zeros(N) for s in candidates}
    failed: set = set()
    data_trace = AtA.diagonal().sum()
    # every system below has (nearly) the pattern of AtA + G: one ordering serves them all
    order = _fill_order((AtA + G).tocsc())
    for f in range(FOLDS):
        rows, Af = fold_rows(f)
        wf, Pf = weights[rows], points[rows]
        WAf = sp.diags(wf) @ Af
        K_fit = AtA - Af.T @ WAf
        rhs = AtP - WAf.T @ Pf
        # G is scaled by the data term (module docstring): here by that of the points kept
        G_fit = (K_fit.diagonal().sum() / data_trace) * G
        GL_fit = G_fit @ fairing_reference(space, uv, points, np.where(fold == f, 0.0, weights),
                                           quadratic)
        for s in candidates:
            if s in failed:
                continue
            try:
                C, _ = _solve((K_fit + s * G_fit).tocsc(), rhs + s * GL_fit, ridge=True,
                              order=order)
            except SingularSystemError:
                failed.add(s)
                continue
            sq[s][rows] = np.sum((Af @ C - Pf) ** 2, axis=1)
    errors = {s: v[:m] for s, v in sq.items() if s not in failed}
    if not errors:
        return DEFAULT_SMOOTHNESS, {}
    return _one_standard_error(errors, weights[:m])


# parameters closer than this fraction of the extent share a cross-validation fold
FOLD_CELL = 1e-7


def _folds(uv: np.ndarray) -> np.ndarray:
    """The cross-validation fold (N,) of each parameter: a hash (splitmix64 finalizer) of the
    cell of a grid of :data:`FOLD_CELL` times the extent that holds it, modulo :data:`FOLDS`.

    Duplicated points, and near duplicates (closer than the cell, e.g. vertices welded badly),
    fall in the same fold: left out one at a time, each would be predicted by its twin and the
    choice would favour too little smoothing. Twins that straddle a cell border (a chance of
    about their distance over the cell) are split. Same input, same folds.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if len(uv) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = column_bounds(uv)
    cell = FOLD_CELL * max(float((hi - lo).max()), 1e-300)
    keys = np.floor((uv - lo) / cell).astype(np.int64).view(np.uint64)
    h = np.full(len(uv), 0x9E3779B97F4A7C15, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for col in keys.T:
            h = (h ^ col) * np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(31)
            h = h * np.uint64(0x94D049BB133111EB)
            h ^= h >> np.uint64(29)
    return (h % np.uint64(FOLDS)).astype(np.int64)


def _one_standard_error(sq: dict, weights: np.ndarray):
    """The one-standard-error rule (Hastie, Tibshirani, Friedman, *The Elements of Statistical
    Learning*, section 7.10) on cross-validated squared errors ``sq = {s: (n,) array}``.

    Score ``m_s = sum w_j e_sj / sum w_j``; ``best`` minimizes it; its standard error is that of
    a weighted mean, ``se = sqrt(sum (w_j / W)^2 (e_best,j - m_best)^2)``; the choice is the
    largest ``s`` with ``m_s <= m_best + se``. Smaller ``s`` fits the data more closely but
    lets the functions that see few points overshoot between them: the rule keeps the smoother
    fit unless the data clearly ask for less smoothing (the minimum score alone picked
    overshooting fits, docs/benchmarks.md). Returns ``(s, {s: sqrt(m_s)})``.
    """
    w = weights / weights.sum()
    mean = {s: float(np.sum(w * e)) for s, e in sq.items()}
    best = min(mean, key=mean.get)
    se = float(np.sqrt(np.sum(w * w * (sq[best] - mean[best]) ** 2)))
    chosen = max(s for s, v in mean.items() if v <= mean[best] + se)
    return chosen, {s: float(np.sqrt(v)) for s, v in mean.items()}


def _refine(C, solver, chunks, weights, points, penalty_grad, steps: int = 10):
    """Iterative refinement with residuals from ``A`` itself (semi-normal equations, Bjorck):
    ``C += K^-1 g`` with ``g = A^T W (P - A C) - penalty'(C)``, while the residual ``|g|``
    (largest entry) falls (at most ``steps``; the ``C`` with the smallest residual is kept).
    The normal equations square the condition number; this recovers the accuracy of a QR
    solve (cubic TCB bases can be nearly dependent: condition 1e17 was measured). A
    well-conditioned quadratic fit reaches the rounding floor after one or two corrections and
    then stops, instead of always making ten passes over ``A`` (0.07 s at 1e5 points).
    """
    best_C, best_g = C, np.inf
    for _ in range(steps):
        g = np.zeros_like(C)
        s = 0
        for A in chunks:
            e = s + A.shape[0]
            g += A.T @ (weights[s:e, None] * (points[s:e] - A @ C))
            s = e
        if penalty_grad is not None:
            g -= penalty_grad(C)
        g_norm = float(np.abs(g).max(initial=0.0))
        if not g_norm < best_g:
            break
        best_C, best_g = C, g_norm
        delta = solver(g)
        C = C + delta
        if np.abs(delta).max() <= 1e-15 * max(np.abs(C).max(), 1e-300):
            best_C = C
            break
    return best_C


class _OrderedLU:
    """The LU factors of ``K[order][:, order]`` answering for ``K``."""

    def __init__(self, lu, order):
        self.lu, self.order, self.U = lu, order, lu.U

    def solve(self, rhs):
        x = np.empty_like(rhs, dtype=np.float64)
        x[self.order] = self.lu.solve(np.ascontiguousarray(rhs[self.order]))
        return x


def _factor(K: sp.csc_matrix, order: np.ndarray | None = None):
    """Symmetric sparse LU (no pivoting: the pivots of an SPD matrix are positive and bounded
    below by its smallest eigenvalue) and the smallest pivot ratio; None if it broke down.

    ``order``: a fill-reducing symmetric ordering to use instead of computing one
    (:func:`_fill_order`); many systems of one sparsity pattern (the candidates and folds of
    ``smoothness="auto"``) then factor 1.5x faster."""
    try:
        if order is None:
            lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
        else:
            lu = _OrderedLU(spla.splu(K[order][:, order].tocsc(), permc_spec="NATURAL",
                                      diag_pivot_thresh=0.0, options={"SymmetricMode": True}),
                            order)
    except RuntimeError:  # "Factor is exactly singular"
        return None, 0.0
    d = lu.U.diagonal()
    ratio = float(d.min(initial=np.inf) / max(np.abs(d).max(initial=0.0), 1e-300))
    return lu, ratio


def _fill_order(K: sp.csc_matrix) -> np.ndarray | None:
    """The minimum-degree ordering SuperLU chooses for ``K`` (as row/column indices), or None."""
    lu, _ = _factor(K)
    return None if lu is None else np.argsort(lu.perm_c)


def _solve(K: sp.csc_matrix, rhs: np.ndarray, ridge: bool = True,
           order: np.ndarray | None = None):
    """Solve the SPD normal equations; never a silent blow-up (method.md section 5).

    (Functions that neither data nor fairing determine are refused before, by the caller.)

    * TCB bases can be linearly dependent (method.md section 2.2). When the plain system has a
      pivot ratio below ``1e-13`` (or a non-positive pivot) and ``ridge`` is on, the smallest
      ridge ``eps trace(K)/n``, ``eps = 1e-15, 1e-14, 1e-13, 1e-12``, whose factor has positive
      pivots (ratio above ``1e-3 eps``) picks a solution in the (near) null-space directions,
      which do not change the surface, and iterated Tikhonov,
      ``C += (K + lambda I)^-1 (rhs - K C)``, removes the ridge's bias from the others until the
      residual stops falling (at most 60 steps; the bias shrinks by ``lambda / (mu + lambda)``
      per step for an eigenvalue ``mu``). A cubic basis with five null directions and genuine
      eigenvalues down to ``1e-15`` of the largest needs both the small ridge and the steps:
      a fixed ``1e-12`` ridge with four steps reproduced a cubic to 1.5e-7, this to 1e-13.
    * No ridge that factors, a non-finite solution or a relative residual above ``1e-6`` is
      refused.
    """
    n = K.shape[0]
    lu, ratio = _factor(K, order)
    ridged = False
    if not ratio > 1e-13 and ridge:
        mean_diag = K.diagonal().sum() / n
        for eps in (1e-15, 1e-14, 1e-13, 1e-12):
            lu, ratio = _factor((K + sp.identity(n, format="csc") * (eps * mean_diag)).tocsc(),
                                order)
            if lu is not None and ratio > 1e-3 * eps:
                ridged = True
                break
        else:
            lu = None
    if lu is None or not (ridged or ratio > 1e-14):
        raise SingularSystemError(
            f"the fitting system ({n} control points) is numerically singular (pivot ratio "
            f"{ratio:.2e}); use fewer control points or a larger smoothness"
        )
    C = lu.solve(rhs)
    if ridged:
        # iterated Tikhonov against the system without the ridge, while the residual falls;
        # the null-space part stays bounded
        res = np.linalg.norm(rhs - K @ C)
        for _ in range(60):
            C_new = C + lu.solve(rhs - K @ C)
            res_new = np.linalg.norm(rhs - K @ C_new)
            if not res_new < res:
                break
            C, converged = C_new, res_new > 0.99 * res
            res = res_new
            if converged:
                break
    if not np.all(np.isfinite(C)):
        raise SingularSystemError("the fit produced non-finite control points")
    resid = np.linalg.norm(K @ C - rhs) / max(np.linalg.norm(rhs), 1e-300)
    if resid > 1e-6:
        raise SingularSystemError(
            f"the fitting system is too ill-conditioned (relative residual {resid:.1e}); use "
            "fewer control points or a larger smoothness"
        )
    return C, lu.solve
