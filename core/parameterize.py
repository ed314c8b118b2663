"""Parameterization: map scanned points or a disk-like mesh to the parameter plane.

See ``method.md`` section 4 (Parameterization). Two maps are implemented:

* **Point clouds** (height fields, gently curved patches): orthogonal projection onto the
  best-fit (PCA) plane, ``uv = ((p - o) . [a_u, a_v]) / s``, with a check for folds.
* **Meshes of disk topology**: the boundary loop goes to the unit circle by chord length (or,
  when it has four corners, to a rectangle of the mesh's proportions, side by side) and the
  interior vertices are placed by Floater's mean-value weights (a Tutte embedding), one sparse
  linear solve for ``u`` and ``v`` together. When it distorts the triangles less, the boundary
  keeps its own shape instead, flattened (:func:`_flattened_map`; not in method.md).

Inputs that cannot be parameterized without folds (closed meshes, several boundary loops,
non-manifold or non-orientable meshes, clouds folding over their best-fit plane) raise a
:class:`~.errors.TopologyError` or :class:`~.errors.ParameterizationError` that says what is needed,
never a wrong parameterization.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import (
    breadth_first_order, connected_components, depth_first_order, minimum_spanning_tree,
)
from scipy.sparse.linalg import splu
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .errors import (
    HolesError, InvalidInputError, OutlierError, ParameterizationError, TCBError, TopologyError,
)
from .geometry import (column_bounds, coordinate_order, ear_clipping, polygon_triangles,
                       simple_polygon)
from .parallel import pmap, row_blocks
from .simplex import orient2d

__all__ = [
    "MIN_POINTS",
    "Normalization",
    "Parameterization",
    "count_duplicates",
    "isolated_points",
    "mesh_spikes",
    "normalize",
    "on_xy_grid",
    "outlier_error",
    "parameterize",
    "parameterize_mesh",
    "parameterize_points",
    "projection_direction",
    "spike_error",
]

MIN_POINTS = 10
"""Fewest distinct points a point cloud must have."""

# Fold detection for point clouds (method.md section 4).
_FOLD_NEIGHBOURS = 12  # neighbours (besides the point itself) of the local PCA and uv tests
_FOLD_MIN_COS = 0.2  # |local normal . plane normal| below this: surface nearly perpendicular
_STRAY_MAX_SHARE = 0.05  # drop_outliers leaves out at most this share of points over others
# a uv-neighbour j of i is on another layer when |q_j - q_i| |n_i . n| exceeds this times its
# offset across the projection plane (n the projection direction; 1 on i's local plane)
_FOLD_OFF_LAYER = 2.0
_FOLD_NOISE_FACTOR = 4.0  # ... and farther off the local plane than this many sigma_i
_FOLD_MIN_OFF_NEIGHBOURS = 0.25  # fraction of uv-neighbours off the surface for a point to count
_FOLD_COHERENCE = 0.5  # fraction of suspect 3D neighbours for a point to be flagged
_FOLD_MAX_FRACTION = 0.02  # fraction of flagged points above which the cloud is rejected
_FOLD_CLEAR = 0.25  # a projection with flags at fewer than this times that is taken at once
_FOLD_RIM = 0.05  # "at the rim": within this fraction of the extent from the convex hull
_FOLD_BACK = 0.02  # a direction given: normals facing away by more than this are folds
# ... and a surface parallel to it (|n_i . n| below this, within 0.6 degrees) at _EDGE_ON of
# the reliable points is seen edge-on: a wall stacked along z was fitted over z as a ribbon
# at half its height, 20% of its diagonal off (user test); Renka's F7 with 3x its heights, the
# steepest height field of the suite, stays above 0.011 everywhere
_FOLD_PARALLEL = 0.01
_UPRIGHT = 0.01  # |n_i . n| below this (0.6 degrees): the surface stands on n there
_FOLD_RIM_SHARE = 0.6  # steep points count as a fold when this share of them is at the rim
_ORIENT_BELOW = 0.15  # first candidate's score below this: a steep cloud, orient the normals
_SIGNED_MIN = -0.05  # the direction the oriented normals face is tried when they score this
_ORIENT_POINTS = 20000  # normals oriented (and scored) at most at this many points
_EDGE_ON = 0.5  # steep points (fold test) at this share of the reliable ones: seen edge-on
_FOLD_MAX_SAMPLE = 40_000  # larger clouds are checked on a seeded random subset of this size
# the choice of the projection direction counts area, not points, when the points' local areas
# (_area_weights) make them weigh as fewer than this share of as many evenly spread points
_UNEVEN_SHARE = 0.25
# noise: when fewer than this share of the local planes are reliable, coarser samples (a
# quarter of the points each, down to _COARSE_MIN) are tried and the most reliable one kept
_MIN_RELIABLE = 0.5
_COARSE_MIN = 250
_MIN_CHECKABLE = 0.3  # below this share of reliable planes at every scale: fold check blind,
_MAX_THICKNESS = 0.5  # and a cloud thicker than this (s_2 / s_1 of its PCA) is refused
_THIN_NEIGHBOURHOOD = 0.25  # lambda_0 / lambda_1 above this: local normal unreliable
_COLLINEAR_RTOL = 1e-9  # RMS distance from the best line, relative to the scale
_OUTLIER_NEIGHBOURS = 8  # d_i: distance to the 8th nearest distinct neighbour (local spacing)
_OUTLIER_FACTOR = 10.0  # candidates: d_i above this times the cloud's median d ...
_OUTLIER_LOCAL = 3.0  # ... and this times its neighbours' lower quartile
_OUTLIER_ISOLATION = 20.0  # isolated: its nearest non-candidate j is this many d_j away


# --------------------------------------------------------------------------------------------
# Validation and normalization
# --------------------------------------------------------------------------------------------


def _as_points(points: np.ndarray, *, what: str = "points") -> np.ndarray:
    """Return ``points`` as a C-contiguous ``(n, 3) float64`` array or raise InvalidInputError
    (complex numbers too: numpy drops their imaginary parts with only a warning; user test)."""
    if np.iscomplexobj(points):
        raise InvalidInputError(f"{what} must be real numbers, got complex ones (take .real "
                                "if that is meant)")
    if np.ma.isMaskedArray(points) and np.ma.getmaskarray(points).any():
        # (the values under the mask had been fitted as data: user test)
        mask = np.ma.getmaskarray(points)
        rows = int(mask.reshape(len(mask), -1).any(axis=1).sum()) if mask.ndim else 1
        raise InvalidInputError(
            f"{rows} of the {what} {'is' if rows == 1 else 'are'} masked, and the values under "
            f"a mask would be fitted as data: leave them out ({what}[~{what}.mask.any(axis=1)]) "
            "or fill them with NaN")
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"{what} must be numbers (an (N, 3) array of x, y, z coordinates): {exc}"
        ) from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        # (x, y, z and intensity or colour, as the command line reads them: user test)
        more = (f"; for x, y, z followed by other columns (intensity, colour) give "
                f"{what}[:, :3]" if arr.ndim == 2 and arr.shape[1] > 3 else "")
        raise InvalidInputError(
            f"{what} must be an (N, 3) array of x, y, z coordinates; got shape {arr.shape}"
            + more)
    return np.ascontiguousarray(arr)


# common no-data fill values of rasters (GDAL's and others' defaults): a raster exported to
# points (gdal_translate -of XYZ) keeps its empty cells with them
FILL_VALUES = (-9999.0, -99999.0, -32767.0, -32768.0, float(np.finfo(np.float32).min))
# ... counted as such when all other values of their coordinate are this far above them
FILL_GAP = 1000.0


# on_xy_grid: at least this share of a grid's nodes hold a point (a DEM's no-data cells)
GRID_MIN_SHARE = 0.25


def on_xy_grid(points: np.ndarray) -> bool:
    """Whether ``(n, 3)`` points are heights over a grid of x and y: their x take few values and
    so do their y (the distinct x times the distinct y at most ``m / GRID_MIN_SHARE``, ``m``
    the nodes held: at least a quarter of the grid's nodes held), and no two points share
    both with different heights (one height per node; the same point twice is one, as where
    tiles that share a row of nodes were put in one file). Such points are a height field
    along z by their making, whatever their slope: a DEM raster's nodes (``.asc``, ``.npz``
    with ``elevation``) and the gridded XYZ text that survey agencies publish DEM tiles as.
    Scattered scans are not (their x are all distinct), nor is a grid turned in the plane. No
    Python loop: 0.04-0.06 s for the Jacksboro DEM's 139 380 nodes, 0.3 s for 1e6 random
    points."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or len(p) < MIN_POINTS or not np.isfinite(p[:, :2]).all():
        return False
    xs, ys = np.unique(p[:, 0]), np.unique(p[:, 1])
    if min(len(xs), len(ys)) < 2 or len(xs) * len(ys) > len(p) / GRID_MIN_SHARE:
        return False
    node = np.searchsorted(xs, p[:, 0]).astype(np.int64) * len(ys) + np.searchsorted(ys, p[:, 1])
    order = np.argsort(node, kind="stable")
    node = node[order]
    twice = node[1:] == node[:-1]
    if twice.any():  # (the same node twice: one height, or no height field)
        z = p[order, 2] if p.shape[1] > 2 else np.zeros(len(p))
        if not np.array_equal(z[1:][twice], z[:-1][twice], equal_nan=True):
            return False
    return len(xs) * len(ys) <= (len(p) - int(twice.sum())) / GRID_MIN_SHARE


def fill_value_rows(points: np.ndarray):
    """The rows of ``points`` (n, 3) whose coordinate is a common no-data fill value
    (:data:`FILL_VALUES`) far (over FILL_GAP units) below all other values of that coordinate:
    ``(rows (bool), column, value, lowest other value)``, or None. Not in method.md."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or not len(p):
        return None
    finite = np.isfinite(p).all(axis=1)
    for j in range(p.shape[1]):
        col = p[finite, j]
        if not col.size:
            return None
        low = float(col.min())
        if low not in FILL_VALUES:
            continue
        rest = col[col != low]
        if rest.size and float(rest.min()) > low + FILL_GAP:
            return (p[:, j] == low) & finite, j, low, float(rest.min())
    return None


# coordinates of at least this size are no data (not in method.md): float32's largest value
# (3.4e38, where Blender stores an infinity typed into a vertex), a fill value above the data;
# one such vertex made all others one point at the scale of the mesh, and the map failed with
# "113 of 200 triangles came out flipped or degenerate" (user test)
HUGE_COORDINATE = 1e30


def huge_rows(points: np.ndarray) -> np.ndarray:
    """Mask (n,) of the finite rows of ``points`` with a coordinate of at least
    HUGE_COORDINATE in size."""
    p = np.asarray(points, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(p).all(axis=1) & (np.abs(p) >= HUGE_COORDINATE).any(axis=1)


def huge_words(rows: np.ndarray, points: np.ndarray, what: str = "points") -> str:
    """How :func:`huge_rows`' find is told: how many, the first, and what it may be."""
    k, first = int(rows.sum()), int(np.flatnonzero(rows)[0])
    x, y, z = (float(v) for v in np.asarray(points, dtype=np.float64)[first, :3])
    return (f"{k} of the {len(rows)} {what} {'has' if k == 1 else 'have'} coordinates of "
            f"1e{int(np.log10(HUGE_COORDINATE))} or more in size (the first: #{first}, "
            f"({x:.4g}, {y:.4g}, {z:.4g})): float32's largest value (an infinity stored in "
            "32 bits) or a fill value, which would be fitted as data")


def fill_value_words(found, total: int, what: str = "points") -> str:
    """How :func:`fill_value_rows`' find is told: the rows, the value, and what it is."""
    rows, j, value, lowest = found
    axis = "xyz"[j] if j < 3 else f"column {j}"
    k = int(rows.sum())
    return (f"{k} of the {total} {what} {'has' if k == 1 else 'have'} {axis} = {value:g}, "
            f"far below all others (lowest {lowest:g}): a no-data fill value (a raster "
            "exported to points keeps its empty cells with it), which would be fitted as data")


def _check_finite(points: np.ndarray, *, what: str = "points") -> None:
    """Raise InvalidInputError naming how many rows of ``points`` contain NaN or inf."""
    bad = ~np.isfinite(points).all(axis=1)
    n_bad = int(bad.sum())
    if n_bad:
        raise InvalidInputError(
            f"{n_bad} of {len(points)} {what} have NaN or infinite coordinates; "
            "remove them (e.g. points[np.isfinite(points).all(axis=1)]) and try again"
        )


def count_duplicates(points: np.ndarray) -> int:
    """Number of rows of ``points`` that exactly repeat an earlier row.

    Rows equal in every coordinate (``==``, so ``-0.0`` equals ``0.0``) are found by sorting a
    64-bit hash of each row's bits: only rows whose hash repeats can be duplicates, and those
    are sorted lexicographically and compared with their neighbours (the count is the number of
    rows equal to the row before them). Exact duplicates only; near duplicates are not counted.
    (``np.unique(points, axis=0)`` gives the same count 5-10x slower: 70 ms on 1e5 points.)

    Args:
        points: ``(n, d)`` array.

    Returns:
        The number of redundant rows (0 when all rows are distinct).
    """
    arr = np.asarray(points)
    if arr.ndim != 2 or len(arr) == 0:
        return 0
    if arr.shape[1] == 0:
        return len(arr) - 1
    if arr.dtype.kind != "f":  # integers (exact, no float rounding): sort the rows themselves
        s = arr[np.lexsort(arr.T[::-1])]
        return int(np.count_nonzero((s[1:] == s[:-1]).all(axis=1)))
    arr = np.ascontiguousarray(arr, dtype=np.float64) + 0.0  # -0.0 -> 0.0: same bits
    bits = arr.view(np.uint64)
    h = bits[:, 0].copy()
    for c in range(1, arr.shape[1]):
        h = (h * np.uint64(0x9E3779B97F4A7C15)) ^ bits[:, c]  # wraps modulo 2^64
    hs = np.sort(h)
    repeated = np.unique(hs[1:][hs[1:] == hs[:-1]])
    if len(repeated) == 0:
        return 0
    sub = arr[np.isin(h, repeated)]
    sub = sub[np.lexsort(sub.T[::-1])]
    return int(np.count_nonzero((sub[1:] == sub[:-1]).all(axis=1)))


@dataclass(frozen=True, eq=False)
class Normalization:
    """Similarity that maps the bounding box of the data to a box of half-diagonal 1.

    ``apply(p) = (p - center) / scale`` and ``undo(q) = q * scale + center``, with ``center`` the
    centre of the bounding box and ``scale`` half its diagonal (method.md section 4; the
    tolerances of this module are relative to this scale). The two maps invert each other to
    about one ulp of the coordinates.

    Attributes:
        center: ``(3,) float64`` centre of the bounding box.
        scale: half the length of the bounding-box diagonal (> 0).
    """

    center: np.ndarray
    scale: float

    def apply(self, p: np.ndarray) -> np.ndarray:
        """Map original coordinates ``(..., 3)`` to normalized ones: ``(p - center) / scale``."""
        return (np.asarray(p, dtype=np.float64) - self.center) / self.scale

    def undo(self, q: np.ndarray) -> np.ndarray:
        """Map normalized coordinates ``(..., 3)`` back: ``q * scale + center``."""
        return np.asarray(q, dtype=np.float64) * self.scale + self.center


