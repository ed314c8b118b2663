"""Adaptive knot insertion: the reconstruction loop (method.md section 6).

1. Initial interior knots in general position, denser where the data bends (a weighted
   centroidal Voronoi tessellation of the data parameters, jittered, never a grid),
   plus rings of auxiliary border knots (method.md section 3).
2. Repeat: build the (feature-sensitive) configurations and the basis, fit (section 5), measure
   ``e_j = |S(x_j) - p_j|``; stop at the tolerance, the control-point budget or the iteration
   limit; rank the ``Gamma_0`` triangles by the error of their data and insert one knot in each
   of the worst, at the error-weighted centroid of its data pulled away from the triangle's
   edges (knot lines) and corners (knots).

A ``callback(report)`` receives a dict per iteration (iteration, knots, control_points, rms, max,
rms_rel, max_rel, seconds) and may return True to cancel: the best surface so far is returned.
"""

from __future__ import annotations

import copy
import inspect
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from .border import border_rings, default_ring_count
from .configurations import link_triangulation_procedure
from .errors import BorderError, InvalidInputError
from .fit import (DEFAULT_SMOOTHNESS, SPARSE_POINTS_PER_CONTROL, DefaultSmoothness, FitResult,
                  check_smoothness, fit_control_points)
from .geometry import column_bounds
from .parallel import background, pmap, row_blocks
from .simplex import orient2d
from .spline_space import SplineSpace, _number, _whole, build_space, validate_knots
from .triangulation import FeatureLinkTriangulator, PlaneFitCost, feature_triangulation, locate

__all__ = [
    "RefineOptions",
    "feature_measure",
    "initial_knots",
    "make_space",
    "locate",
    "insertion_points",
    "area_weights",
    "adaptive_fit",
]


_WHOLE = ("degree", "max_control_points", "max_iterations", "initial_knots",
          "knots_per_iteration", "seed")
_WORDS = {"mode": ("tcb", "dcb"), "criterion": ("rms", "max")}
_FLAGS = ("relative", "feature_sensitive")


@dataclass(frozen=True)
class RefineOptions:
    """Settings of the adaptive loop (see :func:`core.fit_surface` for their meaning).

    Values that mean a valid setting are stored in one spelling (``2.0`` and ``np.int64(2)``
    as ``2``, ``"TCB"`` as ``"tcb"``, numpy bools as bools); :meth:`validate` refuses the rest
    with :class:`InvalidInputError`.
    """

    degree: int = 2
    mode: str = "tcb"
    tolerance: float = 1e-3
    relative: bool = True
    criterion: str = "rms"
    max_control_points: int = 2000
    max_iterations: int = 20
    smoothness: float | str = DEFAULT_SMOOTHNESS  # or "auto" (core.fit)
    initial_knots: int | None = None
    knots_per_iteration: int | None = None
    feature_sensitive: bool = True
    seed: int = 0

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        if isinstance(self.smoothness, str):  # " AUTO " -> "auto" (what files store)
            put("smoothness", check_smoothness(self.smoothness))
        elif isinstance(self.smoothness, DefaultSmoothness):
            pass  # the default (not chosen by the user): sparse clouds cross-validate it
        elif _number(self.smoothness) is not None:
            put("smoothness", _number(self.smoothness))
        for name in _WHOLE:
            if _whole(getattr(self, name)) is not None:
                put(name, _whole(getattr(self, name)))
        for name in _WORDS:
            if isinstance(getattr(self, name), str):
                put(name, getattr(self, name).strip().lower())
        for name in _FLAGS:
            if isinstance(getattr(self, name), np.bool_):
                put(name, bool(getattr(self, name)))
        if _number(self.tolerance) is not None:
            put("tolerance", _number(self.tolerance))

    def validate(self) -> None:
        """Raise :class:`InvalidInputError` saying which setting is wrong and what it accepts."""
        if type(self.degree) is not int or self.degree not in (2, 3):
            raise InvalidInputError(f"degree must be 2 or 3, got {self.degree!r}")
        for name, words in _WORDS.items():
            if not isinstance(getattr(self, name), str) or getattr(self, name) not in words:
                raise InvalidInputError(
                    f"{name} must be {words[0]!r} or {words[1]!r} (any case), "
                    f"got {getattr(self, name)!r}"
                )
        if not (isinstance(self.tolerance, float) and np.isfinite(self.tolerance)
                and self.tolerance >= 0):
            raise InvalidInputError(
                f"tolerance must be a nonnegative number, got {self.tolerance!r}"
            )
        for name in _FLAGS:
            value = getattr(self, name)
            if not isinstance(value, bool):
                raise InvalidInputError(f"{name} must be True or False, got {value!r}")
        for name, least in (("max_control_points", 10), ("max_iterations", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise InvalidInputError(f"{name} must be a whole number of at least {least}, "
                                        f"got {value!r}")
        for name, auto in (("initial_knots", "the automatic start (about 1/12 of the budget)"),
                           ("knots_per_iteration", "the automatic 15% more per iteration")):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, int) or isinstance(value, bool)
                                      or value < 1):
                raise InvalidInputError(
                    f"{name} must be a whole number of at least 1, or None for {auto}; "
                    f"got {value!r}"
                )
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise InvalidInputError(f"seed must be a nonnegative whole number, got {self.seed!r}")
        check_smoothness(self.smoothness)


def check_callback(callback) -> None:
    """Refuse a ``callback`` that is neither None nor callable, or that cannot take one
    argument (before any work is done: one without arguments failed after the first fit with
    a TypeError; user test)."""
    if callback is not None and not callable(callback):
        raise InvalidInputError(
            f"callback must be a function callback(report) -> bool (or None), got {callback!r}"
        )
    if callback is not None:
        try:
            # (not through functools.wraps: a decorator may call it with other arguments)
            inspect.signature(callback, follow_wrapped=False).bind({})
        except ValueError:  # (no signature to read, as for some builtins: called as it is)
            pass
        except TypeError:
            raise InvalidInputError(
                f"callback must take one argument, the iteration's report (callback(report) "
                f"-> bool); {getattr(callback, '__name__', callback)!r} cannot") from None


def kept_words(kept: dict, scale: float = 1.0, unit: str = "") -> str:
    """How a refined surface compared with the one refine started from, which was kept
    (``report["kept_start"]``), its errors over ``scale`` followed by ``unit``: "has a higher
    RMS, a against b", or "is no better (RMS a)" where the two print alike (a stalled run's
    refit of the same net: "0.00389 against 0.00389" had been said; user test)."""
    what = "max error" if kept.get("criterion") == "max" else "RMS"
    refined, start = (f"{kept[k] / scale:.4g}{unit}" for k in ("refined", "start"))
    if refined == start:
        return f"is no better ({what} {start})"
    return f"has a higher {what}, {refined} against {start}"


def returned_why(report: dict, criterion: str = "rms") -> str:
    """Why the surface returned is an earlier iteration's fit (adaptive_fit's choice), in
    words for the command line and Blender: they had said "lowest RMS" also of a smaller net
    kept after a coarser start missed the tolerance and of the criterion "max"'s lowest max
    (review, user test). A refine whose surface is worse than the one it started from
    returns that one (``report["kept_start"]``: :meth:`core.TCBSurface.refine`)."""
    kept = report.get("kept_start")
    if kept:
        return (f"the surface refine started from: the refined one, iteration "
                f"{kept['refined_iteration']}'s, {kept_words(kept)}")
    if report.get("stop_reason") == STALLED:
        return "lowest estimated error"
    if report.get("stop_reason") == "tolerance reached":  # (a coarser start missed it after)
        return "the smallest net that met the tolerance"
    return "lowest max error" if criterion == "max" else "lowest RMS"


def _cancel_requested(callback, report: dict) -> bool:
    """Call ``callback`` with (a copy of) an iteration's report; True means cancel."""
    answer = callback(copy.deepcopy(report))
    if answer is None or isinstance(answer, (bool, np.bool_)):
        return bool(answer)
    raise InvalidInputError(
        "the callback must return None or False (go on) or True (cancel), "
        f"got {type(answer).__name__} {answer!r:.60}"
    )