def principal_axes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values ``(3,)`` (descending) and right singular vectors ``vt`` (3, 3) of the
    centred ``(n, 3)`` array ``x``, as ``np.linalg.svd(x, full_matrices=False)`` gives them.

    From the eigen-decomposition of the 3 x 3 scatter matrix ``x^T x`` (5-8x faster than the SVD
    of the tall matrix at 1e6 points); that squares the condition number: ``s_2`` of a flat
    cloud comes out near ``1e-8 s_0`` instead of 0, and ``s_1`` of exactly collinear points
    near ``1e-8 s_0`` (1e-6 at 2e7 points). So when ``s_1 < 1e-3 s_0`` (a thin strip or nearly
    collinear points, where the rank test needs ``s_1`` to ~1e-9 relative) the SVD of ``x``
    itself is taken.
    """
    w, v = np.linalg.eigh(x.T @ x)
    sv = np.sqrt(np.maximum(w[::-1], 0.0))
    if not sv[1] > 1e-3 * sv[0]:
        _, sv, vt = np.linalg.svd(x, full_matrices=False)
        return sv, vt
    return sv, np.ascontiguousarray(v[:, ::-1].T)


def box_normalization(p: np.ndarray) -> Normalization:
    """The :class:`Normalization` of ``(n, 3)`` points: bounding-box centre and half-diagonal,
    without the checks of :func:`normalize` (for points it has already accepted)."""
    lo, hi = column_bounds(p)
    return Normalization(center=_readonly(0.5 * (lo + hi)), scale=0.5 * float(np.linalg.norm(hi - lo)))


# the coordinates' 64-bit spacing may be at most this share of the half-diagonal (normalize)
_MAX_ROUNDING = 1e-4  # (1 mm objects at UTM coordinates, 5e-7, fit as at the origin: review)


def normalize(points: np.ndarray) -> tuple[np.ndarray, Normalization]:
    """Validate a point cloud and map it into the box centred at 0 with half-diagonal 1.

    ``q = (p - c) / s`` with ``c`` the bounding-box centre and ``s`` half the bounding-box
    diagonal (method.md section 4).

    Args:
        points: ``(n, 3)`` array of x, y, z coordinates.

    Returns:
        ``(q, normalization)``: ``q`` is ``(n, 3) float64``; ``normalization.undo(q)`` gives the
        points back.

    Raises:
        InvalidInputError: wrong shape, NaN/inf rows, fewer than 10 (distinct) points, all
            points identical, or all points on one line. Exact duplicates are allowed as long
            as at least 10 distinct points remain.
    """
    p = _as_points(points)
    _check_finite(p)
    n = len(p)
    if n < MIN_POINTS:
        raise InvalidInputError(
            f"at least {MIN_POINTS} points are needed to fit a surface; got {n}"
        )
    norm = box_normalization(p)
    if not norm.scale > 0.0:
        raise InvalidInputError(
            f"all {n} points are identical; a surface needs points spread in two directions"
        )
    far = float(np.abs(p).max())
    if np.spacing(far) > _MAX_ROUNDING * norm.scale:
        # (1e15 from the origin, 64-bit coordinates are 0.125 apart: "more auxiliary border
        # rings are needed" had been the error; user test)
        raise InvalidInputError(
            f"the points lie {far:.3g} from the origin, where 64-bit coordinates are "
            f"{np.spacing(far):.3g} apart, {np.spacing(far) / (2 * norm.scale):.2g} of the "
            "points' extent: too coarse for their shape; subtract an offset (e.g. the "
            "coordinates of a corner of the data) from them before they are rounded"
        )
    n_dup = count_duplicates(p)
    if n - n_dup < MIN_POINTS:
        raise InvalidInputError(
            f"only {n - n_dup} distinct points ({n_dup} of {n} are exact duplicates); at least "
            f"{MIN_POINTS} distinct points are needed to fit a surface"
        )
    q = norm.apply(p)
    # Rank test: RMS distance of the points from their best line, relative to the scale (1 now).
    sv, _ = principal_axes(q - q.mean(axis=0))
    if sv[1] / np.sqrt(n) <= _COLLINEAR_RTOL:
        raise InvalidInputError(
            f"all {n} points lie on one straight line; a surface needs points spread in two "
            "directions"
        )
    return q, norm


def _readonly(a: np.ndarray) -> np.ndarray:
    """Return ``a`` flagged read-only (the dataclasses below are immutable values)."""
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------------------------
# The result
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Parameterization:
    """Parameters ``uv`` of the input points and the domain they cover (method.md section 4).

    Attributes:
        uv: ``(n, 2) float64`` parameters of the input points, row ``i`` for point ``i``. For a
            ``"plane"`` the domain is scaled to ``[-1, 1]^2`` (the longer side spans it), for a
            ``"disk"`` it is the unit disk (or a rectangle of half-diagonal 1 in it, for a
            boundary with four corners, or the mesh's own boundary flattened, in a box of
            half-diagonal 1 centred at 0). Rows of mesh vertices that no face references are
            NaN (see ``used``).
        kind: ``"plane"`` (point cloud projected on its best-fit plane) or ``"disk"`` (mesh).
        domain_polygon: ``(b, 2) float64`` counter-clockwise polygon bounding the parameter
            domain of the data: the convex hull of ``uv`` for a plane, the boundary polygon
            (vertices on the unit circle, on the rectangle, or the flattened boundary, which
            need not be convex) for a disk.
        used: ``(n,) bool``; False for mesh vertices that no face references (they have no
            parameter and must be left out of a fit) and for outliers left out of a point cloud
            or spike vertices dissolved out of a mesh (``drop_outliers``); their ``uv`` rows
            are NaN.
        boundary: ``(b,) int64`` indices of the boundary loop in counter-clockwise uv order
            (``uv[boundary] == domain_polygon``), or None for a point cloud.
        faces: ``(f, 3) int64`` triangles actually used (degenerate and duplicate faces
            removed, polygons split), oriented so that every uv triangle has positive area;
            None for a point cloud.
        origin: ``(3,) float64`` point of the best-fit plane that maps to ``uv = 0`` (plane).
        axes: ``(3, 3) float64`` orthonormal rows ``(a_u, a_v, n)``, right-handed, ``n`` the
            plane normal (plane only).
        scale: 3D length of one uv unit (plane only): ``uv = ((p - origin) @ axes[:2].T) /
            scale``.
        stretch: ``(n,) float64`` (disk only): at each vertex, the largest ratio of 3D to uv
            length over its mesh edges (NaN for unused vertices); the map to the disk
            compresses steep and outlying parts of a mesh, and the tessellation refines there.
            None for a point cloud (and for files written before it existed).
        holes: ``(h,) int64`` (``fill_holes=True``): for a disk, the number of boundary
            vertices of each hole of the mesh that was filled for the map (the surface spans
            it, held by the fairing); for a plane, the lattice cells of each hole of the
            cloud's domain that its tessellation covers (:func:`cloud_holes`); None when there
            were none.
        flipped: (disk only) True when the faces given were wound the other way than the
            canonical winding (:func:`winding_flipped`): the map, and ``faces``, ``boundary``
            and ``domain_polygon``, are those of the faces reversed (bit for bit for faces
            reversed as ``f[:, ::-1]``, to rounding for Blender's Flip Normals, which keeps
            each face's first corner), so a mesh and its copy with Flip Normals get the same
            map; a surface fitted to it turns its
            tessellation's and control net's triangles back and negates its normals (the
            given winding's way). False for a point cloud and for files written before it.
        outliers: ``(k,) int64`` (disk only, ``drop_outliers=True``): the spike vertices
            (:func:`mesh_spikes`) dissolved out of the mesh before its map (``used`` False,
            ``uv`` NaN, as loose vertices); None when there were none (and in files: the
            report's ``outliers`` counts them).
    """

    uv: np.ndarray
    kind: str
    domain_polygon: np.ndarray
    used: np.ndarray
    boundary: np.ndarray | None = None
    faces: np.ndarray | None = None
    origin: np.ndarray | None = None
    axes: np.ndarray | None = None
    scale: float | None = None
    stretch: np.ndarray | None = None
    holes: np.ndarray | None = None
    flipped: bool = False
    outliers: np.ndarray | None = None

    def contains(self, uv: np.ndarray, tol: float = 1e-12) -> np.ndarray:
        """Mask of parameters inside ``domain_polygon`` (points on its edges count as inside).

        Even-odd (crossing number) test: a horizontal ray from ``x`` crosses edge ``a -> b`` when
        ``(a_v > x_v) != (b_v > x_v)`` and ``x_u < a_u + (x_v - a_v)(b_u - a_u)/(b_v - a_v)``;
        ``x`` is inside when it crosses an odd number of edges, or when its distance to an edge
        is at most ``tol`` (relative to the polygon size).

        Args:
            uv: ``(m, 2)`` parameters (or a single ``(2,)`` point).
            tol: boundary tolerance relative to the polygon's bounding-box size.

        Returns:
            ``(m,) bool`` (or a bool scalar for a single point).
        """
        x = np.asarray(uv, dtype=np.float64)
        single = x.ndim == 1
        x = np.atleast_2d(x)
        if x.shape[-1] != 2:
            raise InvalidInputError(f"uv must be an (M, 2) array; got shape {x.shape}")
        inside = _points_in_polygon(x, self.domain_polygon, tol)
        return bool(inside[0]) if single else inside

    def in_holes(self, uv: np.ndarray) -> np.ndarray:
        """Mask (m,) of the parameters ``uv`` (m, 2) inside one of the holes that were filled
        for the map (``holes``; ``fill_holes=True``): there the surface spans a gap, with no
        data under it. The holes are the loops of the faces' border edges (edges of one face)
        besides the outer ``boundary``, all tested at once by the even-odd rule
        (:func:`_points_in_polygon`); a point on a hole's border may count either way. All
        False when no hole was filled. A point cloud's holes (:func:`cloud_holes`) are cells
        of a lattice (computed at the first call), where no data point is."""
        x = np.atleast_2d(np.asarray(uv, dtype=np.float64))
        if self.holes is not None and self.kind == "plane":
            lattice = _cloud_hole_lattice(self)
            lo, h, mask = lattice.lo, lattice.h, lattice.mask
            cell = np.floor((x - lo) / h)
            cell = np.where(np.isfinite(cell), cell, -1).astype(np.int64)
            ok = ((cell >= 0) & (cell < [mask.shape[1], mask.shape[0]])).all(axis=1)
            found = np.zeros(len(x), dtype=bool)
            found[ok] = mask[cell[ok, 1], cell[ok, 0]]
            return found
        if self.holes is None or self.faces is None or self.boundary is None:
            return np.zeros(len(x), dtype=bool)
        f = np.asarray(self.faces)
        start, end = f.ravel(), np.roll(f, -1, axis=1).ravel()
        n = len(self.uv)
        key = np.minimum(start, end) * n + np.maximum(start, end)
        _, index, count = np.unique(key, return_inverse=True, return_counts=True)
        border = count[index.reshape(-1)] == 1
        outer = np.zeros(n, dtype=bool)
        outer[np.asarray(self.boundary)] = True
        hole = border & ~outer[start]  # (a hole's loop shares no vertex with the outer one)
        return _points_in_polygon(x, self.uv[start[hole]], 0.0, ends=self.uv[end[hole]])

    def project(self, points: np.ndarray) -> np.ndarray:
        """Parameters of new 3D points of a plane parameterization.

        ``uv = ((p - origin) @ axes[:2].T) / scale`` (orthogonal projection on the best-fit
        plane, method.md section 4).

        Raises:
            InvalidInputError: for a mesh (``"disk"``) parameterization, which has parameters
                only at its vertices.
        """
        if self.kind != "plane" or self.origin is None or self.axes is None or not self.scale:
            raise InvalidInputError(
                "project() maps 3D points only for a point-cloud (plane) parameterization; a "
                "mesh parameterization has parameters only at its vertices"
            )
        p = np.asarray(points, dtype=np.float64)
        return ((p - self.origin) @ self.axes[:2].T) / self.scale


def _points_in_polygon(x: np.ndarray, poly: np.ndarray, tol: float,
                       ends: np.ndarray | None = None) -> np.ndarray:
    """Even-odd point-in-polygon test with an on-edge tolerance; see Parameterization.contains.
    The edges run from each vertex of ``poly`` to the next, or to the same row of ``ends``
    when given (several loops at once, in any order: the parity counts all their edges).

    Vectorized over (point, edge) pairs; only the pairs that can matter are formed: with the
    points sorted by ``v``, an edge is straddled exactly by the points with ``v`` in
    ``[min(a_v, b_v), max(a_v, b_v))``, one contiguous run of the sorted points (a
    ``searchsorted`` each), and only points of a run widened by the tolerance can lie within
    it of the edge. So the work is the number of crossings (a few per point on a simple
    polygon), not points times edges, and the result is that of the crossing-number formula
    evaluated on every pair.
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(x), dtype=bool)
    if not len(a) or not len(x):
        return out
    b = (np.roll(a, -1, axis=0) if ends is None
         else np.asarray(ends, dtype=np.float64).reshape(-1, 2))
    e = b - a
    ee = np.einsum("ij,ij->i", e, e)
    ee_safe = np.where(ee > 0.0, ee, 1.0)
    size = float(np.ptp(a, axis=0).max())
    atol = tol * max(size, np.finfo(float).tiny)
    order = np.argsort(x[:, 1], kind="stable")
    ys = x[order, 1]
    lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    # crossings: a horizontal ray from x crosses edge a -> b when (a_v > x_v) != (b_v > x_v),
    # i.e. lo <= x_v < hi, and x_u < a_u + (x_v - a_v)(b_u - a_u)/(b_v - a_v)
    crossings = np.zeros(len(x), dtype=np.int64)
    for edge, pt in _runs(order, np.searchsorted(ys, lo), np.searchsorted(ys, hi)):
        xe = x[pt]
        u_cross = a[edge, 0] + (xe[:, 1] - a[edge, 1]) * e[edge, 0] / e[edge, 1]
        crossings += np.bincount(pt[xe[:, 0] < u_cross], minlength=len(x))
    out = crossings % 2 == 1
    # points outside by parity may still lie on an edge (within atol): segment distance, for
    # the points whose v is within atol of the edge's v-range (the others are farther)
    outside = np.flatnonzero(~out)
    if len(outside):
        order = outside[np.argsort(x[outside, 1], kind="stable")]
        ys = x[order, 1]
        near = np.zeros(len(x), dtype=bool)
        # (widened by 2 atol: lo - atol itself is rounded; the distance test decides)
        for edge, pt in _runs(order, np.searchsorted(ys, lo - 2 * atol),
                              np.searchsorted(ys, hi + 2 * atol, side="right")):
            xe, ae, ed = x[pt], a[edge], e[edge]
            t = np.clip(np.einsum("mk,mk->m", xe - ae, ed) / ee_safe[edge], 0.0, 1.0)
            d2 = np.sum((xe - (ae + t[:, None] * ed)) ** 2, axis=1)
            near[pt[d2 <= atol * atol]] = True
        out |= near
    return out


def _runs(order: np.ndarray, start: np.ndarray, stop: np.ndarray, pairs: int = 4_000_000):
    """Yield ``(edge, point)`` index pairs, edge ``i`` paired with ``order[start[i]:stop[i]]``,
    in batches of about ``pairs`` pairs (memory stays bounded)."""
    count = np.maximum(stop - start, 0)
    ends = np.cumsum(count)
    first = 0
    while first < len(count):
        base = ends[first - 1] if first else 0
        last = max(int(np.searchsorted(ends, base + pairs, side="right")), first + 1)
        c = count[first:last]
        edge = np.repeat(np.arange(first, last), c)
        offset = np.arange(len(edge)) - np.repeat(np.cumsum(c) - c, c)
        yield edge, order[np.repeat(start[first:last], c) + offset]
        first = last


# --------------------------------------------------------------------------------------------
# Point clouds: best-fit plane
# --------------------------------------------------------------------------------------------


def _local_planes(
    q: np.ndarray, k: int, idx: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Local PCA of every point over itself and its ``k`` nearest neighbours (3D).

    ``C_i = (1/(k+1)) sum_j (q_j - mean)(q_j - mean)^T`` with eigenvalues
    ``lambda_0 <= lambda_1 <= lambda_2`` (batched ``np.linalg.eigh`` on the ``(n, 3, 3)``
    stack). The normal ``n_i`` is the eigenvector of ``lambda_0`` and ``sigma_i =
    sqrt(lambda_0)`` the RMS distance of the neighbourhood from its plane. The normal is
    *reliable* when the neighbourhood is a thin disk, ``lambda_0 < 0.25 lambda_1`` (neither a
    line, as on sparse scan lines, nor a noise blob).

    Returns:
        ``normals (n, 3)``, ``sigma (n,)``, ``reliable (n,) bool``, ``idx (n, k+1)`` the
        neighbourhoods (each point's own index among them; ``idx`` when given, e.g. the first
        ``k + 1`` columns of a larger query).
    """
    if idx is None:
        _, idx = cKDTree(q).query(q, k=k + 1, workers=-1)

    def block(bounds):
        s, e = bounds
        nb = np.take(q, idx[s:e], axis=0)  # faster row gather than q[idx[s:e]]
        nb -= nb.mean(axis=1, keepdims=True)
        return np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb) / (k + 1))

    parts = pmap(block, row_blocks(len(q)))  # blocks on parallel threads (core.parallel)
    w = np.maximum(np.concatenate([p[0] for p in parts]), 0.0)
    normals = np.concatenate([p[1][:, :, 0] for p in parts])
    reliable = w[:, 0] < _THIN_NEIGHBOURHOOD * w[:, 1]
    return normals, np.sqrt(w[:, 0]), reliable, idx


def local_scatter(points: np.ndarray, sample: int = 20_000, seed: int = 0) -> tuple[float, float]:
    """The data's scatter about their local planes, and how far to trust it: the median over
    a seeded sample of at most ``sample`` points of ``sigma_i`` of :func:`_local_planes` (the
    RMS distance of each point's neighbourhood, itself and its _FOLD_NEIGHBOURS nearest among
    the sample, from its best-fit plane; not in method.md), and the share of those
    neighbourhoods that are thin disks (``reliable``). Noise sets the scatter on a scan; on
    clean data it is the curvature over a neighbourhood. Noise larger than the sample's
    spacing makes the neighbourhoods blobs picked from a layer of the noise, and the scatter
    too small (a plane of 20 000 points with noise 4 times their spacing: 4.2x too small, 6%
    of the neighbourhoods thin disks; review). (0, 0) for fewer than _FOLD_NEIGHBOURS + 1
    points."""
    p = np.asarray(points, dtype=np.float64)
    if len(p) <= _FOLD_NEIGHBOURS:
        return 0.0, 0.0
    if len(p) > sample:
        p = p[np.sort(np.random.default_rng(seed).choice(len(p), sample, replace=False))]
    centre, scale = p.mean(axis=0), float(np.ptp(p, axis=0).max()) or 1.0
    _, sigma, reliable, _ = _local_planes((p - centre) / scale, _FOLD_NEIGHBOURS)
    return float(np.median(sigma)) * scale, float(reliable.mean())


# local_noise: the two neighbourhood sizes (besides the point itself) and the sample; and the
# growth of the residual variance from the near to the far size above which the curvature
# dominates and no noise is measured (noisy meshes: 1.0-2.5; clean coarse or creased ones whose
# estimate survives the extrapolation: 3.2-24)
_NOISE_NEAR, _NOISE_FAR, _NOISE_SAMPLE, _NOISE_GROWTH = 12, 40, 4000, 3.0


def local_noise(points: np.ndarray, sample: int = _NOISE_SAMPLE, seed: int = 0) -> float:
    """The data's noise: the RMS scatter of the points across a smooth surface through them
    (not in method.md). Unlike :func:`local_scatter` it does not count the surface's curvature
    as noise: clean meshes mostly score 0 (below: where not).

    For a seeded sample of at most ``sample`` points, each neighbourhood of the point and its
    ``k`` nearest (``k`` = 12 and 40) is fitted by a quadric height field ``h = c0 + c1 a + c2 b
    + c3 a^2 + c4 ab + c5 b^2`` over its principal plane (a least-squares fit of 6 parameters),
    and ``s_k^2 = RSS / (k + 1 - 6)`` is the residual variance. Noise of variance ``sigma^2``
    gives ``s_k^2 ~ sigma^2 chi^2_nu / nu``; the terms of third order that a quadric misses add
    ``beta r^6`` with ``r^2 ~ k`` the neighbourhood's squared radius. Of the medians
    ``v_k = median(s_k^2) / m_nu`` (``m_nu = (1 - 2 / (9 nu))^3``, the Wilson-Hilferty median
    of ``chi^2_nu / nu``), ``sigma^2 = v_12 - (v_40 - v_12) / (R - 1)`` with ``R = (41/13)^3``.
    The medians pass over the neighbourhoods across a crease or along a border while they are
    fewer than half. Where ``v_40 > 3 v_12`` the curvature dominates, does not grow like that
    (steps, creases, a mesh so coarse that 41 vertices span much of it), and the result is 0: a
    staircase of 8 steps scored 1.8e-3 of its diagonal, a 16 x 16 grid of a quadric 3.9e-5 (a
    review; /tmp/s30/ratio.py).

    Measured (/tmp/s30/noiseest3.py and ratio_check.py of the thirtieth session): grid meshes
    of 21 x 21 to 317 x 317 vertices with Gaussian noise of 0.0002-0.005 of the diagonal on
    every coordinate, 0.88-0.99x the noise (the least where the noise is 0.4 of the spacing).
    0 on the clean meshes of benchmarks/mesh_maps.py (caps, a half cylinder, coarse grids,
    combs, patch-01, three_peaks), where planes fitted to the same neighbourhoods leave up to
    9e-3 of their diagonal (curvature, and patch-01's crease); 0 on the scanned face of 299
    vertices (3.5e-3 without the rule on the growth: its neighbourhoods of 41 span an eighth of
    it) and on 19 of 21 clean CAD-like, anisotropic, uneven and coarse meshes of a review (five
    scored 1e-4 to 1.4e-2 without the rule); two corrugated sheets, whose folds are two to
    three vertices apart, score as noise (3.4e-3 and 9.4e-3), and so does one folded every 4
    vertices (1.7e-3), and grids of 10 x 10 to 22 x 22 vertices of a wave of 3.5-7 vertices per
    wavelength (0.03-0.07: at that resolution the vertices do not tell the wave from noise).
    Short of the truth: noise larger than the vertex spacing (an 81 x 81 grid with noise of
    1.2 and 2.4 times its spacing: 0.64x and 0.39x; a review), and noise on less than half of
    the points (a median: noise on 30% of a grid scores about 0). A grid of 12 x 12 vertices
    with noise of 0.2% scores 0 (growth 9.8). 0.13 s for 1e5 points. 0 for fewer than 41
    points."""
    p = np.asarray(points, dtype=np.float64)
    k = _NOISE_FAR + 1
    if len(p) < k:
        return 0.0
    pick = np.arange(len(p))
    if len(p) > sample:
        pick = np.sort(np.random.default_rng(seed).choice(len(p), sample, replace=False))
    centre, scale = p.mean(axis=0), float(np.ptp(p, axis=0).max()) or 1.0
    q = (p - centre) / scale
    _, idx = cKDTree(q).query(q[pick], k=k, workers=-1)

    def variance(m: int) -> float:
        nb = np.take(q, idx[:, :m], axis=0)
        nb -= nb.mean(axis=1, keepdims=True)
        w, frame = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
        local = np.einsum("nki,nij->nkj", nb, frame)  # columns: normal, then the plane's axes
        r = np.sqrt(np.maximum(w[:, 2] / m, 1e-300))[:, None]
        a, b = local[:, :, 2] / r, local[:, :, 1] / r  # (scaled: the 6 x 6 systems stay tame)
        A = np.stack([np.ones_like(a), a, b, a * a, a * b, b * b], axis=2)
        h = local[:, :, 0]
        c = np.linalg.solve(np.einsum("nki,nkj->nij", A, A) + 1e-12 * np.eye(6),
                            np.einsum("nki,nk->ni", A, h)[..., None])[..., 0]
        nu = m - 6
        rss = ((h - np.einsum("nki,ni->nk", A, c)) ** 2).sum(axis=1)
        return float(np.median(rss / nu)) / (1.0 - 2.0 / (9.0 * nu)) ** 3

    near, far = variance(_NOISE_NEAR + 1), variance(k)
    if far > _NOISE_GROWTH * near:
        return 0.0
    grow = (k / (_NOISE_NEAR + 1.0)) ** 3
    return float(np.sqrt(max(near - max(far - near, 0.0) / (grow - 1.0), 0.0))) * scale


def _distance_to_hull(uv: np.ndarray, chunk: int = 20_000) -> np.ndarray:
    """Distance (n,) of parameters to the boundary of their convex hull, to within 1e-3 of the
    extent (chunked over points).

    Inside a convex polygon the distance to the boundary is the smallest distance to the lines
    of its edges, ``min_e (x - a_e) . n_e`` with ``n_e`` the inward unit normals. The hull is
    first thinned: runs of vertices within 1e-3 of the extent from the chord that replaces them
    are dropped (an inscribed convex polygon, far closer than the 5% rim width this serves): a
    dense round rim has thousands of hull vertices, and ``points x vertices`` work made refusing
    a folded 1e5-point cap take 14 s (1.2 s now).
    """
    hull = uv[ConvexHull(uv).vertices]  # counter-clockwise
    tol = 1e-3 * float(np.ptp(uv, axis=0).max())
    keep, skipped = [0], []
    for i in range(1, len(hull)):
        # drop vertex i if it and the vertices dropped since the last kept one lie within tol
        # of the chord from the last kept vertex to vertex i + 1
        a, b = hull[keep[-1]], hull[(i + 1) % len(hull)]
        ab = b - a
        run = hull[skipped + [i]]
        dist = np.abs(ab[0] * (run[:, 1] - a[1]) - ab[1] * (run[:, 0] - a[0]))
        if (dist > tol * max(float(np.hypot(*ab)), 1e-300)).any():
            keep.append(i)
            skipped = []
        else:
            skipped.append(i)
    a = hull[keep]
    e = np.roll(a, -1, axis=0) - a
    inward = np.c_[-e[:, 1], e[:, 0]] / np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
    offset = (a * inward).sum(axis=1)
    out = np.empty(len(uv))
    for s in range(0, len(uv), chunk):
        out[s : s + chunk] = np.abs((uv[s : s + chunk] @ inward.T - offset).min(axis=1))
    return out


def _degrees_note(points) -> str:
    """Words for a refused cloud whose x and y look like longitude and latitude in degrees
    and whose heights like metres (a DEM exported from a GIS: the Jacksboro DEM so, with z
    given, was "two or more layers about 28 apart ... align the scans"; user test), else ""."""
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    across = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    if (lo[0] >= -180 and hi[0] <= 180 and lo[1] >= -90 and hi[1] <= 90 and 0 < across < 10
            and hi[2] - lo[2] > 100 * across):
        return (" (if x and y are longitude and latitude in degrees and z a height in metres, "
                "project them to metres first, e.g. to UTM: the surface needs one unit in all "
                "three)")
    return ""


def _fold_sample(q: np.ndarray) -> np.ndarray:
    """Indices of the (seeded) subset of at most 40 000 points used by the fold checks.

    What the sample must resolve is the gap between two overlapping layers against the spacing
    of the sampled points (the overlap test looks at 12 parameter-space neighbours): a sheet
    folded back with a layer gap of 1% of its extent, 80k points, is refused with 40 000 samples
    and was let through with 20 000 (a test keeps it refused)."""
    if len(q) > _FOLD_MAX_SAMPLE:
        return np.sort(np.random.default_rng(0).choice(len(q), _FOLD_MAX_SAMPLE, replace=False))
    return np.arange(len(q))


def _area_weights(q: np.ndarray, idx: np.ndarray, reliable: np.ndarray) -> np.ndarray | None:
    """Each point's share of the surface's area when the density of the points ``q`` is uneven,
    else None: the median over its neighbourhood ``idx`` (``(n, k+1)``, as :func:`_local_planes`
    gives them) of the squared distance to the farthest neighbour (a disc with ``k`` neighbours
    covers ``pi d_k^2``), clipped at the 99th percentile; 0 where the local plane is not
    ``reliable``. A point off the surface has no area of its own: a tile with 10% spikes of
    N(0, 20 m) was uneven by the spikes' own distances and was projected sideways; by the
    median over the reliable points its spikes hold 3% of the weight, and it is even (0.95).

    The density is uneven when the weights make the reliable points count as fewer than
    ``_UNEVEN_SHARE`` (a quarter) of as many evenly spread ones: their effective share ``(sum
    w)^2 / (n sum w^2)`` is below it. Evenly spread clouds measure over 0.5 (random uniform
    samples of Renka's functions, grids, the vertices of three_peaks.off, that spiky tile) and
    keep the counts: their projections are the same as before to the bit. A scanner that dwelt
    (20 000 points N(0.5, 0.02) over Franke's function and 1 500 uniform) measures 0.05. (Not
    :func:`core.refine.area_weights`: it counts cells of the parameter plane, which the
    direction chosen here makes; in 3D, slopes spread the areas of even clouds too: Renka's
    cosine peak measures 0.68, hence the lower share than its 1 / 1.2.)"""
    if not reliable.any():
        return None
    d = q[idx[:, -1]] - q
    a = np.median(np.einsum("ij,ij->i", d, d)[idx], axis=1)
    a = np.where(reliable, np.minimum(a, np.quantile(a[reliable], 0.99)), 0.0)
    total = float(a.sum())
    if not total > 0.0 or total**2 >= _UNEVEN_SHARE * np.count_nonzero(reliable) * float(a @ a):
        return None
    return a


def _weighted_quantile(x: np.ndarray, w: np.ndarray, p: float) -> np.ndarray:
    """The lower weighted ``p``-quantile of ``x`` ``(n,)`` or ``(n, m)`` along its first axis,
    weights ``w`` ``(n,)``: the smallest value at which the weights of the values up to it, in
    ascending order, reach ``p`` of their total (``(m,)``, or a scalar for ``(n,)``)."""
    order = np.argsort(x, axis=0, kind="stable")
    cw = np.cumsum(w[order], axis=0)
    at = np.minimum(np.count_nonzero(cw < p * cw[-1], axis=0), len(x) - 1)
    if x.ndim == 1:
        return x[order[at]]
    return np.take_along_axis(x, np.take_along_axis(order, at[None], axis=0), axis=0)[0]


# a given projection along a coordinate axis keeps the other axes as the parameters' unless
# that makes their bounding box this many times as large as the principal directions' do
AXIS_BOX_SLACK = 1.25


def _projection_normals(q: np.ndarray, pca_normal: np.ndarray, planes,
                        weights: np.ndarray | None = None):
    """Projection directions to try (a generator), best first: the one that makes the cloud
    most like a height field, then the other candidates by score, and the direction of
    :func:`_least_steep_direction` (second if it is clearly less steep than the first, else
    last).

    Candidates: the PCA normal, the mean of the local normals (oriented towards the PCA
    normal) and the three coordinate axes. Score: the 2nd percentile of ``|n_i . n|`` over the
    reliable local normals (how steep the steepest parts are). A height field whose height range
    is comparable to its width tilts the PCA plane (Franke's function: 45 degrees) and makes
    its flanks look nearly perpendicular; the mean normal or the vertical axis does not. The
    PCA normal comes first unless another direction is clearly (0.05) less steep.

    A steep cloud (the first candidate scores under 0.15) is also scored with consistently
    oriented normals (:func:`_oriented_normals`, at most 20 000 of the points): the direction
    all of them face (``_least_steep_direction(signed=True)``) comes before everything else when
    its signed score is at least -0.05 and 0.05 above the first candidate's. Unsigned scores
    cannot tell a fold's two layers from one; the oriented normals of a fold face opposite ways.

    ``weights`` (:func:`_area_weights`, one per point of ``q``): the mean normal is their
    weighted mean and the scores weighted quantiles (:func:`_weighted_quantile`), so that the
    steepest 2% are of the area, not of the points: 20 000 of 21 500 points in a blob over
    Franke's function made the PCA normal, 45 degrees from z, score 0.535 (z 0.518), and 109
    of the 1 500 others overhung it; by area it scores 0.04, z 0.28.
    """
    normals, _, reliable, _ = planes
    keep = reliable if reliable.any() else np.ones(len(normals), dtype=bool)
    nr = normals[keep]
    wr = None if weights is None else weights[keep]

    def low(x, w):  # the score: the 2nd percentile (weighted: of the area)
        return np.quantile(x, 0.02) if w is None else _weighted_quantile(x, w, 0.02)

    oriented = nr * np.where(nr @ pca_normal < 0, -1.0, 1.0)[:, None]
    mean = oriented.mean(axis=0) if wr is None else wr @ oriented / wr.sum()
    cands = [pca_normal]
    if np.linalg.norm(mean) > 1e-12:
        cands.append(mean / np.linalg.norm(mean))
    cands.extend(np.eye(3))
    scores = np.array([low(np.abs(nr @ c), wr) for c in cands])
    best = int(np.argmax(scores))
    first = 0 if scores[best] <= scores[0] + 0.05 else best
    rest = [i for i in np.argsort(-scores, kind="stable") if i != first]
    if scores[first] < _ORIENT_BELOW:
        # a steep cloud: the direction the whole surface faces (oriented normals), first when
        # it clearly beats the first candidate by the signed score (turned Franke x3 with
        # noise: 12.8 degrees off the true axis and 5.8% of its triangles flipped over the
        # first candidate; 6.3 degrees and none over this one)
        sub = np.unique(np.linspace(0, len(q) - 1, min(len(q), _ORIENT_POINTS)).astype(np.int64))
        on = _oriented_normals(q[sub], normals[sub], reliable[sub], pca_normal)
        on_keep = reliable[sub] if reliable[sub].any() else np.ones(len(sub), dtype=bool)
        on = on[on_keep]
        won = None if weights is None else weights[sub][on_keep]
        facing, signed = _least_steep_direction(on, signed=True, weights=won)
        now = max(low(on @ cands[first], won), low(-on @ cands[first], won))
        if signed >= _SIGNED_MIN and signed > now + 0.05:
            yield facing
    yield cands[first]
    # then the least steep direction of all (searched only now: most clouds do not fold over
    # the first), next if clearly (0.05) less steep than the first, else last: a tilted height
    # field whose slopes reach 70 degrees folds over every other candidate
    found, score = _least_steep_direction(nr, weights=wr)
    if score > scores[first] + 0.05:
        yield found
    yield from (cands[i] for i in rest)
    if score <= scores[first] + 0.05:
        yield found


def _least_steep_direction(
    normals: np.ndarray, rounds: int = 4, signed: bool = False,
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """The direction ``n`` that maximizes the 2nd percentile of ``|n_i . n|`` over the local
    normals ``n_i`` (the score of :func:`_projection_normals`), and that score: a search over
    600 directions spread over the hemisphere (a Fibonacci lattice), then ``rounds`` of 48
    directions around the best within shrinking angles (3.5 down to 0.4 degrees). A cloud
    that is a height field over some plane has a positive score there; a sheet that turns
    over has none. Every ``len // 5000``-th of the normals is scored (all below 5000; up to 10 000).

    ``signed``: the 2nd percentile of ``n_i . n`` for consistently oriented normals
    (:func:`_oriented_normals`; every ``len // 2000``-th: all below 2000, up to 4000), over 1200
    directions of the whole sphere. Positive only over
    a plane the whole surface faces: a fold's layers face opposite ways along every direction
    (``|n_i . n|`` cannot tell them from one layer).

    ``weights`` (one per normal, :func:`_area_weights`): the weighted 2nd percentile
    (:func:`_weighted_quantile`) instead."""
    step = max(1, len(normals) // (2000 if signed else 5000))
    sub = normals[::step]
    rank = max(int(0.02 * (len(sub) - 1)), 0)
    wsub = None if weights is None else weights[::step]

    def score(dirs):  # (m,) 2nd percentile (lower order statistic) of |sub . d| (or sub . d)
        dots = sub @ dirs.T
        if wsub is not None:
            return _weighted_quantile(dots if signed else np.abs(dots), wsub, 0.02)
        return np.partition(dots if signed else np.abs(dots), rank, axis=0)[rank]

    count = 1200 if signed else 600
    i = np.arange(count) + 0.5
    # the whole sphere, or the upper hemisphere (|n_i . n| does not see the sign of n)
    z = 1.0 - (2.0 if signed else 1.0) * i / count
    r, t = np.sqrt(1.0 - z * z), np.pi * (3.0 - np.sqrt(5.0)) * i
    dirs = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    s = score(dirs)
    best, top = dirs[int(np.argmax(s))], float(s.max())
    ring = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    for step in np.radians(3.5) * 0.5 ** np.arange(rounds):
        a = np.cross(best, [1.0, 0.0, 0.0] if abs(best[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(best, a)
        offs = (step * np.array([1.0, 2.0 / 3.0, 1.0 / 3.0])[:, None, None]
                * (np.cos(ring)[:, None] * a + np.sin(ring)[:, None] * b)).reshape(-1, 3)
        trial = best + offs
        trial /= np.linalg.norm(trial, axis=1, keepdims=True)
        st = score(trial)
        if st.max() > top:
            best, top = trial[int(np.argmax(st))], float(st.max())
    return best, top


def _oriented_normals(
    q: np.ndarray, normals: np.ndarray, reliable: np.ndarray, towards: np.ndarray, k: int = 12
) -> np.ndarray:
    """The local ``normals`` at the points ``q`` (:func:`_local_planes`) with consistent signs:
    neighbours agree unless the surface turns between them (Hoppe et al. 1992, "Surface
    reconstruction from unorganized points", section 3.3).

    A minimum spanning tree of the k-nearest-neighbour graph with edge costs ``1 - |n_i . n_j|``
    (plus 1 where either plane is unreliable, so that signs travel through flat discs) carries
    the sign from a root to every point: ``n_i`` flips when ``n_i . n_parent < 0``. The parity
    of the flips on each point's path to its root is found by pointer jumping (``log2 n``
    vectorized rounds). A virtual root joins the trees of separate pieces; each piece is then
    oriented so that its normals sum to a positive component along ``towards``.

    Not a proof against folds: two layers closer than the neighbour reach have nearly
    parallel planes, so the tree can cross between them at no cost and give both the same
    sign. The directions these normals suggest are only tried first; each one is still checked
    for folds (:func:`_fold_fraction`) before it is used.
    """
    n = len(q)
    if n < 2:  # nothing to agree with
        return normals * np.where(normals @ towards < 0, -1.0, 1.0)[:, None]
    k = min(k, n - 1)
    _, idx = cKDTree(q).query(q, k=k + 1, workers=-1)
    rows, cols = np.repeat(np.arange(n), k), idx[:, 1:].ravel()
    cost = (1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols])) + 1e-9
            + (~reliable[rows] | ~reliable[cols]))
    graph = sp.coo_matrix((cost, (rows, cols)), shape=(n, n)).tocsr()
    tree = minimum_spanning_tree(graph.maximum(graph.T)).tocoo()
    pieces, label = connected_components(tree, directed=False)
    first = np.unique(label, return_index=True)[1]  # one point of each piece, under the root
    tree = sp.coo_matrix(
        (np.r_[tree.data, np.ones(pieces)], (np.r_[tree.row, np.full(pieces, n)], np.r_[tree.col, first])),
        shape=(n + 1, n + 1),
    )
    _, parent = breadth_first_order(tree.tocsr(), n, directed=False, return_predecessors=True)
    parent[n] = n
    padded = np.vstack([normals, np.zeros(3)])  # the virtual root's "normal" flips nothing
    parity = np.einsum("ij,ij->i", padded, padded[parent]) < 0
    for _ in range(int(np.ceil(np.log2(n + 1))) + 1):  # pointer jumping
        parity, parent = parity ^ parity[parent], parent[parent]
    oriented = normals * np.where(parity[:n], -1.0, 1.0)[:, None]
    facing = np.bincount(label, weights=oriented @ towards, minlength=pieces)
    return oriented * np.where(facing[label] < 0, -1.0, 1.0)[:, None]


def _on_a_line(uv: np.ndarray) -> bool:
    """The projected points (normalized coordinates) lie on one line: the RMS distance from
    their best line is at most ``_COLLINEAR_RTOL`` of their extent (a wall projected along a
    direction in its plane; qhull cannot take them)."""
    d = uv - uv.mean(axis=0)
    ev = np.linalg.eigvalsh(d.T @ d / len(d))
    return bool(np.sqrt(max(ev[0], 0.0)) <= _COLLINEAR_RTOL * max(float(np.ptp(uv, axis=0).max()), 1e-300))


def _project(q: np.ndarray, m: np.ndarray, vt: np.ndarray, n: np.ndarray,
             aligned: bool = False):
    """Axes ``(a_u, a_v, n)`` (3, 3), centre ``c`` and scale ``s`` of the projection of the
    centred cloud along ``n``, and the parameters ``uv = ((q - m) . [a_u, a_v] - c) / s``.

    ``a_u`` is the largest principal direction projected into the plane; with ``aligned``
    and ``n`` along a coordinate axis, the next coordinate axis (x for z, y for x, z for y)
    unless that makes the parameters' bounding box over AXIS_BOX_SLACK times as large (a
    strip along a diagonal). The principal directions of a square tile are arbitrary: tiles
    fitted over z had their tessellation grids turned 0-90 degrees against the tile and each
    other, and the same resolution gave 1.8x as many vertices on some (user test)."""
    # u along the largest principal direction projected into the plane
    a_u = vt[0] - (vt[0] @ n) * n
    if np.linalg.norm(a_u) < 1e-8:
        a_u = vt[1] - (vt[1] @ n) * n
    a_u /= np.linalg.norm(a_u)
    # deterministic signs: largest |component| positive for a_u and for the normal
    a_u *= np.sign(a_u[np.argmax(np.abs(a_u))])
    if n[np.argmax(np.abs(n))] < 0.0:
        n = -n
    frames = [a_u]
    axis = int(np.argmax(np.abs(n)))
    if aligned and abs(n[axis]) == 1.0:
        frames.insert(0, np.eye(3)[(axis + 1) % 3])
    best = None
    for u in frames:
        axes = np.stack([u, np.cross(n, u), n])
        proj = (q - m) @ axes[:2].T
        lo, hi = column_bounds(proj)
        area = float(np.prod(hi - lo))
        if best is None or area * AXIS_BOX_SLACK < best[0]:
            best = (area, axes, proj, lo, hi)
    _, axes, proj, lo, hi = best
    c = 0.5 * (lo + hi)
    s = 0.5 * float((hi - lo).max())
    return axes, c, s, (proj - c) / s


def _reliable_scale(q: np.ndarray, sample: np.ndarray, planes, k: int):
    """The sample of ``q`` and its local planes (:func:`_local_planes`, ``k`` neighbours) at the
    scale where the most local planes are reliable, and that share.

    Noise of the order of the point spacing makes the neighbourhoods of ``k`` points noise
    blobs: their normals are random, the fold tests see no suspects and let a folded
    projection through (a turned Franke cloud of 30 000 points with noise as large as its
    spacing was accepted with 8% of its triangles flipped). A neighbourhood of ``k`` points of
    a quarter of the sample is twice as wide, so noise weighs half as much against it; curvature
    weighs more. While fewer than half the planes are reliable, coarser samples (seeded, each a
    quarter of the last, down to 250 points) are tried, and one is kept when its share of
    reliable planes is 0.1 higher than the best so far (for a steep, curved cloud without noise,
    such as Renka's F7, the share falls as the sample thins, and the full sample stays)."""
    rng = np.random.default_rng(1)
    share = float(planes[2].mean())
    coarse = sample
    while share < _MIN_RELIABLE and len(coarse) >= 4 * _COARSE_MIN:
        coarse = np.sort(rng.choice(coarse, len(coarse) // 4, replace=False))
        trial = _local_planes(q[coarse], k)
        if trial[2].mean() > share + 0.1:
            sample, planes, share = coarse, trial, float(trial[2].mean())
    return sample, planes, share


def projection_direction(projection) -> np.ndarray | None:
    """The unit projection direction named by ``projection``: None (automatic), ``"x"``,
    ``"y"``, ``"z"`` (any case) or three numbers, not all zero (the data's own coordinates).

    Raises:
        InvalidInputError: anything else.
    """
    if projection is None:
        return None
    if isinstance(projection, str):
        axis = {"x": 0, "y": 1, "z": 2}.get(projection.strip().lower())
        if axis is None:
            raise InvalidInputError(
                f"projection must be \"x\", \"y\", \"z\" or three numbers, got {projection!r}"
            )
        return np.eye(3)[axis]
    try:
        d = np.asarray(projection, dtype=np.float64)
    except (TypeError, ValueError):
        d = np.zeros(0)
    if d.shape != (3,) or not np.isfinite(d).all() or not np.linalg.norm(d) > 0:
        raise InvalidInputError(
            "projection must be \"x\", \"y\", \"z\" or three finite numbers, not all zero "
            f"(a direction), got {projection!r}"
        )
    return d / np.linalg.norm(d)


def _fold_fraction(
    q: np.ndarray, uv: np.ndarray, normal: np.ndarray, planes=None, sample=None,
    details: dict | None = None, steep_test: bool = True, weights: np.ndarray | None = None,
) -> float:
    """Fraction of points where the cloud is not a height field over its best-fit plane
    (``steep_test`` False, for a direction given: the overlap test's, and at the rim the
    points whose consistently oriented normals face away from ``normal``, where the surface
    turns past it; the steep share is still in ``details``).

    Two tests (method.md section 4, "detect folds"), with the local planes of
    :func:`_local_planes` (``k = 12`` neighbours):

    * steep: ``|n_i . n| < 0.2`` with ``n`` the normal of the best-fit plane (the surface is
      nearly perpendicular to the plane; a fold turns through there). Counted only when at
      least 60% of the steep points lie at the rim of the projection (within 5% of the extent
      from the convex hull): a cap of 90 degrees or more turns over at its rim, while a steep
      height field (Renka's F7) has steep stripes everywhere and projects without folding;
    * overlap: among the 12 nearest neighbours ``j`` of ``uv_i`` *in the parameter plane*, at
      least 3 on another layer: their 3D offset ``d = q_j - q_i`` is longer than an offset in
      the local plane of ``i`` can be for its offset ``d_p`` across the projection plane,
      ``|d| |n_i . n| > 2 |d_p|`` (an offset in the local plane shortens in projection by at
      most ``|n_i . n|``), and it leaves the local plane beyond the noise, ``|d . n_i| > 4
      sigma_i``; tested where ``|n_i . n| >= 0.2`` (steeper points are the first test's). The
      projection put points of another layer next to ``i``: their order flipped. (The earlier
      test, ``d`` at more than 60 degrees to the local plane, missed layers under a sheet
      tilted to the projection: a spiral sheet and rotated steep height fields passed with
      7-49% of their triangles flipped.)

    Only points with a reliable local normal are suspects, and a point counts as flagged only
    when at least half of its 3D neighbourhood are suspects (folds are regions; noise makes
    isolated suspects), so noise and line-like neighbourhoods do not cause false alarms.
    Clouds of more than 40 000 points are checked on a seeded (deterministic) random subset of
    that size; ``planes`` are the local planes of that subset when already computed.

    ``details``, when given, receives ``steep`` and ``overlap`` (the shares of the points
    flagged by each test), ``strays`` (indices into the sample of the uv-neighbours on
    another layer of the overlap-flagged points), ``edge_on`` (the share of the reliable
    points that are steep) and ``layer_gap``: the median over the overlap-flagged points of the
    median ``|d . n_i|`` of their off-layer neighbours (how far apart the layers are, in the
    units of ``q``; 0 without overlaps), for the error's words.

    ``weights`` (:func:`_area_weights`, one per point of the sample): the fraction is the
    flagged points' share of the weights (of the area) instead; the shares in ``details`` stay
    shares of the points.
    """
    sample = _fold_sample(q) if sample is None else sample
    q, uv = q[sample], uv[sample]
    normals, sigma, reliable, idx = planes if planes is not None else _local_planes(
        q, min(_FOLD_NEIGHBOURS, len(q) - 1)
    )
    k = idx.shape[1] - 1
    steep = np.abs(normals @ normal) < _FOLD_MIN_COS
    _, jdx = cKDTree(uv).query(uv, k=k + 1, workers=-1)
    d = np.take(q, jdx, axis=0) - q[:, None, :]  # (n, k+1, 3); np.take: faster than q[jdx]
    dn = np.abs(np.einsum("nkj,nj->nk", d, normals))
    # an offset d in the local plane of i shortens in projection by at most |n_i . n|:
    # |d_proj| >= |n_i . n| |d|. A uv-neighbour much farther in 3D than that allows is on
    # another layer (docstring)
    d2 = np.einsum("nkj,nkj->nk", d, d)
    dproj = np.sqrt(np.maximum(d2 - (d @ normal) ** 2, 0.0))
    cos = np.abs(normals @ normal)
    off = ((np.sqrt(d2) * cos[:, None] > _FOLD_OFF_LAYER * dproj)
           & (dn > _FOLD_NOISE_FACTOR * sigma[:, None]) & (cos >= _FOLD_MIN_COS)[:, None])
    overlap = np.count_nonzero(off, axis=1) >= _FOLD_MIN_OFF_NEIGHBOURS * k
    # folds are regions, noise flags isolated points: keep a flag only where it is coherent
    def coherent(mask):
        return np.count_nonzero(mask[idx], axis=1) >= _FOLD_COHERENCE * (k + 1)

    flagged = coherent(reliable & overlap)
    steep_flag = coherent(reliable & steep)
    layered = flagged.copy()
    edge_on = np.count_nonzero(steep_flag) / max(np.count_nonzero(reliable), 1)
    if details is not None:
        details["edge_on"] = edge_on
    near_rim = None
    if steep_flag.any():
        # a sheet that turns over does so at the rim of its projection; steep stripes inside
        # the domain are a steep height field (Renka's F7), which projects without folding
        near_rim = _distance_to_hull(uv) < _FOLD_RIM * float(np.ptp(uv, axis=0).max())
        if np.count_nonzero(steep_flag & near_rim) >= _FOLD_RIM_SHARE * np.count_nonzero(steep_flag):
            if steep_test:  # (else only reported in details: the words of the error)
                flagged |= steep_flag
        else:
            steep_flag[:] = False
    if not steep_test:
        # a direction given: the surface folds where it turns past it, its consistently
        # oriented normals facing away (a sphere cap to 95-100 degrees from the pole, over
        # z, had been accepted with no word, 0.097 of its diagonal off; review), while a
        # steep height field turns steep but never past. Counted at the rim, where a fold
        # turns (noise flips normals inside a steep field: Renka's F7 turned with noise,
        # 3.0% flagged), and nearly along the direction (the orientation fails across a
        # ridge narrower than the points' spacing, and whole flat parts then face away: a
        # 1.5 m ridge in a 200 m tile of 2e4 points, 13% of the points)
        facing = _oriented_normals(q, normals, reliable, normal) @ normal
        back = coherent(reliable & (facing < -_FOLD_BACK) & (facing > -_FOLD_MIN_COS))
        if back.any():
            if near_rim is None:
                near_rim = _distance_to_hull(uv) < _FOLD_RIM * float(np.ptp(uv, axis=0).max())
            flagged |= back & near_rim
        parallel = coherent(reliable & (cos < _FOLD_PARALLEL))
        if np.count_nonzero(parallel) >= _EDGE_ON * np.count_nonzero(reliable):
            flagged |= parallel  # (seen edge-on: _FOLD_PARALLEL)
    if details is not None:
        gap = 0.0
        own = layered & overlap  # (a coherent flag may have no off-layer neighbour itself)
        # the other layer: the off-layer neighbours of the flagged points that are not
        # flagged themselves (a power line's points); when both layers are flagged (a bridge
        # deck over the ground) there is no stray layer: all of the deck and the ground under
        # it had been left out, a hole 60 m long (review)
        strays = np.unique(jdx[own][off[own]])
        details["strays"] = strays[~flagged[strays]]  # (into q)
        if own.any():
            gap = float(np.median(np.nanmedian(np.where(off[own], dn[own], np.nan), axis=1)))
        details.update(steep=np.count_nonzero(steep_flag) / len(q),
                       overlap=np.count_nonzero(layered) / len(q), layer_gap=gap)
    if weights is not None:
        return float(weights[flagged].sum() / weights.sum())
    return float(np.count_nonzero(flagged)) / len(q)


def _stray_points(q: np.ndarray, sample: np.ndarray, strays) -> tuple[np.ndarray, int]:
    """The points of ``q`` off the surface (sorted indices) that ``drop_outliers`` leaves out
    when the fold check fails: those nearer to a stray of the fold sample (``strays``,
    indices into ``q[sample]``: the other layer over the overlap-flagged points, see
    :func:`_fold_fraction`) than to any other sample point, when they are at most
    _STRAY_MAX_SHARE of the points; else none (a second layer of that size is a layer, not
    strays). Not in method.md. A power line 20 m over a 200 m terrain tile (400 points on
    the wire, 20 000 on the ground) made the fold check refuse the tile, with or without
    drop_outliers (review): the wire's points are not isolated (0.5 m apart) and not spikes
    (their neighbours are wire points). Returns them and how many there were (also when
    they were too many to leave out)."""
    strays = np.asarray(strays, dtype=np.int64)
    if len(strays) == 0:
        return np.zeros(0, dtype=np.int64), 0
    is_stray = np.zeros(len(sample), dtype=bool)
    is_stray[strays] = True
    near = cKDTree(q[sample]).query(q, workers=-1)[1]
    off = np.flatnonzero(is_stray[near])
    if len(off) > _STRAY_MAX_SHARE * len(q):
        return np.zeros(0, dtype=np.int64), len(off)
    return off, len(off)


def _layers_note(details: dict, scale: float) -> str | None:
    """The words for a cloud that lies in layers (``details`` of :func:`_fold_fraction`; the
    layer distance times ``scale``, in the user's units), or None when its flags are not
    mostly overlaps: two scans of one surface that are not aligned (a 0.5 offset between
    two copies of a 4 x 4 terrain had been "the surface is nearly perpendicular to that plane
    or overlaps itself in projection ... split the scan into patches": user test L2)."""
    if not details or details.get("overlap", 0.0) < 4.0 * details.get("steep", 0.0):
        return None
    if not details["overlap"] >= 0.1:  # (a few percent: spikes above and below, not a layer)
        return None
    return (f"the points lie in two or more layers about {details['layer_gap'] * scale:.3g} "
            "apart across the surface (scans that are not aligned to each other, both sides "
            "of a thin object, a sheet folded flat, or objects over the ground such as "
            "buildings or trees): align the scans, fit each layer (a scan, a side) on its own, "
            "or keep the ground points only (a classified scan's ground class)")


def isolated_points(
    q: np.ndarray, sample: np.ndarray | None = None, knn: tuple | None = None
) -> np.ndarray:
    """Indices (sorted) of the points of a cloud that lie far from all others: gross outliers
    of a scan (stray returns, a spike) and small groups of them, which would stretch the
    parameter domain and pull the surface away from the data.

    ``d_i`` is the distance from a reference point to its 8th nearest neighbour among the
    distinct reference points (the local spacing; duplicates count once). A point is a
    *candidate* when

        ``d_i > 10 median(d)``  and  ``d_i > 3 q25_{j in N(i)}(d_j)``

    (``N(i)`` its 8 neighbours, ``q25`` their lower quartile): far above the cloud's spacing
    and above the spacing of its own surroundings, so the inside of a sparsely scanned region
    is not one (its neighbours are as far apart). A candidate is *isolated* when its nearest
    non-candidate ``j`` is farther than ``20 d_j``: far from the cloud at the cloud's spacing
    there; a candidate that continues the plane of its nearest points (beside a hard-edged
    dense cluster, whose points are its neighbours) must also be that far from the nearest
    non-candidate with ``d_j`` above the gap (of a sparse region). A region scanned more sparsely than the rest therefore stays, also at its border
    with a denser one (its nearest non-candidate is a neighbour inside it, or a point of the
    denser part less than 20 of its spacings away: a scan line sampled 20x more sparsely than
    its neighbours 12 dense spacings away, a DEM at 20x the spacing of a lidar inset); so does
    a second piece of surface of more than about 6 points (the lower quartile of a group's
    neighbours is then one of the group). Measured: no point flagged on 190 sample clouds and
    on clouds whose density drops 8-400x, all strays found in clouds with a spike, a stray
    pair and a group of 5 strays.

    The reference is the seeded fold sample of at most 40 000 points (:func:`_fold_sample`;
    all points of smaller clouds). Any other point is isolated when its nearest non-candidate
    reference point ``j`` is farther than ``max(10 median(d), 20 d_j)`` (and so is the nearest
    one of a sparse region; a nearest-neighbour query against the reference for the points
    that share no grid cell of side ``5 median(d)`` with a non-candidate, which are within
    the gap of it); so in a larger
    cloud a separate piece with at most about 6 points in the sample (``6 n / 40 000`` points)
    counts as strays.

    Args:
        q: ``(n, 3)`` points (finite).
        sample: indices of the reference (default: :func:`_fold_sample`).
        knn: ``(dist, idx)`` of a query of the reference against itself with at least 9
            columns, each point first (reused when given and the reference has no duplicates).

    Returns:
        ``(m,) int64`` indices into ``q``.
    """
    k = _OUTLIER_NEIGHBOURS
    none = np.zeros(0, dtype=np.int64)
    sample = _fold_sample(q) if sample is None else np.asarray(sample, dtype=np.int64)
    ref = q[sample]
    if knn is None or (knn[0][:, 1] == 0).any():  # duplicates: the distinct points
        ref, inv = np.unique(ref, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        if len(ref) <= k + 1:
            return none
        dist, idx = cKDTree(ref).query(ref, k=k + 1, workers=-1)
    else:
        inv = np.arange(len(ref))
        dist, idx = knn[0][:, : k + 1], knn[1][:, : k + 1]
    d = dist[:, k]
    gap = _OUTLIER_FACTOR * float(np.median(d))
    if not gap > 0:
        return none
    # the rows' lower quartiles, as np.quantile's (linear: between the 2nd and 3rd of 8 sorted,
    # b - (b - a) / 4, its formula for weights past a half) from one sort of the short rows:
    # 0.002 s instead of 0.02-0.03 at 40 000 rows
    ranked = np.sort(np.take(d, idx[:, 1:]), axis=1)
    h = 0.25 * (ranked.shape[1] - 1)
    a, b, w = ranked[:, int(h)], ranked[:, min(int(h) + 1, ranked.shape[1] - 1)], h - int(h)
    around = b - (b - a) * (1 - w) if w >= 0.5 else a + (b - a) * w
    cand = (d > gap) & (d > _OUTLIER_LOCAL * around)
    if cand.all():
        return none
    if not cand.any() and len(sample) == len(q):
        return none
    solid = np.flatnonzero(~cand)
    trees: dict = {}  # made when first needed

    def tree():
        if "solid" not in trees:
            trees["solid"] = cKDTree(ref[solid])
        return trees["solid"]
    # the non-candidates of a sparse region (spacing above the gap): a sparse point next to a
    # hard-edged dense cluster has its nearest non-candidate in the cluster (tiny d_j) but
    # sparse neighbours within their spacing (user test: 5 of 1000 tile points next to a 1 m
    # square of 20 000 points were refused as outliers)
    coarse = solid[d[solid] > gap]
    coarse_tree = cKDTree(ref[coarse]) if len(coarse) else None

    def in_plane(x: np.ndarray, near: np.ndarray) -> np.ndarray:
        """``x`` lies along the cloud's best-fit plane from the points ``near`` (its offset
        within 27 degrees of the plane), or along the plane of ``near`` and the 8 points of
        the sparse region nearest to ``x`` (a batched PCA of those 9), as a sparse point
        beside a dense cluster does; a spike above the cluster does not (review: a spike above
        a lidar inset within a coarse DEM escaped a rule without this). Not the plane of the
        dense cluster's points: its 8 nearest span less than its noise. The sparse region's
        too: where the surface is steep across the cloud's plane (Franke beside a dense disk
        of 20 000 of its points, whose plane is 45 degrees off the vertical there), a point
        0.03 beside the disk was 36 degrees off the cloud's plane and refused (user test)."""
        normals = [principal_axes(ref - ref.mean(axis=0))[1][2][None, :]]
        k = min(_OUTLIER_NEIGHBOURS, len(coarse))
        if k >= 3:
            j = coarse_tree.query(x, k=k, workers=-1)[1].reshape(len(x), k)
            local = np.concatenate([ref[coarse[j]], near[:, None, :]], axis=1)
            local = local - local.mean(axis=1, keepdims=True)
            normals.append(np.linalg.eigh(np.einsum("nki,nkj->nij", local, local))[1][:, :, 0])
        off = x - near
        along = np.einsum("ni,ni->n", off, off)
        ok = np.zeros(len(x), dtype=bool)
        for normal in normals:  # (two planes)
            up = np.abs(np.einsum("ni,ni->n", off, np.broadcast_to(normal, off.shape)))
            ok |= up <= 0.5 * np.sqrt(np.maximum(along - up * up, 0.0))
        return ok

    def far_from_all(x: np.ndarray) -> np.ndarray:
        """Farther than 20 d_j from the nearest non-candidate j; for a point that continues
        the surface of its neighbours, also from the nearest one of a sparse region."""
        r, j = tree().query(x, k=1, workers=-1)
        far = r > _OUTLIER_ISOLATION * d[solid[j]]
        if coarse_tree is not None and far.any():
            look = np.flatnonzero(far)
            look = look[in_plane(x[look], ref[solid[j[look]]])]
            if len(look):
                r, j = coarse_tree.query(x[look], k=1, workers=-1)
                far[look] = r > _OUTLIER_ISOLATION * d[coarse[j]]
        return far

    isolated = np.zeros(len(ref), dtype=bool)
    if cand.any():
        isolated[cand] = far_from_all(ref[cand])
    out = [sample[isolated[inv]]]
    if len(sample) < len(q):
        rest = np.ones(len(q), dtype=bool)
        rest[sample] = False
        rest = np.flatnonzero(rest)
        # the points sharing a grid cell of side gap / 2 with a non-candidate are within the
        # gap of it (the cell's diagonal is 0.87 gap): only the others are queried, with the
        # same result (the query of all of them took 0.04 s of this function's 0.06 at 1e5
        # points)
        lonely = rest[_without_cellmate(q[rest], ref[solid], 0.5 * gap)]
        far = lonely
        if len(lonely):
            near, _ = tree().query(q[lonely], k=1, distance_upper_bound=gap, workers=-1)
            far = lonely[np.isinf(near)]
        if len(far):
            out.append(far[far_from_all(q[far])])
    return np.sort(np.concatenate(out)).astype(np.int64)


def _without_cellmate(x: np.ndarray, ref: np.ndarray, cell: float) -> np.ndarray:
    """Indices of the points ``x`` in whose cell of a grid of side ``cell`` (anchored at the
    lowest corner of ``x`` and ``ref``) no point of ``ref`` lies; all of them when the grid
    would have more than 2^60 cells (a cell far below the extent)."""
    if not len(ref) or not cell > 0:
        return np.arange(len(x))
    lo = np.minimum(x.min(axis=0), ref.min(axis=0))
    dims = np.floor((np.maximum(x.max(axis=0), ref.max(axis=0)) - lo) / cell) + 1
    if not np.prod(dims) < 2.0**60:
        return np.arange(len(x))
    dims = dims.astype(np.int64)

    def keys(p):
        g = np.minimum(np.floor((p - lo) / cell).astype(np.int64), dims - 1)
        return (g[:, 0] * dims[1] + g[:, 1]) * dims[2] + g[:, 2]

    occupied = np.unique(keys(ref))
    k = keys(x)
    at = np.minimum(np.searchsorted(occupied, k), len(occupied) - 1)
    return np.flatnonzero(occupied[at] != k)


_DROP_ADVICE = ("fit_surface(..., drop_outliers=True), on the command line --drop-outliers, in "
                "Blender the Drop Outliers option")
# what drop_outliers does to a mesh's spike vertices, in the advice of each caller's words
SPIKES_DISSOLVED = ("dissolves them (each vertex and its faces removed, the hole filled by "
                    "triangles of its neighbours)")
_SPIKE_ADVICE = (f"fit_surface(..., drop_outliers=True) {SPIKES_DISSOLVED}, on the command "
                 "line --drop-outliers, in Blender the Drop Outliers option")


# spikes (spike_points): neighbours of the local quadratic and how many of them it leaves
# out, how far off it a point must be (in the neighbours' noise, and in their distance), and
# the largest share of points that can be spikes (more: a rough surface, not a spiky scan)
DROP_SPIKES = True  # drop_outliers=True also leaves out spike_points
_SPIKE_NEIGHBOURS = 16
_SPIKE_TRIM = 3
_SPIKE_SIGMA = 8.0
_SPIKE_SLOPE = 1.0
_SPIKE_MAX_SHARE = 0.05
_SPIKE_REUSE = 64  # a pass whose pool lost at most this many points reuses the last KD-tree
_SPIKE_FLOOR_SAMPLE = 2000  # spike_points(only=...): points sampled for the noise level
# a point at the edge of the cloud (its neighbours to one side: their mean offset above
# _SPIKE_ONE_SIDED times their median distance) that their quadratic misses by less than its
# slope rises over that distance is no spike: a surface turning vertical towards its edge (a
# half cylinder seen across its axis) is extrapolated badly there (a noise-free one: 3
# "spikes" warned of, 14 points dropped with drop_outliers: user test; its 41 points so
# missed by 0.11-0.33 of that rise, the spikes of +5 found on sin 3x, slope up to 3, by
# 3.5-9.1 of it, /tmp/s42/spk2.py). Of a uniform cloud's points the ratio is 0.24 inside (median; 0.60 at
# the 99th percentile) and 0.59 at the edge (0.35 at the 5th; /tmp/s42/spk.py).
_SPIKE_ONE_SIDED = 0.35
_STACK_NEIGHBOURS = 8  # stacks: the neighbours looked at for one steeply above or below
_STACK_MAX_SHARE = 0.1  # ... and the largest share of points with one (more: steep surface)
_STACK_LINK = 2.0  # a group: members at most this many data spacings apart, linked ...
_STACK_SPAN = 12.0  # ... spanning at most this many (a pole, a crown; not a ridge's band)
_STACK_UNDER = 0.75  # ... with ground this near under them, in the median (not a roof, a pit)


def spike_points(q: np.ndarray, direction: np.ndarray | None = None,
                 chunk: int = 100_000, stats: dict | None = None, only=None,
                 slope: float = _SPIKE_SLOPE) -> np.ndarray:
    """Indices (sorted) of the points of a cloud that stick out of the surface of their
    neighbours like spikes or pits: stray returns inside the cloud, which
    :func:`isolated_points` does not see (a point 5 m above a terrain scanned every metre
    has ground points 5 m away). Not in method.md.

    For each point ``i``: its ``k = 16`` nearest other points across ``direction`` (the
    projection's, or the normal of the cloud's best-fit plane; :func:`parameterize_points`
    passes the projection it found: a pit 50 m deep among other deep pits has ground points
    as its neighbours there, not the other pits), their heights along it fitted by a
    quadratic over the across coordinates (least squares, then again without the 3 that fit
    worst, so that a spike among them does not bend it); ``d_i`` the point's height above or
    below that quadratic, ``r_j`` the residuals of all ``k`` neighbours from it, ``s_i`` the
    median distance of those kept from the point. A spike has

        ``d_i > s_i``  (steeper than 45 degrees from its neighbours' surface),
        ``d_i > 8 max(sigma_i, sigma_0)``, ``sigma_i = 1.4826 median(r_j) sqrt(13 / 7)``
        (their noise: the MAD, robust to the 3 left out, corrected for the 6 parameters;
        ``sigma_0`` the median ``sigma_i`` of the cloud, so that a few neighbours that
        happen to fit well do not make a point of a noisy cloud a spike),

    and it lies above (below) all of the neighbours kept by more than ``d_i / 2``, which fit
    their quadratic within ``d_i / 2``; unless the point is at the cloud's edge (the mean of
    its neighbours' across offsets more than 0.35 times their median distance ``s_i``) and
    ``d_i`` is less than their quadratic's slope times ``s_i`` (a surface turning vertical
    towards its edge, whose extrapolated quadratic misses the edge's points: a noise-free
    half cylinder projected across its axis had 3 such points warned of, 14 dropped; user
    test). (The mean offset is over 0.35 ``s_i`` at most edge points, and at some inside
    ones, where a spike is far beyond the slope's rise.) A point at a step, with neighbours
    on both levels, is between them (a steep surface can fit such neighbours and miss the
    point: 2 of 3e4 points of a noisy 20 m step were flagged without this). Spikes among
    each other's neighbours: the test is made again (up to 4 passes) without the spikes
    found, at the points whose neighbours held one and at those that passed the slope test
    only. If more
    than 5% of the points are spikes, the surface is rough rather than spiky and none is
    returned (``stats``, when given, receives ``too_many``: the count at which the search
    stopped, or 0; a cloud of fewer than 15 points has none).

    Stacks: the points of a compact group over the surface (a pole, a tree's crown) are each
    other's nearest points, and the test above takes their group for the surface (poles and
    clusters of 6 or more points stayed). The points with one of their 8 nearest steeply
    above or below them (steeper than 45 degrees, by more than 8 noise levels) are tested
    again against the nearest points that have none. They count when their group of steep
    points (linked within 2 data spacings) spans at most 12 spacings (not the band of a
    ridge or a wall) and stands over the ground: the nearest of their own 8 nearest points
    that lies on that surface is within 0.75 spacings, in the group's median (the ground
    goes on under a pole or a crown; beside a roof or in a pit it begins at the wall: the
    review found 4 of a 4 x 4 m roof's 16 points, and of a pit's, dropped without this).
    Only when at most 10% of the points are steep.

    Measured: none on the 26 clouds of benchmarks/compare.py (two seeds) but one point at
    the sharp apex of F10's grid, none on clouds with Gaussian or Laplace noise, a step, a
    crease, a cone, a steep tanh, a narrow ridge, terraces, a lidar fall-off, roofs of 3-8 m
    or a pit (the same as without the stacks on 129 clouds and the review's 13); 281 of
    the 293 of the user test's spikes more than 0.5 m off (all those above 2.2 m); poles of
    1-20 points and crowns of up to 40 (all but the lowest point, 3 m up, of some poles;
    /tmp/s18/pole.py and spikefp.py of the eighteenth session). O(n k) in chunks of 1e5;
    0.5-0.7 s for 3e4 points, 1.9-2.5 s for 1e5 (1.1-1.3x the time without the stacks).

    ``only`` (indices): test these points only (and a random sample of _SPIKE_FLOOR_SAMPLE
    for the noise level), without the stacks, and return those of them that are spikes: the
    check after a fit of the points it misses most (:func:`core.surface.data_spikes`).
    ``slope``: how steep a spike must be (1: 45 degrees).
    """
    n = len(q)
    k = min(_SPIKE_NEIGHBOURS, n - 2)
    none = np.zeros(0, dtype=np.int64)
    if k - _SPIKE_TRIM < 10:  # a quadratic (6) and a noise estimate from the rest
        return none
    if direction is None:
        direction = principal_axes(q - q.mean(axis=0))[1][2]
    w = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    a = np.cross(w, np.eye(3)[int(np.argmin(np.abs(w)))])
    a /= np.linalg.norm(a)
    flat = np.column_stack([q @ a, q @ np.cross(w, a)])  # across the direction
    height = q @ w
    spike = np.zeros(n, dtype=bool)
    check = np.random.default_rng(0).permutation(n)  # (the first chunk: a random sample)
    if only is not None:  # (a sample for the noise level first, then those asked about)
        only = np.unique(np.asarray(only, dtype=np.int64))
        check = np.r_[check[:_SPIKE_FLOOR_SAMPLE], only]
    floor = None

    trees: list = []  # (pool, its KD-tree) of the passes so far

    def nearest(at, pool):
        """Indices into ``q`` of the ``k + 1`` nearest points of ``pool`` (sorted indices) to
        the points ``at``, nearest first. A pool that is an earlier one less at most
        _SPIKE_REUSE points (the spikes of a pass) is queried in that one's tree for as many
        more neighbours, those left out dropped: a KD-tree of 1e5 points is 0.03 s a pass."""
        inpool = np.zeros(n, dtype=bool)
        inpool[pool] = True
        for base, tree in trees:
            r = len(base) - len(pool)
            if 0 <= r <= _SPIKE_REUSE and k + 1 + r <= len(base):
                if np.count_nonzero(inpool[base]) == len(pool):  # pool within base
                    idx = base[tree.query(flat[at], k=k + 1 + r, workers=-1)[1]]
                    order = np.argsort(~inpool[idx], axis=1, kind="stable")[:, : k + 1]
                    return np.take_along_axis(idx, order, axis=1)
        tree = cKDTree(flat[pool])
        trees.append((pool, tree))
        return pool[tree.query(flat[at], k=k + 1, workers=-1)[1]]

    def test(at, keep):
        """The spike test of the points ``at`` against their nearest points among ``keep``:
        (hit, far: steeper than 45 degrees, their neighbours)."""
        nonlocal floor
        idx = nearest(at, keep)
        own = idx[:, 0] == at  # the point itself is its own nearest (else a duplicate)
        nbr = np.where(own[:, None], idx[:, 1:], idx[:, :-1])
        # the neighbours' heights along the direction, as a quadratic over the across
        # coordinates (least squares, then again without the 3 worst: a spike among them)
        uv = flat[nbr] - flat[at][:, None, :]
        h = height[nbr] - height[at][:, None]
        u, v = uv[:, :, 0], uv[:, :, 1]
        A = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=2)
        use = np.ones(h.shape, dtype=bool)
        r = np.zeros_like(h)
        for trim in (0, _SPIKE_TRIM):
            if trim:
                worst = np.argsort(r, axis=1)[:, k - trim :]
                np.put_along_axis(use, worst, False, axis=1)
            Aw = A * use[:, :, None]
            G = np.einsum("mki,mkj->mij", Aw, A)
            G += 1e-9 * np.einsum("mii->m", G)[:, None, None] * np.eye(6)
            coef = np.linalg.solve(G, np.einsum("mki,mk->mi", Aw, h)[:, :, None])[:, :, 0]
            r = np.abs(h - np.einsum("mki,mi->mk", A, coef))
        d = np.abs(coef[:, 0])  # the point itself is at (0, 0) and height 0
        rs = np.where(use, r, np.nan)
        spacing = np.nanmedian(np.where(use, np.linalg.norm(uv, axis=2), np.nan), axis=1)
        far = d > slope * spacing
        # the noise: MAD of all the neighbours' residuals from the trimmed fit (robust to
        # the spikes left out), corrected for the 6 parameters fitted to the others
        kept_n = k - _SPIKE_TRIM
        sigma = 1.4826 * np.median(r, axis=1) * np.sqrt(kept_n / (kept_n - 6))
        if floor is None:  # the cloud's noise level: the median over the first chunk of
            floor = float(np.median(sigma))  # the first pass (all points, to 1e5)
        hit = far & (d > _SPIKE_SIGMA * np.maximum(sigma, floor))
        # and beyond all of its neighbours' heights (the point is at height 0): a point
        # at a step between neighbours on both levels fits a steep surface badly, but
        # is not above or below them all
        hk = np.where(use, h, np.nan)
        beyond = np.maximum(-np.nanmax(hk, axis=1), np.nanmin(hk, axis=1))
        hit &= beyond > 0.5 * d
        # and its neighbours fit their surface well (a narrow dip of a smooth surface,
        # sampled by few points, is a feature its neighbours do not fit either)
        hit &= np.nanmax(rs, axis=1) < 0.5 * d
        # and not at the cloud's edge where its surface turns steep (extrapolated there)
        side = np.linalg.norm(np.nanmean(np.where(use[:, :, None], uv, np.nan), axis=1), axis=1)
        rise = np.hypot(coef[:, 1], coef[:, 2]) * spacing  # (over one spacing)
        hit &= ~((side > _SPIKE_ONE_SIDED * spacing) & (d < rise))
        return hit, far, nbr, coef

    def tested(points, pool):
        """:func:`test` of ``points`` against ``pool``, in chunks: (at, hit, far, nbr, coef)."""
        return [(at, *test(at, pool))
                for at in (points[lo : lo + chunk] for lo in range(0, len(points), chunk))]

    for _ in range(4):
        found, again = [], []
        for at, hit, far, nbr, _ in tested(check, np.flatnonzero(~spike)):
            found.append(at[hit])
            again.append((at[far & ~hit], nbr[hit]))
        new = np.concatenate(found)
        if len(new) == 0:
            break
        spike[new] = True
        if spike.sum() > _SPIKE_MAX_SHARE * n:
            if stats is not None:
                stats["too_many"] = int(spike.sum())
            return none
        # next: the suspects, and the neighbours of the spikes just found
        check = np.unique(np.concatenate([np.concatenate([sus, nb.ravel()])
                                          for sus, nb in again]))
        check = check[~spike[check]]
        if len(check) == 0:
            break
    # stacks: the points of a compact group over the surface (a pole, a tree's crown) are
    # each other's nearest points, so the test above took their group for the surface. The
    # points with a neighbour steeply above or below them (more than 45 degrees and
    # _SPIKE_SIGMA noise levels) are tested again against the nearest points that have none
    # (the ground around a pole; at a step, both levels: then not a spike)
    keep = np.flatnonzero(~spike)
    if only is not None:
        return only[spike[only]]
    if floor is not None and len(keep) > k + _STACK_NEIGHBOURS:
        tree = cKDTree(flat[keep])
        steep = np.zeros(n, dtype=bool)
        for lo in range(0, len(keep), chunk):
            at = keep[lo : lo + chunk]
            dist, idx = tree.query(flat[at], k=_STACK_NEIGHBOURS + 1, workers=-1)
            rise = np.abs(height[keep[idx]] - height[at][:, None])
            steep[at] = ((rise > _SPIKE_SLOPE * dist) & (rise > _SPIKE_SIGMA * floor)).any(axis=1)
        members = np.flatnonzero(steep)
        pool = np.flatnonzero(~spike & ~steep)
        if 0 < len(members) <= _STACK_MAX_SHARE * n and len(pool) > k:
            hits, coefs = [], []
            for at, hit, _, _, coef in tested(members, pool):
                hits.append(at[hit])
                coefs.append(coef[hit])
            hits, coef = np.concatenate(hits), np.concatenate(coefs)
            # over the surface, not the top of it: among the points nearest to each (but
            # those found) one lies on its neighbours' surface (the ground under a pole; a
            # sharp peak's nearest points are on the peak too)
            rest = np.flatnonzero(~spike)
            rest = rest[~np.isin(rest, hits)]
            if len(hits) and len(rest) >= _STACK_NEIGHBOURS:
                dist, idx = cKDTree(flat[rest]).query(flat[hits], k=_STACK_NEIGHBOURS,
                                                      workers=-1)
                idx = rest[idx]
                uv = flat[idx] - flat[hits][:, None, :]
                u, v = uv[:, :, 0], uv[:, :, 1]
                A = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=2)
                off = np.abs(height[idx] - height[hits][:, None] - np.einsum("mki,mi->mk", A, coef))
                ground = off < 0.25 * np.abs(coef[:, 0])[:, None]
                # how far across the projection the nearest of them is: under a pole or a
                # crown the ground goes on (about half a spacing, as anywhere), beside a
                # roof or in a pit it begins at the wall (review: 4 of a 4 x 4 m roof's 16
                # points, and of a pit's, had gone)
                under = np.where(ground, dist, np.inf).min(axis=1)
                spike[_compact_groups(flat, members, hits, under)] = True
            if spike.sum() > _SPIKE_MAX_SHARE * n:
                if stats is not None:
                    stats["too_many"] = int(spike.sum())
                return none
    return np.flatnonzero(spike).astype(np.int64)


def _compact_groups(flat: np.ndarray, members: np.ndarray, hits: np.ndarray,
                    under: np.ndarray) -> np.ndarray:
    """The ``hits`` (indices into ``flat``, the points across the projection) that belong
    to compact groups of the ``members`` (which hold them) over the ground: linked by steps
    of at most _STACK_LINK data spacings, spanning at most _STACK_SPAN of them (a pole, a
    crown and the ground around it; not the long band of a steep ridge or a wall), whose
    hits have ground points (``under``: each hit's distance to the nearest) closer than
    _STACK_UNDER spacings, in the median (the ground goes on under a crown; beside a roof
    or in a pit it begins at the wall)."""
    if len(hits) == 0:
        return hits
    sample = np.random.default_rng(0).permutation(len(flat))[:20_000]
    # the data spacing sqrt(area / points), from the distance to the 6th nearest: on a grid
    # (1.41 steps) and for random points (1.34 / sqrt(density), median) alike, about
    # r6 sqrt(pi / 6); (twice the distance to the nearest is 2 steps on a grid: review)
    r6 = cKDTree(flat[sample]).query(flat[sample], k=min(7, len(sample)))[0][:, -1]
    spacing = float(np.median(r6)) * np.sqrt(np.pi / 6) * np.sqrt(len(sample) / len(flat))
    x = flat[members]
    pairs = cKDTree(x).query_pairs(_STACK_LINK * spacing, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(x), len(x)))
    _, label = connected_components(graph, directed=False)
    lo = np.full((label.max() + 1, 2), np.inf)
    hi = np.full((label.max() + 1, 2), -np.inf)
    np.minimum.at(lo, label, x)
    np.maximum.at(hi, label, x)
    span = np.linalg.norm(hi - lo, axis=1)
    # each hit's group (members hold the hits: searchsorted into the sorted members)
    order = np.argsort(members)
    group = label[order[np.searchsorted(members[order], hits)]]
    near = np.zeros(len(span))
    for g in np.unique(group):  # (a few groups: the compact ones over the surface)
        near[g] = np.median(under[group == g])
    keep = (span[group] <= _STACK_SPAN * spacing) & (near[group] <= _STACK_UNDER * spacing)
    return hits[keep]


def outlier_error(points: np.ndarray, isolated, label=None, advice: str = _DROP_ADVICE
                  ) -> OutlierError:
    """The error for the outliers ``isolated`` (indices) among ``points`` (N, 3), naming the
    first three by ``label(i)`` (default ``#i``, their row) and their coordinates, and how to
    leave them out (``advice``).

    Callers that merged or filtered the user's input build it again with the user's numbering
    (the command line after ``--drop-invalid``, Blender with object names and its option)."""
    label = label or (lambda i: f"#{i}")
    isolated = np.asarray(isolated, dtype=np.int64)
    show = ", ".join(
        f"{label(int(i))} ({', '.join(f'{c:.6g}' for c in points[i])})" for i in isolated[:3]
    )
    more = f" and {len(isolated) - 3} more" if len(isolated) > 3 else ""
    verb = "lies" if len(isolated) == 1 else "lie"
    return OutlierError(
        f"{len(isolated)} of the {len(points)} points {verb} far from all others (outliers: "
        f"{show}{more}); they would stretch the surface's domain and pull it away from the "
        f"data. Remove them, or let the fit leave them out: {advice}",
        isolated,
    )


def spike_error(points: np.ndarray, spikes, heights=None, label=None,
                advice: str = _SPIKE_ADVICE) -> OutlierError:
    """The error for the spike vertices ``spikes`` (indices, :func:`mesh_spikes`) of a mesh
    of the vertices ``points`` (N, 3), naming the first three by ``label(i)`` (default ``#i``)
    and their coordinates, how far the first sticks out (``heights``, above its neighbours'
    plane) and how to leave them out (``advice``), in the words of :func:`outlier_error`."""
    label = label or (lambda i: f"#{i}")
    spikes = np.asarray(spikes, dtype=np.int64)
    show = ", ".join(
        f"{label(int(i))} ({', '.join(f'{c:.6g}' for c in points[i])})" for i in spikes[:3]
    )
    more = f" and {len(spikes) - 3} more" if len(spikes) > 3 else ""
    one = len(spikes) == 1
    high = ("" if heights is None or not len(heights) else
            f", {'it' if one else 'the first'} {float(heights[0]):.4g} above the plane of its "
            "neighbours")
    return OutlierError(
        f"{len(spikes)} of the {len(points)} vertices of the mesh {'sticks' if one else 'stick'}"
        f" out of it as {'a spike' if one else 'spikes'} (outliers: {show}{more}{high}), far "
        "more steeply than any surface the fit follows; the mesh's faces hold "
        f"{'it' if one else 'them'} in the fit, and {'it' if one else 'they'} would pull the "
        f"surface away from the other vertices. Move or delete the "
        f"{'vertex' if one else 'vertices'}, or let the fit leave {'it' if one else 'them'} "
        f"out: {advice}",
        spikes, None if heights is None else np.asarray(heights, dtype=np.float64),
    )


def parameterize_points(
    points: np.ndarray, drop_outliers: bool | None = False, projection=None,
    spikes: bool = True, strays: bool | None = None,
) -> Parameterization:
    """Parameterize a point cloud by orthogonal projection on its best-fit plane.

    The projection normal ``n`` is the PCA normal (SVD of the centred points) unless another
    direction makes the cloud clearly less steep (see :func:`_projection_normals`: for height
    fields whose height range is comparable to their width, the mean local normal or the
    vertical axis); if the cloud folds over that plane, the other candidate directions are
    tried in turn and the first over which it does not fold is used (a steep height field much
    taller than wide has a vertical PCA plane); for a steep cloud the direction its
    consistently oriented normals all face is tried first (:func:`_oriented_normals`); ``a_u`` is the largest principal direction
    projected into that plane and
    ``a_v = n x a_u`` (right-handed, signs fixed so that the largest components of ``a_u`` and
    ``n`` are positive). The parameters are
    ``uv = ((p - o) . [a_u, a_v]) / s`` where ``o`` and ``s`` centre the projected bounding box
    at 0 and scale its longer side to ``[-1, 1]`` (method.md section 4). On a plane the map is an
    isometry up to the factor ``s``.

    Folds are detected as in :func:`_fold_fraction`, at the scale of :func:`_reliable_scale`
    (noise). The first candidate with flags at under 0.5% of the points is used (unless the
    surface stands upright over it in places, two reliable local planes of a neighbourhood
    within 0.6 degrees of parallel to it, and a later candidate over which it does not passes
    as clearly, face-on: a steep peak off the centre overhung its tilted PCA plane); when none is
    that clear, the passing one with the fewest flags (a narrow pass over the PCA plane let
    three_peaks' turned vertices through with 2.9% of their triangles flipped). It is an error

    * when more than 2% of the points are flagged over every candidate plane (reported for the
      first one);
    * when the local planes are reliable at fewer than 30% of the points at every scale and
      the cloud is not thin across its best-fit plane (``s_2 > 0.5 s_1``; a noisy slab is
      thin): the check would be blind (noisy turned steep fields were accepted with 47-49% of
      their triangles flipped; their ``s_2 / s_1`` is 0.90-0.98).

    A ``projection`` given replaces the candidates and is trusted on such clouds (it is still
    checked).

    Outliers (:func:`isolated_points`) are an error unless ``drop_outliers`` is True: then the
    cloud without them is parameterized, their ``uv`` rows are NaN and ``used`` is False
    (``None``: not checked, for callers that already did).

    Args:
        points: ``(n, 3)`` points, ``n >= 10`` distinct, not all on a line.
        drop_outliers: leave outliers out instead of refusing the cloud; True also leaves out
            the spikes and pits inside it (:func:`spike_points`, across the projection found
            for the cloud without its isolated points), which are not an error otherwise.
        spikes: False: not the spikes (internal: the first pass of ``drop_outliers``).
        strays: leave out a few points off the surface that the fold check sees over it
            (internal; default: ``drop_outliers``): see :func:`_stray_points`.
        projection: the direction to project along (:func:`projection_direction`), or None.

    Returns:
        A ``"plane"`` :class:`Parameterization` with ``domain_polygon`` the convex hull of uv.

    Raises:
        InvalidInputError: bad input (see :func:`normalize`).
        ParameterizationError: the cloud folds over every candidate plane (or the one given),
            or is too noisy to be checked for folds (with no ``projection``).
    """
    # the cloud in an order of its coordinates (coordinate_order): the checks' seeded samples
    # pick the same points of the same cloud stored in another order; the rows given back
    # (and an outlier error's indices) are in the order given
    p = _as_points(points)
    order = coordinate_order(p)
    if order is None:
        return _parameterize_points(p, drop_outliers, projection, spikes, strays)
    try:
        par = _parameterize_points(p[order], drop_outliers, projection, spikes, strays)
    except OutlierError as exc:
        if len(exc.indices) == 0:
            raise
        raise outlier_error(p, np.sort(order[np.asarray(exc.indices)])) from None
    uv = np.empty_like(par.uv)
    used = np.empty_like(par.used)
    uv[order], used[order] = par.uv, par.used
    return replace(par, uv=_readonly(uv), used=_readonly(used))


def _parameterize_points(points, drop_outliers, projection, spikes, strays) -> Parameterization:
    """:func:`parameterize_points` of the points in the order given."""
    direction = projection_direction(projection)
    if drop_outliers and spikes and DROP_SPIKES:
        # the spikes and pits inside the cloud too (spike_points), across the projection
        # direction the cloud without its isolated points takes; then without them
        par = parameterize_points(points, True, projection, spikes=False)
        used = np.flatnonzero(par.used)
        q = normalize(np.asarray(points, dtype=np.float64)[used])[0]
        stats: dict = {}
        spiky = used[spike_points(q, par.axes[2], stats=stats)]
        if stats.get("too_many"):  # (it had been silent: review)
            warnings.warn(
                f"drop_outliers: at least {stats['too_many']} of the {len(used)} points "
                f"({100 * stats['too_many'] / len(used):.0f}%) stick out of their neighbours "
                f"like spikes or pits, more than the {100 * _SPIKE_MAX_SHARE:.0f}% that can be "
                "told from a rough surface, so none of them was left out: clean the scan "
                "first (a noise or outlier filter), or fit it as it is", RuntimeWarning,
                stacklevel=4)
        if len(spiky) == 0:
            return par
        kept = par.used.copy()
        kept[spiky] = False
        try:
            sub = parameterize_points(np.asarray(points, dtype=np.float64)[kept], None,
                                      projection)
        except TCBError as exc:  # say that its numbers are those of the points kept
            raise type(exc)(f"{exc} (after leaving out {len(points) - kept.sum()} outliers "
                            f"of the {len(points)} points)") from None
        uv = np.full((len(kept), 2), np.nan)
        uv[kept] = sub.uv
        return replace(sub, uv=_readonly(uv), used=_readonly(kept))
    strays = bool(drop_outliers) if strays is None else strays
    q, norm = normalize(points)
    sample = _fold_sample(q)
    k = min(_FOLD_NEIGHBOURS, len(sample) - 1)
    knn = cKDTree(q[sample]).query(q[sample], k=max(k, _OUTLIER_NEIGHBOURS) + 1, workers=-1)
    if drop_outliers is not None:
        isolated = isolated_points(q, sample, knn)
        if len(isolated) and not drop_outliers:
            raise outlier_error(np.asarray(points, dtype=np.float64), isolated)
        if len(isolated):
            kept = np.ones(len(q), dtype=bool)
            kept[isolated] = False
            try:
                sub = parameterize_points(
                    np.asarray(points, dtype=np.float64)[kept], None, projection, strays=strays
                )
            except TCBError as exc:  # say that its numbers are those of the points kept
                raise type(exc)(
                    f"{exc} (after leaving out {len(isolated)} outliers of the {len(q)} points)"
                ) from None
            uv = np.full((len(q), 2), np.nan)
            uv[kept] = sub.uv
            return replace(sub, uv=_readonly(uv), used=_readonly(kept))
    m = q.mean(axis=0)
    sv, vt = principal_axes(q - m)
    planes = _local_planes(q[sample], k, knn[1][:, : k + 1])
    sample, planes, share = _reliable_scale(q, sample, planes, k)
    # where the density is uneven the direction is chosen by area, not by points: the best-fit
    # plane, the candidates' scores and the fold share (a scanner that dwelt, 20 000 points
    # in a blob over Franke's function and 1 500 uniform, was projected 45 degrees from z, the
    # blob's tangent plane, with 109 of the 1 500 overhanging: the fit stalled at 17% of the
    # height off; user test). Even densities keep the counts (_area_weights: None)
    weights = _area_weights(q[sample], planes[3], planes[2])
    if weights is not None:
        w = weights / weights.sum()
        m = w @ q[sample]
        vt = principal_axes((q[sample] - m) * np.sqrt(w)[:, None])[1]
    # a cloud thin across its best-fit plane cannot hide layers farther apart than its noise
    if direction is None and share < _MIN_CHECKABLE and sv[2] > _MAX_THICKNESS * sv[1]:
        raise ParameterizationError(
            f"the point cloud is too noisy, or too sparse for how much it curves, to be checked "
            f"for folds: the points' neighbourhoods are flat discs at only {100 * share:.0f}% "
            "of them, at every scale tried, and the cloud is too thick to be one layer (its "
            f"thickness across its best-fit plane is {100 * sv[2] / sv[1]:.0f}% of its width). If the surface is a height field over a known "
            "direction, give it (fit_surface(..., projection=\"z\"), on the command line "
            "--projection z, in Blender the Projection option); otherwise smooth the scan "
            "or supply a mesh of disk topology (with faces)" + _degrees_note(points)
        )
    # the most height-field-like direction first; if the cloud folds over that plane, the
    # other candidates (a steep height field far taller than wide, Renka's F7, has a vertical
    # PCA plane and folds over it, but not over the horizontal one)
    fractions, tried, found = [], [], []
    normals = (_projection_normals(q[sample], np.cross(vt[0], vt[1]), planes, weights)
               if direction is None else [direction])

    def upright(n):  # reliable local planes parallel to n (within 0.6 degrees), two in one
        # neighbourhood: the surface stands on n there (noise makes single ones: Franke's
        # function with noise 1% of its height had one over z, and was projected 3 degrees off)
        on = planes[2] & (np.abs(planes[0] @ n) < _UPRIGHT)
        return bool(np.any(on & (np.count_nonzero(on[planes[3]], axis=1) >= 2)))

    # a clear pass over which the surface stands upright somewhere is used only when no later
    # candidate without such points passes clearly (face-on): it is as steep as it can be there,
    # and a little more turns it past the direction, too thin a band for the fold tests to see.
    # A steep peak off the centre of its square tilts the PCA plane 7.8 degrees from z and 13
    # of 8000 points overhung it (6 stand upright, 2 of them paired): the fit stalled at 22% of
    # the height off (user test); over the mean normal none stand upright: 0.46%. Renka's
    # cosine peak on 2000 points stalled at 1.6% over its PCA normal; now over the least steep
    # direction, 3 degrees from z, it meets the tolerance (0.6%)
    first_upright, chosen = None, None
    for n in normals:
        if first_upright is not None and upright(n):
            continue
        tried.append(n)
        uv_n = _project(q, m, vt, n)[3]
        found.append({})
        if _on_a_line(uv_n):  # the surface is parallel to n: no height field over its plane
            fractions.append(np.inf)
            continue
        # a direction given is trusted to see a height field where the surface only turns
        # steep: its overlaps are folds, and where it turns past the direction (a terrain
        # tile with a bank of 80 degrees 4 m from its edge, and a height field on a grid
        # whose slopes reach 80 degrees, were refused over z by the steep test at the rim,
        # 3.0% and 4.3%: user test)
        fractions.append(_fold_fraction(q, uv_n, n, planes, sample, found[-1],
                                        steep_test=direction is None, weights=weights))
        if fractions[-1] <= _FOLD_CLEAR * _FOLD_MAX_FRACTION:
            if first_upright is None and direction is None and upright(n):
                first_upright = len(tried) - 1
                continue
            if first_upright is None or found[-1].get("edge_on", 0.0) < _EDGE_ON:
                chosen = len(tried) - 1
                break
    # a clear pass ends the search; after a narrow one (flags at 0.5-2% of the points: a
    # fold the check only partly sees) the passing direction with the fewest flags is used,
    # one that sees the surface face-on before one that sees most of it edge-on (steep at
    # over _EDGE_ON of the reliable points). The fold test lets steep points inside the
    # domain through (Renka's F7 is a height field over the horizontal plane with 95% of its
    # points steeper than 78 degrees), so a terrain projected along a horizontal axis has
    # no flags: a tile with 10% spikes passed the vertical candidates narrowly (1.7-1.9%,
    # the spikes) and was projected sideways, as the candidate with the fewest flags (review;
    # with 15% spikes the vertical ones fail, 7-8%, and it still is: a limit)
    # (with an upright pass and no other, the candidates up to it, as if the search had ended)
    edge_on = [f.get("edge_on", 0.0) >= _EDGE_ON for f in found]
    last = len(fractions) if first_upright is None else first_upright + 1
    best = chosen if first_upright is not None and chosen is not None else min(
        range(last), key=lambda i: (fractions[i] > _FOLD_MAX_FRACTION, edge_on[i], fractions[i]))
    frac = fractions[best] if fractions[best] <= _FOLD_MAX_FRACTION else fractions[0]
    axes, c, s, uv = _project(q, m, vt, tried[best], aligned=direction is not None)
    if not np.isfinite(frac) and direction is not None:
        raise ParameterizationError(
            f"projected along the direction given ({', '.join(f'{x:.3g}' for x in direction)}) "
            "the points fall on one line: the surface is parallel to that direction; give a "
            "direction across the surface (e.g. the axis it faces), or leave the projection "
            "automatic"
        )
    tail = _degrees_note(points) if frac > _FOLD_MAX_FRACTION else ""
    if frac > _FOLD_MAX_FRACTION and strays:
        # a few points of another layer over the surface (a power line over terrain): left
        # out, and the rest parameterized as if they were not there
        off, seen = _stray_points(q, sample, found[0].get("strays", ()))
        if seen and not len(off):  # (the refusal said nothing of them: review)
            tail = (f" (drop_outliers found {seen} points of another layer over the surface, "
                    f"more than the {100 * _STRAY_MAX_SHARE:.0f}% of the points it leaves out)")
        if len(off):
            kept = np.ones(len(q), dtype=bool)
            kept[off] = False
            try:
                sub = parameterize_points(np.asarray(points, dtype=np.float64)[kept], None,
                                          projection, strays=False)
            except TCBError as exc:
                raise type(exc)(f"{exc} (after leaving out {len(off)} points off the surface "
                                f"over it of the {len(q)} points)") from None
            uv = np.full((len(q), 2), np.nan)
            uv[kept] = sub.uv
            return replace(sub, uv=_readonly(uv), used=_readonly(kept))
    layers = _layers_note(found[best if frac == fractions[best] else 0], norm.scale)
    of = "of the points" if weights is None else "of the area (the density is uneven)"
    if frac > _FOLD_MAX_FRACTION and layers:
        raise ParameterizationError(
            f"the point cloud overlaps itself in projection at {100 * frac:.1f}% {of}: "
            f"{layers}{tail}"
        )
    if frac > _FOLD_MAX_FRACTION and direction is not None:
        raise ParameterizationError(
            f"the point cloud folds over the plane across the projection direction "
            f"({', '.join(f'{x:.3g}' for x in direction)}): at {100 * frac:.1f}% {of} "
            "the surface is nearly parallel to that direction or overlaps itself along it; give "
            f"another direction, or leave the projection automatic{tail}"
        )
    if frac > _FOLD_MAX_FRACTION:
        # every candidate failed: the share is the best one's, not the best-fit plane's (a
        # 200-degree cylinder segment was refused "at 100.0% of the points", its PCA plane
        # edge-on, while across its axis 22% fold; 185 degrees said 15%: user test)
        least = fractions[best]
        where = "its best-fit plane"
        if len(tried) > 1 and np.isfinite(least) and least < frac:
            frac = least
            where = (f"its best-fit plane and every other plane tried (the best of them "
                     f"across {', '.join(f'{x:.3g}' for x in tried[best])})")
        raise ParameterizationError(
            f"the point cloud folds over {where}: at {100 * frac:.1f}% {of} "
            "the surface is nearly perpendicular to that plane or overlaps itself in projection; "
            "a height field or a gently curved patch is needed: split the scan into patches "
            f"that each face one direction, or supply a mesh of disk topology (with faces){tail}"
        )
    try:
        hull = ConvexHull(uv)  # 2D: vertices are in counter-clockwise order
    except QhullError:
        raise InvalidInputError(
            "the points lie almost on one straight line; a surface needs points spread in two "
            "directions"
        ) from None
    origin = norm.undo(m + c @ axes[:2])
    return Parameterization(
        uv=_readonly(uv),
        kind="plane",
        domain_polygon=_readonly(uv[hull.vertices]),
        used=_readonly(np.ones(len(uv), dtype=bool)),
        origin=_readonly(origin),
        axes=_readonly(axes),
        scale=s * norm.scale,
    )


# --------------------------------------------------------------------------------------------
# Meshes: disk topology, Floater mean-value map
# --------------------------------------------------------------------------------------------


# vertices of separate pieces this share of the diagonal apart or closer are a seam not quite
# welded (_welded_pieces): exports round a seam's two copies apart (1e-7 of the diagonal: user
# test); Blender's Merge by Distance takes 1e-4 m by default
WELD_GAP = 1e-5


def _welded_pieces(points: np.ndarray, tris: np.ndarray, distance: float = 0.0
                   ) -> tuple[int, float]:
    """Pieces of the triangles joined through their edges once vertices at exactly equal
    positions are one, or with ``distance`` > 0 also vertices of different such pieces at
    most that far apart; and the largest distance between two vertices so joined (0 at equal
    positions). Through edges, not vertices: two patches that touch at one vertex of equal
    position were "1 once merged", and after Merge by Distance the fit refused the mesh again
    for its non-manifold vertex (user test). (Close vertices within one piece, as of a
    sliver, are left as they are: they had set the distance to merge by; review.)"""
    _, first = np.unique(points, axis=0, return_inverse=True)
    first = first.reshape(-1)
    count, label = _edge_pieces(first, tris)
    if distance <= 0 or count == 1:
        return count, 0.0
    piece = np.full(len(points), -1)
    piece[tris.reshape(-1)] = np.repeat(label, 3)
    pairs = cKDTree(points).query_pairs(distance, output_type="ndarray")
    pairs = pairs[(piece[pairs[:, 0]] >= 0) & (piece[pairs[:, 1]] >= 0)
                  & (piece[pairs[:, 0]] != piece[pairs[:, 1]])]
    if not len(pairs):
        return count, 0.0
    m = int(first.max()) + 1
    graph = sp.coo_matrix((np.ones(len(pairs)), (first[pairs[:, 0]], first[pairs[:, 1]])),
                          shape=(m, m))
    merged = connected_components(graph, directed=False)[1][first]
    gap = float(np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1).max())
    return _edge_pieces(merged, tris)[0], gap


def _edge_pieces(vertex: np.ndarray, tris: np.ndarray) -> tuple[int, np.ndarray]:
    """How many pieces the triangles ``tris`` make, joined through their edges with the
    vertices renumbered by ``vertex`` (n,), and the piece of each triangle (f,)."""
    t = vertex[tris]
    m = int(vertex.max()) + 1
    a, b = t.reshape(-1), np.roll(t, -1, axis=1).reshape(-1)
    _, edge = np.unique(np.minimum(a, b) * m + np.maximum(a, b), return_inverse=True)
    face = np.repeat(np.arange(len(tris)), 3)
    n_edges = int(edge.max()) + 1
    # faces and edges as one graph: a face is joined to its three edges
    graph = sp.coo_matrix((np.ones(len(face)), (face, len(tris) + edge.reshape(-1))),
                          shape=(len(tris) + n_edges,) * 2)
    _, label = connected_components(graph, directed=False)
    label = label[: len(tris)]
    return len(np.unique(label)), label


def _ragged_polygons(faces) -> list[np.ndarray] | None:
    """The rows of ``faces``, a sequence of polygons of different lengths (lists or arrays of
    vertex indices), as 1-D arrays; None if ``faces`` is no such sequence."""
    try:
        rows = [np.asarray(row) for row in faces]
    except (TypeError, ValueError):
        return None
    if not rows or any(r.ndim != 1 for r in rows):
        return None
    return rows


def _fans(f: np.ndarray) -> np.ndarray:
    """The triangles ``(v0, v_j, v_{j+1})``, ``j = 1..k-2``, of the polygons ``f`` (F, k),
    polygon by polygon."""
    k = f.shape[1]
    j = np.arange(1, k - 1)
    return np.stack([np.broadcast_to(f[:, :1], (len(f), k - 2)), f[:, j], f[:, j + 1]],
                    axis=-1).reshape(-1, 3)


def _as_triangles(faces: np.ndarray, n_vertices: int, points: np.ndarray | None = None
                  ) -> np.ndarray:
    """Validate ``faces`` (``(f, k)`` integer, ``k >= 3``, or a sequence of polygons of any
    lengths) and split the polygons into triangles, in the order of the polygons.

    Given the ``points``, polygons are cut by their shape, whatever corner they start at
    (:func:`core.geometry.polygon_triangles`: quads along the shorter diagonal, larger ones by
    their best ears); without them a polygon ``(v0, ..., v_{k-1})`` becomes the fan
    ``(v0, v_j, v_{j+1})``, ``j = 1..k-2``.
    """
    rows = None
    try:
        f = np.asarray(faces)
    except (TypeError, ValueError) as exc:
        f, why = None, str(exc)
    if f is None or (f.dtype == object and f.ndim == 1):
        # triangles, quads and other polygons in one list (what a mesh's polygons are)
        rows = _ragged_polygons(faces)
        if rows is None:
            why = why if f is None else f"got an array of {len(f)} objects"
            raise InvalidInputError(
                f"faces must be an (F, 3) integer array, or a list of polygons (lists of "
                f"vertex indices): {why}") from None
        short = [i for i, r in enumerate(rows) if len(r) < 3]
        if short:
            raise InvalidInputError(
                f"{len(short)} of the {len(rows)} faces have fewer than 3 vertices (the "
                f"first: face {short[0]}, {rows[short[0]].tolist()}); leave them out")
        try:
            f = np.concatenate(rows)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(f"faces must hold integer vertex indices: {exc}") from None
    elif f.ndim != 2 or f.shape[1] < 3:
        raise InvalidInputError(
            f"faces must be an (F, 3) array of vertex indices (or (F, 4) quads); got shape "
            f"{f.shape}"
        )
    if len(f) == 0:
        raise InvalidInputError(
            "the mesh has no faces; give faces of a disk-like patch, or parameterize the "
            "vertices as a point cloud (faces=None)"
        )
    if rows is None and len(f) in (3, 4) and f.shape[1] > 8 and any(
            len(np.unique(row)) < len(row) for row in np.asarray(f)):
        # (3, F) is a transposed (F, 3), not three F-gons (refused as non-manifold edges,
        # which sent the user to repair a mesh that is fine: user test); a polygon repeats
        # no vertex, a column of a mesh's faces does (three 11-gons are a mesh: review)
        raise InvalidInputError(
            f"faces must be an (F, 3) array of vertex indices (or (F, 4) quads); got shape "
            f"{f.shape}, {len(f)} polygons of {f.shape[1]} vertices: transposed? pass faces.T"
        )
    integral = (np.issubdtype(f.dtype, np.integer) and f.dtype != bool) or (
        np.issubdtype(f.dtype, np.floating) and np.all(np.isfinite(f)) and np.all(f == np.round(f))
    )
    if not integral:
        raise InvalidInputError(
            f"faces must hold integer vertex indices; got values of type {f.dtype}"
        )
    if np.issubdtype(f.dtype, np.integer) and n_vertices - 1 > np.iinfo(f.dtype).max == f.max():
        # (uint8 faces of a 299-vertex mesh had wrapped round: "non-manifold edges"; faces
        # of a small type that stay below its largest value may leave the rest unused)
        raise InvalidInputError(
            f"the faces are {f.dtype} integers, which hold indices up to "
            f"{np.iinfo(f.dtype).max}, and reach it, but the mesh has {n_vertices} vertices: "
            "larger indices cannot be stored (they wrap round); make the faces int32 or int64"
        )
    f = f.astype(np.int64)
    bad = (f < 0) | (f >= n_vertices)
    if bad.any():
        hint = ("; they run from 1 to the vertex count: numbered from 1 (as in OBJ files)? "
                "pass faces - 1" if f.min() == 1 and f.max() == n_vertices else "")
        raise InvalidInputError(
            f"{int(bad.sum())} face indices are out of range (the mesh has {n_vertices} "
            f"vertices, valid indices are 0..{n_vertices - 1}); fix the face list{hint}"
        )
    def split(polys):  # by their shape (with the points: quads, ears), else fans
        if polys.shape[1] >= 4 and points is not None:
            return polygon_triangles(points, polys)
        return _fans(polys)

    if rows is None:
        return split(f)
    # fans of the polygons of each length, put back in the order of the polygons
    size = np.array([len(r) for r in rows])
    first = np.concatenate([[0], np.cumsum(size)[:-1]])
    tris, owner = [], []
    for k in np.unique(size):
        which = np.flatnonzero(size == k)
        tris.append(split(f[first[which, None] + np.arange(k)]))
        owner.append(np.repeat(which, k - 2))
    return np.concatenate(tris)[np.argsort(np.concatenate(owner), kind="stable")]


def _is_cap(tris: np.ndarray, p: np.ndarray, rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """Cap mask (f,) of ``tris``: height over the longest edge at most ``rtol`` times its length
    (``|(b - a) x (c - a)| <= rtol L^2``), and the squared edge lengths (f, 3), edge ``j`` from
    vertex ``j`` to ``j + 1``."""
    a, b, c = (np.take(p, tris[:, j], axis=0) for j in range(3))
    length2 = np.stack([((b - a) ** 2).sum(1), ((c - b) ** 2).sum(1), ((a - c) ** 2).sum(1)], 1)
    n = np.cross(b - a, c - a)
    return np.einsum("ij,ij->i", n, n) <= rtol**2 * length2.max(axis=1) ** 2, length2


def _flip_caps(tris: np.ndarray, p: np.ndarray, rtol: float = 1e-10,
               frozen: np.ndarray | None = None) -> np.ndarray:
    """Remove zero-area "cap" triangles ``(a, b, c)`` (``c`` on the segment ``ab``) by flipping
    ``ab``, their longest edge, with the triangle ``(a, b, d)`` across it: ``(a, d, c)`` and
    ``(d, b, c)``. Fanning an n-gon with three collinear vertices makes such caps (a hexagon
    merged from two quads); left in, they give the mean-value map angles of 0 and pi, and a
    fit of 400 vertices used 1983 control points without reaching the tolerance (547 as quads).

    A flip keeps the vertices and the boundary (``ab`` is interior, shared by exactly two
    triangles); it is made only when neither new triangle is a cap and ``cd`` is not already an
    edge, so every flip lowers the number of caps and the passes end. Each pass makes
    non-overlapping flips (vectorized; where two caps share a neighbour, the first one flips);
    passes repeat until no cap can be flipped (a collinear run of k vertices takes k - 1). Caps
    on the boundary or at non-manifold edges stay (the topology checks report the latter).
    Orientation is made consistent afterwards (:func:`_orient_consistently`).
    ``frozen``: (f,) True for the triangles that take part in no flip (those that close a
    mesh's holes, :func:`_with_holes_filled`).
    """
    n = len(p)
    tris = tris.copy()
    for _ in range(len(tris) + 1):  # each pass flips at least one cap or stops
        cap_mask, length2 = _is_cap(tris, p, rtol)
        cap = np.flatnonzero(cap_mask)
        if len(cap) == 0:
            break
        e = np.stack([tris, np.roll(tris, -1, axis=1)], axis=-1)  # (f, 3, 2) edges (j, j+1)
        key = np.minimum(e[..., 0], e[..., 1]) * n + np.maximum(e[..., 0], e[..., 1])  # (f, 3)
        flat = key.reshape(-1)
        order = np.argsort(flat, kind="stable")
        sorted_keys = flat[order]
        j = length2[cap].argmax(axis=1)  # the longest edge: (a, b) = tris[t, j], tris[t, j+1]
        k = key[cap, j]
        lo = np.searchsorted(sorted_keys, k)
        hi = np.searchsorted(sorted_keys, k, side="right")
        shared = hi - lo == 2  # an interior, manifold edge: exactly one other triangle
        cap, j, lo = cap[shared], j[shared], lo[shared]
        a, b, c = tris[cap, j], tris[cap, (j + 1) % 3], tris[cap, (j + 2) % 3]
        other = order[lo] // 3
        other = np.where(other == cap, order[lo + 1] // 3, other)
        d = tris[other].sum(axis=1) - a - b  # the vertex of the other triangle off ab
        new1, new2 = np.stack([a, d, c], 1), np.stack([d, b, c], 1)
        ok = (d != c) & ~np.isin(np.minimum(c, d) * n + np.maximum(c, d), sorted_keys)
        ok &= ~_is_cap(new1, p, rtol)[0] & ~_is_cap(new2, p, rtol)[0]
        if frozen is not None:
            ok &= ~frozen[cap] & ~frozen[other]
        cap, other, new1, new2 = cap[ok], other[ok], new1[ok], new2[ok]
        if len(cap) == 0:
            break
        # one flip per triangle and pass: a candidate flips when it is the first to touch
        # both of its triangles (the first candidate always does)
        m = len(cap)
        first = np.full(len(tris), m)
        np.minimum.at(first, np.concatenate([cap, other]), np.tile(np.arange(m), 2))
        go = (first[cap] == np.arange(m)) & (first[other] == np.arange(m))
        tris[cap[go]], tris[other[go]] = new1[go], new2[go]
    return tris


def _edge_pairs(edge_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two half-edges ``(h1, h2)`` of each edge that two faces share, from the undirected
    edge id of every half-edge (every edge has one or two half-edges)."""
    order = np.argsort(edge_id, kind="stable")
    sid = edge_id[order]
    pair = np.flatnonzero(sid[1:] == sid[:-1])  # positions of interior-edge pairs in `order`
    return order[pair], order[pair + 1]


def _orient_consistently(tris: np.ndarray, edge_id: np.ndarray) -> np.ndarray:
    """Flip triangles so that every interior edge is traversed once in each direction.

    The face graph is lifted to its orientation double cover: nodes ``(f, 0)`` (as given) and
    ``(f, 1)`` (flipped); neighbours ``f, g`` sharing an edge are joined ``(f, s)-(g, s)`` when
    they traverse it in opposite directions (consistent) and ``(f, s)-(g, 1-s)`` otherwise. The
    surface is orientable iff ``(f, 0)`` and ``(f, 1)`` lie in different components; in each
    piece the side needing fewer flips is kept.

    Args:
        tris: ``(f, 3)`` triangles.
        edge_id: ``(3 f,)`` undirected edge id of half-edge ``(tris[i, c], tris[i, c+1])`` at
            position ``3 i + c``; every edge has one or two half-edges.

    Returns:
        The triangles, some reversed.

    Raises:
        TopologyError: the mesh is not orientable.
    """
    nf = len(tris)
    he_from = tris.reshape(-1)
    he_to = np.roll(tris, -1, axis=1).reshape(-1)
    face_of = np.repeat(np.arange(nf), 3)
    h1, h2 = _edge_pairs(edge_id)
    f1, f2 = face_of[h1], face_of[h2]
    consistent = he_from[h1] == he_to[h2]  # opposite directions
    if consistent.all():  # (as most meshes come: every piece keeps its faces, none flips;
        return tris.copy()  # its graph was 1.2-2 s of a 1e6-vertex mesh's map)
    s = (~consistent).astype(np.int64)
    rows = np.concatenate([f1, f1 + nf])
    cols = np.concatenate([f2 + nf * s, f2 + nf * (1 - s)])
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * nf, 2 * nf))
    _, label = connected_components(graph, directed=False)
    l0, l1 = label[:nf], label[nf:]
    if np.any(l0 == l1):
        raise TopologyError(
            "the mesh is not orientable (like a Moebius strip); a disk-like patch is needed: "
            "cut the strip open or supply another patch"
        )
    # side A of each piece = double-cover component with the smaller label
    side_a = l0 < l1
    piece = np.minimum(l0, l1)
    n_a = np.bincount(piece, weights=side_a, minlength=2 * nf)
    n_all = np.bincount(piece, minlength=2 * nf)
    keep_a = n_a[piece] >= n_all[piece] - n_a[piece]  # keep the majority orientation
    flip = side_a != keep_a
    out = tris.copy()
    out[flip] = out[flip][:, ::-1]
    return out


def _split_vertices(tris: np.ndarray, edge_id: np.ndarray) -> np.ndarray:
    """The vertices (sorted) whose faces form more than one fan: the faces at a vertex, joined
    where they share an edge at it, fall into several groups. Two sheets touch there: a bow
    tie on the border, or a part that meets the rest at one vertex inside it (an eye touching
    a head), which the border alone does not show (the mesh then had "3 boundary loops" or
    "handles or tunnels", and the vertex was never named: user test). The corners ``3 f + j``
    (of vertex ``tris[f, j]``) are the nodes; the two faces of each interior edge ``(a, b)``
    join their corners at ``a`` and at ``b`` (``edge_id`` as for
    :func:`_orient_consistently`, no edge in more than two faces); a vertex whose corners lie
    in more than one connected component is split."""
    nf = len(tris)
    he_from = tris.reshape(-1).astype(np.int64)
    start = np.arange(3 * nf)  # the corner at the half-edge's first vertex ...
    end = 3 * (start // 3) + (start % 3 + 1) % 3  # ... and at its second
    h1, h2 = _edge_pairs(edge_id)
    same = he_from[h1] == he_from[h2]  # (both faces run the edge the same way)
    rows = np.concatenate([start[h1], end[h1]])
    cols = np.concatenate([np.where(same, start[h2], end[h2]), np.where(same, end[h2], start[h2])])
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * nf, 3 * nf))
    _, label = connected_components(graph, directed=False)
    fans = np.bincount(np.unique(he_from * (3 * nf) + label) // (3 * nf))
    return np.flatnonzero(fans > 1)


def _mean_value_weights(p: np.ndarray, tris: np.ndarray, n: int, terms=None) -> sp.csr_matrix:
    """Floater's mean-value weights ``W`` (``(n, n)`` CSR, positive on mesh edges).

    ``w_ij = (tan(alpha_ij / 2) + tan(beta_ij / 2)) / |p_j - p_i|`` where ``alpha_ij, beta_ij``
    are the angles at ``p_i`` of the two triangles sharing edge ``ij`` (one on the boundary).
    Computed per triangle corner with ``tan(theta / 2) = |e1 x e2| / (|e1||e2| + e1 . e2)``,
    which is accurate for small angles (method.md section 4; ``terms``: :func:`_corner_terms`
    when known).
    """
    i, j, k = tris[:, 0], tris[:, 1], tris[:, 2]
    cross3, dot3, l13, l23 = _corner_terms(p, tris) if terms is None else terms
    rows, cols, vals = [], [], []
    for corner, (a, b, c) in enumerate(((i, j, k), (j, k, i), (k, i, j))):
        l1, l2, cross = l13[:, corner], l23[:, corner], cross3[:, corner]
        den = l1 * l2 + dot3[:, corner]
        tan_half = cross / np.maximum(den, 1e-12 * l1 * l2)
        rows += [a, a]
        cols += [b, c]
        vals += [tan_half / l1, tan_half / l2]
    w = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )
    return w.tocsr()  # duplicates (the two triangles of an edge) are summed


# a boundary vertex is a corner when the boundary turns there by more than this (degrees); a
# loop with exactly four, and no other turn above RECTANGLE_SMOOTH, goes to a rectangle
RECTANGLE_CORNERS = True
CORNER_TURN = 50.0
RECTANGLE_SMOOTH = 25.0
RECTANGLE_CURL = 2.0  # the longest ratio of a side's length to the distance of its ends
CORNER_GAP = 2  # turns at most this many edges apart are one group (boundary_corners)
CORNER_SPAN = 0.03  # a corner's group spans at most this share of the loop's length
CORNER_MIN_COARSE = 24  # a ragged loop is read at coarser scales of at least this many vertices


def _ears(tris: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """The positions in the boundary ``loop`` of the vertices ``k`` of the triangles of
    ``tris`` whose three vertices are the loop's ``k - 1``, ``k``, ``k + 1`` (sorted): on a
    side of the rectangle such a triangle is flat, so ``k`` has to be a corner."""
    B = len(loop)
    pos = np.full(int(tris.max()) + 1, -1)
    pos[loop] = np.arange(B)
    s = pos[tris]
    s = s[(s >= 0).all(axis=1)]
    mid = []
    for j in range(3):
        m, a, c = s[:, j], s[:, (j + 1) % 3], s[:, (j + 2) % 3]
        around = {1, B - 1}  # (the two others one step either side of m)
        hit = np.isin((a - m) % B, list(around)) & np.isin((c - m) % B, list(around)) & (a != c)
        mid.append(m[hit])
    return np.unique(np.concatenate(mid)) if B > 3 else np.zeros(0, dtype=np.int64)


def boundary_corners(b: np.ndarray, ears: np.ndarray | None = None) -> np.ndarray | None:
    """The four corners of a boundary loop ``b`` (its points in order, (B, 3)) that is a
    quadrilateral's (sorted positions in the loop), or None: :func:`_turn_corners` of the loop,
    else of the loop read at a coarser scale where it is ragged (not in method.md).

    A loop with four or more vertices that turn by RECTANGLE_SMOOTH degrees or more and no four
    corners by :func:`_turn_corners` (noise on a scan's border) is read again by
    :func:`_chord_corners` at the scale of ``h`` of its edges, ``h`` = 2, 3, 4, 6, 8, 11, ...
    while the loop has CORNER_MIN_COARSE times ``h`` vertices or more: noise that turns each
    edge by tens of degrees turns chords ``h`` edges long by about ``1 / h`` of that, and a
    corner still turns by its angle. A noisy grid mesh of 200 x 200 vertices (noise 0.1% of its
    diagonal on every coordinate: its border's vertices turn by up to 130 degrees) went to the
    circle, the square's corners squeezed: its max error 1.5e-2 of the diagonal, at the
    corners, and the true surface's corners 1.45e-2 from the fit (user test; on the rectangle
    6.1e-3 and 2.3e-3; /tmp/s39/f9c.py of the thirty-ninth session). The corners of noisy grids
    of 41 x 41 to 317 x 317 vertices with noise up to 0.5% of the diagonal come out within 3
    vertices of the true ones (seed 0, /tmp/s39/turns.py; a review found up to 8 on other seeds
    at 317 x 317 with 0.5%, 2 at 0.2%, and all 120 noisy grids and strips of 50 x 50 to 300 x
    30 vertices with noise 0.03-0.2% on rectangles); noisy circles and ellipses of 400 to 4000
    vertices (noise up to the spacing), noisy sphere caps and the staircase borders of
    benchmarks/mesh_maps.py have none; a 21 x 21 grid without one boundary triangle (a notch
    that hid its corner) has its four. ``ears`` (:func:`_ears`) are kept as corners where one
    is near; a staircase's steps are ears, and the corners read at a coarser scale miss them
    (the rectangle is then refused). Short of the truth: strips narrower than about 2 h + 1
    vertices, whose two corners at an end are one peak (300 x 6 with noise 0.1%;
    :func:`_denoised_own_map` gives it its own shape), and one spurious peak of
    RECTANGLE_SMOOTH degrees or more at every scale (a 60 x 60 grid with noise 0.5%, two of
    eight seeds); a noisy stadium of 400 vertices had four corners on a quarter of its seeds
    (review; with about the circle's max error and 1.1-1.3x its control points)."""
    corners = _turn_corners(b)
    B = len(b) if corners is None else 0
    if B and np.count_nonzero(_turns(b)[0] >= RECTANGLE_SMOOTH) >= 4:
        h = 2
        while B // h >= CORNER_MIN_COARSE:
            corners = _chord_corners(b, h, ears)
            if corners is not None:
                return corners
            h = h + 1 if h < 4 else int(round(h * 1.4142))
    return corners


def _chord_corners(b: np.ndarray, h: int, ears: np.ndarray | None) -> np.ndarray | None:
    """The four corners of a loop ``b`` (B, 3) read at the scale of ``h`` of its edges
    (:func:`boundary_corners`), or None: the vertices whose chords to the vertices ``h``
    before and after turn most within ``h`` vertices either way, by more than CORNER_TURN,
    exactly four, every other such peak under RECTANGLE_SMOOTH, and no side of the loop
    averaged over ``2 h + 1`` vertices curled (RECTANGLE_CURL). A corner moves to the nearest
    of the ``ears`` (:func:`_ears`) within ``h / 2`` of it."""
    turn = _turns(b, h)[0]
    peak = (turn >= RECTANGLE_SMOOTH) & (
        turn == ndimage.maximum_filter1d(turn, 2 * h + 1, mode="wrap"))
    peak &= turn > np.roll(turn, 1)  # (the first of a plateau)
    at = np.flatnonzero(peak)
    corners = at[turn[at] > CORNER_TURN]
    if len(corners) != 4 or len(corners) != len(at):
        return None
    if ears is not None and len(ears):
        for k, c in enumerate(corners):
            near = ears[np.abs((ears - c + len(b) // 2) % len(b) - len(b) // 2) <= h // 2]
            if len(near):
                off = np.abs((near - c + len(b) // 2) % len(b) - len(b) // 2)
                corners[k] = near[np.argmin(off)]
    corners = np.unique(corners)
    smooth = sum(np.roll(b, s, axis=0) for s in range(-h, h + 1)) / (2 * h + 1)
    return corners if len(corners) == 4 and _sides_straight(smooth, corners) else None


def _turns(b: np.ndarray, h: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """How much each vertex of a loop ``b`` (B, 3) turns, in degrees, and the same signed by
    the loop's normal (:func:`_turn_corners`): from its chord to the vertex ``h`` before to
    its chord to the vertex ``h`` after (its edges for ``h`` = 1)."""
    d_out = np.roll(b, -h, axis=0) - b
    d_in = b - np.roll(b, h, axis=0)
    cos = np.einsum("ij,ij->i", d_in, d_out) / np.maximum(
        np.linalg.norm(d_in, axis=1) * np.linalg.norm(d_out, axis=1), 1e-300)
    turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    normal = np.cross(b, np.roll(b, -1, axis=0)).sum(axis=0)  # (Newell: twice the area vector)
    normal /= max(float(np.linalg.norm(normal)), 1e-300)
    # the turn within the loop's plane (the edges projected on it), signed by the normal; a
    # vertex turns by the smaller of that and its 3D turn: a bend out of the plane (a crease
    # crossing the boundary, a terrain's ups and downs along a DEM mesh's straight sides)
    # counts little or nothing, and a sheet curled beyond a half cylinder, whose projected
    # arcs double back, keeps its small 3D turns there
    p_in = d_in - np.outer(d_in @ normal, normal)
    p_out = d_out - np.outer(d_out @ normal, normal)
    across = np.einsum("ij,j->i", np.cross(p_in, p_out), normal)
    flat = np.degrees(np.arctan2(across, np.einsum("ij,ij->i", p_in, p_out)))
    # a bend with no part across the normal counts 0: where a wall leans over the floor its
    # edge's projection points back (a turn of 180 in the plane; review: a channel with
    # leaning walls lost its corners)
    small = 1e-9 * np.linalg.norm(d_in, axis=1) * np.linalg.norm(d_out, axis=1)
    turn = np.where(np.abs(across) > small, np.minimum(turn, np.abs(flat)), 0.0)
    signed = turn * np.sign(flat)
    return turn, signed


def _sides_straight(b: np.ndarray, corners: np.ndarray) -> bool:
    """Whether no side of the loop ``b`` between its sorted ``corners`` is more than
    RECTANGLE_CURL times as long along the loop as the straight distance between its ends."""
    seg = np.linalg.norm(np.roll(b, -1, axis=0) - b, axis=1)
    run = np.concatenate([[0.0], np.cumsum(seg)])  # (the loop's length from vertex 0)
    side = np.diff(np.append(run[corners], run[-1]))  # from each corner to the next
    side[3] += run[corners[0]]  # (the last side goes on past vertex 0 to the first corner)
    chord = b[np.roll(corners, -1)] - b[corners]
    return not np.any(side > RECTANGLE_CURL * np.linalg.norm(chord, axis=1))


def _turn_corners(b: np.ndarray) -> np.ndarray | None:
    """The four corners of a loop ``b`` (B, 3) read from the turns of its vertices
    (:func:`boundary_corners`), or None.

    Each vertex turns by the angle between its incoming and outgoing edge, or by the angle
    between their projections on the loop's plane (normal: Newell's) where that is smaller,
    signed by the normal; a bend out of the loop's plane (a crease crossing the boundary of
    patch-01.off, the terrain along a DEM mesh's sides: the Jacksboro DEM as a grid mesh went
    to the circle) counts little or nothing. Vertices that turn by RECTANGLE_SMOOTH degrees
    or more form groups: such vertices at most CORNER_GAP edges apart (a chamfer's two
    45-degree turns, a notch's +90, -90, +90 where a corner cell is missing), except that two
    sharp turns (above CORNER_TURN) the same way are two corners (a short side). A group is a
    corner when its turns add up to more than CORNER_TURN within CORNER_SPAN of the loop's
    length (at the vertex where half of it is reached); every other group must add up to
    less than RECTANGLE_SMOOTH. The loop is a quadrilateral's with exactly four corners and
    no side more than RECTANGLE_CURL times as long along the loop as the straight distance
    between its corners (a half circle: pi / 2). Without the last test a disk with a small
    rectangular tab (four sharp corners within 7 of its 310 boundary vertices) went onto a 2
    x 0.1 rectangle, the disk's arc (6.1 long, its ends 0.25 apart) opposite the tab's 0.1:
    RMS 0.31 instead of 0.0026 (review). Sides of very different lengths are fine: a 100:1
    strip, or a quad whose top is 0.04 and bottom 2 (max error 0.0027 on the rectangle,
    0.061 on the circle). A 41 x 41 grid with a corner cell missing was on the circle: 486
    control points at 1e-3 instead of 142 (review)."""
    B = len(b)
    if B < 4:
        return None
    turn, signed = _turns(b)
    seg = np.linalg.norm(np.roll(b, -1, axis=0) - b, axis=1)
    sig = np.flatnonzero(turn >= RECTANGLE_SMOOTH)
    if len(sig) < 4:
        return None
    sharp, way = turn[sig] > CORNER_TURN, np.sign(signed[sig])
    # a group ends after sig[k] when the next is farther, or when one of the two is sharp and
    # they turn the same way
    ends = ((np.roll(sig, -1) - sig) % B > CORNER_GAP) | (
        (sharp | np.roll(sharp, -1)) & (way == np.roll(way, -1)))
    if not ends.any():
        return None  # one chain all around
    last = np.flatnonzero(ends)
    start, stop = sig[(np.roll(last, 1) + 1) % len(sig)], sig[last]  # each group's span
    length = (stop - start) % B + 1  # vertices in the span
    # sums over the (cyclic) spans from cumulative sums of the loop taken twice
    ct = np.concatenate([[0.0], np.cumsum(np.tile(signed, 2))])
    cs = np.concatenate([[0.0], np.cumsum(np.tile(seg, 2))])
    total = ct[start + length] - ct[start]
    arc = cs[start + length - 1] - cs[start]
    corner = (np.abs(total) > CORNER_TURN) & (arc <= CORNER_SPAN * seg.sum())
    if np.count_nonzero(corner) != 4 or np.any(np.abs(total[~corner]) >= RECTANGLE_SMOOTH):
        return None
    at = []
    for s0, n0, t0 in zip(start[corner], length[corner], total[corner]):  # (four)
        run = np.abs(ct[s0 + 1 : s0 + n0 + 1] - ct[s0])
        at.append((s0 + int(np.argmax(run >= 0.5 * abs(t0)))) % B)
    corners = np.sort(np.array(at))
    return corners if _sides_straight(b, corners) else None


# a mesh's own boundary shape (not in method.md, whose section 4 puts the boundary on a circle
# or a square): the map with the flattened boundary is taken when its distortion
# (:func:`_map_energy`, 1 for an isometry) exceeds 1 by less than FLAT_GAIN times the fixed
# boundary's excess, less FLAT_MIN_GAIN. On a circle, a ragged border (a scan's edge, faces
# deleted in Blender) is straightened and the triangles along it crushed: a 41 x 41 grid patch
# cut by a wavy ragged border took 1272 control points at the default tolerance, flattened 140
# (benchmarks/mesh_maps.py). The gain is generous: the circle's failure (crushed triangles)
# costs far more than the flattened map's (area distortion of a curved patch); a review
# measured patch-01 (distortion excess 0.69 of the rectangle's) at 0.9-1.1x the control points.
FLAT_BOUNDARY = True
FLAT_GAIN = 0.9
FLAT_MIN_GAIN = 1e-6  # and by at least this much (a planar mesh maps exactly either way)
FLAT_PINCH = 2.0  # and no boundary vertices come this many times closer in uv than in 3D (_pinch)
FLAT_WEDGE = 0.5  # and no reflex angle changes by this share of the gap it leaves (_flattened_map)
PROJECTED_BOUNDARY = True  # a flattened loop refused: its projection tried (_projected_map)


def _pinch(q: np.ndarray, edge: np.ndarray, stretch: np.ndarray, k: int = 12,
           apart: int = 3) -> float:
    """How much closer a map's boundary ``edge`` (B, 2) brings boundary vertices together than
    they are in 3D (``q``, (B, 3)), against the map's own stretch there: the largest ``|q_i -
    q_j| / (max(s_i, s_j) |x_i - x_j|)`` over the ``k`` nearest boundary vertices ``j`` in the
    plane of each ``i`` that are more than ``apart`` steps away along the loop (``s =
    stretch``: 3D per uv length at each boundary vertex, the largest over the mesh's edges at
    it, :func:`_vertex_stretch`). About 1 when the loop keeps its shape; a ramp of 0.95 turn
    flattens into a loop whose two ends nearly meet (3.8; 0.98 turn 6.5) while they are a climb
    apart, and the spline has to jump the gap (review: a swing warning, the surface 1% of the
    diagonal off the mesh). Measured 0.93-1.07 on every other benchmarks/mesh_maps.py mesh,
    flattened. Against the loop's mean stretch instead, a comb on a steep surface (0.8 sin 3x
    cos 2y) projected scored 2.0 across its gaps, whose 3D width is that of its steep slopes
    (1.3 against the stretch of the edges there; the ramp's ends 3.8 either way)."""
    B = len(edge)
    d, j = cKDTree(edge).query(edge, k=min(k, B))
    steps = np.abs(np.arange(B)[:, None] - j)
    steps = np.minimum(steps, B - steps)
    far = np.linalg.norm(q[:, None, :] - q[j], axis=2)
    ratio = far / np.maximum(np.maximum(stretch[:, None], stretch[j]) * d, 1e-300)
    return float(ratio[steps > apart].max(initial=0.0))


def _corner_terms(p: np.ndarray, tris: np.ndarray, lengths: bool = True
                  ) -> tuple[np.ndarray, ...]:
    """At each corner ``tris[:, j]`` of each triangle, with the edges ``e_1 = p[tris[:, j +
    1]] - p[tris[:, j]]`` and ``e_2 = p[tris[:, j + 2]] - p[tris[:, j]]`` (indices mod 3)
    leaving it: ``(|e_1 x e_2|, e_1 . e_2, |e_1|, |e_2|)``, each (f, 3) (the first two
    without ``lengths``). The terms of the corner angles (:func:`corner_angles`), of the
    cotangent weights (:func:`_cotan_weights`) and of the mean-value weights
    (:func:`_mean_value_weights`), computed once for the three (method.md section 4's map:
    three passes over the corners were 7.3 s of a 1e6-vertex mesh's map on a busy machine,
    this one 1.5 s). From the three edge vectors ``d_j = p[tris[:, j + 1]] - p[tris[:, j]]``
    of each triangle: ``e_1 = d_j``, ``e_2 = -d_{j+2}``; negation is exact, so each term is
    the same to the last bit as from ``e_1, e_2`` formed apart."""
    d = [p[tris[:, (j + 1) % 3]] - p[tris[:, j]] for j in range(3)]
    cross, dot = np.empty(tris.shape), np.empty(tris.shape)
    for j in range(3):
        e1, e2 = d[j], d[(j + 2) % 3]  # (e_2 = -e2: |e_1 x e_2| and -e_1 . e_2 the same)
        cross[:, j] = np.linalg.norm(np.cross(e1, e2), axis=1)
        dot[:, j] = -np.einsum("ij,ij->i", e1, e2)
    if not lengths:
        return cross, dot
    size = np.column_stack([np.linalg.norm(e, axis=1) for e in d])
    return cross, dot, size, size[:, [2, 0, 1]]


def corner_angles(p: np.ndarray, tris: np.ndarray, terms=None) -> np.ndarray:
    """The 3D angle (f, 3) of each triangle at each of its corners ``tris[:, j]``:
    ``atan2(|e_1 x e_2|, e_1 . e_2)`` of the edges ``e_1, e_2`` leaving it. ``terms``:
    :func:`_corner_terms` when known."""
    cross, dot = (_corner_terms(p, tris, lengths=False) if terms is None else terms)[:2]
    return np.arctan2(cross, dot)


def _angle_sums(p: np.ndarray, tris: np.ndarray, terms=None) -> np.ndarray:
    """Sum (n,) of the 3D corner angles of the triangles at each vertex:
    ``theta_i = sum atan2(|e_1 x e_2|, e_1 . e_2)`` over the corners at ``i``
    (:func:`corner_angles`; ``terms``: :func:`_corner_terms` when known)."""
    angle = corner_angles(p, tris, terms)
    total = np.zeros(len(p))
    for j in range(3):  # (corner by corner: the sums as they were, to the last bit)
        total += np.bincount(tris[:, j], weights=angle[:, j], minlength=len(p))
    return total


def _closed_polygon(length: np.ndarray, turning: np.ndarray) -> np.ndarray | None:
    """The plane polygon (B, 2) whose edge ``i`` (from vertex ``i`` to ``i + 1``) has about
    ``length[i]`` and which turns left by ``turning[i]`` at vertex ``i`` (the turns sum to
    ``2 pi``), or None. Edge ``i`` runs along ``T_i = (cos phi_i, sin phi_i)``,
    ``phi_i = turning[1] + ... + turning[i]``; the lengths are changed as little as closes it:
    ``l~ = l - l (T . lam)``, the least change in ``sum (l~ - l)^2 / l`` with
    ``sum l~_i T_i = 0`` (``(sum l T T^T) lam = sum l T``; boundary-first flattening's
    closing step, Sawhney and Crane 2017). None if a length would not stay positive."""
    phi = np.concatenate([[0.0], np.cumsum(turning[1:])])
    T = np.column_stack([np.cos(phi), np.sin(phi)])
    lam = np.linalg.lstsq(np.einsum("i,ij,ik->jk", length, T, T), length @ T, rcond=None)[0]
    closed = length * (1.0 - T @ lam)
    if not (closed > 0).all():
        return None
    return np.vstack([[0.0, 0.0], np.cumsum(closed[:-1, None] * T[:-1], axis=0)])


def _energy_frames(p: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, ...]:
    """The 3D part of :func:`_map_energy`, the same for every map of the mesh: the triangles
    of positive area (mask, (f,)) and of those ``l_1``, the area, ``x_2`` and ``y_2`` (the
    3D edges ``(l_1, 0)`` and ``(x_2, y_2)`` in each triangle's plane)."""
    e1, e2 = p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]
    l1 = np.linalg.norm(e1, axis=1)
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    ok = area > 0
    l1, area, e1, e2 = l1[ok], area[ok], e1[ok], e2[ok]
    x2 = np.einsum("ij,ij->i", e1, e2) / l1
    return ok, l1, area, x2, 2.0 * area / l1


def _map_energy(p: np.ndarray, tris: np.ndarray, uv: np.ndarray, frames=None) -> float:
    """Distortion of the map of the triangles ``tris`` from 3D (``p``) to ``uv``: the
    area-weighted mean of the symmetric Dirichlet energy ``(s_1^2 + s_2^2 + s_1^-2 + s_2^-2)
    / 4`` of each triangle's linear map (singular values ``s``), after scaling ``uv`` to the
    3D area; 1 for an isometry, infinite if a uv triangle is flipped or flat. Per triangle
    ``|J|_F^2 = |f_1|^2 / l_1^2 + |f_2 - f_1 x_2 / l_1|^2 / y_2^2`` (``f`` the uv edges,
    ``(l_1, 0)`` and ``(x_2, y_2)`` the 3D edges in the triangle's plane) and
    ``|J^-1|_F^2 = |J|_F^2 / det J^2``, ``det J = area_uv / area_3D``. ``frames``: its 3D
    part (:func:`_energy_frames`) when known (a mesh's maps are compared on it)."""
    f1, f2 = uv[tris[:, 1]] - uv[tris[:, 0]], uv[tris[:, 2]] - uv[tris[:, 0]]
    area_uv = 0.5 * (f1[:, 0] * f2[:, 1] - f1[:, 1] * f2[:, 0])
    if not (area_uv > 0).all():
        return float("inf")
    ok, l1, area, x2, y2 = _energy_frames(p, tris) if frames is None else frames
    f1, f2, area_uv = f1[ok], f2[ok], area_uv[ok]
    s2 = area.sum() / area_uv.sum()  # uv scaled to the 3D area
    col2 = f2 - f1 * (x2 / l1)[:, None]
    frob = s2 * (np.einsum("ij,ij->i", f1, f1) / l1**2 + np.einsum("ij,ij->i", col2, col2) / y2**2)
    det = s2 * area_uv / area
    return float(np.sum(area * frob * (1.0 + 1.0 / det**2)) / (4.0 * area.sum()))


# the parts of a nested dissection (_dissection_order) left whole: at most this many vertices
DISSECTION_LEAF = 32


def _dissection_order(r: np.ndarray, c: np.ndarray, x: np.ndarray,
                      leaf: int = DISSECTION_LEAF) -> np.ndarray:
    """A fill-reducing ordering (nested dissection) of the ``m = len(x)`` unknowns of a system
    whose off-diagonal pattern is the edges ``r[k] - c[k]``, with positions ``x`` (m, 3): each
    part of more than ``leaf`` vertices is cut at the median of its longest side, the
    vertices of its second half with an edge to the first are its separator (ordered after
    both halves), and the halves are cut in turn, all parts of a level at once. Coordinate
    bisection: any cut is a valid separator, its quality only changes the fill. As a
    permutation ``order`` of ``range(m)``: factor ``A[order][:, order]``.

    On the 1000x1000 grid mesh's mean-value system, SuperLU's factor of it took 6.3 s with
    1.14e8 entries of L + U, against 17.1 s and 1.48e8 with its own MMD_AT_PLUS_A ordering
    (2.6 s for this ordering, made once for the two systems; the cut's new part gathered
    once at each end of an edge, not its part and side, cut it by 18%: 4.3 to 3.4 s on the
    edges of all faces, the same order); 450x450: 0.85 s (1.93e7) against 1.4 s (2.16e7),
    0.4 s to order; 400x400 0.62 s against 1.05 s; 120x120 the same time (0.033 s) with 7%
    more fill, so it is used at every size (benchmarked as /tmp/h91w/small.py did)."""
    m = len(x)
    part = np.zeros(m, np.int64)
    active = np.ones(m, bool)
    key = np.zeros(m, np.int64)  # base 3 digits, a level each: half 0, half 1, separator 2
    o = np.arange(m)  # the active vertices, by part
    for _ in range(38):  # (3^39 > 2^63)
        if not len(o):
            break
        po = part[o]
        start = np.flatnonzero(np.r_[True, po[1:] != po[:-1]])
        size = np.diff(np.r_[start, len(o)])
        if not (size > leaf).any():
            break
        xo = x[o]
        axis = np.argmax(np.maximum.reduceat(xo, start, axis=0)
                         - np.minimum.reduceat(xo, start, axis=0), axis=1)
        group = np.repeat(np.arange(len(start)), size)
        s = np.lexsort((xo[np.arange(len(o)), axis[group]], group))
        rank = np.empty(len(o), np.int64)
        rank[s] = np.arange(len(o)) - start[group[s]]
        split = np.repeat(size > leaf, size)
        half = np.full(m, -1, np.int64)  # the part a cut puts a vertex in: 2 part + side
        half[o[split]] = 2 * po[split] + (rank[split] >= np.repeat(size // 2, size)[split])
        hr, hc = half[r], half[c]
        cross = (hr >= 0) & (hc >= 0) & (hr != hc) & ((hr >> 1) == (hc >> 1))
        sep = np.where(hr[cross] & 1, r[cross], c[cross])
        digit = np.where(half >= 0, half & 1, 0)
        digit[sep] = 2
        key = 3 * key + digit
        cut = half >= 0
        part[cut] = half[cut]
        active[o[~split]] = False
        active[sep] = False
        o = o[s]
        o = o[active[o]]
    return np.argsort(key, kind="stable")


class _OrderedLU:
    """SuperLU's factor of ``a[order][:, order]`` (its ordering NATURAL, its pivoting as
    by default) answering for ``a``, or of ``a`` by MMD_AT_PLUS_A when ``order`` is None."""

    def __init__(self, a, order=None):
        self.order = order
        if order is None:
            self.lu = splu(sp.csc_matrix(a), permc_spec="MMD_AT_PLUS_A")
        else:
            self.lu = splu(sp.csr_matrix(a)[order][:, order].tocsc(), permc_spec="NATURAL")

    def solve(self, rhs, trans="N"):
        if self.order is None:
            return self.lu.solve(rhs, trans=trans)
        x = np.empty(rhs.shape)
        x[self.order] = self.lu.solve(np.asfortranarray(rhs[self.order]), trans=trans)
        return x


def _cotan_weights(p: np.ndarray, tris: np.ndarray, n: int, terms=None) -> sp.csr_matrix:
    """The cotangent weights ``C`` (``(n, n)`` CSR, symmetric): ``c_ij = (cot alpha_ij +
    cot beta_ij) / 2``, ``alpha_ij, beta_ij`` the angles opposite edge ``ij`` in its two
    triangles (one on the boundary); ``L = diag(C 1) - C`` is the Dirichlet energy's matrix
    of the piecewise linear functions on the mesh. ``cot = e_1 . e_2 / |e_1 x e_2|`` at each
    corner (``terms``: :func:`_corner_terms` when known)."""
    cross, dot = (_corner_terms(p, tris, lengths=False) if terms is None else terms)[:2]
    rows, cols, vals = [], [], []
    for j, (a, b, c) in enumerate(((tris[:, 0], tris[:, 1], tris[:, 2]),
                                   (tris[:, 1], tris[:, 2], tris[:, 0]),
                                   (tris[:, 2], tris[:, 0], tris[:, 1]))):
        half_cot = 0.5 * dot[:, j] / np.maximum(cross[:, j], 1e-300)
        rows += [b, c]
        cols += [c, b]
        vals += [half_cot, half_cot]
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n)).tocsr()


def _cotan_system(p, tris, loop, interior, terms=None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """The cotangent Laplacian of the ``interior`` vertices, ``L_II = diag(C_I 1) - C_II``,
    and the weights ``C_IB`` of their edges to the boundary ``loop``
    (:func:`_cotan_weights`; ``terms``: :func:`_corner_terms` when known); the whole ``C``
    is not kept."""
    c = _cotan_weights(p, tris, len(p), terms)[interior]
    return sp.diags(np.asarray(c.sum(axis=1)).ravel()) - c[:, interior], c[:, loop]


def _cotan_carried(p, tris, loop, interior, defect, order=None, system=None
                   ) -> np.ndarray | None:
    """:func:`_carried_curvature` by the cotangent Laplacian, or None when its system is
    singular or its solution not finite. Factored with SuperLU's minimum-degree ordering of
    ``A^T + A`` (MMD_AT_PLUS_A; the matrix is symmetric), not its default COLAMD: on a
    450x450 grid mesh 1.9x less time and 44% less fill (21.6e6 entries of L + U against
    38.3e6), the same solution to 4e-14 (relative); ``order``: the ordering of
    :func:`_dissection_order` instead (:class:`_OrderedLU`); ``system``: ``(L_II, C_IB)``
    (:func:`_cotan_system`) when made already."""
    lap, c_loop = _cotan_system(p, tris, loop, interior) if system is None else system
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (a singular factor is caught below)
            carried = c_loop.T @ _OrderedLU(lap, order).solve(defect)
        if np.isfinite(carried).all():
            return carried
    except RuntimeError:
        pass
    return None


def _carried_curvature(p, tris, loop, interior, defect, w, lu) -> np.ndarray:
    """The share of the interior's angle defects ``K_I`` (``defect``) that each boundary
    vertex of ``loop`` takes: boundary-first flattening's Dirichlet-to-Neumann map (Sawhney
    and Crane 2017, with the boundary's scale kept, ``u_B = 0``): solve ``L_II u_I = -K_I``
    with the cotangent Laplacian (:func:`_cotan_weights`), then ``h_B = (L u)_B = C_IB^T
    L_II^-1 K_I``; ``sum h_B = sum K_I``. If that system is singular or its solution not
    finite (degenerate triangles), the harmonic measure of the mean-value weights ``w`` (the
    exit probabilities of their random walk, ``H = a^-1 W_IB``, with the factor ``lu`` of
    ``a = D - W_II``) carries them instead: ``h_B = W_IB^T a^-T K_I``
    (:func:`_cotan_carried` is the first, which :func:`_parameterize_mesh` calls before it
    factors ``a``, so that the two factors are never held at once)."""
    carried = _cotan_carried(p, tris, loop, interior, defect)
    return carried if carried is not None else w[:, loop].T @ lu.solve(defect, trans="T")


def _flattened_map(p, tris, loop, interior, w, lu, known=None) -> np.ndarray | None:
    """The mesh's map with its own boundary shape flattened: ``uv`` (n, 2) of the boundary
    ``loop`` and of the ``interior`` vertices (NaN elsewhere), in a box of half-diagonal 1
    centred at 0, or None. Boundary-first flattening (Sawhney and Crane, "Boundary first
    flattening", ACM TOG 2017) with lengths kept: the boundary keeps its 3D edge lengths and
    turns at each vertex by its geodesic curvature ``pi - theta_b`` plus its share of the
    interior's angle defects ``K_I = 2 pi - theta_I`` (:func:`_carried_curvature`); by
    Gauss-Bonnet the turns sum to ``2 pi``. The interior follows by the same mean-value
    solve as on the circle (``w``: the weight rows of the interior, ``lu``: their factor).
    None when the flattened boundary is not a simple polygon: a ramp of more than one turn
    develops into a loop that overlaps itself (review: every uv triangle positive, distortion
    1.0, and the fit stuck at 4.5% of the diagonal); when it brings parts of the border
    together that are far apart in 3D (:func:`_pinch` above FLAT_PINCH: a ramp of just under
    one turn); or when it opens a slit's tip (FLAT_WEDGE, below). ``known``: ``(theta,
    carried)`` already computed (:func:`_angle_sums`, :func:`_cotan_carried`; ``carried``
    None when that failed)."""
    theta = _angle_sums(p, tris) if known is None else known[0]
    carried = np.zeros(len(loop))
    if len(interior) and known is None:
        carried = _carried_curvature(p, tris, loop, interior, 2.0 * np.pi - theta[interior],
                                     w, lu)
    elif len(interior):  # (the mean-value fallback of _carried_curvature when None)
        carried = known[1] if known[1] is not None else (
            w[:, loop].T @ lu.solve(2.0 * np.pi - theta[interior], trans="T"))
    turning = np.pi - theta[loop] + carried
    if not abs(turning.sum() - 2.0 * np.pi) < 1e-6:
        return None
    # a vertex the domain almost surrounds whose angle the carried curvature changes by a
    # good part of the gap left: the tip of a slit (its two sides split vertices of one
    # place) opened 5 degrees wide by 5 of curvature. The surface there must bridge the gap
    # in the plane from both sides, which meet at other angles in 3D than in the plane: a
    # kink no C^1 spline reaches (user test: the fit stalled at 1.2% of the diagonal with
    # 486 control points; on the circle the tolerance with 602). Measured at most 0.29 of
    # the gap on the benchmarks/mesh_maps.py meshes, 0.98 at the slit's tip.
    angle = theta[loop] - carried  # the angle of the domain at each boundary vertex
    reflex = angle > np.pi
    if (np.abs(carried[reflex]) > FLAT_WEDGE * (2.0 * np.pi - angle[reflex])).any():
        return None
    length = np.linalg.norm(p[np.roll(loop, -1)] - p[loop], axis=1)
    edge = _closed_polygon(length, turning)
    return None if edge is None else _inside_boundary(p, tris, edge, loop, interior, w, lu)


def _inside_boundary(p, tris, edge, loop, interior, w, lu, inner=None) -> np.ndarray | None:
    """The map ``uv`` (n, 2) with the boundary ``loop`` on the counter-clockwise polygon
    ``edge`` (B, 2), scaled into a box of half-diagonal 1 centred at 0, and the ``interior``
    placed by the mean-value solve (``w``, ``lu``: as for :func:`_flattened_map`), or at
    ``inner`` (its positions in the frame of ``edge``, scaled alike) when given; NaN
    elsewhere. None when the polygon is not simple, when a coordinate is not finite, or when
    it brings parts of the border together that are far apart in 3D (:func:`_pinch` above
    FLAT_PINCH, with the stretch of the triangles ``tris`` at the boundary)."""
    if not simple_polygon(edge):
        return None
    lo, hi = edge.min(axis=0), edge.max(axis=0)
    uv = np.full((len(p), 2), np.nan)
    uv[loop] = (edge - 0.5 * (lo + hi)) / (0.5 * np.linalg.norm(hi - lo))
    if len(interior) and inner is not None:
        uv[interior] = (inner - 0.5 * (lo + hi)) / (0.5 * np.linalg.norm(hi - lo))
    elif len(interior):
        uv[interior] = lu.solve(np.asfortranarray(w[:, loop] @ uv[loop]))
    if not (np.isfinite(uv[loop]).all() and np.isfinite(uv[interior]).all()):
        return None
    at = np.isin(tris, loop).any(axis=1)  # (the triangles at the boundary)
    stretch = _vertex_stretch(p, uv, tris[at].ravel(), np.roll(tris[at], -1, axis=1).ravel(),
                              np.isfinite(uv[:, 0]))
    return None if _pinch(p[loop], uv[loop], stretch[loop]) > FLAT_PINCH else uv


def _projected_map(p, tris, loop, interior, w, lu, frames=None) -> np.ndarray | None:
    """The mesh's map with its boundary projected onto a plane (method.md section 4's
    projection of point clouds; not in method.md), or None: ``x_b = (p_b - o) . [e_1, e_2]``
    for a unit normal ``n`` and ``e_1, e_2`` completing it to an orthonormal frame, turned
    counter-clockwise (``e_2`` negated if the loop's signed area is negative); the interior
    placed by the same mean-value solve, or projected alike (:func:`_inside_boundary`, which
    refuses a map as it refuses a flattened loop). Two normals are tried: the faces'
    area-weighted mean normal (``sum (b - a) x (c - a)``: where a height field faces; its
    principal axes tilt with its heights, 50 degrees on a comb on 1.5 sin 3x cos 2y) and the
    least principal axis of the vertices (which turns a ramp of 0.95 turn so that its ends
    stay apart). Of each interior the map that distorts the triangles less
    (:func:`_map_energy`) is kept, and the projected interior is returned when its distortion
    exceeds 1 by less than FLAT_GAIN times the mean-value one's. Tried when
    :func:`_flattened_map` is None. A comb of fingers on a wavy surface develops into fingers
    that bend into each other (a flattened loop that overlaps itself), and on the circle its
    fingers are crushed to slivers (distortion 96 against 1.01 projected; 982 control points
    against 149 at the default tolerance, with 0.2% of the surface folded over;
    benchmarks/mesh_maps.py). Mean-value weights inside a boundary that is not convex may
    flip triangles (a comb on 1.5 sin 3x cos 2y), and they strain a steep one (0.8 sin 3x
    cos 2y: 1.37 against 1.18 projected whole, 569 control points against 199); the
    projection of a height field along its mean normal flips none. ``frames``: the 3D part
    of the distortion (:func:`_energy_frames`) when known."""
    frames = _energy_frames(p, tris) if frames is None else frames
    ids = np.concatenate([loop, interior])
    centre = p[ids].mean(axis=0)
    facing = np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]).sum(axis=0)
    best = {"mean-value": (np.inf, None), "projected": (np.inf, None)}
    for normal in (facing, principal_axes(p[ids] - centre)[1][2]):
        size = np.linalg.norm(normal)
        if not size > 0:
            continue
        normal = normal / size
        e1 = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
        e1 /= np.linalg.norm(e1)
        frame = np.column_stack([e1, np.cross(normal, e1)])
        edge = (p[loop] - centre) @ frame
        if np.dot(edge[:, 0], np.roll(edge[:, 1], -1)) < np.dot(np.roll(edge[:, 0], -1),
                                                                 edge[:, 1]):
            frame[:, 1] = -frame[:, 1]
            edge[:, 1] = -edge[:, 1]
        for kind, inner in (("mean-value", None), ("projected", (p[interior] - centre) @ frame)):
            uv = _inside_boundary(p, tris, edge, loop, interior, w, lu, inner)
            energy = np.inf if uv is None else _map_energy(p, tris, uv, frames)
            if energy < best[kind][0]:
                best[kind] = (energy, uv)
    (smooth, smooth_uv), (flat, flat_uv) = best["mean-value"], best["projected"]
    # (the projected interior only when it distorts clearly less: a ramp of 0.95 turn
    # projected whole, 1.0080 against 1.0081, had a 7x larger max error, 1.9e-2)
    return flat_uv if flat - 1.0 < FLAT_GAIN * (smooth - 1.0) else smooth_uv


def _rectangle_boundary(seg: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Boundary parameters on a rectangle, counter-clockwise from its lower left corner
    (method.md section 4's chord-length map, side by side): the loop's edges ``seg`` (3D
    lengths, the loop starting at its first corner), ``corners`` (positions in the loop, the
    first 0). The rectangle's sides are the mean lengths of the opposite sides, scaled to a
    half-diagonal of 1 (inside the unit disk)."""
    B = len(seg)
    ends = np.append(corners, B)
    side = np.array([seg[ends[k] : ends[k + 1]].sum() for k in range(4)])
    w, h = 0.5 * (side[0] + side[2]), 0.5 * (side[1] + side[3])
    w, h = w / np.hypot(w, h), h / np.hypot(w, h)
    start = np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
    out = np.empty((B, 2))
    for k in range(4):
        idx = np.arange(ends[k], ends[k + 1])
        t = np.concatenate([[0.0], np.cumsum(seg[idx[:-1]])]) / max(side[k], 1e-300)
        out[idx] = start[k] + t[:, None] * (start[(k + 1) % 4] - start[k])
    return out


# winding_flipped: a vector area whose largest component is within this share of the sum of
# its terms' magnitudes (a bound of its rounding error, ~1e-16 per term) has no sign to trust
WINDING_RTOL = 1e-9


def _half_edges(faces, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The half-edges ``a -> b`` (int64) of ``faces``, each polygon's corner to its next, of an
    ``(f, k)`` array or a sequence of polygons; None when they are no integer polygons of at
    least 3 indices in ``0..n-1`` (:func:`_as_triangles` names what is wrong)."""
    try:
        f = np.asarray(faces)
    except (TypeError, ValueError):
        f = None
    if f is not None and f.ndim == 2 and f.dtype != object:
        a, b = f.reshape(-1), np.roll(f, -1, axis=1).reshape(-1)
    else:
        rows = _ragged_polygons(faces)
        if rows is None:
            return None
        size = np.array([len(r) for r in rows])
        try:
            a = np.concatenate(rows)
        except (TypeError, ValueError):
            return None
        first = np.repeat(np.cumsum(size) - size, size)
        last = np.repeat(np.cumsum(size) - 1, size)
        at = np.arange(len(a))
        b = a[np.where(at == last, first, at + 1)]
    if len(a) == 0 or (f is not None and f.ndim == 2 and f.dtype != object and f.shape[1] < 3):
        return None
    integral = (a.dtype.kind in "iu") or (a.dtype.kind == "f" and np.isfinite(a).all()
                                          and (a == np.round(a)).all())
    if not integral:
        return None
    a, b = a.astype(np.int64), b.astype(np.int64)
    if a.min() < 0 or a.max() >= n:
        return None
    return a, b


def _reversed_polygons(faces):
    """``faces`` with every polygon's corners in reverse order (the other winding): ``f[:,
    ::-1]`` of an ``(f, k)`` array, each row reversed of a sequence of polygons."""
    try:
        f = np.asarray(faces)
    except (TypeError, ValueError):  # (ragged)
        f = None
    if f is not None and f.ndim == 2 and f.dtype != object:
        return f[:, ::-1]
    return [np.asarray(row)[::-1] for row in faces]  # (a loop over the polygons)


def winding_flipped(points: np.ndarray, faces) -> bool:
    """Whether ``faces`` are wound against the canonical winding of their mesh, which depends
    on the geometry alone (not in method.md; section 4 maps the boundary "in the direction of
    the oriented faces", which made a mesh and its copy with Flip Normals two mirrored maps,
    and every later frame- or seed-dependent choice differed: nefertiti got 496 and 564
    control points, three_peaks 635 and 647).

    Rule: the vector area ``A = sum over half-edges a -> b of (p_a - c) x (p_b - c)`` (twice
    the sum of the faces' vector areas; ``c`` the centre of the vertices' bounding box, so
    that coordinates far from the origin do not cancel), summed edge by edge: each
    undirected edge ``{i < j}`` counts ``(p_i - c) x (p_j - c)`` times its half-edges ``i ->
    j`` less its half-edges ``j -> i`` (0 for an interior edge of consistently oriented
    faces, so ``A`` is the boundary loop's vector area), in the order of the edges. The
    other winding negates every count, so its ``A`` is exactly ``-A``, bit for bit. The
    canonical winding has ``A_k > 0`` along the axis ``k`` of the largest ``|A_k|`` (the
    first of equal ones). When ``|A_k|`` is within WINDING_RTOL of ``sum |terms_k|`` (a
    boundary whose vector area cancels: a figure of eight, a nearly closed mesh with a
    pinhole), the rule is instead: of the vertices on edges with a nonzero count, the one of
    least coordinates (x, then y, then z, then index), and of its such edges the one to the
    neighbour of least coordinates; the canonical winding runs that edge away from it. A
    mesh with no such edge (closed; refused later) is left as given.

    Args:
        points: ``(n, 3)`` vertices.
        faces: ``(f, k)`` polygons or a sequence of polygons; faces that are no valid polygons
            are left as given (False) for :func:`parameterize_mesh` to refuse.

    Returns:
        True when the faces are to be reversed to the canonical winding.
    """
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    edges = _half_edges(faces, n)
    if edges is None:
        return False
    a, b = edges
    a, b = a[a != b], b[a != b]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key, inverse = np.unique(lo * n + hi, return_inverse=True)
    count = np.bincount(inverse.reshape(-1), weights=np.where(a < b, 1.0, -1.0),
                        minlength=len(key))
    on = count != 0.0
    if not on.any():
        return False
    key, count = key[on], count[on]
    i, j = key // n, key % n
    ends = np.concatenate([i, j])
    if not np.isfinite(p[ends]).all():
        return False
    c = 0.5 * (p[ends].min(axis=0) + p[ends].max(axis=0))
    terms = count[:, None] * np.cross(p[i] - c, p[j] - c)
    area = terms.sum(axis=0)
    k = int(np.argmax(np.abs(area)))
    if abs(area[k]) > WINDING_RTOL * float(np.abs(terms[:, k]).sum()):
        return bool(area[k] < 0.0)
    # no sign to trust: the edge from the vertex of least coordinates to its least neighbour
    verts = np.unique(ends)
    v = verts[np.lexsort((verts, *p[verts].T[::-1]))[0]]
    at = np.flatnonzero((i == v) | (j == v))
    other = np.where(i[at] == v, j[at], i[at])
    e = at[np.lexsort((other, *p[other].T[::-1]))[0]]
    away = (count[e] > 0.0) == (i[e] == v)  # (count > 0: more half-edges i -> j)
    return bool(not away)


# Spike vertices of a mesh (mesh_spikes): a vertex far above the plane of its 1-ring, steeper
# than any surface feature a smooth spline fits, over a ring that is itself nearly flat.
# Measured d / r (below): at most 0.92 on the bundled meshes and coarse test meshes, 5.7 at the
# apex of a cone of half-angle 10 degrees (8.1 at 7, 11 at 5: a needle); a vertex raised by 10
# on a grid of spacing 0.05 has 143 (on the border 180), its neighbours 0.02
_MESH_SPIKE_SLOPE = 10.0  # height above the ring's plane over the ring's size (84 degrees)
# ... and over the ring's own scatter off that plane: the raised vertex's ring scatters with the
# surface's curvature (d / s 2e5 there); at the most steeply raised vertex of each bundled mesh
# and coarse test mesh d / s is 2-14 and d / r below 1, and a ring bent round its vertex (a
# vertex beside a spike, a fin's edge) scatters about as far as the vertex is high
_MESH_SPIKE_FLAT = 10.0
_MESH_SPIKE_MAX_SHARE = 0.05  # more spikes than this share of the vertices: a rough mesh
_MESH_SPIKE_ROUNDS = 3  # the spikes found, dissolved, then the mesh without them checked again
_MESH_SPIKE_LEFT_OUT = 2  # the test again without 1, then 2 of each ring's farthest neighbours
_MESH_SPIKE_SLOPE_OF_3 = 30.0  # ... and where 3 are left, steeper than this (88 degrees)


def mesh_spikes(p: np.ndarray, tris: np.ndarray, edges=None) -> tuple[np.ndarray, np.ndarray]:
    """The spike vertices of the mesh ``(p, tris)`` (sorted indices) and their heights above
    the plane of their neighbours: a stray vertex raised out of the surface (a scan's spike, a
    vertex moved by mistake), which a mesh's faces hold in the fit as much as any other: a
    2-unit grid mesh of a smooth function with one vertex raised by 10 got 635 control points
    instead of 144 and missed its other vertices by up to 1.7e-2 (8.2e-4 without it); raised
    by 1e4, 178 control points and 0.151 (user test).

    At each vertex with at least 3 neighbours: the plane of its neighbours (PCA of the ring,
    the vertex itself not in it), the vertex's height ``d`` above it, the ring's size ``r``
    (the mean distance of the neighbours from their centroid) and the ring's own scatter ``s``
    off its plane (RMS). A spike has ``d > _MESH_SPIKE_SLOPE r`` (steeper than 84 degrees all
    round: a cone of half-angle below 5.7 degrees) and ``d > _MESH_SPIKE_FLAT s`` (its ring
    flat: at a crease, a ridge or a vertex beside a spike the ring is bent). Measured
    (/tmp/h86_measure.py of helper-86): the largest ``d / r`` is 0.65 on nefertiti.off, 0.92
    on patch-01.off, 0.52 on three_peaks.off, 0.79 on a grid folded along a 90-degree crease,
    at most 0.38 on sphere caps of 17-223 vertices, 0.69 on a half UV sphere of 13 vertices,
    0.58 on a half cylinder of 3 segments, 5.7 at the apex of a cone of half-angle 10 degrees;
    a vertex of a 40 x 30 grid (spacing 0.05) raised by 10 has 143 (on the border 180, by 1e4
    1.4e5), the vertices beside it 0.02. More than ``_MESH_SPIKE_MAX_SHARE`` of the vertices:
    a rough mesh, none is a spike. The vertex beside a spike sees it in its ring (bent: not
    flagged); two adjacent spikes see each other, so the test is made again with each ring
    without the neighbour farthest from its centroid, then the next one (at least 3 left;
    with 3, whose plane has no scatter, steeper than _MESH_SPIKE_SLOPE_OF_3): each is found
    then; a corner vertex of fewer than 3 neighbours is tested against the plane of its
    neighbours and theirs. A mesh of fewer than 20 vertices
    may have one spike (the share rounded up). Vectorized: sums over the edges (bincount) and
    one batched 3 x 3 eigendecomposition: 1.9 s for a grid mesh of 4.9e5 vertices (its map
    46 s, on the same busy machine); the rings without neighbours, on the vertices off their
    ring's centroid only, and the corners made it 1.2-1.5x (1.6-1.7 s against 1.1-1.35 s in one
    run, /tmp/s35/spk_t.py). ``edges``: the mesh's edges ``(ea, eb)`` when known."""
    n = len(p)
    none = np.zeros(0, dtype=np.int64), np.zeros(0)
    if edges is None:
        a, b = tris.reshape(-1), np.roll(tris, -1, axis=1).reshape(-1)
        key = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
        edges = key // n, key % n
    i, j = np.r_[edges[0], edges[1]], np.r_[edges[1], edges[0]]  # i's neighbour j
    # offsets from the vertex itself first (no cancellation at coordinates of 1e6 and more)
    rel = p[j] - p[i]
    spike, height, (deg, c, r) = _ring_spikes(i, rel, n, 3, stats=True)
    # the ring without the neighbour farthest from its centroid, then without the next one
    # (at least 3 left each time): adjacent spikes see each other in their rings, which are
    # bent, and none was found. Tested where the vertex is farther from its ring's centroid
    # than half the ring's size (a spike with m of its k neighbours raised: k / 2m, at least
    # 1.25 for the k >= m + 3 tested; a flat grid's inner vertices 0, its border ones 0.6)
    # (deg, c, r: the degrees, ring centroids and ring sizes, as _ring_spikes found them)
    sub = (deg >= 4)[i] & (np.linalg.norm(c, axis=1) > 0.5 * r)[i]
    ii, rr = i[sub], rel[sub]
    keep = np.ones(len(ii), dtype=bool)
    for _ in range(_MESH_SPIKE_LEFT_OUT if len(ii) else 0):
        left = np.maximum(np.bincount(ii[keep], minlength=n), 1)
        c = (np.column_stack([np.bincount(ii[keep], rr[keep, k], n) for k in range(3)])
             / left[:, None])
        far = np.where(keep, np.linalg.norm(rr - c[ii], axis=1), -1.0)
        order = np.lexsort((-far, ii))
        first = np.r_[True, ii[order][1:] != ii[order][:-1]]  # each vertex's farthest first
        keep[order[first]] = False
        # (3 left: their plane has no scatter, so the flat test cannot fail; then steeper:
        # a rough Delaunay mesh had a vertex 9x its 3 nearest neighbours' ring size above
        # them refused, review)
        more, high = _ring_spikes(ii[keep], rr[keep], n, 3, slope_of_3=_MESH_SPIKE_SLOPE_OF_3)
        height = np.where(spike, height, high)
        spike |= more
    # a corner vertex of fewer than 3 neighbours (one triangle, or two): against the plane of
    # its neighbours and theirs
    low = np.flatnonzero((deg > 0) & (deg < 3))
    if len(low):
        adjacency = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
        near = (adjacency[low] @ adjacency + adjacency[low]).tocoo()
        at, other = low[near.row], near.col
        mine = at != other
        more, high = _ring_spikes(at[mine], p[other[mine]] - p[at[mine]], n, 3)
        height = np.where(spike, height, high)
        spike |= more
    found = np.flatnonzero(spike)
    at = np.count_nonzero(deg >= 3)
    if len(found) == 0 or len(found) > max(1.0, _MESH_SPIKE_MAX_SHARE * at):
        return none
    return found.astype(np.int64), height[found]


def _ring_spikes(i: np.ndarray, rel: np.ndarray, n: int, least: int,
                 slope_of_3: float = _MESH_SPIKE_SLOPE, stats: bool = False):
    """:func:`mesh_spikes`' test at each of the ``n`` vertices with at least ``least`` of the
    neighbours given (``rel``: vertex ``i``'s neighbour minus the vertex), steeper than
    _MESH_SPIKE_SLOPE (``slope_of_3`` where exactly 3 are given): whether it is a spike (n,)
    and its height above the plane of those neighbours (n,; 0 where not tested); with
    ``stats`` also ``(deg, c, r)``: each vertex's number of neighbours given, their
    centroid (n, 3; relative to the vertex) and their mean distance from it (n,), which
    :func:`mesh_spikes` uses next. Neighbours of fewer than a quarter of the vertices (the
    rings without neighbours, the corners): tested on those vertices alone (the same sums
    in the same order, so the same values; not arrays of all ``n`` for a few rings)."""
    if not stats and 4 * len(i) < n:
        u, local = np.unique(i, return_inverse=True)
        spike, height = np.zeros(n, dtype=bool), np.zeros(n)
        spike[u], height[u] = _ring_spikes(local.reshape(-1), rel, len(u), least, slope_of_3)
        return spike, height
    deg = np.bincount(i, minlength=n)
    at = np.flatnonzero(deg >= least)
    spike, height = np.zeros(n, dtype=bool), np.zeros(n)
    if len(at) == 0 and not stats:
        return spike, height
    c = (np.column_stack([np.bincount(i, rel[:, k], n) for k in range(3)])
         / np.maximum(deg, 1)[:, None])
    x = rel - c[i]  # the neighbours from their centroid
    cov = np.empty((n, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(i, x[:, a] * x[:, b], n)
    cov /= np.maximum(deg, 1)[:, None, None]
    r = np.bincount(i, np.linalg.norm(x, axis=1), n) / np.maximum(deg, 1)
    if len(at) == 0:
        return spike, height, (deg, c, r)
    w, v = np.linalg.eigh(cov[at])
    s = np.sqrt(np.maximum(w[:, 0], 0.0))
    d = np.abs(np.einsum("ij,ij->i", c[at], v[:, :, 0]))  # (the vertex is at 0: -c off)
    slope = np.where(deg[at] == 3, slope_of_3, _MESH_SPIKE_SLOPE)
    spike[at] = (d > slope * r[at]) & (d > _MESH_SPIKE_FLAT * s)
    height[at] = d
    return (spike, height, (deg, c, r)) if stats else (spike, height)


def _dissolved(p: np.ndarray, tris: np.ndarray, spikes: np.ndarray) -> np.ndarray:
    """``tris`` (consistently oriented) without the vertices ``spikes`` and their faces, the
    polygon of each one's ring cut as a mesh's polygons are (core.geometry.polygon_triangles)
    instead (its neighbours in the order of its faces: a cycle inside, a chain closed by the
    edge between its two boundary neighbours on the border), with the faces' orientation. A
    loop over the spikes (a few)."""
    for v in spikes:
        mine = (tris == v).any(axis=1)
        around = tris[mine]
        k = np.argmax(around == v, axis=1)
        a = around[np.arange(len(around)), (k + 1) % 3]  # (v, a, b): the edge a -> b opposite
        b = around[np.arange(len(around)), (k + 2) % 3]
        after = dict(zip(a.tolist(), b.tolist()))
        starts = set(after) - set(b.tolist())  # a chain's first vertex (on the border)
        if len(starts) > 1:  # (a ring that is no single cycle or chain: left as it is)
            continue
        ring = [next(iter(starts)) if starts else int(a[0])]
        while ring[-1] in after and len(ring) <= len(around):
            ring.append(after[ring[-1]])
        if not starts:
            ring.pop()  # (the cycle back at its first vertex)
        ring = np.asarray(ring, dtype=np.int64)
        tris = tris[~mine]
        if len(ring) >= 3:  # (by the rule of a mesh's polygons: in its plane, its best ears)
            tris = np.vstack([tris, polygon_triangles(p, ring[None])])
    return tris


def parameterize_mesh(points: np.ndarray, faces: np.ndarray,
                      fill_holes: bool = False, _fill_from: int | None = None,
                      drop_outliers: bool | None = False) -> Parameterization:
    """Parameterize a triangle (or quad) mesh of disk topology over the unit disk (or a
    rectangle, or its own boundary flattened: below).

    ``fill_holes``: a mesh with holes (boundary loops besides the outer one, each at most
    half its size) is mapped as if they were filled (:func:`_with_holes_filled`), instead
    of refused; the surface then spans them.

    Boundary (method.md section 4): the boundary loop ``b_0, ..., b_{B-1}`` (in the direction of
    the oriented faces) goes to the unit circle by chord length,
    ``uv(b_i) = (cos 2 pi t_i, sin 2 pi t_i)``, ``t_i = L_i / L``, ``L_i`` the 3D length of the
    loop from ``b_0`` to ``b_i``. A loop with four corners (:func:`boundary_corners`: a grid
    mesh, a rectangular patch) goes to a rectangle instead, each side by chord length
    (:func:`_rectangle_boundary`; method.md's "or the unit square", in the mesh's
    proportions); the loop then starts at a corner. On the circle a corner's 90 degrees
    became 180: a 41 x 41 grid mesh's corners ended 0.03-0.05 off its fit (max error 0.049,
    272 control points; as a cloud 0.0017, 152); on the rectangle 0.0014 with 153, and
    three_peaks.off meets the default tolerance with 730 control points instead of 918.
    Interior: ``sum_j w_ij (uv_i - uv_j) = 0`` with Floater's
    mean-value weights (:func:`_mean_value_weights`), one sparse LU solve with two right-hand
    sides. Positive weights and a convex boundary give an embedding (Tutte/Floater); every uv
    triangle is checked to have positive area anyway.

    The boundary's own shape (not in method.md): :func:`_flattened_map` flattens the loop with
    its 3D edge lengths and turning angles (the interior's Gaussian curvature carried to it)
    and places the interior with the same mean-value solve (the factor is reused). That map is
    taken when its distortion (:func:`_map_energy`) exceeds an isometry's by less than
    ``FLAT_GAIN`` times the circle's or rectangle's (and has no flipped triangle). A ragged
    border on the circle is straightened and the triangles along it crushed: a 21 x 21 grid
    mesh without one boundary triangle needed 546 control points at the default tolerance
    (140 flattened), a 60-degree cap cut from a grid with a staircase border 781 (141), the
    scanned face 824 (722; benchmarks/mesh_maps.py). Steep peaks (three_peaks.off) keep their
    rectangle.

    Cleaning: quads are cut along their shorter diagonal, larger polygons by their best ears
    (:func:`core.geometry.polygon_triangles`, whatever corner they start at); faces with a
    repeated vertex and repeated faces are dropped; zero-area caps are flipped away
    (:func:`_flip_caps`); faces are re-oriented consistently (majority orientation kept).
    Vertices that no face references are left out: their ``uv`` rows are NaN and ``used`` is
    False.

    Spikes (not in method.md): a vertex that sticks out of its neighbours' plane far more
    steeply than any surface feature (:func:`mesh_spikes`) is refused (OutlierError, naming
    it), or with ``drop_outliers`` dissolved (:func:`_dissolved`: removed with its faces, the
    polygon of its neighbours triangulated in its plane) before the map, and left out as a
    loose vertex is (``outliers`` lists them). ``drop_outliers=None``: not checked.

    Winding (not in method.md): faces wound against the canonical winding of their geometry
    (:func:`winding_flipped`) are reversed first, so the map is that of the mesh with its
    normals flipped (bit for bit for ``f[:, ::-1]``, to rounding for Blender's Flip Normals,
    which keeps each face's first corner; an OBJ written with the other winding;
    they had mirrored maps, and nefertiti got 496 and 564 control points), and ``flipped``
    records it: a surface fitted to it faces the given winding's way
    (:class:`core.surface.TCBSurface`). ``_fill_from`` (the mesh with its holes closed,
    :func:`_with_holes_filled`): canonical already, taken as given.

    Args:
        points: ``(n, 3)`` vertex coordinates.
        faces: ``(f, 3)`` triangles or ``(f, k)`` polygons (e.g. quads) of vertex indices.

    Returns:
        A ``"disk"`` :class:`Parameterization`.

    Raises:
        InvalidInputError: bad arrays (shape, NaN, indices out of range, zero-length edges).
        TopologyError: non-manifold edges or vertices, several pieces, non-orientable, closed,
            several boundary loops, or not a disk (handles).
        ParameterizationError: a uv triangle came out flipped or degenerate.
        OutlierError: spike vertices (:func:`mesh_spikes`), unless ``drop_outliers``.
    """
    flipped = False
    if _fill_from is None:
        flipped = winding_flipped(_as_points(points, what="vertices"), faces)
        if flipped:
            faces = _reversed_polygons(faces)
    param = _parameterize_mesh(points, faces, fill_holes, _fill_from, drop_outliers)
    return replace(param, flipped=True) if flipped else param


def _parameterize_mesh(points: np.ndarray, faces: np.ndarray,
                       fill_holes: bool = False, _fill_from: int | None = None,
                       drop_outliers: bool | None = False) -> Parameterization:
    """:func:`parameterize_mesh` of faces taken in the winding given (the map itself).

    Cost: the two sparse factorizations (the cotangent Laplacian of :func:`_cotan_carried`,
    then the mean-value system) are most of it. ``parameterize`` of a binary-PLY grid mesh
    of a noisy bump (/tmp/u35/big_mesh_timing.py's generator; ``/usr/bin/time -v python -c
    "parameterize(*read_geometry('bigmesh.ply'))"``, versions alternated on a shared 2-core
    machine), seconds and peak RSS:

    ========================================  ==============  ===============
    ordering of the factors                   450x450 (2e5)   1000x1000 (1e6)
    ========================================  ==============  ===============
    COLAMD (the default), both held at once   7.4 s, 1.15 GB  91 s, 6.6 GB
    MMD_AT_PLUS_A, the cotangent one freed    5.3 s, 0.55 GB  50 s, 2.7 GB
    one :func:`_dissection_order` for both    4.3 s, 0.52 GB  34 s, 2.4 GB
    ========================================  ==============  ===============

    The uv the same to 5e-14 there and on data/*.off. A noisy mesh left on the circle makes
    the two again of its vertices smoothed (:func:`_denoised_own_map`, the first two freed
    before: 0.7-0.8 s more on a noisy L-shaped mesh of 250 x 250 vertices; review)."""
    p = _as_points(points, what="vertices")
    n = len(p)
    tris = _as_triangles(faces, n, p)

    # drop degenerate (repeated index) and repeated faces
    ok = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    tris = tris[ok]
    row = np.flatnonzero(ok)  # (the faces' rows: those from _fill_from on close holes)
    if len(tris) == 0:
        raise InvalidInputError(
            "every face of the mesh is degenerate (repeats a vertex); a disk-like patch of "
            "triangles or quads is needed"
        )
    corners = np.sort(tris, axis=1).astype(np.int64)
    if n < 2_097_152:  # (n^3 < 2^63) each face's sorted corners as one integer: 4.6x faster
        # than rows compared as records (1.7 against 0.37 s for 2e6 faces), the same firsts
        corners = (corners[:, 0] * n + corners[:, 1]) * n + corners[:, 2]
        _, first = np.unique(corners, return_index=True)
    else:
        _, first = np.unique(corners, axis=0, return_index=True)
    corners = None
    tris, row = tris[np.sort(first)], row[np.sort(first)]

    used = np.bincount(tris.ravel(), minlength=n) > 0
    if used.sum() < MIN_POINTS <= n:  # the plain "at least 10 points" would contradict n
        raise InvalidInputError(
            f"only {int(used.sum())} of the {n} vertices are in faces, and a mesh is fitted "
            f"through its faces (at least {MIN_POINTS} vertices are needed); to fit the vertices "
            "as a point cloud, pass them without faces (in Blender: delete the faces)"
        )
    _check_finite(p[used], what="referenced vertices")
    tris = _flip_caps(tris, p, frozen=None if _fill_from is None else row >= _fill_from)

    # undirected edges and their face counts
    he_from = tris.reshape(-1)
    he_to = np.roll(tris, -1, axis=1).reshape(-1)
    key = np.minimum(he_from, he_to) * n + np.maximum(he_from, he_to)
    ekey, edge_id, ecount = np.unique(key, return_inverse=True, return_counts=True)
    edge_id = edge_id.reshape(-1)
    n_nonmanifold = int(np.count_nonzero(ecount > 2))
    if n_nonmanifold:
        one = n_nonmanifold == 1
        raise TopologyError(
            f"the mesh has {n_nonmanifold} non-manifold edge{'' if one else 's'} (shared by more "
            "than two faces); a disk-like patch is needed: remove the extra faces at "
            f"{'that edge' if one else 'those edges'} (Blender: Select > Select All by Trait > "
            "Non Manifold)"
        )
    ea, eb = ekey // n, ekey % n

    # one connected piece
    graph = sp.coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    n_pieces = len(np.unique(label[used]))
    # the pieces' sizes in triangles, largest first (a stray piece of a selection is easy to
    # miss; triangles: a quad is two, and "faces" had summed to twice a selection's; user test)
    sizes = np.sort(np.bincount(label[tris[:, 0]]))[::-1] if n_pieces > 1 else None
    graph = label = None  # (freed: the arrays of the edges and half-edges are most of what
    # a large mesh's map holds besides its factors, 0.9 GB at 1e6 vertices)
    if n_pieces > 1:
        welded, gap = _welded_pieces(p, tris)
        if welded == n_pieces:  # none at equal positions: at nearly equal ones?
            lo, hi = column_bounds(p[used])
            welded, gap = _welded_pieces(p, tris, WELD_GAP * float(np.linalg.norm(hi - lo)))
        # (a seam whose copies an export rounded apart: the distance to merge by)
        where = ("equal positions" if gap == 0 else
                 f"nearly equal positions (up to {gap:.3g} apart)")
        merge = ("merge vertices at equal positions" if gap == 0 else
                 f"merge vertices by a distance above {gap:.3g}"
                 ) + " (Blender: Mesh > Clean Up > Merge by Distance) and fit again"
        if welded < n_pieces / 2:  # STL-style: corners not shared
            at = "the same position as" if gap == 0 else "nearly the position of"
            raise TopologyError(
                f"the mesh has {n_pieces} separate pieces because its faces do not share "
                f"vertices: each corner is its own vertex at {at} its neighbours' (as in STL "
                f"files); {merge}"
            )
        if welded < n_pieces:  # pieces that meet at vertices of equal positions: a seam
            raise TopologyError(
                f"the mesh has {n_pieces} separate pieces, which meet along a seam of "
                f"vertices at {where} (duplicated there, as by a UV seam split or an "
                f"export): merged, they are {welded}; {merge}")
        shown = ", ".join(str(int(k)) for k in sizes[sizes > 0][:5]) + (
            ", ..." if n_pieces > 5 else "")
        raise TopologyError(
            f"the mesh has {n_pieces} separate pieces (connected components) of {shown} "
            "triangles; "
            "one connected disk-like patch is needed: keep the largest piece or fit each piece "
            "separately"
        )

    tris = _orient_consistently(tris, edge_id)
    he_from = tris.reshape(-1)
    he_to = np.roll(tris, -1, axis=1).reshape(-1)
    key = np.minimum(he_from, he_to) * n + np.maximum(he_from, he_to)
    edge_id = np.searchsorted(ekey, key)  # reversed faces list their edges in another order

    # boundary: half-edges of edges with one face, in face direction (interior on the left)
    on_boundary = ecount[edge_id] == 1
    if not on_boundary.any():
        raise TopologyError(
            "the mesh is closed (it has no boundary); a disk-like open patch is needed: delete "
            "some faces to open it"
        )
    bf, bt = he_from[on_boundary], he_to[on_boundary]
    pinched = _split_vertices(tris, edge_id)
    he_from = he_to = key = edge_id = ecount = on_boundary = None  # (freed)
    if len(pinched):
        # a vertex duplicated at the same position, some of its faces on each copy: a slit
        # that meets the border at a vertex of equal position (user test)
        twins = cKDTree(p[used]).query(p[pinched], k=2)[0][:, 1] <= 0.0
        advice = ("merge vertices at equal positions (Blender: Mesh > Clean Up > Merge by "
                  "Distance): vertices there are duplicated, some of the faces around them on "
                  "each copy" if twins.any() else
                  "split or remove the faces there (Blender: Select > Select All by Trait > "
                  "Non Manifold with only Vertices on finds "
                  + ("it" if len(pinched) == 1 else "them")
                  + "; then Mesh > Split > Faces by Edges, or delete the touching faces)")
        where = ", ".join(f"{c:.6g}" for c in p[pinched[0]])
        raise TopologyError(
            f"the mesh has {len(pinched)} non-manifold "
            + ("vertex" if len(pinched) == 1 else "vertices")
            + " (the surface touches itself at a single vertex, "
            + ("" if len(pinched) == 1 else "the first ")
            + f"at ({where})); a disk-like patch is needed: {advice}"
        )
    if _fill_from is None and drop_outliers is not None:
        # spike vertices: refused, or dissolved and the mesh without them mapped (once)
        spikes, heights = mesh_spikes(p, tris, (ea, eb))
        if len(spikes):
            # dissolved, they may leave spikes that stood among them (the middle one of three
            # in a row: its ring bent by both), found on the mesh without them
            kept = _dissolved(p, tris, spikes)
            # (the share of a rough mesh, _MESH_SPIKE_MAX_SHARE, over all rounds: review)
            most = max(1.0, _MESH_SPIKE_MAX_SHARE * np.count_nonzero(np.bincount(
                np.r_[ea, eb], minlength=n) >= 3))
            for _ in range(_MESH_SPIKE_ROUNDS - 1):
                more, high = mesh_spikes(p, kept)
                if not len(more) or len(spikes) + len(more) > most:
                    break
                kept = _dissolved(p, kept, more)
                spikes, heights = np.r_[spikes, more], np.r_[heights, high]
            order = np.argsort(spikes)
            spikes, heights = spikes[order], heights[order]
        if len(spikes) and not drop_outliers:
            raise spike_error(p, spikes, heights)
        if len(spikes):
            param = _parameterize_mesh(p, kept, fill_holes, None, None)
            return replace(param, outliers=_readonly(spikes))
    bgraph = sp.coo_matrix((np.ones(len(bf)), (bf, bt)), shape=(n, n)).tocsr()
    _, blabel = connected_components(bgraph, directed=False)
    n_loops = len(np.unique(blabel[bf]))
    if n_loops > 1:
        return _with_holes_filled(p, tris, bf, bt, blabel, fill_holes)
    euler = int(np.count_nonzero(used)) - len(ekey) + len(tris)
    if euler != 1:
        raise TopologyError(
            f"the mesh is not a disk (Euler characteristic {euler}, a disk has 1): it has "
            f"handles or tunnels; cut them open so that the patch is a disk"
        )

    # the loop in order, starting at its vertex of least coordinates (x, then y, then z), so
    # that the map does not depend on how the vertices are numbered (from the least index, a
    # grid mesh's domain turned with the numbering, and its fit changed: user test)
    start = int(bf[np.lexsort(p[bf].T[::-1])[0]])
    loop = depth_first_order(bgraph, start, directed=True, return_predecessors=False)
    if len(loop) != len(bf):  # cannot happen after the checks above; keep the guarantee
        raise TopologyError("the boundary of the mesh is not a simple loop; a disk is needed")

    seg = np.linalg.norm(p[np.roll(loop, -1)] - p[loop], axis=1)
    elen = np.linalg.norm(p[eb] - p[ea], axis=1)
    n_zero = int(np.count_nonzero(elen <= 0.0))
    elen = None
    if n_zero:
        raise InvalidInputError(
            f"the mesh has {n_zero} zero-length edge{'' if n_zero == 1 else 's'} (coincident "
            "vertices); merge vertices by "
            "distance (Blender: Mesh > Clean Up > Merge by Distance) and try again"
        )
    uv = np.full((n, 2), np.nan)
    ears = _ears(tris, loop)
    corners = boundary_corners(p[loop], ears) if RECTANGLE_CORNERS else None
    if corners is not None and not np.isin(ears, corners).all():
        corners = None  # (a triangle of three vertices on one side would be flat: the circle)
    if corners is None:
        t = np.concatenate([[0.0], np.cumsum(seg[:-1])]) / seg.sum()
        uv[loop] = np.column_stack([np.cos(2.0 * np.pi * t), np.sin(2.0 * np.pi * t)])
    else:
        loop = np.roll(loop, -int(corners[0]))
        seg = np.roll(seg, -int(corners[0]))
        uv[loop] = _rectangle_boundary(seg, corners - corners[0])

    # interior: (D - W)_II uv_I = W_IB uv_B, D = diag(row sums of W)
    interior = used.copy()
    interior[loop] = False
    ii = np.flatnonzero(interior)
    w = lu = known = order = None
    if len(ii):  # (one ordering for the two systems on the interior's edges)
        at = np.full(n, -1)
        at[ii] = np.arange(len(ii))
        inner = (at[ea] >= 0) & (at[eb] >= 0)
        order = _dissection_order(at[ea[inner]], at[eb[inner]], p[ii])
    # the corner terms of the angle sums and of both weights, once (_corner_terms)
    terms = _corner_terms(p, tris) if (FLAT_BOUNDARY or len(ii)) else None
    if len(ii):
        w = _mean_value_weights(p, tris, n, terms)[ii]
    if FLAT_BOUNDARY:  # (the cotangent solve of _flattened_map first, its factor freed)
        theta = _angle_sums(p, tris, terms)
        system = _cotan_system(p, tris, loop, ii, terms) if len(ii) else None
        terms = None
        known = (theta, _cotan_carried(p, tris, loop, ii, 2.0 * np.pi - theta[ii], order,
                                       system) if len(ii) else np.zeros(len(loop)))
        system = None
    terms = None
    if len(ii):
        a = sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w[:, ii]
        rhs = w[:, loop] @ uv[loop]
        try:
            lu = _OrderedLU(a, order)  # (its pattern that of the cotangent system)
            sol = lu.solve(np.asfortranarray(rhs))
        except RuntimeError as exc:  # singular factor
            raise ParameterizationError(
                f"the mean-value system is singular ({exc}); the mesh has degenerate "
                "triangles: clean it up (Blender: Mesh > Clean Up > Degenerate Dissolve)"
            ) from None
        if not np.all(np.isfinite(sol)):
            raise ParameterizationError(
                "the mean-value system has no finite solution; the mesh has degenerate "
                "triangles: clean it up (Blender: Mesh > Clean Up > Degenerate Dissolve)"
            )
        uv[ii] = sol

    # the boundary's own shape instead, when that distorts the triangles less (FLAT_GAIN)
    flat = _flattened_map(p, tris, loop, ii, w, lu, known) if FLAT_BOUNDARY else None
    frames = None  # (the 3D part of the distortion, once for the maps compared)
    if flat is None and FLAT_BOUNDARY and PROJECTED_BOUNDARY:
        frames = _energy_frames(p, tris)
        flat = _projected_map(p, tris, loop, ii, w, lu, frames)
    if flat is not None:
        frames = _energy_frames(p, tris) if frames is None else frames
        fixed_energy = _map_energy(p, tris, uv, frames)
        flat_energy = _map_energy(p, tris, flat, frames)
        if flat_energy - 1.0 < FLAT_GAIN * (fixed_energy - 1.0) - FLAT_MIN_GAIN:
            uv = flat
    if flat is not uv and corners is None and len(ii) and FLAT_BOUNDARY and MAP_DENOISE:
        # a noisy mesh left on the circle: its own shape again, of its vertices smoothed
        w = lu = known = None  # (their factor freed first)
        uv = _denoised_own_map(p, tris, loop, ii, ea, eb, used, order, uv)

    # fold-over check: det(a, b, c) > 0 for every uv triangle
    ua, ub, uc = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    det = orient2d(ua, ub, uc)
    n_flipped = int(np.count_nonzero(~(det > 0.0)))
    if n_flipped:
        raise ParameterizationError(
            f"{n_flipped} of {len(tris)} triangles came out flipped or degenerate in the "
            "parameter domain; this happens with zero-area (sliver) triangles: clean up the mesh "
            "(Blender: Mesh > Clean Up > Degenerate Dissolve) and try again"
        )
    return Parameterization(
        uv=_readonly(uv),
        kind="disk",
        domain_polygon=_readonly(uv[loop]),
        used=_readonly(used),
        boundary=_readonly(loop.astype(np.int64)),
        faces=_readonly(tris),
        stretch=_readonly(_vertex_stretch(p, uv, ea, eb, used)),
    )


# a noisy mesh left on the circle (its own shape refused or distorting more) whose noise
# (local_noise) is at least this share of its median edge length tries its own shape again, of
# its vertices smoothed (_denoised_own_map)
MAP_DENOISE = True
MAP_NOISE_SPACING = 0.1
# Taubin passes (a shrinking and an inflating step each), tried in turn
MAP_SMOOTH_STEPS = (10, 30, 90)
MAP_SMOOTH_LAMBDA, MAP_SMOOTH_MU = 0.5, -0.53


def _smoothing(p, ea, eb, loop, used):
    """The operator of :func:`_denoised_own_map`'s smoothing of a mesh's vertices ``p`` (edges
    ``ea``-``eb``, boundary ``loop``; not in method.md): ``(mean, alone)``, ``mean @ p`` the mean
    of each vertex's neighbours (interior vertices: all of them; the boundary's: its two along
    it) and ``alone`` the vertices in no edge, which stay; None unless the mesh's noise
    (:func:`local_noise` of the ``used`` vertices) is at least MAP_NOISE_SPACING of its median
    edge length."""
    seg = np.linalg.norm(p[eb] - p[ea], axis=1)
    ids = np.flatnonzero(used)
    if len(ids) <= _NOISE_FAR or not len(seg):
        return None
    if not local_noise(p[ids]) >= MAP_NOISE_SPACING * float(np.median(seg)):
        return None
    n = len(p)
    border = np.zeros(n, dtype=bool)
    border[loop] = True
    rows, cols = np.r_[ea, eb], np.r_[eb, ea]
    inner = ~border[rows]
    rows = np.r_[rows[inner], loop, loop]
    cols = np.r_[cols[inner], np.roll(loop, 1), np.roll(loop, -1)]
    a = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    degree = np.asarray(a.sum(axis=1)).ravel()
    return sp.diags(1.0 / np.maximum(degree, 1.0)) @ a, degree == 0


def _denoised_own_map(p, tris, loop, interior, ea, eb, used, order, uv) -> np.ndarray:
    """A noisy mesh's map with its own boundary shape made of its vertices smoothed (the
    flattened map, else the projected one: :func:`_flattened_map`, :func:`_projected_map`)
    where that flips no triangle and distorts them less than the circle does (FLAT_GAIN and
    FLAT_MIN_GAIN, both maps of the smoothed vertices: the circle's interior solved again with
    their weights, and the distortion measured on them; against the circle of the noisy
    vertices' weights, whose rough interior distorts far more, a noisy cap and three_peaks.off
    with noise 0.3% had taken their own shape with no gain, the latter's fit's RMS 1.8x;
    review), else ``uv`` (its map on the circle; not in method.md). ``order``: the interior's
    ordering for the sparse factor.

    The smoothing is Taubin's ``lambda | mu`` (Taubin 1995: ``q += lambda (L q - q)``, then
    ``q += mu (L q - q)``, ``L q`` the mean of each vertex's neighbours, :func:`_smoothing`),
    which damps the noise at the scale of the edges and keeps the shape at larger ones without
    shrinking it; MAP_SMOOTH_STEPS passes in turn while the own shape is refused (an L-shaped
    mesh of 250 x 250 vertices with noise 0.2% of its diagonal, 0.7 of its spacing, needs 30;
    review). Only meshes whose noise is at least MAP_NOISE_SPACING of their median edge.

    Noise turns a border's vertices by tens of degrees, and the mesh's angle sums, by which
    the flattened border turns, are noise too: a noisy sheet whose border is L-shaped, ragged
    or a triangle went to the circle (its flattened border overlapped itself, or mean-value
    weights inside its dents flipped triangles), which squeezed its corners, the largest
    errors there (user test: 9-17 times the noise)."""
    smoothing = _smoothing(p, ea, eb, loop, used)
    if smoothing is None:
        return uv
    mean, alone = smoothing
    q, done = p.copy(), 0
    for steps in MAP_SMOOTH_STEPS:  # (more passes while its own shape is refused)
        for _ in range(steps - done):
            for step in (MAP_SMOOTH_LAMBDA, MAP_SMOOTH_MU):
                q += step * (mean @ q - q)
                q[alone] = p[alone]
        done = steps
        own = _own_map_of(q, tris, loop, interior, order, uv)
        if own is not None:
            return own[0] if own[1] else uv
    return uv


def _own_map_of(q, tris, loop, interior, order, uv) -> tuple[np.ndarray, bool] | None:
    """:func:`_denoised_own_map`'s map of the smoothed vertices ``q``: None when it is refused
    (not closed, not simple, pinched, flipping a triangle, or a failed factor), else the map
    and whether it distorts the triangles less than the circle ``uv``'s boundary with the
    interior of ``q``'s weights (FLAT_GAIN, FLAT_MIN_GAIN)."""
    terms = _corner_terms(q, tris)
    w = _mean_value_weights(q, tris, len(q), terms)[interior]
    theta = _angle_sums(q, tris, terms)
    system = _cotan_system(q, tris, loop, interior, terms)
    known = (theta, _cotan_carried(q, tris, loop, interior, 2.0 * np.pi - theta[interior],
                                   order, system))
    system = terms = None
    try:
        lu = _OrderedLU(sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w[:, interior], order)
    except RuntimeError:
        return None
    own = _flattened_map(q, tris, loop, interior, w, lu, known)
    frames = _energy_frames(q, tris)
    if own is None and PROJECTED_BOUNDARY:
        own = _projected_map(q, tris, loop, interior, w, lu, frames)
    if own is None or not (orient2d(own[tris[:, 0]], own[tris[:, 1]], own[tris[:, 2]]) > 0).all():
        return None
    circle = uv.copy()
    circle[interior] = lu.solve(np.asfortranarray(w[:, loop] @ uv[loop]))
    gain = _map_energy(q, tris, own, frames) - 1.0
    fixed = _map_energy(q, tris, circle, frames) - 1.0
    return own, bool(gain < FLAT_GAIN * fixed - FLAT_MIN_GAIN)


def _vertex_stretch(p, uv, ea, eb, used) -> np.ndarray:
    """How much a mesh's map compresses each vertex's surroundings: the largest ratio of 3D to
    uv length over the edges ``ea[i] - eb[i]`` at the vertex (NaN where not ``used``)."""
    ratio = np.linalg.norm(p[ea] - p[eb], axis=1) / np.maximum(
        np.linalg.norm(uv[ea] - uv[eb], axis=1), 1e-300
    )
    stretch = np.zeros(len(p))
    np.maximum.at(stretch, ea, ratio)
    np.maximum.at(stretch, eb, ratio)
    stretch[~used] = np.nan
    return stretch


def _loops_text(loops: int) -> str:
    return (f"the mesh has {loops} boundary loops (separate borders: an outer one and "
            f"{loops - 1} hole{'s' if loops > 2 else ''}, or the two ends of a tube)")


def holes_error(loops: int, advice: str = "fill_holes=True") -> HolesError:
    """The error for a mesh with ``loops`` boundary loops given without filling its holes;
    ``advice``: how to ask for that (the command line and Blender word it their way)."""
    return HolesError(
        f"{_loops_text(loops)}; a disk-like patch with exactly one border is needed: fill the "
        f"holes, or let the surface span them ({advice}), or cut the patch open, or fit its "
        "vertices alone as a point cloud (without the faces) if it is a height field", loops)


# fill_holes: a boundary loop is a hole when its bounding box's diagonal is at most this share
# of the largest loop's (a tube's two ends are not holes of one another)
HOLE_MAX_SHARE = 0.5
# ... and is closed by a fan around its border's mean when at most this share of the fan's
# area (in the plane of the hole's vector area) faces backwards, else by ear clipping of its
# border (:func:`_clipped_hole`): a C-shaped gap's fan overlaps the mesh (37% of it backwards,
# a crescent's 27%, an L's 9%: 319-616 control points where a round hole needs 147); a round
# hole in a triangulated grid, whose staircase border makes a few thin backward fan
# triangles, 0.1%; holes punched into three_peaks.off 2-4.5%, fitted as well as the whole.
# Fans span large round holes better than clipped borders (a hole of 912 cells in an 80 x 80
# grid: 0.0066 of the diagonal off the function inside it against 0.011)
HOLE_BACKWARD = 0.05
# ... and a hole whose fan bulges away from it is closed by ear clipping too: when the clipped
# border spans it with less than this share of the fan's area (3D). A slot two cells wide along
# the bend of a strip (benchmarks/holes.py) has 0.93, 0.81, 0.50 of its fan's area clipped at
# 15, 30, 90 degrees of bend, its fan facing backwards nowhere; clipped, the fit's RMS is
# 0.07-0.21x and its max 0.09-0.21x the fan's at 15-120 degrees (/tmp/s24/bendfit.py). Round holes have 0.99-1.0 and
# 29 holes punched into three_peaks.off 0.90-1.12, where clipping is no better (scratch
# /tmp/s24/area.py of the twenty-fourth session). The clipped area is at least the border's
# vector area, so a hole whose fan has more than this share of it in that area is not tried
HOLE_BULGE = 0.85


def _clipped_hole(p, a, b, normal, mesh_edges, uv=None) -> np.ndarray | None:
    """Triangles (m - 2, 3) closing a hole whose boundary half-edges are ``a -> b`` (the faces on
    their left), by its own border vertices, oriented as the faces; None when none is found.
    The border is walked against the half-edges (the hole then on its left, as a fan
    triangle ``(b, a, centre)`` has it) and clipped into ears
    (:func:`core.geometry.ear_clipping`, each ear chosen by its shape in 3D, ``p``) in the
    plane through the hole with unit ``normal`` when the border is a simple polygon there
    (C-, L-, S-shaped holes and crescents in a grid: 147-150 control points and max errors
    of 4.7-7.3e-4 of the diagonal, as for a round hole, where fans needed 558-616 and missed
    by 0.012-0.079); given ``uv`` (the plane failed), in the parameter domain ``uv`` of the
    mesh mapped with the hole closed by its fan (an embedding, so the border is a simple counter-clockwise
    polygon there; but a squeezed one: a crescent got max 0.017 so, 7.1e-4 in the plane). A
    diagonal that is an edge of the mesh (``mesh_edges``: sorted pair keys ``i n + j``,
    ``n = len(p)``) would make a non-manifold edge: the plane is then not used (in the map,
    that edge and the diagonal would be one segment, inside and outside the hole: it cannot
    happen there)."""
    m, n = len(a), len(p)
    order = np.argsort(a)
    succ = order[np.searchsorted(a, b, sorter=order)]  # position of b[i] in a
    walk = depth_first_order(sp.csr_matrix((np.ones(m), (np.arange(m), succ)), shape=(m, m)),
                             0, directed=True, return_predecessors=False)
    if len(walk) != m:
        return None
    r = a[walk][::-1]
    e1 = np.cross(normal, np.eye(3)[int(np.argmin(np.abs(normal)))])
    e1 /= np.linalg.norm(e1)
    q = p[r] - p[r].mean(axis=0)
    xy = np.column_stack([q @ e1, q @ np.cross(normal, e1)])
    if np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]) < 0:
        xy[:, 1] = -xy[:, 1]  # counter-clockwise (the vertex order, so the faces', is kept)
    side = np.sort(np.column_stack([r, np.roll(r, -1)]), axis=1)
    for plane in (xy,) if uv is None else (np.asarray(uv)[r],):
        if not simple_polygon(plane):
            continue
        tri = ear_clipping(plane, p[r])
        if tri is None:
            continue
        tri = r[tri]
        e = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        key = e[:, 0] * n + e[:, 1]
        diagonal = ~np.isin(key, side[:, 0] * n + side[:, 1])
        if not np.isin(key[diagonal], mesh_edges).any():
            return tri
    return None


def _with_holes_filled(p, tris, bf, bt, blabel, fill_holes: bool) -> Parameterization:
    """The map of a mesh with several boundary loops (``bf -> bt``: its boundary half-edges,
    ``blabel``: the loop of each vertex): with ``fill_holes``, every loop but the largest is
    a hole when the diagonal of its bounding box is at most HOLE_MAX_SHARE of the largest's
    (a loop's 3D length would count a border zigzagging down a steep slope as large: review).
    Each hole is closed by a fan of triangles around a new vertex at the mean of its border
    vertices, the filled mesh (one boundary loop) is mapped by :func:`parameterize_mesh`
    (the triangles that close holes take part in no cap flip), and the new vertices and
    triangles are left out again: the map of the mesh's own vertices and faces, over a domain
    that spans the holes (method.md section 4 has one boundary loop; not in it). Mean-value
    weights are positive on the fans as on any triangle, so the map has no folds; but where
    the centre does not see the whole border (a C-shaped gap) the fans overlap the mesh and
    squeeze its map (a C-shaped hole in a grid: max error 0.082 of the diagonal instead of
    1e-3; review). A hole more than HOLE_BACKWARD of whose fan area, in the plane of the
    hole's vector area, faces backwards is closed by triangles of its own border vertices
    instead (:func:`_clipped_hole`) and the mesh mapped again; one that cannot be (its
    border crosses itself in that plane and in the fans' map) is refused with advice. A hole
    whose fan bulges away from it (a slot along a bend) is clipped too when its border's
    triangles span it with less than HOLE_BULGE of the fan's area; otherwise, or when no
    such triangles are found, it keeps its fan."""
    n = len(p)
    loops = np.unique(blabel[bf])
    lo = np.full((int(blabel.max()) + 1, 3), np.inf)
    hi = np.full((int(blabel.max()) + 1, 3), -np.inf)
    np.minimum.at(lo, blabel[bf], p[bf])
    np.maximum.at(hi, blabel[bf], p[bf])
    size = np.linalg.norm(hi - lo, axis=1)
    outer = loops[np.argmax(size[loops])]
    holes = loops[loops != outer]
    share = float(size[holes].max() / size[outer])
    if share > HOLE_MAX_SHARE:  # (with or without fill_holes: no hole to fill)
        raise TopologyError(
            f"{_loops_text(len(loops))}; a disk-like patch with exactly one border is "
            f"needed, and the second largest border is {share:.2f} times the size of the "
            "largest, too large for a hole to be spanned (the two ends of a tube, a strip "
            "closed into a ring): cut the mesh open into a patch with one border, or fill the "
            "holes in the mesh"
        )
    if not fill_holes:
        raise holes_error(len(loops))
    # a fan per hole: for each of its boundary half-edges a -> b (faces on its left) the
    # triangle (b, a, centre), so that the fans are oriented as the faces
    on_hole = blabel[bf] != outer
    a, b = bf[on_hole], bt[on_hole]
    which = np.searchsorted(holes, blabel[a])
    count = np.bincount(which, minlength=len(holes))
    centre = np.column_stack([np.bincount(which, weights=p[a, k], minlength=len(holes))
                              for k in range(3)]) / count[:, None]
    fans = np.column_stack([b, a, n + which])
    normal = np.cross(p[a] - centre[which], p[b] - centre[which])  # (of (b, a, c), negated)
    vector_area = np.column_stack([np.bincount(which, weights=normal[:, k],
                                               minlength=len(holes)) for k in range(3)])
    unit = vector_area / np.maximum(np.linalg.norm(vector_area, axis=1), 1e-300)[:, None]
    along = np.einsum("ij,ij->i", normal, unit[which])  # twice the fan's area in the hole's plane
    back = np.bincount(which, weights=np.maximum(-along, 0.0), minlength=len(holes))
    total = np.bincount(which, weights=np.abs(along), minlength=len(holes))
    # every hole closed by its fan: mean-value weights are positive on any triangle, so the
    # map is an embedding; but a fan squeezes it where its centre does not see the hole's
    # border (C-shaped, L-shaped, crescents): those holes are closed by ear clipping of their
    # border instead (:func:`_clipped_hole`), in their plane or, failing that, in the map of
    # the mesh with the fans (made only then: a second solve; review)
    p_all = np.vstack([p, centre])
    fill = fans
    must = back > HOLE_BACKWARD * np.maximum(total, 1e-300)
    # fans that may bulge away from their hole (a slot along a bend): tried clipped too, and
    # clipped when that spans the hole with less than HOLE_BULGE of the fan's area
    fan_area = 0.5 * np.bincount(which, weights=np.linalg.norm(normal, axis=1),
                                 minlength=len(holes))
    may = ~must & (0.5 * np.linalg.norm(vector_area, axis=1) < HOLE_BULGE * fan_area)
    clip = np.flatnonzero(must | may)
    if len(clip):
        e = np.sort(np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        mesh_edges = np.unique(e[:, 0] * len(p_all) + e[:, 1])
        on = [which == h for h in clip.tolist()]  # (a loop over the holes to clip)
        closed = [_clipped_hole(p_all, a[w], b[w], unit[h], mesh_edges) for h, w in zip(clip, on)]
        if any(c is None for c in closed):
            try:
                fan_map = parameterize_mesh(p_all, np.vstack([tris, fans]), _fill_from=len(tris))
            except TCBError:  # (a fan's centre on its border: the hole is refused below)
                fan_map = None
            if fan_map is not None:
                closed = [c if c is not None else _clipped_hole(
                    p_all, a[w], b[w], unit[h], mesh_edges, uv=fan_map.uv)
                    for c, h, w in zip(closed, clip, on)]
        # a hole that only may be clipped keeps its fan unless clipping spans it with less area
        def area(t):
            return 0.5 * float(np.linalg.norm(np.cross(p_all[t[:, 1]] - p_all[t[:, 0]],
                                                       p_all[t[:, 2]] - p_all[t[:, 0]]),
                                              axis=1).sum())

        keep = [must[h] or (c is not None and area(c) < HOLE_BULGE * fan_area[h])
                for h, c in zip(clip, closed)]
        clip = clip[np.asarray(keep, dtype=bool)]
        closed = [c for c, k in zip(closed, keep) if k]
        refused = [int(h) for h, c in zip(clip, closed) if c is None]
        if refused:
            h = refused[0]
            where = ", ".join(f"{c:.6g}" for c in centre[h])
            raise ParameterizationError(
                f"{len(refused)} of the mesh's {len(holes)} holes cannot be spanned (the "
                f"first: a border of {int(count[h])} vertices around ({where})): the gap winds "
                "so that neither a fan from its centre nor a triangulation of its border "
                "closes it without squeezing the map; fill such holes in the mesh first "
                "(Blender: select the hole's border, then Face > Grid Fill or F) and fit again"
            )
        fill = np.vstack([fans[~np.isin(which, clip)]] + closed)
    filled = parameterize_mesh(p_all, np.vstack([tris, fill]), _fill_from=len(tris))
    if len(filled.faces) != len(tris) + len(fill):  # (rows kept in order: none is dropped)
        raise ParameterizationError("filling the mesh's holes changed its faces; fill the "
                                    "holes in the mesh first and fit again")
    faces = filled.faces[: len(tris)]
    uv = np.array(filled.uv[:n])
    used = np.array(filled.used[:n])
    edges = np.unique(np.sort(np.vstack([faces[:, [0, 1]], faces[:, [1, 2]],
                                         faces[:, [2, 0]]]), axis=1), axis=0)
    return Parameterization(
        uv=_readonly(uv),
        kind="disk",
        domain_polygon=filled.domain_polygon,
        used=_readonly(used),
        boundary=filled.boundary,
        faces=_readonly(faces),
        stretch=_readonly(_vertex_stretch(p, uv, edges[:, 0], edges[:, 1], used)),
        holes=_readonly(count.astype(np.int64)),
    )


# --------------------------------------------------------------------------------------------
# Where a point cloud's surface reaches, and the holes of a cloud (fill_holes)
# --------------------------------------------------------------------------------------------

# a cloud scanned in lines (its points' nearest spread across their line by less than TRIM_LINE
# of their variance along it) gets a tessellation reaching TRIM_GAP_FACTOR times the lower
# quartile of the distance to the data over a TRIM_LATTICE x TRIM_LATTICE lattice
# (trim_distance: the gaps between the lines)
# (the median ratio: random points 0.44, a grid 1; lines jittered across by 0.5 and 1 times
# their spacing along 0.03 and 0.10: /tmp/s24/ratio.py)
TRIM_LINE = 0.1
TRIM_GAP_FACTOR = 6.0
TRIM_LATTICE = 100
# the holes of a cloud (cloud_holes) are found on a lattice of cells of half the trim distance,
# at most this many along the longer side of the domain's box
CLOUD_HOLE_CELLS = 1024


def data_spacing(data: np.ndarray, tree: cKDTree) -> tuple[float, np.ndarray]:
    """The data's spacing: the median distance of a point to its nearest one at another place
    (a doubled point's twin is not its spacing), over a sample of about 5000 of the
    parameters ``data`` taken in the order of their coordinates
    (:func:`core.geometry.coordinate_order`: the same for any order of the points); ``tree``
    a KD-tree of them. Also the sample's 9 nearest points ``(s, 9)`` (fewer for fewer data),
    themselves first. 0.0 when no two points are apart."""
    order = coordinate_order(data)
    sample = (data if order is None else data[order])[:: max(1, len(data) // 5000)]
    dist, nb = tree.query(sample, k=min(9, len(data)))
    apart = np.where(dist[:, 1:] > 0, dist[:, 1:], np.inf).min(axis=1, initial=np.inf)
    apart = apart[np.isfinite(apart)]
    return (float(np.median(apart)) if len(apart) else 0.0), nb


def trim_distance(param: Parameterization, data: np.ndarray | None = None,
                  tree: cKDTree | None = None) -> float:
    """How far from the data a cloud's tessellation reaches (not in method.md): 4 times
    the data's spacing (the median distance of a point to its nearest one); for a scan
    made in lines (the median point's 8 nearest spread across their line by less than
    TRIM_LINE of their variance along it: profiles, sonar tracks, a CMM), whose spacing
    along the lines does not see the gaps between them (user test: 10 profiles 0.11 apart,
    1000 points each, tessellated at 256 covered 0.11 of the area between them), the
    larger of that and TRIM_GAP_FACTOR times the lower quartile of the distance to the
    data over a TRIM_LATTICE x TRIM_LATTICE lattice in the domain: points of the lattice
    in a gap between lines are up to half its width from the data, evenly, so the
    quartile is about an eighth of it. (Not for clouds spread in two directions: a thin
    L-shaped cloud or a road round a bend covers so little of its hull that the quartile
    falls in the empty part; review.) ``data``: the finite rows of ``param.uv`` and
    ``tree`` a KD-tree of them (made when not given). The sample of the points measured is
    taken in the order of their coordinates (:func:`core.geometry.coordinate_order`), so the
    same cloud stored in another order gets the same distance (a gap had been a hole in some
    orders and not in others: review), and the spacing is to the nearest point at another
    place (a cloud of doubled points had a spacing, so a reach, of 0: its mesh fell apart into
    404 pieces at resolution 128; review)."""
    if data is None:
        data = np.asarray(param.uv)[np.isfinite(param.uv).all(axis=1)]
    if tree is None:
        tree = cKDTree(data)
    spacing, nb = data_spacing(data, tree)
    if nb.shape[1] < 3:
        return 4 * spacing
    X = data[nb]
    X = X - X.mean(axis=1, keepdims=True)
    ev = np.linalg.eigvalsh(np.einsum("mki,mkj->mij", X, X))  # ascending
    ratio = float(np.median(ev[:, 0] / np.maximum(ev[:, 1], 1e-300)))
    if ratio >= TRIM_LINE:
        return 4 * spacing
    poly = np.asarray(param.domain_polygon, dtype=np.float64)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    g = [np.linspace(lo[k], hi[k], TRIM_LATTICE + 2)[1:-1] for k in range(2)]
    grid = np.stack(np.meshgrid(*g), -1).reshape(-1, 2)
    grid = grid[param.contains(grid)]
    if len(grid) == 0:
        return 4 * spacing
    gap = float(np.quantile(tree.query(grid)[0], 0.25))
    return max(4 * spacing, TRIM_GAP_FACTOR * gap)


class HoleLattice(NamedTuple):
    """The holes of a point cloud's domain (:func:`_cloud_hole_lattice`)."""

    lo: np.ndarray
    h: float
    mask: np.ndarray
    sizes: np.ndarray
    wide: float
    depth: np.ndarray
    trim: float


def _cloud_hole_lattice(param: Parameterization) -> HoleLattice:
    """Kept on ``param`` (immutable) after the first call: :func:`_hole_lattice`."""
    lattice = param.__dict__.get("_hole_lattice")
    if lattice is None:
        lattice = _hole_lattice(param)
        object.__setattr__(param, "_hole_lattice", lattice)
    return lattice


def _hole_lattice(param: Parameterization) -> HoleLattice:
    """:class:`HoleLattice` ``(lo, h, mask, sizes, wide, depth, trim)``: the holes of a point
    cloud's domain on a lattice of cells of side ``h`` from ``lo`` (cell ``[i, j]`` is centred
    at ``lo + h (j + 1/2, i + 1/2)``), ``mask[i, j]`` True in a hole, ``sizes`` the cells of
    each hole and ``depth`` about the largest distance of its cells' centres from the data (uv
    units; from a distance transform of the lattice, to a cell),
    ``wide`` the largest box diagonal of an empty region too large to be a hole, as a share of
    the domain's (0.0 when there is none). No data point lies in a hole's cell (its
    centre is farther than its half-diagonal from all). A hole is a 4-connected region of cells
    whose centres are farther than :func:`trim_distance` less the cells' half-diagonal from
    every data parameter (so every point farther than the trim distance is in one of them)
    that does not reach the border of the domain (the convex hull: a region that
    does is a bay or a notch, the shape of the data's outline), and whose box has at most
    HOLE_MAX_SHARE of the diagonal of the domain's box, both boxes in the model's axes (the
    plane points of the cells and of the domain polygon: the uv axes turn with the data; a
    mesh's hole: :func:`_with_holes_filled`; a ring's wide middle is not a hole). Not in
    method.md."""
    data = np.asarray(param.uv)[np.isfinite(param.uv).all(axis=1)]
    tree = cKDTree(data, balanced_tree=False, compact_nodes=False)  # (2.5x faster to make)
    trim = trim_distance(param, data, tree)
    poly = np.asarray(param.domain_polygon, dtype=np.float64)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    extent = hi - lo
    h = max(trim / 2, float(extent.max()) / CLOUD_HOLE_CELLS, 1e-12)
    # a cell is empty when its centre is farther than this from the data: then every point
    # farther than trim is in an empty cell (its centre within h / sqrt 2 of it: a gap
    # narrower than a cell had left a pinhole at resolution 256; review), and no data point
    # is (within h / sqrt 2 of the centre)
    reach = max(trim - h / np.sqrt(2), h / np.sqrt(2))
    nu, nv = (np.ceil(extent / h).astype(int) + 1).tolist()
    cu = lo[0] + h * (np.arange(nu) + 0.5)
    cv = lo[1] + h * (np.arange(nv) + 0.5)
    centres = np.stack(np.meshgrid(cu, cv), -1).reshape(-1, 2)
    inside = param.contains(centres)
    far = np.ones(len(centres), dtype=bool)
    far[inside] = tree.query(centres[inside], distance_upper_bound=reach)[0] > reach
    # a ring of cells outside the lattice: regions touching its edge reach the border
    empty = np.pad(far.reshape(nv, nu), 1, constant_values=True)
    outside = np.pad(~inside.reshape(nv, nu), 1, constant_values=True)
    labels, count = ndimage.label(empty)
    border = np.zeros(count + 1, dtype=bool)
    border[labels[outside]] = True
    border[0] = True  # (cells near the data)
    # each region's box in the model's axes (the plane points of its cells' centres)
    def plane(x):
        return x @ np.asarray(param.axes)[:2] * param.scale

    cells = labels[1:-1, 1:-1].ravel()
    which = ~border[cells]
    at, lab = plane(centres[which]), cells[which]
    low = np.full((count + 1, 3), np.inf)
    high = np.full((count + 1, 3), -np.inf)
    np.minimum.at(low, lab, at)
    np.maximum.at(high, lab, at)
    box = plane(poly)
    share = (np.linalg.norm(np.maximum(high - low, 0.0), axis=1)
             / float(np.linalg.norm(np.ptp(box, axis=0))))
    share[border] = 0.0
    large = share > HOLE_MAX_SHARE
    hole = ~border & ~large
    wide = float(share.max(initial=0.0)) if large.any() else 0.0
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[hole]
    mask = hole[labels]
    # how far each hole reaches from the data: from its cells' distance (in cells) to the
    # nearest cell near the data (a query of every hole cell took 2.6 s for a hole of radius
    # 0.45 in 1e6 points; review)
    steps = ndimage.distance_transform_edt(empty)
    depth = np.zeros(count + 1)
    inner = hole[labels]
    np.maximum.at(depth, labels[inner], reach + h * (steps[inner] - 1.0))
    return HoleLattice(lo, h, mask[1:-1, 1:-1], sizes.astype(np.int64), wide, depth[hole], trim)


def cloud_holes(param: Parameterization) -> Parameterization:
    """``param`` (a point cloud's) with ``holes`` set to the cells of each hole of its domain
    (:func:`_cloud_hole_lattice`), or None when it has none: ``fill_holes=True`` for a cloud.
    Its tessellation then covers the holes, where the surface is held by the fairing as
    between any data, and :meth:`Parameterization.in_holes` finds them. A gap inside the
    cloud too large to be a hole (a ring's middle) is left open, with a RuntimeWarning."""
    lattice = _cloud_hole_lattice(param)
    if lattice.wide:
        warnings.warn(
            f"fill_holes: a gap inside the point cloud {lattice.wide:.2f} times its size across "
            f"(more than {HOLE_MAX_SHARE:g}: the middle of a ring, not a hole in a scan) is left "
            "open", RuntimeWarning, stacklevel=4)
    if not len(lattice.sizes):
        return param
    param = replace(param, holes=_readonly(lattice.sizes))
    object.__setattr__(param, "_hole_lattice", lattice)  # (the same data: its cache)
    return param


def gaps_beyond(param: Parameterization, reach: float | None = None) -> int:
    """How many holes of a point cloud (:func:`_cloud_hole_lattice`) reach farther than
    ``reach`` (uv units; at least the trim distance, its default) from the data: the gaps a
    tessellation that keeps to within ``reach`` of the data leaves open, or with
    ``fill_holes`` covers (``report["holes_filled"]``; the voids between random points
    nearer than that, which the lattice finds too, are covered but not counted). 0 for a
    mesh. About a KD-tree of the data parameters at the first call (0.06 s at 3e4 points,
    1.3 s at 1e6; cached on ``param``)."""
    if param.kind != "plane":
        return 0
    lattice = _cloud_hole_lattice(param)
    reach = lattice.trim if reach is None else max(float(reach), lattice.trim)
    return int(np.count_nonzero(lattice.depth > reach))


def in_voids(param: Parameterization, uv, reach: float | None = None) -> np.ndarray:
    """Mask (m,) of the parameters ``uv`` (m, 2) in a void of a point cloud: a hole of its
    lattice (:func:`_cloud_hole_lattice`) that reaches no farther than ``reach`` (uv units; at
    least the trim distance, its default) from the data, which :func:`gaps_beyond` does not
    count. Such voids are the spaces between random points a little wider than the trim
    distance, not gaps: the tessellation and :meth:`core.surface.TCBSurface.heights` cover
    them (15 000 random points: the largest empty circle is about 4.3 times the median
    spacing, and ``heights`` had been NaN at a point of a 120 x 120 grid over the cloud with
    the nearest data 1.05 trim distances away). All False for a mesh. Not in method.md."""
    x = np.atleast_2d(np.asarray(uv, dtype=np.float64))
    found = np.zeros(len(x), dtype=bool)
    if param.kind != "plane" or not len(x):
        return found
    lattice = _cloud_hole_lattice(param)
    if not len(lattice.depth):
        return found
    reach = lattice.trim if reach is None else max(float(reach), lattice.trim)
    # the holes, labelled as _hole_lattice labels them (4-connected, in the lattice's order)
    labels, _ = ndimage.label(lattice.mask)
    small = np.r_[False, lattice.depth <= reach]
    cell = np.floor((x - lattice.lo) / lattice.h)
    cell = np.where(np.isfinite(cell), cell, -1).astype(np.int64)
    ok = ((cell >= 0) & (cell < [labels.shape[1], labels.shape[0]])).all(axis=1)
    found[ok] = small[labels[cell[ok, 1], cell[ok, 0]]]
    return found


def open_holes(param: Parameterization, reach: float | None = None) -> int:
    """How many holes of a point cloud reach farther than ``reach`` (see :func:`gaps_beyond`)
    and are left open: 0 for a mesh and for a cloud fitted with ``fill_holes``."""
    if param.kind != "plane" or param.holes is not None:
        return 0
    return gaps_beyond(param, reach)


def parameterize(
    points: np.ndarray, faces: np.ndarray | None = None, drop_outliers: bool = False,
    projection=None, fill_holes: bool = False,
) -> Parameterization:
    """Parameterize a point cloud (``faces is None``) or a disk-like mesh (method.md section 4).

    Dispatches to :func:`parameterize_points` (best-fit plane; outliers are refused, or left
    out with ``drop_outliers``) or :func:`parameterize_mesh` (mean-value map onto the unit
    disk; spike vertices, :func:`mesh_spikes`, are refused, or with ``drop_outliers``
    dissolved out of the mesh and left out as loose vertices are).
    """
    if faces is None:
        param = parameterize_points(points, bool(drop_outliers), projection)
        return cloud_holes(param) if fill_holes else param
    if projection is not None:
        raise InvalidInputError(
            "a projection direction applies to point clouds; a mesh is parameterized by its "
            "faces (flattened): leave the projection automatic (in Blender: Auto)"
        )
    return parameterize_mesh(points, faces, fill_holes=fill_holes,
                             drop_outliers=bool(drop_outliers))