def feature_measure(uv: np.ndarray, points: np.ndarray, k: int = 12, max_points: int = 20_000,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Surface variation ``lambda_min / (lambda_1 + lambda_2 + lambda_3)`` of the covariance of
    each point's ``k`` nearest neighbours in parameter space (Pauly et al.), on a subsample.

    Returns the sample's indices (s,) and their measures (s,); batched eigenvalues, no loop.
    """
    N = len(uv)
    rng = np.random.default_rng(seed)
    sample = np.sort(rng.choice(N, max_points, replace=False)) if N > max_points else np.arange(N)
    k = min(k, len(sample))
    tree = cKDTree(uv[sample])
    _, nb = tree.query(uv[sample], k=k, workers=-1)
    P = points[sample]

    def block(bounds):
        s, e = bounds
        Q = np.take(P, nb[s:e], axis=0)  # (b, k, 3); np.take: faster row gather than P[...]
        Q = Q - Q.mean(axis=1, keepdims=True)
        return np.linalg.eigvalsh(np.einsum("ski,skj->sij", Q, Q) / k)

    # blocks on parallel threads (core.parallel); rounding can make a zero eigenvalue negative
    ev = np.maximum(np.concatenate(pmap(block, row_blocks(len(sample)))), 0.0)
    total = ev.sum(axis=1)
    f = np.where(total > 0, ev[:, 0] / np.where(total > 0, total, 1.0), 0.0)
    return sample, np.clip(f, 0.0, 1.0 / 3.0)


def initial_knots(uv: np.ndarray, points: np.ndarray, count: int, seed: int = 0,
                  iterations: int = 8, measure: tuple | None = None) -> np.ndarray:
    """``count`` interior knots in general position, well spread, denser where the data bends.

    A weighted centroidal Voronoi tessellation of the data parameters (Lloyd's iterations,
    vectorized: nearest-centre labels from a KD-tree, weighted centroids with ``bincount``),
    weights ``sqrt(1 + 4 f / mean f)`` with ``f`` the surface variation, so the knot density
    follows the curvature measure. Random knots leave gaps that dominate the error: on Franke's
    function this placement measured 2.4x lower RMS than sampling the data at random. The
    centres are then jittered by 0.1 of their spacing and kept clear of the lines through
    nearby knots, so lattice data and the near-hexagonal CVT give neither co-circular nor
    collinear knots (method.md sections 2.4 and 6). ``measure``: :func:`feature_measure` of
    the same data and seed when already computed (the sizing restarts of one run).
    """
    rng = np.random.default_rng(seed)
    sample, f = measure if measure is not None else feature_measure(uv, points, seed=seed)
    w = np.sqrt(1.0 + 4.0 * f / max(f.mean(), 1e-300))
    X = uv[sample]
    count = int(min(count, len(X)))
    c = X[rng.choice(len(X), count, replace=False, p=w / w.sum())].copy()
    for _ in range(iterations):
        _, label = cKDTree(c).query(X, workers=-1)
        ws = np.bincount(label, weights=w, minlength=count)
        cu = np.bincount(label, weights=w * X[:, 0], minlength=count)
        cv = np.bincount(label, weights=w * X[:, 1], minlength=count)
        ok = ws > 0
        c[ok] = np.c_[cu[ok], cv[ok]] / ws[ok, None]
    if count >= 2:
        d, _ = cKDTree(c).query(c, k=2)
        h = float(np.median(d[:, 1]))
    else:
        h = 0.0
    c = c + rng.uniform(-0.1, 0.1, c.shape) * h
    c = np.unique(c, axis=0)
    return place_clear_of_lines(c, np.zeros((0, 2)), fallbacks=c + 0.3 * h * (rng.random(c.shape) - 0.5))


def make_space(
    knots: np.ndarray,
    degree: int,
    mode: str,
    cost: PlaneFitCost | None,
    n_interior: int,
) -> SplineSpace:
    """The spline space for one iteration: DCB, plain TCB, or feature-sensitive TCB."""
    if mode == "dcb":
        return build_space(knots, degree, mode="dcb")
    if cost is None:
        return build_space(knots, degree, mode="tcb")
    knots = validate_knots(knots)
    movable = np.zeros(len(knots), dtype=bool)
    movable[:n_interior] = True
    tri0 = feature_triangulation(knots, cost, movable=movable)
    configs = link_triangulation_procedure(
        knots, degree, triangulation=tri0,
        link_triangulator=FeatureLinkTriangulator(cost, degree, movable),
    )
    return SplineSpace(knots, degree, "tcb", configs)


# A new knot must lie at least this fraction of |ab| away from the line through any two nearby
# knots a, b: near-collinear triples make near-degenerate simplex splines (huge, thin leaves)
# and the fit overshoots; exactly collinear ones also break C^1 (method.md section 1).
LINE_CLEARANCE = 0.08


def _clearance(x: np.ndarray, nbrs: np.ndarray) -> np.ndarray:
    """For points ``x`` (M, 2) and their neighbour knots ``nbrs`` (M, K, 2): min over pairs
    (a, b) of ``|det(a, b, x)| / |ab|^2`` (distance to the line ab in units of |ab|), over the
    pairs whose segment is near ``x`` (midpoint not farther than ``|ab|``); ``inf`` where there
    is none. Vectorized over points and pairs, (M,)."""
    K = nbrs.shape[1]
    if K < 2:
        return np.full(len(x), np.inf)
    i, j = np.triu_indices(K, 1)
    a, b = np.take(nbrs, i, axis=1), np.take(nbrs, j, axis=1)  # (M, P, 2)
    ab = b - a
    L2 = np.einsum("mpi,mpi->mp", ab, ab)
    xa = x[:, None, :] - a
    det = np.abs(ab[..., 0] * xa[..., 1] - ab[..., 1] * xa[..., 0])
    dm = 0.5 * (a + b) - x[:, None, :]
    near = np.einsum("mpi,mpi->mp", dm, dm) <= L2
    r = np.where(near, det / np.where(near, np.maximum(L2, 1e-300), 1.0), np.inf)
    return r.min(axis=1)


def place_clear_of_lines(
    candidates: np.ndarray, existing: np.ndarray, fallbacks: np.ndarray | None = None,
    neighbours: int = 10,
) -> np.ndarray:
    """Move candidate knots so that none is nearly collinear with two nearby knots.

    For candidate ``x`` with fallback ``f`` (e.g. the centroid of its triangle), the positions
    ``x + t (f - x)``, ``t = 0, 0.25, 0.5, 0.75, 1`` are tried in order and the first whose
    :data:`LINE_CLEARANCE` holds against its ``neighbours`` nearest knots (the existing ones and
    the other candidates) is kept; if none does, the one with the best clearance. All candidates
    move together: each round tries the next ``t`` for the candidates not yet clear, against
    everybody's current positions (one KD-tree query and one batched clearance per round), and
    a second sweep revisits candidates that a later move brought too close to a line.

    Among well-spread knots the criterion seldom holds everywhere (a knot lies near the line
    through two opposite neighbours), so for most candidates this keeps the clearest of the
    five positions; what it prevents is a knot almost on a line, e.g. lattice data. The
    sequential loop this replaces gave the same clearances (5th percentile 0.001-0.002 of
    ``|ab|`` on 50-1500 knots) 5x slower at 1500 knots.
    """
    cand = np.asarray(candidates, dtype=np.float64).reshape(-1, 2)
    fallbacks = cand if fallbacks is None else np.asarray(fallbacks, dtype=np.float64).reshape(-1, 2)
    pool = np.asarray(existing, dtype=np.float64).reshape(-1, 2)
    M, E = len(cand), len(pool)
    if M == 0:
        return cand.copy()
    K = min(neighbours, E + M - 1)
    pos = cand.copy()
    todo = np.arange(M)
    for _ in range(2):
        best, best_c = pos[todo].copy(), np.full(len(todo), -1.0)
        pending = np.ones(len(todo), dtype=bool)
        for t in (0.0, 0.25, 0.5, 0.75, 1.0):
            if not pending.any() or K < 2:
                break
            sel = todo[pending]
            y = cand[sel] + t * (fallbacks[sel] - cand[sel])
            pos[sel] = y
            allp = np.concatenate([pool, pos])
            _, nb = cKDTree(allp).query(y, k=K + 1, workers=-1)
            nb = nb.reshape(len(sel), K + 1)
            # drop the candidate itself (or the farthest neighbour if it is not among them)
            own = nb == (E + sel)[:, None]
            own[~own.any(axis=1), K] = True
            nb = nb[~own].reshape(len(sel), K)
            c = _clearance(y, np.take(allp, nb, axis=0))
            ps = np.flatnonzero(pending)
            better = c > best_c[ps]
            best[ps[better]], best_c[ps[better]] = y[better], c[better]
            pending[ps[c >= LINE_CLEARANCE]] = False
        pos[todo] = np.where(pending[:, None], best, pos[todo])
        if K < 2:
            break
        # a later move may have put an earlier candidate next to a line: one more sweep for those
        allp = np.concatenate([pool, pos])
        _, nb = cKDTree(allp).query(pos, k=K + 1, workers=-1)
        nb = nb.reshape(M, K + 1)
        own = nb == (E + np.arange(M))[:, None]
        own[~own.any(axis=1), K] = True
        c = _clearance(pos, allp[nb[~own].reshape(M, K)])
        todo = np.flatnonzero(c < LINE_CLEARANCE)
        if len(todo) == 0:
            break
    return pos


def insertion_points(
    knots: np.ndarray,
    triangles: np.ndarray,
    uv: np.ndarray,
    errors: np.ndarray,
    count: int,
    criterion: str = "rms",
    min_points: int = 4,
) -> np.ndarray:
    """New knots: one in each of the ``count`` worst ``Gamma_0`` triangles (method.md section 6).

    Triangles are ranked by the sum of squared errors (``criterion="rms"``) or the largest error
    (``"max"``) of their data; only triangles with at least ``min_points`` data points are
    refined. The knot goes to the error-weighted centroid of the triangle's data, with its
    barycentric coordinates clamped to at least 0.15 so it stays away from the knot lines and
    knots of the triangle, then moved towards the triangle's centroid as far as needed to keep
    clear of the lines through nearby knots (:func:`place_clear_of_lines`).
    """
    owner = locate(knots, triangles, uv)
    ok = owner >= 0
    o, e = owner[ok], errors[ok]
    T = len(triangles)
    counts = np.bincount(o, minlength=T)
    e2 = e * e
    score = np.bincount(o, weights=e2, minlength=T)
    if criterion == "max":
        score = np.zeros(T)
        np.maximum.at(score, o, e)
    score[counts < min_points] = -1.0
    order = np.argsort(-score, kind="stable")
    worst = order[: count][score[order[: count]] > 0]
    if len(worst) == 0:
        return np.zeros((0, 2))
    wsum = np.bincount(o, weights=e2, minlength=T)
    cu = np.bincount(o, weights=e2 * uv[ok, 0], minlength=T)
    cv = np.bincount(o, weights=e2 * uv[ok, 1], minlength=T)
    cen = np.stack([cu, cv], axis=1)[worst] / np.maximum(wsum[worst], 1e-300)[:, None]
    a, b, c = (knots[triangles[worst, j]] for j in range(3))
    det = orient2d(a, b, c)
    beta = np.stack([orient2d(cen, b, c), orient2d(a, cen, c), orient2d(a, b, cen)], axis=1)
    beta /= det[:, None]
    beta = np.where(np.isfinite(beta), beta, 1.0 / 3.0)
    beta = np.maximum(beta, 0.15)
    beta /= beta.sum(axis=1, keepdims=True)
    new = beta[:, :1] * a + beta[:, 1:2] * b + beta[:, 2:] * c
    # not on a data point: where one point carries all of a triangle's error (exact data, a
    # narrow ridge) the centroid is that point, and at a knot the half-open supports of its
    # configurations did not sum to one (BorderError "does not sum to one at 1 of 20000 data
    # parameters", deviation 0.44, after 13 iterations): a hundredth of the way to the centre
    mid = (a + b + c) / 3
    size = np.sqrt(np.abs(det))
    on = cKDTree(uv).query(new, workers=-1)[0] <= 1e-9 * size
    new[on] = 0.99 * new[on] + 0.01 * mid[on]
    return place_clear_of_lines(new, knots, fallbacks=mid)


# swing_places: data points sampled (the neighbours are searched among them), the points whose
# midpoints with their neighbours are checked, how many neighbours, and how close a knot must be
SWING_SAMPLE = 20_000
SWING_POINTS = 5_000
SWING_NEIGHBOURS = 3
SWING_KNOTS = 1.0
SWING_GAPS = True  # also at the centroids of the sample's Delaunay triangles
SWING_GAP_SPAN = 4.0  # ... of longest side at most this times the median one
SWING_CROWD = 4.0  # knots closer than this many data spacings: all data around them checked
# the domain checks of the final surface (swing_places(..., domain=True)): places per side of
# the grid over the data's parameters, the neighbours whose slab a place must stay near, and
# how near: SWING_SLAB times the slab's thickness (plus 5% of its width) and SWING_REACH times
# the neighbours' radius, both (past 3 times their largest error)
SWING_GRID = 64
SWING_SLAB_NEIGHBOURS = 8
SWING_SLAB = 3.0
SWING_REACH = 0.5
SWING_NEAR = 3.0  # ... at grid places at most this many data spacings from a data point
# ... whose nearest points spread across their line at least this share of their width along
# it: the nearest points of a place between the lines of a scan made in lines are on one line,
# whose slab does not bound the surface beside it (20 profiles of a smooth function, fitted
# within 6e-4 of it, were flagged at 1826 places by up to 0.0146: user test)
SWING_LINE = 0.1


def swing_places(space, C, uv, points, errors, seed: int = 0,
                 margin: float = 0.0, domain: bool = False) -> tuple[np.ndarray, int, float]:
    """Where the surface swings away from the data between neighbouring data points (not in
    method.md): ``space`` with control points ``C`` (all functions), the data's parameters
    ``uv``, ``points`` and fit errors ``errors`` (one unit).

    At the parameter midpoint ``m`` of a data point ``i`` and each of its 3 nearest
    neighbours ``j`` (in uv), the surface point ``S(m)`` should lie within ``|p_i - p_j| + 3
    max(e_i, e_j)`` of the segment ``p_i p_j``: a surface that follows the data does not
    move farther between two points than they are apart. Where more knots crowd than the data
    hold (a 20 m step fitted along the vertical: functions whose supports hold data only at
    their edges), it swung 70-90 m beyond the data between points 1 m apart, while the errors
    at the data stayed under 9 m (user test). Checked at the points with a knot closer than
    their 3rd neighbour (where functions can be smaller than the data spacing), among up to
    5000 of a random sample of up to 20 000 points (seeded; 0.06 s for a fit of 1e5 points
    with 1500 knots).

    Also in the gaps between the data (SWING_GAPS): at the centroid of each Delaunay
    triangle of the sample (none with a side on its hull, none with a longest side above
    SWING_GAP_SPAN times the median one) that has a knot closer than its longest side,
    ``S`` should lie within the triangle's longest side plus 3 times its corners' largest
    error of the triangle ``p_a p_b p_c``. A spike between points 1-1.4 m apart reaches none
    of their midpoints: a 20 m cliff in a 200 m tile of 5e4 points dipped 43 m below points
    fitted within 0.9 m, and only this check sees it (up to 5000 triangles, the sample's
    triangulation kept between calls). The sample's triangles are larger than the data's:
    around the knots that crowd (closer together than SWING_CROWD data spacings) the
    triangles of all the data are checked too (up to SWING_SAMPLE points): 1e5 points with a
    cliff had fins 30-40 m beyond the data between points 0.63 m apart that the sample's
    triangles missed (user test). 0.11 s instead of 0.03 for 5e4 points and 1000 control
    points, 0.29 s for 1e5 and 1517.

    No place was flagged on the 16 datasets of benchmarks/compare.py at three settings each
    (the final surfaces; the loop took back insertions in the same 2 of the 48 fits as
    without the gap checks: F7 scattered at 1e-4 three, 844 control points instead of 1951,
    hold-out RMS 1.31e-3 instead of 1.28e-3), nor on noisy or sparse clouds. A swing inside
    a gap wider than the data spacing is measured against the far points across it, so it
    shows only when it is larger than the gap (conservative). A place is flagged when its
    excess is above ``margin`` (the loop passes its tolerance: it took back fits for swings
    of 0.7 mm with a tolerance of 0.29 m: review).

    ``domain`` (the final surface: :func:`core.surface.data_swings`) also checks the whole
    domain, near knots or not (:func:`_domain_checks`): the edges of the data's convex hull
    at a quarter, half and three quarters (the segment rule above), where a mesh fitted with
    smoothness 0 flared out 3 diagonals beyond its border, and a grid of SWING_GRID places
    per side, where the surface must stay near the slab of its nearest data points (1000
    points of the DEM on 492 control points swung 2.3 km off terrain of 0.8 km relief; user
    test: flagged, but that case is near the limit, and the same fit of the DEM read with
    its nodes at the cells' centres swings 0.3 km and is not). Not in the loop: it would
    take back insertions at cusps (F10's cone point dips between the data by about their
    spacing; it was flagged before the grid kept to places near the data).
    Returns (the places flagged (f, 2), places checked, the largest excess).
    """
    uv = np.asarray(uv, dtype=np.float64)
    n = len(uv)
    k = SWING_NEIGHBOURS
    if n <= k:
        return np.zeros((0, 2)), 0, 0.0
    sub = _swing_sample(n, seed)
    x, p, e = uv[sub], np.asarray(points, dtype=np.float64)[sub], np.asarray(errors)[sub]
    pick = np.arange(min(len(sub), SWING_POINTS))
    x_tree = cKDTree(x)  # (also the domain checks')
    dd, nb = x_tree.query(x[pick], k=k + 1, workers=-1)
    knot_tree = cKDTree(space.knots)  # (one for the midpoints and both gap checks)
    dk, _ = knot_tree.query(x[pick], workers=-1)
    near = dk < SWING_KNOTS * dd[:, -1]
    i, j = np.repeat(pick[near], k), nb[near, 1:].ravel()
    mid = 0.5 * (x[i] + x[j])
    a, ab = p[i], p[j] - p[i]
    reach = np.sqrt(np.einsum("ij,ij->i", ab, ab)) + 3.0 * np.maximum(e[i], e[j])
    # gaps: the centroids of the sample's Delaunay triangles near a knot (a spike between
    # data points 1-1.4 m apart, none of whose midpoints it reaches: the cliff, 5e4 points),
    # and of all the data's triangles around knots that crowd (fins along a cliff between
    # points 0.63 m apart, 1e5 points: a sample's triangles are too large to see them)
    parts = [(mid, (a, a + ab), reach)]
    if SWING_GAPS and len(x) >= 3:
        parts.append(_gap_checks(knot_tree, x, p, e, _gap_triangles(x), seed + 1))
        spacing = float(np.median(dd[:, 1])) * np.sqrt(len(x) / n)  # of all the data
        K = np.asarray(space.knots)
        gap = knot_tree.query(K, k=2, workers=-1)[0][:, 1]
        crowd = K[gap < SWING_CROWD * spacing]
        if len(crowd):
            r = SWING_CROWD * spacing
            d = cKDTree(crowd).query(uv, distance_upper_bound=r, workers=-1)[0]
            sel = np.flatnonzero(d <= r)
            if len(sel) > SWING_SAMPLE:
                sel = np.sort(np.random.default_rng(seed + 2).choice(sel, SWING_SAMPLE,
                                                                     replace=False))
            parts.append(_gap_checks(knot_tree, uv[sel], np.asarray(points, dtype=np.float64)[sel],
                                     np.asarray(errors)[sel], _interior_triangles(uv[sel]),
                                     seed + 3))
    if domain and len(x) >= 3:
        parts.extend(_domain_checks(x, p, e, x_tree))
    places = np.vstack([q[0] for q in parts])
    if len(places) == 0:
        return np.zeros((0, 2)), 0, 0.0
    S = space.evaluate(places) @ C
    away, at = [], 0
    reach_of = [q[2] for q in parts]
    # above rounding: duplicated points of exact data give zero-length segments (review: 1e-12)
    floor = max(margin, 1e-9 * float(np.ptp(p, axis=0).max()))
    for where, corners, _ in parts:
        m = len(where)
        Sm = S[at : at + m]
        if len(corners) == 2:
            away.append(_segment_distance(Sm, corners[0], corners[1] - corners[0]))
        elif len(corners) == 4:  # a hull edge: its segment, and the slab of its neighbours
            pa, pb, slab, slab_reach = corners
            seg = _segment_distance(Sm, pa, pb - pa) - reach_of[len(away)]
            off = _slab_distance(Sm, *slab) - slab_reach
            # flagged only when both are exceeded, by the segment's excess (the measure of
            # the others; + its reach, which is subtracted below)
            away.append(np.where(off > floor, seg, np.minimum(seg, off)) + reach_of[len(away)])
        elif len(corners) == 3:
            away.append(_triangle_distance(Sm, *corners))
        else:  # a slab: centre, normal, lowest and highest neighbour along it, a marker
            away.append(_slab_distance(Sm, *corners[:4]))
        at += m
    excess = np.concatenate(away) - np.concatenate(reach_of)
    flagged = excess > floor
    return places[flagged], len(places), float(excess.max()) if flagged.any() else 0.0


def _domain_checks(x, p, e, tree) -> list:
    """The domain checks of :func:`swing_places` for the parameters ``x`` (points ``p``, errors
    ``e``; ``tree`` a KD-tree of ``x``): parts ``(places, corners, reach)``. The convex
    hull's edges (between neighbouring points on it, at most SWING_GAP_SPAN times their
    median length) at 1/4, 1/2 and 3/4 (segments: the surface within the edge's length plus 3
    times its ends' largest error of the edge; flagged only when it is also outside the slab
    of the place's SWING_SLAB_NEIGHBOURS nearest points, see below, by more than 3 times their
    largest error), and a grid of SWING_GRID places per side inside the hull, within
    SWING_NEAR data spacings (or a grid step) of a data point: the surface within
    ``3 max e + max(SWING_SLAB (t + 0.05 w), SWING_REACH r)`` of the slab of the place's
    SWING_SLAB_NEIGHBOURS nearest points (their principal frame: ``t`` their thickness along
    the normal, ``w`` their width along the first axis, ``r`` their largest distance from
    their centroid). Measured on compare.py's 48 fits: the largest of the two ratios' smaller
    one is 0.43 of the limit but at F10's cone point (1.72: a dip between the data as deep as
    they are apart, in a gap 3 spacings wide: no longer looked at); 1.76 for the DEM's 2.3 km
    swing, 10.7 for a mesh fitted with smoothness 0 (/tmp/s18/envrun3.py of the eighteenth
    session). None of the 48 is flagged; nor a cloud with a hole or an L-shaped one (review)."""
    tri = _delaunay(x)  # (the gap checks' one)
    if tri is None:  # (degenerate: on a line)
        return []
    # the hull's edges between neighbouring points (the Delaunay triangles' sides without a
    # neighbour: a grid's side holds all its points, not only its corners)
    side = np.flatnonzero((tri.neighbors < 0).ravel())
    T = tri.simplices.ravel()
    a, b = T[(side // 3) * 3 + (side % 3 + 1) % 3], T[(side // 3) * 3 + (side % 3 + 2) % 3]
    # not across the gaps of a scattered cloud's rim (a long edge of F7 bends with the
    # surface, 1.3 off its chord 0.65 long), as for the Delaunay gaps: SWING_GAP_SPAN
    length = np.linalg.norm(x[b] - x[a], axis=1)
    short = length <= SWING_GAP_SPAN * np.median(length)
    a, b = a[short], b[short]
    t = np.array([0.25, 0.5, 0.75])
    where = (x[a][:, None] + t[None, :, None] * (x[b] - x[a])[:, None]).reshape(-1, 2)
    pa, pb = np.repeat(p[a], 3, axis=0), np.repeat(p[b], 3, axis=0)
    reach = (np.linalg.norm(pb - pa, axis=1)
             + 3.0 * np.repeat(np.maximum(e[a], e[b]), 3))
    k = min(SWING_SLAB_NEIGHBOURS, len(x))
    if len(where) and k >= 4:
        # and outside the slab of the place's nearest data points by more than 3 times their
        # largest error: the chord of a long edge of a steep surface is no bound (F7 with 3x
        # its heights, 5000 points: the surface bent 5.9 off a chord 0.3 long, as the
        # function does, inside that slab and within 0.08 of the function; flagged, the
        # default was replaced by a smoothness 31x worse in cross-validation). The grid's
        # reach would be too loose at a coarse mesh's border (nefertiti with smoothness 1e-7
        # flares 0.029 diagonals past the chord rule, 0.010 outside the slab, within its
        # reach of 0.059)
        slab, slab_reach = _slabs(p, e, tree.query(where, k=k, workers=-1)[1], 0.0, 0.0)
        parts = [(where, (pa, pb, slab, slab_reach), reach)]
    else:
        parts = [(where, (pa, pb), reach)]
    lo, hi = x.min(axis=0), x.max(axis=0)
    d = float((hi - lo).max()) / SWING_GRID
    g = [np.arange(lo[j] + d / 2, hi[j], d) for j in range(2)]
    grid = np.stack(np.meshgrid(*g), -1).reshape(-1, 2)
    # inside the hull: its edges' half-planes (Delaunay.find_simplex sometimes walked for
    # 100-300 s on the 20 000-point sample of a 1e5 fit)
    hull = ConvexHull(x)
    grid = grid[(grid @ hull.equations[:, :2].T + hull.equations[:, 2] <= 1e-12).all(axis=1)]
    if len(grid) and k >= 4:
        # near the data only: not in a hole or a notch inside the hull, where the surface is
        # not shown (the tessellation trims it) and extrapolates (review: a hole of radius
        # 0.3 in Franke's function was flagged at 225 places, up to 20% of the diagonal)
        step = float(np.median(tree.query(x[: min(len(x), 2000)], k=2, workers=-1)[0][:, 1]))
        dist, nb = tree.query(grid, k=k, workers=-1)
        near = dist[:, 0] <= max(SWING_NEAR * step, d)
        grid, nb = grid[near], nb[near]
    if len(grid) and k >= 4:
        slab, reach = _slabs(p, e, nb)
        parts.append((grid, slab + ("slab",), reach))
    return parts


def _slabs(p, e, nb, slab_factor: float = SWING_SLAB, reach_factor: float = SWING_REACH):
    """The slabs of the neighbours ``nb`` (m, k) of places (points ``p``, errors ``e``) for
    :func:`_domain_checks`: ((centre, normal, lowest and highest neighbour along it), how
    far a surface point may be off it: ``3 max e + max(slab_factor (t + 0.05 w),
    reach_factor r)``)."""
    Q = p[nb]
    c = Q.mean(axis=1)
    X = Q - c[:, None]
    _, R = np.linalg.eigh(np.einsum("mki,mkj->mij", X, X))  # axes by ascending spread
    nrm = R[:, :, 0]
    h = np.einsum("mki,mi->mk", X, nrm)
    along = np.einsum("mki,mi->mk", X, R[:, :, 2])
    across = np.einsum("mki,mi->mk", X, R[:, :, 1])
    thick, width = np.ptp(h, axis=1), np.ptp(along, axis=1)
    radius = np.linalg.norm(X, axis=2).max(axis=1)
    reach = 3.0 * e[nb].max(axis=1) + np.maximum(slab_factor * (thick + 0.05 * width),
                                                 reach_factor * radius)
    # neighbours along a line (a scan made in lines) make no slab: no bound (SWING_LINE)
    reach[np.ptp(across, axis=1) < SWING_LINE * width] = np.inf
    return (c, nrm, h.min(axis=1), h.max(axis=1)), reach


def _slab_distance(S, c, nrm, lo, hi):
    """How far the points ``S`` (m, 3) are outside their slabs (:func:`_slabs`), along the
    slabs' normals (negative inside)."""
    h = np.einsum("ij,ij->i", S - c, nrm)
    return np.maximum(h - hi, lo - h)


def _gap_checks(knot_tree, x, p, e, T, seed):
    """The places to check in the triangles ``T`` of the parameters ``x`` (points ``p``,
    errors ``e``; ``knot_tree`` a KD-tree of the knots) for swing_places: the centroids of
    those with a knot closer than their
    longest side and a longest side of at most SWING_GAP_SPAN times the median one (up to
    SWING_POINTS of them, seeded), their corner points, and how far the surface may be from
    the triangle of those: its longest side plus 3 times its corners' largest error."""
    if len(T) == 0:
        return np.zeros((0, 2)), (np.zeros((0, 3)),) * 3, np.zeros(0)
    cen = x[T].mean(axis=1)
    span = np.max([np.linalg.norm(x[T[:, q]] - x[T[:, q - 1]], axis=1) for q in range(3)],
                  axis=0)
    near = ((knot_tree.query(cen, workers=-1)[0] < SWING_KNOTS * span)
            & (span <= SWING_GAP_SPAN * np.median(span)))
    T, cen = T[near], cen[near]
    if len(T) > SWING_POINTS:
        keep = np.random.default_rng(seed).choice(len(T), SWING_POINTS, replace=False)
        T, cen = T[keep], cen[keep]
    P3 = p[T]
    longest = np.max([np.linalg.norm(P3[:, q] - P3[:, q - 1], axis=1) for q in range(3)],
                     axis=0)
    return cen, (P3[:, 0], P3[:, 1], P3[:, 2]), longest + 3.0 * e[T].max(axis=1)


_GAP_CACHE: dict = {}  # the last sample's triangles (the loop checks the same sample each time)


def _swing_sample(n: int, seed: int) -> np.ndarray:
    """The data points :func:`swing_places` samples, of ``n`` (seeded): a random order (a scan
    stored line by line would otherwise be checked at its first lines only: review), of which
    the first SWING_POINTS are checked."""
    return np.random.default_rng(seed).permutation(n)[:SWING_SAMPLE]


def prefetch_swing_triangles(uv: np.ndarray, seed: int = 0) -> None:
    """Start the Delaunay triangulation of the sample that :func:`swing_places` will take of
    ``uv`` with ``seed`` on a thread of its own (:func:`core.parallel.background`: qhull
    releases the GIL), so that it is ready when the fit is checked. 0.10-0.16 s for the 20 000
    points of a fit of 1e5, which the check waited for."""
    uv = np.asarray(uv, dtype=np.float64)
    if len(uv) > SWING_NEIGHBOURS:
        x = np.ascontiguousarray(uv[_swing_sample(len(uv), seed)])
        _GAP_CACHE["last"] = (_sample_key(x), background(lambda: _triangulate(x)))


def _sample_key(x: np.ndarray) -> tuple:
    return hash(np.ascontiguousarray(x).tobytes()), x.shape


def _triangulate(x: np.ndarray):
    """The Delaunay triangulation of ``x``, or None (fewer than 4 points, or all on a line)."""
    if len(x) < 4:
        return None
    try:
        return Delaunay(x)
    except Exception:  # a degenerate set (all on a line): no gaps to check
        return None


def _delaunay(x: np.ndarray):
    """The Delaunay triangulation of the sample ``x``, or None (:func:`_triangulate`). The last
    one is kept (0.09 s for 20 000 points; the loop checks the same sample after every
    insertion, and the final check uses it twice), or started ahead by
    :func:`prefetch_swing_triangles`."""
    key = _sample_key(x)
    # one tuple, read and replaced whole: fits in two threads (Blender's job and a script)
    # never pair one sample's key with another's triangulation
    last = _GAP_CACHE.get("last")
    if last is not None and last[0] == key:
        return last[1]()
    tri = _triangulate(x)
    _GAP_CACHE["last"] = (key, lambda: tri)
    return tri


def _gap_triangles(x: np.ndarray) -> np.ndarray:
    """The Delaunay triangles of the sample ``x`` that have no side on its hull (slivers along
    the hull: a flat triangle between points far apart on a curved surface is no measure of
    it; F7 scattered was 0.35 off such a one, 0.07 of its diagonal); its triangulation kept
    (:func:`_delaunay`)."""
    return _interior_triangles(x, _delaunay(x))


def _interior_triangles(x: np.ndarray, tri=False) -> np.ndarray:
    """The Delaunay triangles of ``x`` with no side on its hull ((t, 3) indices), of ``tri``
    when given (None: there are none), else of a triangulation made and not kept."""
    tri = _triangulate(x) if tri is False else tri
    if tri is None:
        return np.zeros((0, 3), dtype=np.intp)
    return tri.simplices[(tri.neighbors >= 0).all(axis=1)]


def _segment_distance(S: np.ndarray, a: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Distances of the points ``S`` (m, 3) from the segments ``a``, ``a + ab`` (m, 3)."""
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", S - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    return np.linalg.norm(S - a - t[:, None] * ab, axis=1)


def _triangle_distance(S, a, b, c) -> np.ndarray:
    """Distances of the points ``S`` (m, 3) from the triangles ``a b c`` (each (m, 3)): to
    the plane where the foot lies inside, else to the nearest edge."""
    n = np.cross(b - a, c - a)
    n2 = np.einsum("ij,ij->i", n, n)
    ok = n2 > 0
    d = S - a
    foot = d - (np.einsum("ij,ij->i", d, n) / np.where(ok, n2, 1.0))[:, None] * n
    # the foot's barycentric signs: inside when it is on the inner side of all three edges
    inside = ok.copy()
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, foot + a - u), n) >= 0
    plane = np.abs(np.einsum("ij,ij->i", d, n)) / np.sqrt(np.where(ok, n2, 1.0))
    edge = np.min([_segment_distance(S, u, v - u) for u, v in ((a, b), (b, c), (c, a))], axis=0)
    return np.where(inside, plane, edge)


AREA_POINTS_PER_CELL = 64  # points per counting cell of area_weights (on average)
AREA_FINE = 4  # occupancy cells per counting cell side
# a cloud is of uneven density when the mean square of its area weights exceeds this: the
# weighted RMS then counts only 1/1.2 of its points' worth (even clouds: 1.00-1.02 for random,
# grid and disk samples; a 1:4 density step 1.4, lidar 1/r^2 fall-off 2.8, a Gaussian blob 3.5)
UNEVEN_DENSITY = 1.2


def area_weights(uv: np.ndarray) -> np.ndarray:
    """The parameter area each point stands for, relative to the mean (mean 1): for the RMS
    of a surface's error over its area rather than over its points.

    Points are counted on a grid of about square cells of 64 points each on average (an
    elongated domain too: a strip gets one row of them); a cell's area is
    the number of its occupied sub-cells (4 x 4 per cell), so a cell the domain's border cuts,
    or a cell half of which holds no data, is given the area its data covers, not the cell's.
    A point's weight is its cell's area over its cell's count: the RMS weighted by it is
    ``sqrt(sum_c A_c mean_{j in c} e_j^2 / sum_c A_c)``, each cell's mean square error weighted
    by its area. A cell of few points leaves some sub-cells empty and so counts a little less
    area than it covers (``m`` points occupy ``16 (1 - (15/16)^m)`` of 16 on average: a 1:4
    density step, cells of 26 and 104 points, gets weights 3.1-3.25:1 instead of 4:1, for
    aspect ratios 1 to 1000; inverting that formula per cell was tried and overshoots on the
    few points of cells the border cuts). Uniformly dense clouds get weights near 1 (the
    weighted RMS was 0.99-1.10 times the plain one on 9 sample clouds); a cluster of 1e5 points
    N(50, 0.5) in a 100 x 100 tile with 2000 points gives the tile's points weights about 2000
    times the cluster's (median; 3 seeds 1954-2031).
    O(n) (bincounts): 10 ms at 1e5 points, 0.2 s at 1e6. Not in method.md (its section 6 says "RMS").
    """
    uv = np.asarray(uv, dtype=np.float64)
    lo, hi = column_bounds(uv)
    ext = np.maximum(hi - lo, 1e-300)
    # about square cells of AREA_POINTS_PER_CELL points on average (a strip: one row of them)
    want = max(len(uv) / AREA_POINTS_PER_CELL, 1.0)
    short = int(np.argmin(ext))
    across = max(1, int(round(np.sqrt(want * ext[short] / ext[1 - short]))))
    cells = np.ones(2, dtype=np.int64)
    cells[short], cells[1 - short] = across, max(1, int(round(want / across)))
    fine_cells = cells * AREA_FINE
    fine = np.minimum(((uv - lo) / ext * fine_cells).astype(np.int64), fine_cells - 1)
    coarse = fine // AREA_FINE
    cell = coarse[:, 0] * cells[1] + coarse[:, 1]
    occupied = np.flatnonzero(np.bincount(fine[:, 0] * fine_cells[1] + fine[:, 1],
                                          minlength=int(fine_cells.prod())))
    owner = (occupied // fine_cells[1]) // AREA_FINE * cells[1] + (occupied % fine_cells[1]) // AREA_FINE
    area = np.bincount(owner, minlength=int(cells.prod())).astype(np.float64)
    count = np.bincount(cell, minlength=int(cells.prod()))
    w = area[cell] / count[cell]
    return w / w.mean()


def _feature_cost(uv: np.ndarray, points: np.ndarray, n_knots: int, seed: int) -> PlaneFitCost:
    """The plane-fit cost on a subsample: at most 20 points per knot (at least 10 000).

    Choosing triangulations needs the shape of the data, not every point; on the 1e5-point DEM
    the full set made the configurations 10x slower than the fit itself.
    """
    m = max(20 * n_knots, 10_000)
    if len(uv) <= m:
        return PlaneFitCost(uv, points)
    pick = np.sort(np.random.default_rng(seed).choice(len(uv), m, replace=False))
    return PlaneFitCost(uv[pick], points[pick])


def _add_ring(ring_knots: np.ndarray, seed: int) -> np.ndarray:
    """One more ring of border knots around the existing ones, at their own spacing."""
    d, _ = cKDTree(ring_knots).query(ring_knots, k=2)
    h = float(np.median(d[:, 1]))
    new = border_rings(ring_knots.min(axis=0), ring_knots.max(axis=0), h, rings=1, seed=seed)
    return np.vstack([ring_knots, new])


@dataclass
class IterationState:
    knots: np.ndarray
    n_interior: int
    space: SplineSpace
    fit: FitResult
    refit: dict | None = None  # the final fit on all points after sampled iterations
    active: np.ndarray | None = None  # the functions that meet the domain (the control points)
    selection: dict | None = None  # smoothness="auto": the cross-validated choice
    iteration: int = 0  # its number in the reports (history[i]["iteration"])

    @property
    def n_control(self) -> int:  # what the budget counts
        return len(self.active) if self.active is not None else self.space.n_basis


# how many times a fit of the loop is checked for straying between its points (stray_check) and
# fitted again with the points added
STRAY_ROUNDS = 2

# Above this many points the iterations of the loop (criterion "rms") fit a seeded random subset
# of this size; the chosen space is then fitted once to all points. The insertion needs the
# error pattern, not every point, and the RMS of 2e5 random points estimates the full one to
# about 1%: a budget-limited run on 1e6 points (12 iterations) took 96 s with every point in
# every iteration and 34-38 s with the subset, at the same accuracy.
ITERATION_POINTS = 200_000

# sizing the start (adaptive_fit): the probe has 1/PROBE_FRACTION of the start's knots, and at
# least MIN_PROBE_KNOTS (smaller starts are not probed)
PROBE_FRACTION = 4
MIN_PROBE_KNOTS = 8
# ... of the start of this budget for any larger budget given (smaller ones: of their own
# start); the fresh starts of the sizing have at most that start's knots. With the budget's
# own start, a larger budget that the fit did not reach gave a larger net (three_peaks.off at
# 1e-3: 647 and 1313 control points at budgets 2000 and 5000; user test F7;
# benchmarks/budgets.py)
PROBE_BUDGET = 2000
# a fresh start that meets the tolerance is followed by a coarser one when the error-rate
# model predicts at most this share of its knots (and at least MIN_START_KNOTS)
SHRINK_FRACTION = 0.7
MIN_START_KNOTS = 6
# ... and kept when its max error at the data is at most SHRINK_MAX times the tolerance, or the
# max of the fit it follows when that is larger. 1 (every point within the tolerance) made
# loose tolerances useless: a smooth 40 x 30 grid got the probe's 149 control points at 1e-3,
# 5e-3 and 1e-2 (coarser fits of 79 and 56 with max 1.7x and 1.1x the tolerance thrown away;
# user test); unbounded, a hemisphere's rim dipped 1.5x the tolerance (RMS 0.4x) below its cut
# and a crease was rounded by 3x (another user test; /tmp/s34/cmp_*.txt)
SHRINK_MAX = 2.0
# ... sized for this share of the tolerance: the insertions stop at the first fit below it,
# typically 0.5-1x of it; a coarser start aimed at the tolerance itself leaves no room (the
# RMS of one knot count is not one number: it varies 1.5x with the knots' draws)
SHRINK_TARGET = 0.5
# a coarser start that misses, with at most 1/SHRINK_SPLIT of the knots of the fit it followed:
# one more start halfway between them (geometric mean of the knot counts), kept if it meets.
# The steps of the coarser starts were ~0.6x each, so the net returned jumped with the draws:
# a grid turned about its normal got 44-90 control points at 1e-3 (user test; /tmp/s35/rot.py)
SHRINK_SPLIT = 1.3
# a run with a tolerance stops when the error has stopped falling (_stalled): over at least
# STALL_WINDOW insertions and 1.5x the knots, the best RMS fell like knots^-r with r <
# STALL_RATE (dense noise, 10 000 points: 0.035-0.05, i.e. about 1.5% less error for 50% more
# knots; with fewer points per control point the training RMS falls faster as the noise is
# fitted) ...
STALL_WINDOW = 3
STALL_RATE = 0.07
# ... on estimates of the error at new points (see _stalled; 4000 noisy points: 0.13-0.38
# before, the rule now fires); a stalled run returns the fit of the lowest such estimate, and
# its default smoothness is cross-validated (adaptive_fit). Switches for benchmarks/noise.py's
# peers, not options.
STALL_DOF = True
BEST_BY_NEW_POINTS = True
CROSS_VALIDATE_STALLED = True
# thin data: fewer fitted points than this per control point, but not sparse. The default is
# cross-validated (with the sparse candidates) and replaced when its cross-validated RMS is
# more than THIN_MARGIN times the choice's: 1000 nodes of the DEM on 371-403 control points
# swung between them (held-out RMS 95-117 m, max 493-2281 m, relief 0.8 km); the choice
# (1-10) gives 70-77 m and 289-366 m. On clean functions the scores are flat and the choice
# (the one-standard-error rule: the smoothest within the noise) was 1.2x farther from
# Franke's function at 1000 points: the default stays there (benchmarks/sparse.py)
THIN_POINTS_PER_CONTROL = 4
THIN_MARGIN = 1.25
STALLED = "the error stopped falling"
# a noisy mesh's loop (adaptive_fit's measured_only) has a budget of at most this many control
# points per vertex: its faces' samples are its vertices interpolated, and a larger net fits
# their noise. The stall test's estimate of the error at new points caps the net's share of the
# vertices at 0.9, so past that it cannot tell, and the automatic start and the fresh starts,
# sized from the user's budget and a tolerance far below the noise, jumped past the windows it
# needs: a noisy cap of a 32 x 16 UV sphere (193 vertices, noise 0.5% of its radius) at 1e-4
# took 1402 control points and ended 1.59e-3 of its diagonal from the sphere (at 1e-3 192 and
# 1.28e-3). With the budget capped (the starts sized from it) the stall test stops it at 97
# and 1.08e-3 at both, and noisy wave grids of 15 x 15 and 21 x 21 vertices at 104 and 154
# instead of 649-1820 and 1074-1921, 1.26-1.35x closer to the wave (/tmp/s38/capbudget.py,
# thirty-eighth session; half a control point per vertex was closer still on 5 of 6, one per
# vertex is the bound that needs no tuning)
NOISY_NET_PER_VERTEX = 1.0
# a knot insertion after which the surface swings away from the data between points
# (swing_places) is taken back near the places that swing, and no knot goes within
# SWING_FREEZE times the distance to their 3rd nearest knot again (adaptive_fit)
REVERT_SWINGS = True
SWING_FREEZE = 8.0
SWINGS_LEFT = "more knots would make the surface swing between the data"
# an insertion taken back this many times in a row ends the run (SWINGS_LEFT)
TAKE_BACKS_IN_A_ROW = 4


def _in_discs(x: np.ndarray, discs: list) -> np.ndarray:
    """Which of the parameters ``x`` (m, 2) lie in one of the ``discs`` (a list of (centres
    (f, 2), radii (f,)) pairs), (m,) bool."""
    inside = np.zeros(len(x), dtype=bool)
    if not discs or len(x) == 0:
        return inside
    centre = np.vstack([c for c, _ in discs])
    radius = np.concatenate([r for _, r in discs])
    k = min(8, len(centre))
    d, j = cKDTree(centre).query(x, k=k, distance_upper_bound=float(radius.max()), workers=-1)
    d, j = d.reshape(len(x), k), j.reshape(len(x), k)
    ok = j < len(centre)  # a neighbour within the largest radius
    inside = (ok & (d <= np.where(ok, radius[np.minimum(j, len(centre) - 1)], -1.0))).any(axis=1)
    return inside


def mostly_taken_back(report: dict) -> bool:
    """Whether a run stopped at its iteration limit after taking back (the surface swung:
    :func:`adaptive_fit`) at least half of its fits, or its last two: more iterations would
    not help (the CLI note and the Blender advice then say what does)."""
    history = report.get("history") or []
    back = sum("knots_taken_back" in h for h in history)
    last = history[-2:]  # (or the last two, in a row)
    return report.get("stop_reason") == "iteration limit" and back > 0 and (
        2 * back >= len(history) or (len(last) == 2 and all("knots_taken_back" in h
                                                             for h in last)))


def _default_excess(validation: dict, chosen: float) -> float:
    """The default smoothness's cross-validated RMS over that of ``chosen`` (``validation``:
    candidate -> cross-validated RMS, as in FitResult); inf when the default was not scored
    (its system singular) and 1 when nothing was."""
    if not validation:
        return 1.0
    mine = validation.get(float(chosen))
    other = validation.get(float(DEFAULT_SMOOTHNESS))
    if other is None or mine is None or not np.isfinite(other):
        return np.inf
    return float(other / mine) if mine > 0 else (1.0 if other <= 0 else np.inf)


def replaced_default_reason(selection: dict | None) -> str | None:
    """Why the engine cross-validated a default smoothness, in a few words ("sparse data" or
    :data:`STALLED`), from ``report["smoothness_selection"]``; None when it did not (no
    selection, or ``smoothness="auto"`` asked for it)."""
    why = str((selection or {}).get("why", ""))
    return None if not why else "sparse data" if why.startswith("sparse") else STALLED


def automatic_start(mode: str, max_control_points: int) -> int:
    """Interior knots of the automatic start: budget / 12 (TCB), i.e. a fit with about a
    quarter of the budget in control points (the border functions that meet the domain add to
    the ~2 per knot: 2000 -> 166 knots -> 470-500 control points); DCB has about 2.4 times as
    many functions per knot. :func:`adaptive_fit` caps it at ``n / 8`` for ``n`` points and,
    with a tolerance, sizes it (:func:`next_start`)."""
    per = 12 if mode == "tcb" else 30
    return int(np.clip(max_control_points / per, 8, 400))


def predicted_knots(n: int, error: float, tol: float, previous: tuple | None,
                    degree: int) -> float:
    """Interior knots that the error-rate model predicts for the tolerance ``tol``, from a fit
    with ``n`` interior knots and error ``error`` (and ``previous = (n_1, e_1)``, an earlier fit
    of the same run, or None).

    Model (an addition to method.md section 6): the error falls like ``n^-r``. ``r = (k + 1) / 2``
    on smooth data (``h^(k+1)`` with ``h ~ n^-1/2``); with an earlier fit (of fewer knots and
    a larger error, or of more knots and a smaller one) it is the measured
    ``log(e_1/e) / log(n/n_1)``, clipped to ``[0.5, (k + 1) / 2]`` (measured between 20 and 166
    knots: scans 0.15-1.7, smooth functions 0.9-2.4). The count is ``n (e / tol)^(1/r)``, with
    10% to spare.
    """
    rate = (degree + 1) / 2
    if previous is not None:
        n1, e1 = previous
        # (a finer fit before, as when coarser starts follow one that met the tolerance: the
        # rate between them too; it had been taken as 0.5, the steepest cut: review)
        falls = n != n1 and e1 > 0 and error > 0 and (n > n1) == (e1 > error)
        measured = np.log(e1 / error) / np.log(n / n1) if falls else 0.0
        rate = float(np.clip(measured, 0.5, rate))
    return 1.1 * n * (error / max(tol, 1e-300)) ** (1.0 / rate)


def next_start(n: int, error: float, tol: float, previous: tuple | None, degree: int,
               n_start: int) -> int | None:
    """The knot count of the next fresh start while sizing, or None to go on by insertion.

    :func:`predicted_knots` for the tolerance, at most the start's count ``n_start`` (the path
    without sizing, after the sizing fits); at most 15% more than ``n`` (about one insertion
    step) and the loop goes on by inserting knots. Measured by benchmarks/net_size.py.
    (Predictions from 0.7 of ``n_start`` were rounded up to it: one cloud got 318-479 control
    points over six seeds of its knots, those rounded up meeting an absolute tolerance of 0.05
    at 0.025, half of it; user test. 318-400 now.)
    """
    want = predicted_knots(n, error, tol, previous, degree)
    if want >= n_start:
        return n_start
    if want <= 1.15 * n:
        return None
    return int(np.ceil(want))


def new_point_factor(control_points, points):
    """``sqrt((1 + p/n) / (1 - p/n))`` with ``p/n`` (control points over fitted points) at most
    0.9: the factor from the RMS on the fitted points to an estimate of the RMS at new points
    of a least-squares fit with ``p`` parameters to ``n`` points with white noise (the noise
    leaves ``sigma^2 (1 - p/n)`` on the data and makes ``sigma^2 (1 + p/n)`` elsewhere)."""
    share = np.minimum(np.asarray(control_points, dtype=np.float64) / max(points, 1), 0.9)
    return np.sqrt((1 + share) / (1 - share))


def _stalled(history: list[dict], n_points: int | None = None,
             estimates: list[float] | None = None) -> bool:
    """The error has stopped falling: the best RMS so far fell like ``knots^-r`` with ``r <
    STALL_RATE`` since the fit ``j`` of the current chain of insertions (after its fresh start)
    that has at most 2/3 of today's knots and at least STALL_WINDOW insertions after it. Best
    RMS at both ends, not single fits: the spaces are not nested, so the RMS of consecutive
    fits is not monotone; and a window of at least 1.5x the knots, so that small insertion
    steps do not make the threshold tiny.

    With ``n_points`` (the points fitted), each RMS is first turned into an estimate of the
    error at new points: a least-squares fit with ``p`` parameters to ``n`` points with noise
    ``sigma`` leaves ``sigma^2 (1 - p/n)`` on its data but makes ``sigma^2 (1 + p/n)`` at new
    points, so ``rms * sqrt((1 + p/n) / (1 - p/n))`` with ``p`` the control points (an upper
    bound: the fairing holds some of them) and ``p/n`` at most 0.9. Where noise dominates, the
    training RMS keeps falling as the net fits the noise (by ``p/n``: with few points per
    control point, fast enough to pass the rate test), while the estimate rises.

    Both ends are the best since the chain's first fit (its fresh start, or the refit of a
    continued net), not since the run's start: a small probe has the smallest ``p/n`` and
    would make any chain look stalled on clean data.

    ``estimates`` (one per fit of ``history``) replaces those estimates: a cloud of uneven
    density, whose RMS over its area has its own estimate (:func:`adaptive_fit`)."""
    n = history[-1]["interior_knots"]
    chain = 0  # fits of the current insertion chain, the last one included
    while chain < len(history) and history[-1 - chain]["knots_placed"] == "inserted":
        chain += 1
    if chain < 1:
        return False
    rms = np.array([h["rms"] for h in history])
    if estimates is not None:
        rms = np.asarray(estimates, dtype=np.float64)
    elif n_points and STALL_DOF:
        rms = rms * new_point_factor(np.array([h["control_points"] for h in history]), n_points)
    start = max(len(history) - 1 - chain, 0)  # the chain's first fit (not an insertion)
    best_now = float(rms[start:].min())
    for j in range(len(history) - 2, len(history) - 2 - chain, -1):
        n1 = history[j]["interior_knots"]
        # a window of STALL_WINDOW insertions and 1.5x the knots, or of insertions that at
        # least doubled them (refine() grows a net by up to that per step) from at least
        # MIN_PROBE_KNOTS (initial_knots=1 stopped after one insertion, to 10 knots, at 3.7e-2
        # on clean Franke: user test)
        doubled = n1 <= n / 2 and n1 >= MIN_PROBE_KNOTS
        if doubled or (n1 <= n / 1.5 and j <= len(history) - 1 - STALL_WINDOW):
            best_then = float(rms[start : j + 1].min())
            return bool(np.log(max(best_then, 1e-300) / max(best_now, 1e-300))
                        < STALL_RATE * np.log(n / n1))
    return False


def adaptive_fit(
    uv: np.ndarray,
    points: np.ndarray,
    options: RefineOptions,
    diagonal: float,
    weights: np.ndarray | None = None,
    start_knots: np.ndarray | None = None,
    ring_knots: np.ndarray | None = None,
    callback=None,
    history_offset: int = 0,
    unit: float = 1.0,
    n_measured: int | None = None,
    domain: np.ndarray | None = None,
    balance: bool = False,
    start_degree: int | None = None,
    measured_only: bool = False,
    normals: np.ndarray | None = None,
    stray_check=None,
) -> tuple[IterationState, list[dict], str]:
    """Run the loop of method.md section 6 on parameters ``uv`` and (normalized) ``points``.

    ``diagonal`` is the bounding-box diagonal in the units of ``points`` (for relative
    tolerances and reports); ``unit`` converts those units to the user's (reports and absolute
    tolerances are in the user's units). ``start_knots``/``ring_knots`` continue an earlier run
    (fitted at ``start_degree``, for messages).
    Only the first ``n_measured`` points (default: all) count for the tolerance, the reports
    and the choice of the best iteration: the rest (e.g. samples on a mesh's faces) are fitted
    and guide the knot insertion. With more than :data:`ITERATION_POINTS` points and the RMS
    criterion, the iterations fit a seeded random subset of that size (their reports say
    ``sampled_points``) and the best iteration's space is fitted to all points at the end
    (``refit`` of the returned state: points, seconds, phases).
    The control-point budget counts the functions whose support meets ``domain`` (a CCW polygon,
    whose convex hull is used; default the convex hull of ``uv``): the others only carry the border rings'
    partition of unity and vanish on the domain (:meth:`SplineSpace.meets`); reports give
    both counts (``control_points`` and ``functions``).
    With a tolerance and the automatic start, the first fits size the start: a probe with a
    quarter of its knots, then fresh starts with the count :func:`next_start` predicts; they
    count as iterations. That start is the one of the default budget (PROBE_BUDGET) for any
    larger budget: a budget above it that the run does not reach does not change it. A fresh
    start that meets the tolerance with room to spare is followed
    by a coarser fresh start, with the knots :func:`predicted_knots` gives for SHRINK_TARGET
    of the tolerance when that is at most SHRINK_FRACTION of them (at least MIN_START_KNOTS),
    as long as they meet it, and with a max error within SHRINK_MAX times the tolerance or the
    max of the fit they follow; the first that misses (or swings) ends the run and the last
    that met it is returned, unless, after a miss (not a swing), one start halfway between
    the two (SHRINK_SPLIT) meets it
    (a plane, a sphere cap, a bump had nets of 140-148 control points,
    the probe's, whatever the tolerance: now 37-55 at 1e-2; benchmarks/net_size.py). A
    continued run (``start_knots``) with a tolerance inserts the knots
    :func:`predicted_knots` says are missing, up to doubling them. Reports say whether an
    iteration's knots were placed ``"afresh"``, ``"continued"`` or ``"inserted"``
    (``knots_placed``). The best iteration is the one that meets the tolerance, else the one of
    lowest RMS within the budget (uneven density: the larger of the two RMS; the criterion
    "max": of lowest max). With ``balance``
    (point clouds), the criterion "rms" and a cloud of uneven density (mean square area weight
    over :data:`UNEVEN_DENSITY`), the tolerance must also be met by the RMS over the area
    (:func:`area_weights`; reports ``rms_area``), and where that one is the larger the knots
    go where it is: a dense part of a cloud of very uneven density met the tolerance for the
    whole, 98% of the domain missing it 3x (user test). A run with a tolerance also stops when the error has stopped
    falling (:func:`_stalled`: noise below the tolerance; reason :data:`STALLED`); it returns
    the fit of the lowest estimated RMS at new points (the RMS times
    :func:`new_point_factor`; for a cloud of uneven density the larger of that and the same
    estimate of the RMS over the area, with the area weights' effective number of points),
    and a default smoothness is then cross-validated. With ``measured_only`` (a noisy mesh)
    that estimate counts only the first ``n_measured`` points: the rest are samples on its
    faces, its vertices interpolated; and with ``normals`` (unit normals at those points,
    smooth over the noise) it is made of the errors' components along them: the noise along
    the surface, which the map of a noisy mesh does not follow, is in the errors and no net
    takes it out (a grid mesh of 120 x 120 vertices with noise of 0.3% of its diagonal: RMS at
    the vertices 1.4 times the noise; its run stopped at 925 control points, where 148 were
    closer to the mesh without noise: user test).
    An insertion after which the surface swings away from the data between points
    (:func:`swing_places`; not in method.md) is taken back: its report says ``swings`` and
    ``knots_taken_back``, it is never returned, and the insertion is made again from the fit
    before it with no knot within :data:`SWING_FREEZE` times the distance to the 3rd nearest
    knot of the places that swung (nor where such places were before). A 20 m step in a 200 m
    tile (1e4 points, 5 cm noise, tolerance 0.1 m, budget 1000; the test's): without this the
    surface swung at 26 places, up to 129 m high (the data: at most 35 m), and was 0.65 m RMS
    (39 m max) off the true shape beyond 3 m of the step; with it, no swing, at most 35.0 m
    high, 0.25 m (8.6 m, ringing 3 m from the step), on 620 control points instead of 829. A
    sizing restart after which the surface swings is taken back too: it is made again with
    half as many more knots than the fit it was sized from (and at last with that one's), and
    the sizing ends. The run's first fit has nothing to go back to: the places where it swings
    are not held against the fits after it (before, a 32 x 32 lattice with a step took back
    every insertion after a swinging restart, for swings that were the restart's own, until
    the iteration limit, and returned the restart: -123 to 68 m for data from -7.5 to 25.7;
    now -8.3 to 26.3). When only such places are left to refine, the loop stops
    (:data:`SWINGS_LEFT`). Of the 48 fits of compare.py's 16 datasets (seed 0; its settings,
    and tolerances 1e-3 and 1e-4) two took insertions back (F7 and F10, scattered, 1e-4):
    hold-out RMS 1.31e-3 on 844 control points instead of 1.28e-3 on 1951 (F7) and the same
    (F10).
    With ``measured_only`` the budget is at most :data:`NOISY_NET_PER_VERTEX` control points
    per measured point (a vertex of the noisy mesh), which also sizes the automatic start; the
    net grows no further, and reaching that is the error having stopped falling
    (:data:`STALLED`, the last report's ``net_capped``), not the user's budget. (A first fit
    above it, of a tiny mesh or a larger net to refine, is not refused: the run stops there.)
    ``stray_check`` (a mesh's: :class:`core.surface.FaceCheck`; not in method.md) is called
    after each fit, unless the iterations fit a subset, as ``stray_check(space,
    control_points, uv, errors)`` with the points fitted and their errors; it returns points
    ``(uv, points)`` to fit as well (where the surface strays between the fitted ones), or
    None. They are appended to the points (after the measured ones, which stay first), the
    space is fitted again, and checked again, up to :data:`STRAY_ROUNDS` times per fit; the
    report says ``stray_samples`` (how many were added).
    Returns the best iteration, the per-iteration reports and why the loop stopped.
    """
    options.validate()
    check_callback(callback)
    asked = options.max_control_points
    if measured_only and n_measured is not None:
        cap = NOISY_NET_PER_VERTEX * n_measured
        if cap < asked:
            options = replace(options, max_control_points=max(int(cap), 10))
    rng_seed = options.seed
    tol = options.tolerance * (diagonal if options.relative else 1.0 / unit)
    lo, hi = column_bounds(uv)
    own_rings = ring_knots is None
    data_uv, data_points = uv, points  # all points (the iterations may fit a subset)

    def rings_for(n_interior: int) -> np.ndarray:
        h = np.sqrt(np.prod(np.maximum(hi - lo, 1e-12)) / max(n_interior, 1))
        # thin domains: ring knots at the interior spacing would be countless (1/h each)
        h = max(h, 0.01 * float(np.max(hi - lo)))
        pad = 1e-6 * float(np.max(hi - lo))
        return border_rings(lo - pad, hi + pad, h, rings=default_ring_count(options.degree),
                            seed=rng_seed)

    measure: list = []  # feature_measure of all points, computed by the first start

    def place(count: int) -> tuple[np.ndarray, np.ndarray]:
        """Interior knots of a fresh start, placed on all points, and its border rings."""
        if not measure:
            measure.append(feature_measure(data_uv, data_points, seed=rng_seed))
        placed = initial_knots(data_uv, data_points, count, seed=rng_seed, measure=measure[0])
        return placed, (rings_for(len(placed)) if own_rings else ring_knots)

    # sizing (next_start; not in method.md section 6): with a tolerance and the automatic
    # start, the first fit is a probe with a quarter of the start's knots; the following
    # fresh starts take the knot count the measured convergence predicts for the tolerance
    # (at most the start's), so the net follows the tolerance instead of the budget. The
    # probe and the start the sizing jumps to are those of the default budget (PROBE_BUDGET)
    # for larger budgets: a budget above it that is not reached does not change the run
    sizing = False
    if start_knots is None:
        held = max(len(uv) // 8, 6)  # what the points hold
        n0 = int(min(options.initial_knots or automatic_start(options.mode,
                                                              options.max_control_points),
                     held))
        if options.initial_knots is not None and options.initial_knots > n0:
            # (it had been cut silently: user test)
            warnings.warn(f"initial_knots={options.initial_knots} is more than {len(uv)} "
                          f"points hold: the first fit has {n0} interior knots (one per 8 "
                          "points at most)", RuntimeWarning, stacklevel=4)
        # the largest start of the sizing: the default budget's, or a smaller budget's own
        # (twice it, a probe at smaller budgets too, gave other nets: a noisy mesh's net,
        # capped at its vertex count, fitted its noise to the tolerance instead of stopping
        # as the error stopped falling), and at most what the points hold
        sized_start = min(automatic_start(options.mode,
                                          min(options.max_control_points, PROBE_BUDGET)), held)
        probe = sized_start // PROBE_FRACTION
        sizing = (options.initial_knots is None and tol > 0 and options.max_iterations > 1
                  and probe >= MIN_PROBE_KNOTS)
        unsized = sized_start if options.initial_knots is None and tol > 0 else n0
        interior, ring_knots = place(probe if sizing else unsized)  # (one iteration, no probe)
    else:
        interior = np.asarray(start_knots, dtype=np.float64)
        if ring_knots is None:
            ring_knots = rings_for(len(interior))
    # a continued run (refine) with a tolerance inserts as many knots as the error-rate model
    # predicts are missing, up to doubling them (not 15%: a net sized for a loose tolerance
    # would crawl towards a much tighter one)
    grow = start_knots is not None and tol > 0 and options.knots_per_iteration is None
    if domain is None:
        domain = uv[ConvexHull(uv).vertices]

    def control(space: SplineSpace) -> np.ndarray:  # the control points: what the budget counts
        return np.flatnonzero(space.meets(domain))

    feature = options.feature_sensitive and options.mode == "tcb"
    # smoothness="auto": the iterations use the default; the surface returned is refitted with
    # the cross-validated choice (choosing in every iteration steered the knots by fits that
    # overshoot in data gaps: held-out errors up to 19x worse on the cliff)
    auto = check_smoothness(options.smoothness) == "auto"
    loop_smoothness = DEFAULT_SMOOTHNESS if auto else float(options.smoothness)
    full = (uv, points, weights, n_measured)
    sampled = options.criterion == "rms" and len(uv) > ITERATION_POINTS
    # the evaluated basis of the best iteration is kept for the auto refit at the same points
    # (a basis is ~80 bytes per point: the others are dropped as soon as they are fitted)
    keep_basis = auto and not sampled
    if sampled:
        pick = np.sort(np.random.default_rng(rng_seed + 1).choice(len(uv), ITERATION_POINTS,
                                                                 replace=False))
        if n_measured is not None:  # the measured points come first; so do their picks
            n_measured = int(np.searchsorted(pick, n_measured))
            if normals is not None:
                normals = normals[pick[:n_measured]]
        uv, points = uv[pick], points[pick]
        weights = None if weights is None else weights[pick]
    # the points that count against the net's size at new points (new_point_factor, _stalled)
    n_data = n_measured if measured_only and n_measured is not None else len(uv)
    # ... and the normals their errors are taken along there (a noisy mesh)
    across = normals if measured_only and n_measured is not None else None

    # the RMS over the area (point clouds): weights of the points fitted (the iterations' and,
    # after sampled iterations, all), made when first needed
    balance = balance and options.criterion == "rms" and tol > 0
    area: dict = {}

    def area_rms(at: np.ndarray, e: np.ndarray) -> float | None:
        """None for a cloud of even density (its points stand for equal areas)."""
        key = (id(at), len(e))  # the measured points come first
        if key not in area:
            w = area_weights(at[: len(e)])
            area[key] = w if np.mean(w * w) > UNEVEN_DENSITY else None
        w = area[key]
        return None if w is None else float(np.sqrt(np.dot(w, e * e) / len(e)))

    def new_point_estimate(rms: float, rms_area: float | None, n_ctrl: int, e: np.ndarray) -> float:
        """The error at new points (:func:`new_point_factor`), to stop on and to choose by: of
        the RMS over the points, and over the area (if any) with ``n / mean(w^2)`` points
        (the area weights' effective count: with the control points spread by area, a
        point's leverage is about ``w p / n``, and ``p / n_eff`` its mean over the area;
        the dwell cloud: 1000 of 21 000). Without it a sparse part's noise was fitted: the
        tile's noisy points took 1000 control points and ended 6x the tolerance off the true
        shape (2.7x with 150 when the area RMS is not asked for). Blind once the control
        points pass 0.9 ``n_eff`` (:func:`new_point_factor`'s cap): a sparse part of fewer
        points than the net has control points is interpolated, noise and all."""
        est = rms * float(new_point_factor(n_ctrl, n_data))
        if rms_area is not None:
            w = area[(id(uv), len(e))]
            n_eff = len(e) / float(np.mean(w * w))
            est = max(est, rms_area * float(new_point_factor(n_ctrl, n_eff)))
        return est

    history: list[dict] = []
    estimates: list[float] = []  # new_point_estimate of each fit
    best: IterationState | None = None  # the lowest error (or the fit meeting the tolerance)
    quiet: IterationState | None = None  # the lowest estimate at new points (for a stall)
    best_rms = quiet_score = np.inf
    n_before, pending = len(interior), np.zeros((0, 2))
    prev = None  # (interior knots, control points) of the last iteration
    last_round = False
    fresh = start_knots is None  # knots placed afresh (the start, a sizing restart)
    sized = grown = None  # (interior knots, error) of the last sizing / growing fit
    frozen: list = []  # (centres, radii) of the regions where knots made the surface swing
    last_insertion: tuple = ()  # insert()'s arguments of the last insertion (pending's)
    known: list = []  # (centres, radii) of where the run's first fit swings
    taken_back: set = set()  # the knots of the insertions taken back (bytes)
    in_a_row = 0  # insertions taken back since the last fit kept
    settle_restart = False  # the fit is the one a restart that swung was sized from
    shrinking = None  # a coarser fresh start after one that met the tolerance by far
    split = False  # ... the start halfway between a coarser one that missed and the finer one
    shrink_max = np.inf  # ... whose max error is held to this (SHRINK_MAX)

    def insert(knots, triangles, at, steer, count) -> np.ndarray:
        """New knots (insertion_points), steered by ``steer`` at the points ``at`` (those of
        the fit it was made of: the face check may add points after it), none in the regions
        where they made it swing."""
        if frozen:
            steer = np.where(_in_discs(at, frozen), 0.0, steer)
        new = insertion_points(knots, triangles, at, steer, count, options.criterion)
        return new[~_in_discs(new, frozen)] if frozen else new
    reason = "iteration limit"
    t_start = time.perf_counter()
    for it in range(options.max_iterations):
        t0 = time.perf_counter()
        cost = _feature_cost(uv, points, len(interior), rng_seed) if feature else None
        for extra in range(3):
            knots = np.vstack([interior, ring_knots])
            space = make_space(knots, options.degree, options.mode, cost, len(interior))
            active = control(space)
            n_ctrl = len(active)
            # the budget is strict: insert fewer knots until the space fits in it
            shrunk_away = False
            while n_ctrl > options.max_control_points and len(pending):
                pending = pending[: len(pending) // 2]
                interior = np.vstack([interior[: n_before], pending])
                knots = np.vstack([interior, ring_knots])
                space = make_space(knots, options.degree, options.mode, cost, len(interior))
                active = control(space)
                n_ctrl = len(active)
                shrunk_away = len(pending) == 0  # not even one new knot fits
            if shrunk_away:
                break
            # a fresh start too: fewer initial knots (a random subset: still well spread)
            while fresh and n_ctrl > options.max_control_points and len(interior) > 6:
                interior = interior[: max(6, len(interior) // 2)]
                knots = np.vstack([interior, ring_knots])
                space = make_space(knots, options.degree, options.mode, cost, len(interior))
                active = control(space)
                n_ctrl = len(active)
            if n_ctrl > options.max_control_points and it > 0 and not fresh:
                break
            t_space = time.perf_counter() - t0
            try:
                fit = fit_control_points(space, uv, points, weights, loop_smoothness,
                                         normals=across)
                break
            except BorderError:
                if extra == 2:
                    raise
                # safety net (method.md section 3 measured one more ring being needed at times)
                ring_knots = _add_ring(ring_knots, seed=rng_seed + extra + 1)
        if (n_ctrl > options.max_control_points and it > 0 and not fresh) or shrunk_away:
            reason = "control-point budget reached"
            break
        added, t_check = 0, time.perf_counter()
        for _ in range(STRAY_ROUNDS if stray_check is not None and not sampled else 0):
            more = stray_check(space, fit.control_points, uv, fit.errors)
            if more is None or not len(more[0]):
                break
            uv, points = np.vstack([uv, more[0]]), np.vstack([points, more[1]])
            if weights is not None:
                weights = np.concatenate([weights, np.ones(len(more[0]))])
            full = (uv, points, weights, n_measured)
            added += len(more[0])
            fit = fit_control_points(space, uv, points, weights, loop_smoothness,
                                     normals=across)
        t_check = time.perf_counter() - t_check
        state = IterationState(knots, len(interior), space, fit, active=active,
                               iteration=history_offset + it + 1)
        e = fit.errors[:n_measured]
        rms, emax = float(np.sqrt(np.mean(e**2))), float(e.max(initial=0.0))
        value = rms if options.criterion == "rms" else emax
        # the RMS over the area: to stop, to size and steer a next iteration, and to choose
        rms_area = area_rms(uv, e) if balance else None
        if rms_area is not None:
            value = max(value, rms_area)
        report = {
            "iteration": history_offset + it + 1,
            "knots": int(len(knots)),
            "interior_knots": int(len(interior)),
            "control_points": n_ctrl,
            "functions": int(space.n_basis),
            "rms": rms * unit,
            "max": emax * unit,
            "rms_rel": rms / diagonal,
            "max_rel": emax / diagonal,
            "smoothness": fit.smoothness,
            "seconds": time.perf_counter() - t0,
            "elapsed": time.perf_counter() - t_start,
            "phases": {"configurations": t_space, **fit.timings},
            "knots_placed": ("afresh" if fresh else "continued" if it == 0 else "inserted"),
        }
        if stray_check is not None and not sampled:
            report["phases"]["face check"] = t_check
        if added:
            report["stray_samples"] = added
        if rms_area is not None:
            report["rms_area"] = rms_area * unit
            report["rms_area_rel"] = rms_area / diagonal
        if sampled:
            report["sampled_points"] = len(uv)
        # a fit after an insertion or a sizing restart that makes the surface swing between
        # the data (a sharp step: more knots than the data hold) is taken back, and that
        # region is left alone; the run's first fit has nothing to go back to: where it swings
        # is known and not held against the later ones (a run of one fit: not checked here)
        swung = np.zeros((0, 2))
        restarted = fresh and sized is not None and not settle_restart
        first = it == 0 and options.max_iterations > 1
        if REVERT_SWINGS and (first or restarted or (not fresh and len(pending))):
            swung = swing_places(space, fit.control_points, uv[: len(e)], points[: len(e)], e,
                                 seed=rng_seed, margin=max(tol, 0.0))[0]
            if first:
                if len(swung):
                    h = cKDTree(knots).query(swung, k=3, workers=-1)[0][:, -1]
                    known.append((swung, SWING_FREEZE * h))
                swung = np.zeros((0, 2))
            elif known and len(swung):
                swung = swung[~_in_discs(swung, known)]
        settle_restart = False
        if len(swung) and restarted and shrinking:
            # a coarser start that swings is a miss: the finer one it followed is returned
            # (as a sizing restart it had been taken back to that one, which then shrank to
            # it again, until the iteration limit: review)
            report["swings"] = int(len(swung))
            history.append(report)
            fit.basis = None
            reason = "tolerance reached"
            break
        if len(swung) and restarted:
            # a restart with more knots than the data hold: again with fewer, half way back
            # to the fit it was sized from (and that one itself at last); no more sizing
            fewer = (sized[0] + len(interior)) // 2
            settle_restart = fewer - sized[0] < max(2, sized[0] // 8)
            report["swings"] = int(len(swung))
            report["knots_taken_back"] = int(max(len(interior) - (
                sized[0] if settle_restart else fewer), 0))
            history.append(report)
            fit.basis = None
            if callback is not None and _cancel_requested(callback, report):
                reason = "cancelled"
                break
            interior, ring_knots = place(sized[0] if settle_restart else fewer)
            n_before, pending, prev, sizing = len(interior), np.zeros((0, 2)), None, False
            continue
        if len(swung):
            # around each place, SWING_FREEZE times its distance to the 3rd nearest knot, and
            # at least to the nearest new knot (so that the next insertion differs)
            h = cKDTree(knots).query(swung, k=3, workers=-1)[0][:, -1]
            d_new = cKDTree(pending).query(swung, workers=-1)[0]
            frozen.append((swung, np.maximum(SWING_FREEZE * h, (1 + 1e-9) * d_new)))
            report["swings"] = int(len(swung))
            report["knots_taken_back"] = int(len(pending))
            history.append(report)
            fit.basis = None
            if callback is not None and _cancel_requested(callback, report):
                reason = "cancelled"
                break
            # the insertion again, from the fit before it, with the regions that swing left out;
            # the same knots as one already taken back would go round in circles (a spiky
            # terrain made the same fit at iterations 17-20, then "raise the iterations"), and
            # so does an insertion taken back TAKE_BACKS_IN_A_ROW times in a row (the same
            # terrain read from text: 7 in a row, each a little different, to the limit)
            taken_back.add(pending.tobytes())
            in_a_row += 1
            pending = insert(*last_insertion)
            if (len(pending) == 0 or pending.tobytes() in taken_back
                    or in_a_row >= TAKE_BACKS_IN_A_ROW):
                reason = SWINGS_LEFT
                break
            interior = np.vstack([interior[:n_before], pending])
            continue
        in_a_row = 0
        # the best: the lowest RMS (criterion "max": the lowest max) within the budget, or the
        # fit that meets the tolerance (a fresh start's knots do not contain the earlier ones:
        # with the criterion "max" a fit of lower RMS may still miss it). A run that stops
        # because the error stopped falling returns the lowest estimate of the RMS at new
        # points instead: there a larger net lowers the RMS on the data by fitting the noise
        within = n_ctrl <= options.max_control_points
        # a coarser start meets it with its max error too: within SHRINK_MAX times the
        # tolerance, or the max of the fit it follows when that is larger
        met = value <= tol and not (shrinking and emax > shrink_max)

        def better(current, key, current_key):
            if shrinking and not met:  # (a coarser start that missed: never returned)
                return False
            return current is None or (within and (current.n_control > options.max_control_points
                                                   or key < current_key or met))

        held = [best, quiet]
        key = rms if rms_area is None else max(rms, rms_area)  # (uneven density: the larger)
        # (criterion "max": the lowest max; a grid's run to a max of 1e-4 ran out of budget
        # and returned 1917 control points with a max of 1.42e-4, of lowest RMS, where 812 had
        # reached 1.06e-4: user test)
        if options.criterion == "max":
            key = emax
        if better(best, key, best_rms):
            best, best_rms = state, key
        # (a noisy mesh: of the errors across the surface)
        score = new_point_estimate(rms if fit.across is None else
                                   float(np.sqrt(np.mean(fit.across**2))), rms_area, n_ctrl, e)
        estimates.append(score)
        if tol > 0 and BEST_BY_NEW_POINTS:
            if better(quiet, score, quiet_score):
                quiet, quiet_score = state, score
        # only the auto refit of the returned space reuses a basis: free the others'
        for old in held + [state]:
            if old is not None and not (keep_basis and (old is best or old is quiet)):
                old.fit.basis = None
        history.append(report)
        if callback is not None and _cancel_requested(callback, report):
            reason = "cancelled"
            break
        if met:
            reason = "tolerance reached"
            # a fresh start that meets the tolerance by far (a loose tolerance, a smooth
            # shape): a coarser fresh start with the knots the error-rate model predicts, at
            # least MIN_START_KNOTS; the finer fit stays the one returned if it misses
            if (fresh and not split and options.initial_knots is None
                    and it < options.max_iterations - 1 and len(interior) > MIN_START_KNOTS):
                want = predicted_knots(len(interior), max(value, 1e-300),
                                       SHRINK_TARGET * tol, sized, options.degree)
                want = max(int(np.ceil(want)), MIN_START_KNOTS)
                if want <= SHRINK_FRACTION * len(interior):
                    sized, sizing, shrinking = (len(interior), value), False, True
                    shrink_max = max(SHRINK_MAX * tol, emax)
                    interior, ring_knots = place(want)
                    n_before, pending, prev = len(interior), np.zeros((0, 2)), None
                    continue
            break
        if shrinking:  # a coarser start missed the tolerance: the finer one is returned ...
            reason = "tolerance reached"
            # ... or one halfway between them (SHRINK_SPLIT), if it meets
            halfway = int(round(np.sqrt(sized[0] * len(interior))))
            if (not split and sized[0] >= SHRINK_SPLIT * len(interior)
                    and it < options.max_iterations - 1 and len(interior) < halfway < sized[0]):
                split = True
                interior, ring_knots = place(halfway)
                n_before, pending, prev = len(interior), np.zeros((0, 2)), None
                continue
            break
        if it == options.max_iterations - 1:
            break
        if last_round:
            reason = "control-point budget reached"
            break
        # the error has stopped falling (noise in the data; a tolerance below its level): more
        # knots fit the noise, so stop rather than spend the budget on it
        kept = [h for h in history if "knots_taken_back" not in h]  # estimates: one each
        if tol > 0 and _stalled(kept, n_data, estimates if (balance or across is not None)
                                and STALL_DOF else None):
            reason = STALLED
            if quiet is not None and quiet is not best:
                best.fit.basis = None
                best = quiet
            break
        if sizing:
            restart = next_start(len(interior), value, tol, sized, options.degree,
                                 sized_start)
            if restart == sized_start < n0:  # (a budget above PROBE_BUDGET)
                # ... but past what insertions of 15% reach from that start by the iteration
                # limit, the prediction, up to the budget's own start (a budget of 5000 at
                # 5 iterations had stopped at 673 control points, RMS 2.5e-4, where its own
                # start reached 1654 and 6.4e-5: review)
                want = predicted_knots(len(interior), value, tol, sized, options.degree)
                if want > sized_start * 1.15 ** max(options.max_iterations - 2 - it, 0):
                    restart = int(min(np.ceil(want), n0))
            sized = (len(interior), value)
            sizing = restart is not None and restart < sized_start
            if restart is not None:  # a fresh start with the predicted knot count
                interior, ring_knots = place(restart)
                n_before, pending, prev, fresh = len(interior), np.zeros((0, 2)), None, True
                continue
        fresh = False
        # how many knots the budget allows: control points grow about linearly with the
        # interior knots, by what the last insertion added per knot (the border functions
        # that meet the domain are a large constant share: n_ctrl / knots would overstate a
        # new knot's cost and stop the loop short of the budget); an optimistic guess is safe,
        # the space is shrunk to the budget above
        marginal = prev is not None and len(interior) > prev[0] and n_ctrl > prev[1]
        per_knot = ((n_ctrl - prev[1]) / (len(interior) - prev[0]) if marginal
                    else n_ctrl / max(len(interior), 1))
        prev = (len(interior), n_ctrl)
        room = int((options.max_control_points - n_ctrl) / max(per_knot, 1e-9))
        want = options.knots_per_iteration or max(10, int(np.ceil(0.15 * len(interior))))
        if grow:
            missing = predicted_knots(len(interior), value, tol, grown, options.degree)
            want = max(want, min(int(np.ceil(missing)) - len(interior), len(interior)))
            grown = (len(interior), value)
        if marginal:
            count = min(want, room)
        else:  # no measured cost per knot yet: try them all if there is any room at all
            count = want if n_ctrl < options.max_control_points else 0
        if count < 1:
            reason = "control-point budget reached"
            break
        # the budget limits this insertion: it is the last one (no crawl of tiny steps)
        last_round = count < want
        steer = fit.errors
        if rms_area is not None and rms_area > rms:  # the sparse parts miss the tolerance
            steer = fit.errors.copy()
            steer[: len(e)] *= np.sqrt(area[(id(uv), len(e))])
        last_insertion = (knots, space.configurations.triangles[0], uv, steer, count)
        new = insert(*last_insertion)
        if len(new) == 0:
            reason = SWINGS_LEFT if frozen else "no triangle has enough data to refine"
            break
        n_before, pending = len(interior), new
        interior = np.vstack([interior, new])
    if best is None:  # cannot happen: the first fit of a run is always made
        raise RuntimeError("the refinement loop made no fit")
    if reason == "control-point budget reached" and options.max_control_points < asked:
        # a noisy mesh's net at its vertex count (NOISY_NET_PER_VERTEX): a stall, which returns
        # the fit of the lowest estimated error at new points, as the stall test's does; the
        # last report says so (report["net_capped"])
        reason = STALLED
        history[-1]["net_capped"] = int(options.max_control_points)
        if quiet is not None and quiet is not best:
            best.fit.basis = None
            best = quiet
    if quiet is not None and quiet is not best:  # not returned: no basis kept for it
        quiet.fit.basis = None
    if best.n_control > asked:  # only the first fit was made or kept
        what = ("even the coarsest surface needs" if start_knots is None
                else "the surface to refine already has" if start_degree in (None, options.degree)
                else f"the surface to refine has, at degree {options.degree} (it was fitted at "
                     f"degree {start_degree}),")
        raise InvalidInputError(
            f"{what} {best.n_control} control points, more than the maximum of "
            f"{asked}; allow more control points"
        )
    # sparse data (fewer fitted points than SPARSE_POINTS_PER_CONTROL per control point): only
    # the fairing holds the surface between the points, and the loop's fits come close to
    # interpolating them. The default weight is replaced by the cross-validated one (60 random
    # points of Franke's function: the surface swung to 2x the data's height range with 1e-4),
    # and a choice is kept even when it misses a tolerance the loop reached (the stop reason
    # then says so).
    fitted = len(full[0]) if full[2] is None else int(np.count_nonzero(full[2] > 0))
    sparse = fitted < SPARSE_POINTS_PER_CONTROL * best.n_control
    thin = not sparse and fitted < THIN_POINTS_PER_CONTROL * best.n_control  # (see THIN_MARGIN)
    # A stalled run's net is often not far from sparse (2-5 points per control point) and
    # chosen on the error at new points: its default weight is cross-validated as well, among
    # the sparse candidates too (clean F10, 3000 points: 0.0039 off the function with the
    # choice, 0.053 with 1e-4 overshooting in the gaps; noisy clouds: 0.92-1.09x)
    stalled = reason == STALLED and CROSS_VALIDATE_STALLED
    default_replaced = ((sparse or stalled or thin) and not auto
                        and isinstance(options.smoothness, DefaultSmoothness))
    auto = auto or default_replaced
    # a cancelled run is not refitted with a choice (30 factorizations the user asked to skip)
    auto = auto and reason != "cancelled"
    if sampled or auto:
        t0 = time.perf_counter()
        fu, fp, fw, fm = full if sampled else (uv, points, weights, n_measured)
        # (a basis of fewer points than fu: samples were added to the fit after best's)
        same = not sampled and len(best.fit.errors) == len(fu)
        fit = fit_control_points(best.space, fu, fp, fw, "auto" if auto else loop_smoothness,
                                 scored=fm, basis=best.fit.basis if same else None,
                                 sparse=sparse or stalled or thin)
        best.fit.basis = None
        selection = None
        if auto:
            selection = {"chosen": fit.smoothness, "seconds": time.perf_counter() - t0,
                         "cross_validated_rms": {f"{k:g}": v * unit for k, v in
                                                 fit.validation.items()}}
            e = fit.errors[:fm]
            value = (np.sqrt(np.mean(e**2)) if options.criterion == "rms"
                     else e.max(initial=0.0))
            rms_area = area_rms(fu, e) if balance else None
            if rms_area is not None:
                value = max(value, rms_area)
            excess = _default_excess(fit.validation, fit.smoothness)
            if default_replaced and sparse:
                selection["why"] = (f"sparse data: {fitted} points for {best.n_control} control "
                                    "points (the default 1e-4 is cross-validated)")
            elif default_replaced and stalled:
                selection["why"] = (f"{STALLED} (noise, or detail the knots cannot resolve): "
                                    "the default 1e-4 is cross-validated")
            elif default_replaced and excess <= THIN_MARGIN:  # thin data: the default does
                fit = (fit_control_points(best.space, fu, fp, fw, loop_smoothness) if sampled
                       else best.fit)
                selection = None
            elif default_replaced:
                selection["why"] = (
                    f"sparse data: {fitted} points for {best.n_control} control points, fewer "
                    f"than {THIN_POINTS_PER_CONTROL} each, and the default 1e-4's "
                    f"cross-validated error is {excess:.2f} times the choice's")
            missed = selection is not None and reason == "tolerance reached" and value > tol
            if missed and (sparse or (thin and default_replaced)):
                reason = ("tolerance reached by the loop; the cross-validated smoothness of "
                          "sparse data misses it")
            elif missed and fit.smoothness != loop_smoothness:
                # the smoother choice would break the tolerance the loop reached: keep the
                # default (the loop's fit, or after sampled iterations its refit on all points)
                fit = (fit_control_points(best.space, fu, fp, fw, loop_smoothness) if sampled
                       else best.fit)
                selection["kept"] = f"{loop_smoothness:g} (the choice misses the tolerance)"
            # (``value`` is the choice's: not where the thin-data rule put the loop's fit back,
            # which missed the tolerance: review)
            if reason in (STALLED, "iteration limit", "control-point budget reached") and (
                    selection is not None and "kept" not in selection and value <= tol):
                # the cross-validated smoothness meets the tolerance the loop's fits at the
                # default missed: reached (an exact quadratic on 169 points, RMS 2.8e-7 of the
                # diagonal for a tolerance of 1e-6, had stopped as "the error stopped falling",
                # told to loosen the tolerance above the RMS reached: user test)
                reason = "tolerance reached"
        refit = ({"points": len(fu), "seconds": time.perf_counter() - t0,
                  "phases": dict(fit.timings)} if sampled else best.refit)
        best = IterationState(best.knots, best.n_interior, best.space, fit, refit, best.active,
                              selection, best.iteration)
    best.fit.basis = None
    return best, history, reason

