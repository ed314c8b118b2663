"""The fitted surface: :class:`TCBSurface` and :func:`fit_surface` (method.md sections 4-7).

Like scipy's ``BSpline``, a surface is a small immutable object (knots, configurations, degree,
control points, parameterization) that is callable on parameters and built by a free function::

    surf = fit_surface(points)              # (N, 3) cloud, or points + faces of a disk mesh
    xyz = surf(uv)                          # (m, 2) parameters -> (m, 3) points
    verts, faces = surf.tessellate(64)
    net_points, net_faces = surf.control_net()
    surf.save("a.npz"); TCBSurface.load("a.npz")

The fit runs in normalized coordinates ``q = (p - c) / s`` (bounding-box centre and half
diagonal); since the basis is a partition of unity, the control points are mapped back with the
same affine map, so the surface is exactly the fit in the user's units.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import io
import json
import os
import secrets
import stat
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from .configurations import Configurations
from .errors import CancelledError, FileFormatError, InvalidInputError, TCBError
from .fit import (AUTO_SMOOTHNESS, DEFAULT_SMOOTHNESS, SPARSE_POINTS_PER_CONTROL,
                  SPARSE_SMOOTHNESS, DefaultSmoothness, check_smoothness, fit_control_points)
from .geometry import column_bounds, coordinate_order, float32_rounding
from .join import join_fit, join_warning, seams
from .parallel import background
from .parameterize import (
    Parameterization, _as_points, _check_finite, _degrees_note, _edge_pairs, _local_planes,
    box_normalization,
    _parameterize_mesh, corner_angles, fill_value_rows, fill_value_words, huge_rows, huge_words,
    in_voids, local_noise, local_scatter, normalize, open_holes, parameterize, spike_points,
    trim_distance, gaps_beyond,
)
from .refine import (ITERATION_POINTS, STALLED, RefineOptions, _cancel_requested, adaptive_fit,
                     area_weights, check_callback, prefetch_swing_triangles, swing_places)
from .smooth_faces import (clough_tocher_points, face_gradients, mean_gradients,
                           vertex_adjacency, vertex_gradients)
from .spline_space import SplineSpace, _whole, derivative_order, frozen
from .simplex import orient2d

__all__ = ["TCBSurface", "fit_surface", "FORMAT_VERSION"]

# 2: the options may hold smoothness "auto" (older readers refuse such files with "update the
# add-on" instead of failing in refine()); files without it are still written as 1.
# 3: compact (``to_bytes(compact=True)``): the data's parameters and errors in float32, which
# older readers would hand on as such; files without either are written as before
# 4: a surface fitted to a mesh wound against its canonical winding (``param_flipped``,
# Parameterization.flipped): older readers would tessellate it facing the other way, so such
# files are refused by them ("update the add-on"); other files are written as before
FORMAT_VERSION = 4
# compact files: these arrays are stored as float32 (the data's parameters and fitted errors, a
# mesh's vertex stretch) and read back as float64; a mesh's faces as "param_faces_delta"
_COMPACT_FLOAT = ("param_uv", "param_stretch", "errors")
# Larger inputs are fitted on a seeded random subset of this size (a RuntimeWarning says so);
# 1e6 points fit in about 0.4 GiB, so this keeps the peak well under the 4 GiB budget.
MAX_FIT_POINTS = 2_000_000
# A parameter domain thinner than this (width / length) is a curve, not a surface.
MIN_ASPECT = 1e-3
# ... unless they hold at least this many point spacings across (for n points over a domain
# of w by l, about sqrt(n w / l))
MIN_ACROSS = 5.0
# closest points (TCBSurface._newton_closest, _descend): a point stops when its next step
# would change its distance by less than this share of the surface's size; a cloud's points
# are also taken from their nearest start when it is more than this many steps of the
# 96-step tessellation from where their projection's descent ended
CLOSEST_DISTANCE_TOL = 1e-9
CLOSEST_SAME_BASIN = 2.0
# ... and a point that ended off the surface (farther than CLOSEST_ON_SURFACE of its size) also
# descends from those of its CLOSEST_STARTS nearest starts that lie on its side of the tangent
# plane at its foot, at an angle above asin(CLOSEST_OTHER_SHEET) from it (another part of the
# surface may be closer there), and again from its foot when its rounds ran out
# (TCBSurface._other_starts): a coarse mesh fitted with many control points folds at its
# creases within a step of the starting tessellation, and its own tessellation's vertices
# measured up to 8.9e-3 of its diagonal from it (user test: 4.4e-3 on a Suzanne patch)
CLOSEST_STARTS = 4
CLOSEST_ON_SURFACE = 1e-7
CLOSEST_OTHER_SHEET = 0.1
# closest points are computed in chunks of this many points: a callback hears of each (progress,
# cancellation) and the descent's work arrays stay bounded (1e6 points in 16 chunks)
CLOSEST_CHUNK = 1 << 16
# ... and those whose closest point lies on the trimmed edge start along it from the nearest of
# this many surface points per edge of the domain polygon (TCBSurface._edge_closest)
CLOSEST_EDGE_SAMPLES = 8
# the finest tessellation (grid steps along the longer side): 2048 took about a minute and 2
# GiB, 3000 86 s and 3.7 GB (user test)
MAX_RESOLUTION = 4096
# tessellation: rounds of edge splits where the data parameters are denser than on average
TESSELLATION_SPLITS = 4
# auto_resolution's candidates, coarsest first: each costs its grid and a sag over all its
# edges (883 control points: 0.2 / 0.7 / 2.5 / 7.5 s at 64 / 128 / 256 / 512 on a loaded
# machine, /tmp/s34/sag_check.py), so 512 is left to Re-tessellate (Blender's warning says so)
AUTO_RESOLUTIONS = (64, 128, 256)
AUTO_RESOLUTION_FLOOR = 1e-6  # ... and a mesh within this share of the diagonal is taken
# auto_resolution measures the edges of every SAG_SAMPLE_STRIDE-th triangle of a candidate it
# may pass over first (an eighth of the evaluations of its whole sag: as many vertices as
# midpoints): one of them beyond the target rejects it, the rest unmeasured. On three_peaks,
# nefertiti and patch-01 (default tolerance and 3e-4) and two clouds, the candidates passed
# over strayed on 0.07-10% of their edges, and the sample rejected each, but for three_peaks'
# and nefertiti's 64 at the default (2 and 1 edges: the rest measured too; /tmp/h97_work/
# analyze.py and count.py of the 97th helper)
SAG_SAMPLE_STRIDE = 24


def sag_target(report, options=None) -> float:
    """How close to the spline :meth:`TCBSurface.auto_resolution` holds its mesh, model units:
    the fit's max error at its data (``report["max"]``), at least AUTO_RESOLUTION_FLOOR of the
    data's diagonal (a plane's max error is rounding, which no mesh is within) and the
    tolerance asked for in ``options`` (the fit's RefineOptions; an exact quadratic fitted
    to 2.8e-7 of its diagonal for a tolerance of 4.4e-6 had been told to Re-tessellate at 512
    for a mesh 1.6e-6 from the spline: user test); NaN without a max."""
    rep = report or {}
    diagonal = float(rep.get("diagonal", 0.0))
    tol = getattr(options, "tolerance", 0.0)
    tol = (float(tol) * (diagonal if getattr(options, "relative", True) else 1.0)
           if isinstance(tol, (int, float)) and np.isfinite(tol) else 0.0)
    return max(float(rep.get("max", np.nan)), AUTO_RESOLUTION_FLOOR * diagonal, tol)

# the edge-split rounds look a mesh's compression up on a grid of at most this many cells along
# the longer side (4x finer than the tessellation's grid up to resolution 128)
TESSELLATION_STRETCH_CELLS = 512
# grid steps across the shorter side of the domain at least (a road strip 250 times longer than
# wide had 143 triangles in one row at resolution 64, up to 0.34 m off an 8 m wide road)
TESSELLATION_MIN_ACROSS = 8
# a domain that fills less than this share of the square on the longer side of its grid frame
# (a long or ragged patch) gets a finer grid step, as many cells inside it as a domain filling
# this share (tessellation_step): a Suzanne brow patch (0.26 of its square) had 1222 vertices
# at resolution 64, its input vertices up to 8.6e-3 of the diagonal from the mesh for a fit
# of 3.3e-3 (user test); now 2440 and 4.1e-3. A disk fills 0.785, nefertiti's map 0.71: as before
TESSELLATION_FULL_SHARE = 0.5
# tessellation_uv keeps this many of the most recent resolutions (a fine one is megabytes)
TESSELLATION_CACHE = 4
# the spline is defined where its basis sums to 1 to within this (TCBSurface.covers)
_COVER_TOL = 1e-9
_OPTION_NAMES = tuple(f.name for f in dataclasses.fields(RefineOptions))
_PARAM_FIELDS = ("uv", "domain_polygon", "used", "boundary", "faces", "origin", "axes", "stretch",
                 "holes", "outliers")


def sag_target_words(report, options=None, length=lambda x: f"{x:.4g}") -> str:
    """What :func:`sag_target` is, for the notes of a straying mesh: "the fit's max error
    0.0013", or "the tolerance asked for, 0.002" where that is the larger (a mesh within the
    tolerance was said to stray "more than the fit's max error": review), or "1e-06 of the
    diagonal"; ``length`` writes a length (Blender: in the scene's unit)."""
    target = sag_target(report, options)
    worst = float((report or {}).get("max", np.nan))
    if not target > worst:
        return f"the fit's max error {length(worst)}"
    if target > AUTO_RESOLUTION_FLOOR * float((report or {}).get("diagonal", 0.0)):
        return f"the tolerance asked for, {length(target)}"
    return f"{AUTO_RESOLUTION_FLOOR:g} of the diagonal"


def finer_resolution(resolution: int, sag: float, target: float,
                     coarser: float | None = None) -> int:
    """The resolution at which a mesh of ``sag`` at ``resolution`` would come within ``target``
    of the spline, rounded up to a power of two times ``resolution`` and at most
    MAX_RESOLUTION (what the command line and Blender advise when Auto Resolution's finest
    strays). The sag falls by ``coarser / sag`` per doubling, ``coarser`` the sag at half the
    resolution, taken between 2 and 4; 4 without it (a quadratic's chord error: h^2). Where
    the spline bends across a knot line sharper than the grid step (a crease) it falls only
    2x: patch-01's fit 2.05, 0.996, 0.481, 0.225, 0.103 at resolutions 64 to 1024, its median
    edge 4x (/tmp/s36/sagrate.py); at 4x the advice had undershot by one doubling."""
    if not (sag > target > 0):
        return int(resolution)
    rate = 4.0 if coarser is None or not np.isfinite(coarser) else float(
        np.clip(coarser / sag, 2.0, 4.0))
    doublings = int(np.ceil(np.log(sag / target) / np.log(rate) - 1e-9))
    return int(min(MAX_RESOLUTION, resolution * 2 ** max(doublings, 1)))


def _readonly(a):
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _frozen_parameterization(param: Parameterization) -> Parameterization:
    """``param`` with read-only arrays (a new object only if one was writeable, e.g. read
    from a file; :func:`parameterize` makes them read-only already)."""
    writeable = {name: frozen(getattr(param, name)) for name in _PARAM_FIELDS
                 if isinstance(getattr(param, name), np.ndarray)
                 and getattr(param, name).flags.writeable}
    return dataclasses.replace(param, **writeable) if writeable else param


class TCBSurface:
    """A TCB (or DCB) spline surface ``S(x) = sum_I c_I B_I(x)`` fitted to data.

    Attributes (arrays are read-only, and so are those of ``space`` and ``parameterization``)
    ----------
    space : SplineSpace (knots, configurations, degree, basis)
    control_points : (n, 3) float64, read-only, in the data's units: one per basis function
        whose support meets the data's parameter domain (``active``); the others only carry
        the border rings' partition of unity (method.md section 3), vanish on the domain and
        are not control points (their coefficients, in ``coefficients``, extend the surface
        outside the domain)
    active : (n,) int, the basis index (in ``space``) of each control point
    coefficients : (n_basis, 3) float64, read-only, the coefficients of every basis function
    parameterization : Parameterization of the data it was fitted to
    errors : (N,) float64, ``|S(x_j) - p_j|`` of the last fit (NaN for unused mesh vertices and
        dropped outliers); of the fit's control points, also after :meth:`with_control_points`
        (the surface keeps no copy of the data to measure an edit against)
    report : dict, statistics of the fit (knots, control points, rms, max, history, ...); a new
        deep copy on every access. Like ``errors`` they are the fit's: a surface whose control
        points were edited since (:meth:`with_control_points`) says so with
        ``report["edited"]``, the number of control points that differ from the fit's
    n_interior : int, the first ``n_interior`` knots are interior knots, the rest border rings
    """

    def __init__(
        self,
        space: SplineSpace,
        control_points: np.ndarray,
        parameterization: Parameterization,
        errors: np.ndarray,
        report: dict,
        n_interior: int,
        options: RefineOptions | None = None,
        active: np.ndarray | None = None,
    ):
        control_points = np.asarray(control_points, dtype=np.float64)
        if control_points.shape != (space.n_basis, 3):
            raise InvalidInputError(
                f"control_points must have shape ({space.n_basis}, 3), got {control_points.shape}"
            )
        if not np.all(np.isfinite(control_points)):
            raise InvalidInputError("control points must be finite")
        self._space = space
        self._c = _readonly(control_points)
        # the control points of the fit that ``errors`` measure (fitted_to); an edit keeps them
        self._fitted_c = self._c
        if active is None:
            active = np.flatnonzero(space.meets(parameterization.domain_polygon))
        self._active = _readonly(np.asarray(active, dtype=np.int64))
        self._ctrl = _readonly(self._c[self._active])
        self._param = _frozen_parameterization(parameterization)
        self._errors = _readonly(errors)
        self._report = report
        self._n_interior = int(n_interior)
        self._options = options or RefineOptions(degree=space.degree, mode=space.mode)
        self._tess_cache: dict = {}  # resolution -> (uv, triangles), most recent last
        self._domain_cache = None  # the convex domain polygon prepared for closest points
        self._sag_cache: dict = {}  # resolution -> tessellation_sag (the surface is immutable)
        # resolution -> the spline at tessellation_uv's vertices, from auto_resolution's sag of
        # the one it chose, handed over to the next tessellate of it: one entry at most, 24
        # bytes per vertex beside the 64 of its tessellation_uv (2.4 MB at 256 on three_peaks)
        self._sag_values: dict = {}

    def __getstate__(self) -> dict:
        """Pickle/copy state: everything but the caches (rebuilt on demand)."""
        state = self.__dict__.copy()
        state["_tess_cache"] = {}
        state["_domain_cache"] = None
        state["_sag_cache"] = {}
        state["_sag_values"] = {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._tess_cache = {}
        self._domain_cache = None
        self._sag_cache = {}
        self._sag_values = {}

    # ---- read-only state ----------------------------------------------------------------
    space = property(lambda self: self._space)
    control_points = property(lambda self: self._ctrl)
    active = property(lambda self: self._active)
    coefficients = property(lambda self: self._c)
    parameterization = property(lambda self: self._param)
    errors = property(lambda self: self._errors)
    # a deep copy: editing it (e.g. appending to its history) cannot change the surface
    report = property(lambda self: copy.deepcopy(self._report))
    n_interior = property(lambda self: self._n_interior)
    options = property(lambda self: self._options)
    degree = property(lambda self: self._space.degree)
    mode = property(lambda self: self._space.mode)
    knots = property(lambda self: self._space.knots)

    @property
    def configurations(self) -> Configurations:
        return self._space.configurations

    # ---- evaluation --------------------------------------------------------------------
    def evaluation_matrix(self, uv, derivative=(0, 0)) -> sp.csr_matrix:
        """Sparse (m, n) matrix ``M`` with ``surface(uv) = M @ control_points`` for ``uv`` in
        the data's domain (outside it the border functions, which are not control points, add
        to the surface, and outside :meth:`covers` the rows sum to less than 1)."""
        A = self._space.evaluate(uv, derivative)
        return A if len(self._active) == self._space.n_basis else A[:, self._active]

    def __call__(self, uv) -> np.ndarray:
        """Surface points (m, 3) at parameters ``uv`` (m, 2); NaN rows where the spline is not
        defined (outside :meth:`covers`).

        The spline is defined on more than the data's domain (:meth:`domain_contains`): the
        border rings around it (method.md section 3) extend the surface a little beyond the
        data, and there its points are finite though no data were fitted (an extrapolation);
        only beyond them are they NaN. So a parameter outside the domain may give a point or
        NaN (user test: two such parameters gave one of each); mask with
        :meth:`domain_contains` to keep to the fitted part."""
        return self._evaluate(uv, [(0, 0)])[0]

    def derivative(self, uv, derivative=(1, 0)) -> np.ndarray:
        """Partial derivative ``d^(du+dv) S / du^du dv^dv`` (m, 3); ``du + dv <= 2``; NaN rows
        outside :meth:`covers` (finite a little outside the data's domain: see
        :meth:`__call__`)."""
        return self._evaluate(uv, [derivative])[0]

    def normals(self, uv) -> np.ndarray:
        """Unit normals ``S_u x S_v / |S_u x S_v|`` (m, 3), negated for a mesh wound against
        its canonical winding (``parameterization.flipped``: the map is the reversed faces',
        and the normals face the given faces' way, as they do for the other winding); NaN
        rows outside :meth:`covers` (finite a little outside the data's domain: see
        :meth:`__call__`)."""
        su, sv = self._evaluate(uv, [(1, 0), (0, 1)])
        n = np.cross(su, sv)
        if self._param.flipped:
            n = -n
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    def covers(self, uv) -> np.ndarray:
        """Mask (m,) of the parameters where the spline is defined: where its basis is a
        partition of unity, ``|sum_I B_I(x) - 1| <= 1e-9`` (method.md section 2.2). That region
        holds the data's domain and part of the border rings around it (method.md section 3);
        beyond it the links of the outer ring do not close, the basis sums to less than 1 and
        fades to 0, so the surface would be pulled towards the origin. :meth:`__call__`,
        :meth:`derivative` and :meth:`normals` give NaN there, and finite values everywhere
        it covers, also outside the data's domain (:meth:`domain_contains`, a smaller
        region)."""
        return self._covered(self._space.evaluate(uv))

    @staticmethod
    def _covered(values: sp.csr_matrix) -> np.ndarray:
        return np.abs(np.asarray(values.sum(axis=1)).ravel() - 1.0) <= _COVER_TOL

    def _evaluate(self, uv, derivatives) -> list:
        """``M @ coefficients`` for each derivative order, with NaN rows outside the region
        where the basis is a partition of unity (the values share one basis pass)."""
        derivatives = [derivative_order(der) for der in derivatives]
        mats = self._space.evaluate_many(uv, [(0, 0)] + [d for d in derivatives if d != (0, 0)])
        covered = self._covered(mats[0])
        it = iter(mats[1:])
        out = []
        for der in derivatives:
            r = (mats[0] if der == (0, 0) else next(it)) @ self._c
            r[~covered] = np.nan
            out.append(r)
        return out

    def domain_contains(self, uv) -> np.ndarray:
        """Mask (m,) of parameters inside the data's parameter domain (a mesh's disk polygon,
        a cloud's convex hull of its parameters): where the surface was fitted. It lies inside
        :meth:`covers`, the larger region where the surface is defined (finite, extrapolated
        by the border rings outside the domain); False here does not mean NaN there."""
        return self._param.contains(uv)

    def heights(self, xy, iterations: int = 20) -> np.ndarray:
        """The surface's z over ground points ``xy`` (m, 2): for each, the z of the surface
        point whose x and y are that point's (a terrain's elevation at new places: a raster's
        nodes, survey points), NaN where no point of the fitted part of the surface (below)
        lies over it. For surfaces fitted to point clouds (a plane
        parameterization, method.md section 4), also when their projection plane is tilted,
        as a DEM's usually is: ``surf(parameterization.project(...))`` of points at some
        height is then off where the surface is not on the plane (user test: a median 72 m
        in x and y on the Jacksboro DEM).

        The fitted part is where :meth:`tessellate` puts the mesh: the domain, less the
        gaps inside a cloud farther from its points than the trim distance
        (:func:`core.parameterize.trim_distance`), which ``fill_holes`` spans.

        Solved per point by damped Newton steps on ``S(u, v)[:2] = (x, y)`` (2x2 systems of
        ``S_u`` and ``S_v``, vectorized), from the projection of the point on the fitted
        plane; a step that does not bring the point closer is halved. Converged: within
        1e-9 of the diagonal in x and y (else NaN, as where the surface is vertical or
        folds over the point; the solution nearest the plane is the one found where it folds).
        Not in method.md."""
        steps = _whole(iterations)
        if steps is None or steps < 1:
            raise InvalidInputError(
                f"iterations must be a positive whole number, got {iterations!r}")
        try:
            q = np.asarray(xy, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError("xy must be an (m, 2) array of x and y coordinates")
        q = q.reshape(1, 2) if q.shape == (2,) else q
        if q.ndim != 2 or q.shape[1] != 2:
            raise InvalidInputError(
                f"xy must be an (m, 2) array of x and y coordinates, got shape {q.shape}"
                + ("; give points[:, :2] for 3D points" if q.ndim == 2 and q.shape[1] == 3
                   else ""))
        param = self._param
        if param.kind != "plane" or param.axes is None or param.origin is None:
            raise InvalidInputError(
                "heights() needs a surface fitted to a point cloud (a height field projected "
                "on a plane); a mesh's surface has parameters only at its vertices: use "
                "closest_points() for the surface points nearest 3D points")
        normal = np.asarray(param.axes[2], dtype=np.float64)
        if not abs(normal[2]) > 1e-3:
            raise InvalidInputError(
                "heights() gives z over x and y, and this surface's projection plane stands "
                "upright (its normal is horizontal): it is no height field over x and y")
        out = np.full(len(q), np.nan)
        finite = np.isfinite(q).all(axis=1)
        origin = np.asarray(param.origin, dtype=np.float64)
        # the start: the point of the fitted plane over (x, y)
        z0 = origin[2] - (q[finite] - origin[:2]) @ normal[:2] / normal[2]
        uv = param.project(np.c_[q[finite], z0])
        goal = q[finite]
        close = 1e-9 * float(self._report.get("diagonal", 1.0) or 1.0)
        at, su, sv = self._evaluate(uv, [(0, 0), (1, 0), (0, 1)])
        miss = np.linalg.norm(at[:, :2] - goal, axis=1)
        scale = np.ones(len(uv))
        todo = np.flatnonzero(np.isfinite(miss) & (miss > close))
        for _ in range(steps):
            if not len(todo):
                break
            r = at[todo, :2] - goal[todo]
            a, b, c, d = su[todo, 0], sv[todo, 0], su[todo, 1], sv[todo, 1]
            det = a * d - b * c
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.c_[d * r[:, 0] - b * r[:, 1], a * r[:, 1] - c * r[:, 0]] / det[:, None]
            trial = uv[todo] - scale[todo, None] * step
            t_at, t_su, t_sv = self._evaluate(trial, [(0, 0), (1, 0), (0, 1)])
            t_miss = np.linalg.norm(t_at[:, :2] - goal[todo], axis=1)
            better = t_miss < miss[todo]  # (NaN: off the spline, not taken)
            ok = todo[better]
            uv[ok], at[ok], su[ok], sv[ok], miss[ok] = (
                trial[better], t_at[better], t_su[better], t_sv[better], t_miss[better])
            scale[ok] = 1.0
            scale[todo[~better]] *= 0.5
            todo = todo[(miss[todo] > close) & (scale[todo] > 2.0**-20)]
        done = (miss <= close) & self._param.contains(uv)
        if param.holes is None and done.any():
            # a gap in the data (inside its hull) is no fitted part, as the tessellation
            # leaves it open (review: a C-shaped cloud's notch had heights)
            data = self._data_parameters()[0]
            tree = cKDTree(data)
            near = tree.query(uv[done], workers=-1)[0] <= trim_distance(param, data, tree)
            near[~near] = in_voids(param, uv[done][~near])  # (between random points: covered)
            done[np.flatnonzero(done)[~near]] = False
        out[np.flatnonzero(finite)[done]] = at[done, 2]
        return out

    # ---- meshes ------------------------------------------------------------------------
    def tessellation_uv(self, resolution: int = 64, callback=None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (V, 2) and triangles (F, 3) covering exactly the data's domain; the
        triangles are counter-clockwise in uv, and clockwise for a mesh wound against its
        canonical winding (``parameterization.flipped``), so that the surface mesh faces the
        way of the faces given (a mesh and its copy with Flip Normals get the same vertices
        and reversed triangles).

        The domain is the disk polygon for meshes and the convex hull of the parameters for
        clouds, trimmed to where data is (triangles farther than a few data spacings from any
        data parameter are dropped). ``resolution`` grid steps span the longer side of the
        domain's bounding box (a cloud's: the smallest rectangle enclosing it, along whose
        sides the grid runs, when its area is under LATTICE_FRAME_GAIN of the box's,
        :func:`grid_frame`); a domain filling less than TESSELLATION_FULL_SHARE of the square
        on that side (a long or ragged patch) gets a finer step, so that it holds about
        ``TESSELLATION_FULL_SHARE resolution^2`` grid cells (:func:`tessellation_step`); and at
        least
        :data:`TESSELLATION_MIN_ACROSS` the shorter one (a long thin strip is not one
        triangle wide); where the parameterization compresses the surface more than on
        average (a mesh's map to the disk compresses steep and outlying parts, a projection
        steep slopes), edges are split until their length times the local compression is at
        most two grid steps (conforming red-green splits, :func:`_split_edges`;
        :data:`TESSELLATION_SPLITS` rounds at most; the compression is looked up at the nearest
        centre of a grid 4x finer than the tessellation's, of at most
        :data:`TESSELLATION_STRETCH_CELLS` cells along the longer side for a mesh and 128 for a
        cloud), so the surface mesh does not coarsen in 3D where the parameters are crowded.
        Meshes measure the compression by the vertex
        ``stretch`` of their parameterization (3D over uv edge length), clouds (and files
        without it) by the density of the data parameters. The parameters depend only on the
        data, not on the control points (``evaluation_matrix`` of them re-evaluates edits).
        ``callback({"grid_step": k, "grid_steps": K})`` hears of each of its steps and may
        return True to stop (CancelledError): resolution 2048 takes 6-8 s before its first
        vertex is evaluated (user test: Esc was not heard for 8 s).
        """
        given = resolution
        try:  # a number of grid steps: int() of it, as always (2.9 -> 2, "8" -> 8)
            resolution = int(resolution)
        except (TypeError, ValueError, OverflowError):  # None, NaN, inf, "abc"
            resolution = 0
        if resolution < 2:
            raise InvalidInputError(
                f"the tessellation resolution must be a number of at least 2 (a whole number of "
                f"grid steps), got {given!r}"
            )
        if resolution > MAX_RESOLUTION:  # (100 000 ran out of memory, 73 GiB: user test)
            raise InvalidInputError(
                f"the tessellation resolution must be at most {MAX_RESOLUTION} (about 12 "
                f"million vertices, several GiB), got {given!r}: evaluate the surface at "
                "parameters of your own for more (surf(uv))"
            )
        cached = self._tess_cache.pop(resolution, None)
        if cached is not None:  # most recent last
            self._tess_cache[resolution] = cached
            return cached
        steps = iter(range(1, TESSELLATION_SPLITS + 4))

        def step():
            k = next(steps)
            if callback is not None and _cancel_requested(
                    callback, {"grid_step": k, "grid_steps": TESSELLATION_SPLITS + 3}):
                raise CancelledError("the tessellation was cancelled")
        poly = np.asarray(self._param.domain_polygon, dtype=np.float64)
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        rot, wlo, whi = grid_frame(self._param)
        d = tessellation_step(self._param, resolution)
        # boundary: every polygon edge resampled at spacing ~d (keeping the corners)
        nxt = np.roll(poly, -1, axis=0)
        seg = np.linalg.norm(nxt - poly, axis=1)
        nseg = np.maximum(np.ceil(seg / d).astype(int), 1)
        t = np.concatenate([np.arange(n) / n for n in nseg])
        start = np.repeat(np.arange(len(poly)), nseg)
        boundary = poly[start] + t[:, None] * (nxt[start] - poly[start])
        # interior: grid points inside the polygon, away from the boundary
        gu = np.arange(wlo[0] + d / 2, whi[0], d)
        gv = np.arange(wlo[1] + d / 2, whi[1], d)
        grid = np.stack(np.meshgrid(gu, gv), -1).reshape(-1, 2)
        if rot is not None:
            grid = grid @ rot.T
        inside = self._param.contains(grid)
        # away from the boundary: more than 0.3 d from it. The boundary samples are at most d
        # apart, so a point whose nearest sample is farther than 0.8 d is more than 0.3 d from
        # the polygon; only the others need the distance to the edges (points near the
        # boundary: O(resolution) of them, not the whole grid times every edge)
        idx = np.flatnonzero(inside)
        gap = cKDTree(boundary).query(grid[idx], distance_upper_bound=2.5 * d)[0]
        near = idx[gap <= 0.8 * d]
        inside[near] = _distance_to_polygon(grid[near], poly) > 0.3 * d
        # deep: more than 2 d from the polygon (nearest boundary sample beyond 2.5 d)
        deep = np.zeros(len(grid), dtype=bool)
        deep[idx[gap > 2.5 * d]] = True
        step()
        uv = np.vstack([boundary, grid[inside]])
        number = np.full(len(grid), -1)
        number[inside] = len(boundary) + np.arange(np.count_nonzero(inside))
        lattice = _lattice(deep.reshape(len(gv), len(gu)), number.reshape(len(gv), len(gu)),
                           np.array([gu[0], gv[0]]) if len(gu) and len(gv) else None, d)
        if rot is not None and lattice[2] is not None:  # (it takes parameters in the frame)
            lattice = (*lattice[:2], lambda x, in_cells=lattice[2]: in_cells(x @ rot))
        lattice = (lattice[0], np.concatenate([np.arange(len(boundary)), lattice[1]]), lattice[2])
        data, ok = self._data_parameters()
        full = cKDTree(data)
        trim = None
        if self._param.kind == "plane":
            trim = max(trim_distance(self._param, data, full), 1.5 * d)
        tri = self._domain_triangles(uv, d, full, trim, lattice)
        step()
        stretch = self._local_stretch(data, full, np.asarray(self._param.stretch)[ok]
                                      if self._param.stretch is not None else None)
        if stretch is not None:
            # evaluated once, on a grid 4x finer than the tessellation's (at most what the
            # compression resolves): at every edge of every round it took 11 of the 14 s of
            # resolution 1024 on the DEM
            stretch = _gridded(stretch, lo, hi, min(4 * resolution, stretch.cells))
        step()
        # the rounds split the marked edges in place (red-green): a new Delaunay triangulation
        # per round cost seconds at resolution ~250, and the rounds were skipped above it, so a
        # steep mesh got a coarser surface at 251 than at 250 (three_peaks: longest 3D edge
        # 2.06 against 0.64, sag 0.80 against 0.07)
        done = []  # triangles no later round changes (their edges stay unmarked)
        for _ in range(TESSELLATION_SPLITS if stretch is not None else 0):
            uv, same, tri = _split_edges(
                uv, tri, lambda length, mid: (length * stretch(mid) > 2.0 * d)
                & (length > d / 2**TESSELLATION_SPLITS))
            done.append(same)
            step()
            if not len(tri):
                break
        tri = np.vstack(done + [tri])
        if self._param.flipped:  # (the given winding's way: the map is the reversed faces')
            tri = tri[:, ::-1]
        used = np.unique(tri)
        remap = np.full(len(uv), -1)
        remap[used] = np.arange(len(used))
        result = (_readonly(uv[used]), _readonly(remap[tri]))
        self._tess_cache[resolution] = result
        for old in list(self._tess_cache)[:-TESSELLATION_CACHE]:
            self._tess_cache.pop(old, None)
        return result

    def _data_parameters(self) -> tuple[np.ndarray, np.ndarray]:
        """The data's parameters (without a mesh's unused vertices) and the mask of them."""
        uv = np.asarray(self._param.uv)
        ok = np.isfinite(uv).all(axis=1)
        return uv[ok], ok

    @staticmethod
    def _local_stretch(data, tree, stretch):
        """``f(x)``: how much the parameterization compresses the surface near parameters ``x``
        (m, 2), relative to its median; from a mesh's vertex ``stretch`` (the nearest used
        vertex) or else from the density of the data parameters (median spacing of the 16th
        nearest neighbour over the local one, of at most 20 000 of them: a scanner samples the
        surface evenly, so the data lie denser in uv where the map compresses). None with too
        few data. ``f.cells``: the lookup grid that resolves it (:func:`_gridded`): the density
        of 20 000 points varies over ~1/35 of the extent, a mesh's vertices are finer."""
        if stretch is not None and np.isfinite(stretch).all() and len(stretch):
            typical = float(np.median(stretch))
            if typical > 0:
                def by_vertex(x):
                    return stretch[tree.query(x)[1]] / typical

                by_vertex.cells = TESSELLATION_STRETCH_CELLS
                return by_vertex
        # distinct parameters only: duplicated points would read as density (+14-31% vertices
        # for doubled clouds; with most points doubled the median spacing was 0)
        data = np.unique(data[:: max(1, len(data) // 20_000)], axis=0)
        k = min(16, len(data) - 1)
        if k < 2:
            return None
        sample = cKDTree(data)
        typical = float(np.median(sample.query(data, k=k + 1)[0][:, k]))

        def by_density(x):
            return typical / np.maximum(sample.query(x, k=k)[0][:, k - 1], 1e-300)

        by_density.cells = 128
        return by_density

    def _domain_triangles(self, uv, d, tree, trim, lattice=None) -> np.ndarray:
        """CCW Delaunay triangles of ``uv`` inside the domain (and, for clouds, within ``trim``
        of the data parameters in ``tree`` or, with ``fill_holes``, over a hole of the cloud:
        :meth:`Parameterization.in_holes`), without zero-area ones.

        ``lattice``: ``(cells, rest, in_cells)`` from :func:`_lattice`: the triangles of the
        grid cells deep inside the domain are given, only the points ``rest`` (the boundary
        strip) are Delaunay-triangulated, and the strip triangles that ``in_cells`` puts in
        those cells are dropped (the cells' outline edges are Delaunay edges of the strip, so
        no strip triangle crosses it)."""
        cells, rest, in_cells = lattice if lattice is not None else (
            np.zeros((0, 3), dtype=np.intp), np.arange(len(uv)), None)
        # triangulated with the points moved by at most 1e-7 d (seeded): qhull slows down
        # super-linearly on the co-circular points of a regular grid (a thin strip is all
        # boundary strip: 72 000 grid points took 23.5 s, 1.3 s moved; Blender user test,
        # a 1000:1 strip took 27 s to tessellate). Triangles of the original points thinner
        # than 1e-6 d (the moves could flip them) are dropped below with the flat ones.
        jitter = np.random.default_rng(0).random((len(rest), 2))
        moved = uv[rest] + TESSELLATION_JITTER * d * jitter
        tri = rest[Delaunay(moved).simplices]
        cen = uv[tri].mean(axis=1)
        keep = self._param.contains(cen)
        if in_cells is not None:
            keep &= ~in_cells(cen)
        a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
        det = orient2d(a, b, c)
        # Delaunay joins collinear points of a straight boundary stretch into zero-area
        # triangles: they cover nothing and have no normal, drop them
        keep &= np.abs(det) > 1e-6 * d * d
        tri = np.vstack([cells, np.where((det < 0)[:, None], tri[:, [0, 2, 1]], tri)[keep]])
        if trim is not None:
            # the search bounded (a hair beyond trim: the same test): unbounded, the triangles
            # in the empty middle of a ring's hull, nearly as far from all data, took 39 of 40 s
            # of a tessellation at 1024 (user test)
            cen = uv[tri].mean(axis=1)
            near = tree.query(cen, distance_upper_bound=trim * (1 + 1e-9))[0] <= trim
            if self._param.holes is not None:  # (fill_holes: a cloud's holes are covered)
                near[~near] = self._param.in_holes(cen[~near])
            else:  # (the voids between random points are no gaps: in_voids)
                near[~near] = in_voids(self._param, cen[~near], trim)
            tri = tri[near]
        return tri

    def open_holes(self, resolution: int = 64) -> int:
        """How many gaps inside a point cloud (:func:`core.parameterize.open_holes`) the
        tessellation at ``resolution`` leaves open, as it leaves out what is farther from the
        data than the trim distance or 1.5 grid steps; 0 for a mesh and with ``fill_holes``
        (the command line and Blender say so, naming the option: a scan's occlusions had come
        out as holes in the mesh with no word of it; user test)."""
        if self._param.kind != "plane":
            return 0
        # (gaps_beyond takes the larger of this and the trim distance)
        return open_holes(self._param, 1.5 * tessellation_step(self._param, resolution))

    def tessellate(self, resolution: int = 64, callback=None) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (V, 3) and triangles (F, 3) of the surface over the data's domain.

        The vertices are evaluated in chunks of CLOSEST_CHUNK parameters, each summed as it
        comes (``SplineSpace.combine``: no sparse matrix of all of them, tens of entries per
        vertex; about the time of ``self(uv)``, and its values to rounding);
        ``callback({"points_done": k, "points": V})`` hears of each chunk and may return True
        to stop (CancelledError); before them, the grid's steps (:meth:`tessellation_uv`).
        Right after :meth:`auto_resolution` chose this resolution, the vertices are those its
        sag evaluated (the same bits: a point's value does not depend on the points evaluated
        with it), handed over once, and the callback hears of all of them at once."""
        uv, faces = self.tessellation_uv(resolution, callback)
        key = int(resolution) if isinstance(resolution, (int, np.integer)) else None
        kept = self._sag_values.get(key)
        if kept is not None and len(kept) == len(uv):
            if callback is not None and callback({"points_done": len(uv), "points": len(uv)}):
                raise CancelledError("the tessellation was cancelled")
            self._sag_values.pop(key, None)  # (handed over: not kept twice)
            return kept, faces.copy()
        return self._points(uv, callback)[0], faces.copy()

    def tessellate_with_matrix(self, resolution: int = 64, callback=None
                               ) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
        """:meth:`tessellate` and the :meth:`evaluation_matrix` of its vertices (V, n), from
        one evaluation of the basis (a live control net's weights: Blender's Re-tessellate
        had evaluated it twice, once for each)."""
        uv, faces = self.tessellation_uv(resolution, callback)
        verts, matrix = self._points(uv, callback, matrix=True)
        return verts, faces.copy(), matrix

    def auto_resolution(self, target: float | None = None,
                        least: int | None = None) -> tuple[int, float]:
        """The coarsest of AUTO_RESOLUTIONS whose tessellation strays from the spline
        (:meth:`tessellation_sag`) by at most ``target`` (model units; default: the fit's max
        error at its data, ``report["max"]``, or AUTO_RESOLUTION_FLOOR of the data's diagonal
        if larger), else the finest: ``(resolution, its sag)`` (not in method.md). With
        ``least``: ``least`` and the AUTO_RESOLUTIONS above it (the command line's
        ``default_resolution``, which grows with the net and over a sparse domain). A tight fit
        needs a fine mesh: at the default 64, the mesh of F7 fitted to 1e-4 (1992 control
        points, max 8.8e-4 of the diagonal) strayed 7.9e-3 from the spline (256: 8.1e-4),
        nefertiti's at 1e-3 6.6e-3 against the fit's 6.2e-3 (128: 2.2e-3;
        benchmarks/tessellation_sag.py); a user measured the mesh, not the spline (user
        test).

        A candidate before the last is rejected as soon as a sample of its edges (those of every
        SAG_SAMPLE_STRIDE-th triangle) strays by more than ``target``: the same choice, and the
        same sag of the one chosen, with an eighth of the evaluations of the whole sag of each
        candidate passed over (its :meth:`tessellation_sag` is measured whole when asked for).
        When the finest strays, the sag at half of it is measured too (see below). The spline
        at the chosen mesh's vertices is kept for the next :meth:`tessellate` of it. Points
        evaluated on three_peaks fitted to 3e-4 (256, straying): 415 000 against 523 000, and
        none more for its tessellate (100 000 before); seconds in docs/benchmarks.md."""
        if target is None:
            target = sag_target(self._report, self._options)
        candidates = AUTO_RESOLUTIONS if least is None else (
            [int(least)] + [r for r in AUTO_RESOLUTIONS if r > least])
        points = None
        for k, resolution in enumerate(candidates):
            last = k == len(candidates) - 1
            sag, points = self._sag_above(resolution, None if last else target, keep=True,
                                          points=last)
            if not sag > target:  # (NaN target or sag: the first)
                break
        half = resolution // 2
        if sag > target and half in candidates and half not in self._sag_cache:
            # the finest strays: the command line and Blender advise a finer resolution from
            # the sag at half of it (finer_resolution), measured here (Blender: on the fit's
            # thread, as when every candidate was measured whole), taking the finest's values
            # where the parameters are the same bits: three_peaks at 3e-4 evaluated 1 803 of
            # the 100 046 at 128, nefertiti 1 357 of 47 404 (128's vertices and midpoints are
            # 256's midpoints and vertices); patch-01 and a cloud, whose grids do not nest to
            # the bit, 55 823 of 56 545 and 59 331 of 63 457
            self._sag_cache[half] = self._sag(half, known=points)[0]
        return resolution, sag

    def tessellation_sag(self, resolution: int = 64) -> float:
        """How far the flat triangles of :meth:`tessellate` ``(resolution)`` stray from the
        spline (model units; not in method.md): the largest distance between the spline and
        the mesh at the midpoints (in uv) of all its edges, where a quadratic piece's sag
        along an edge peaks. The mesh, not the spline, is what a user sees and measures: a net
        of 709 control points fitted to 2.0e-3 of the diagonal showed 6.4e-3 at resolution 64
        and 2.3e-3 at 256 (user test). Every edge: a sample of 5000 triangles had found 3.7e-4
        at 256 where all edges have 1.07e-3, at a spot of a few triangles (review). About two
        evaluations per triangle (see AUTO_RESOLUTIONS for seconds). NaN when no edge has both
        ends on the domain. Kept per resolution (the surface does not change)."""
        return self._sag_above(resolution)[0]

    def _sag_above(self, resolution, above: float | None = None, keep: bool = False,
                   points: bool = False) -> tuple[float, tuple | None]:
        """:meth:`tessellation_sag`, kept per resolution; with ``above``, possibly only a lower
        bound of it that exceeds ``above`` (not kept), see :meth:`_sag`. ``keep``: the spline
        at the vertices, when measured, replaces those kept for :meth:`tessellate`. With
        ``points``, also the parameters evaluated and the values there (None if kept)."""
        key = int(resolution) if isinstance(resolution, (int, np.integer)) else None
        if key is not None and key in self._sag_cache:
            return self._sag_cache[key], None
        sag, vertex, evaluated = self._sag(resolution, above, points=points)
        if vertex is not None and key is not None:
            self._sag_cache[key] = sag
            if keep:  # (one resolution's at most)
                self._sag_values = {key: vertex}
        return sag, evaluated

    def _sag(self, resolution, above: float | None = None, known: tuple | None = None,
             points: bool = False) -> tuple[float, np.ndarray | None, tuple | None]:
        """:meth:`tessellation_sag`, computed, the spline at the vertices of
        :meth:`tessellation_uv` (None if not all measured), and with ``points`` the parameters
        evaluated and the values there (else None). With ``above``, the edges of every
        SAG_SAMPLE_STRIDE-th triangle first: if one of them strays by more than ``above``, the
        largest of their gaps (at most the sag) and None, the other edges not measured.
        ``known``: parameters and values evaluated already, taken where a parameter is the
        same bits (:func:`_same_rows`). A point's value is the same bits whichever points it is
        evaluated with (``SplineSpace.combine`` sums each point's pairs in one order), so the
        sag of the sample and the rest, or with values known, is the one pass's, bit for
        bit."""
        uv, tri = self.tessellation_uv(resolution)
        if len(tri) == 0:
            return float("nan"), None, None
        n = len(uv)  # (every vertex is on a triangle: tessellation_uv keeps only those)

        def edge_keys(t):  # a * n + b for each edge (a, b), a < b, sorted, once each
            e = np.sort(np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
            return np.unique(e[:, 0].astype(np.int64) * n + e[:, 1])

        key = edge_keys(tri)
        vertex = np.empty((n, 3))
        todo_vertex = np.ones(n, dtype=bool)
        todo_edge = np.ones(len(key), dtype=bool)
        gaps, evaluated = [], []

        def measure(verts, edges):  # the gaps at ``edges`` (indices into key), ``verts`` new
            a, b = key[edges] // n, key[edges] % n
            x = np.vstack([uv[verts], 0.5 * (uv[a] + uv[b])])
            if known is None:
                values = self._points(x)[0]
            else:
                at = _same_rows(known[0], x)
                values = np.empty((len(x), 3))
                values[at >= 0] = known[1][at[at >= 0]]
                values[at < 0] = self._points(x[at < 0])[0]
            if points:
                evaluated.append((x, values))
            vertex[verts] = values[: len(verts)]
            todo_vertex[verts] = False
            todo_edge[edges] = False
            gaps.append(np.linalg.norm(values[len(verts):] - 0.5 * (vertex[a] + vertex[b]),
                                       axis=1))

        if above is not None and above == above and len(tri) > SAG_SAMPLE_STRIDE:
            sample = tri[::SAG_SAMPLE_STRIDE]
            measure(np.unique(sample), np.searchsorted(key, edge_keys(sample)))
            if np.isfinite(gaps[0]).any() and np.nanmax(gaps[0]) > above:
                return float(np.nanmax(gaps[0])), None, None
        measure(np.flatnonzero(todo_vertex), np.flatnonzero(todo_edge))
        gap = np.concatenate(gaps)
        sag = float(np.nanmax(gap)) if np.isfinite(gap).any() else float("nan")
        if not points:
            return sag, vertex, None
        return sag, vertex, tuple(np.concatenate(c) for c in zip(*evaluated))

    def _points(self, uv, callback=None, matrix: bool = False):
        """``self(uv)`` (m, 3), to rounding, by chunks with ``callback`` (see tessellate), and
        with ``matrix`` the :meth:`evaluation_matrix` of ``uv`` (else None)."""
        uv = np.asarray(uv, dtype=np.float64)
        # the fourth column sums the basis: NaN rows where it is no partition of unity
        c = np.c_[self._c, np.ones(len(self._c))]
        out = np.empty((len(uv), 3))
        parts = []
        for s in range(0, max(len(uv), 1), CLOSEST_CHUNK):
            e = min(s + CLOSEST_CHUNK, len(uv))
            if e > s:
                if matrix:
                    A = self._space.evaluate(uv[s:e])
                    values = A @ c
                    parts.append(A if len(self._active) == A.shape[1] else A[:, self._active])
                else:
                    values = self._space.combine(uv[s:e], c)[0]
                values[np.abs(values[:, 3] - 1.0) > _COVER_TOL, :3] = np.nan
                out[s:e] = values[:, :3]
            if callback is not None and callback({"points_done": e, "points": len(uv)}):
                raise CancelledError("the tessellation was cancelled")
        if not matrix:
            return out, None
        if not parts:
            return out, sp.csr_matrix((0, len(self._active)))
        return out, sp.vstack(parts, format="csr")

    def texture_coordinates(self, uv) -> np.ndarray:
        """Texture coordinates (m, 2) of parameters ``uv`` (m, 2), e.g. those of
        :meth:`tessellation_uv`: the parameters moved and scaled so that the domain's bounding
        box has its corner at 0 and its longer side 1 (the aspect kept; a UV map for textures
        follows the spline's own parameters: a projection for a cloud, the mesh's flattening
        for a mesh; not in method.md), mirrored (``u -> w - u``, ``w`` the box's width in them)
        for a mesh wound against its canonical winding, so that the triangles of
        :meth:`tessellate` run counter-clockwise in them as seen from the side their normals
        face (an image is not shown mirrored). One parameter pair (2,) gives
        (1, 2), as ``surf(uv)`` gives one point (1, 3)."""
        x = np.asarray(uv, dtype=np.float64)
        x = x[None] if x.shape == (2,) else x
        if x.ndim != 2 or x.shape[1] != 2:
            raise InvalidInputError(f"uv must be an (M, 2) array; got shape {x.shape}")
        poly = np.asarray(self._param.domain_polygon, dtype=np.float64)
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        t = (x - lo) / max(float(np.max(hi - lo)), 1e-300)
        if self._param.flipped:
            t[:, 0] = float(hi[0] - lo[0]) / max(float(np.max(hi - lo)), 1e-300) - t[:, 0]
        return t

    def control_net(self) -> tuple[np.ndarray, np.ndarray]:
        """Control points (n, 3) and the control-net triangles (f, 3) over them (method.md 7:
        the triangles of the centroid triangulation whose three vertices are control points).

        For DCB surfaces the net is ambiguous (several control points share a Greville point)
        and no faces are returned. The triangles are reversed for a mesh wound against its
        canonical winding (``parameterization.flipped``), as the tessellation's are.
        """
        where = np.full(self._space.n_basis, -1)
        where[self._active] = np.arange(len(self._active))
        faces = where[self._space.net_faces]
        faces = faces[(faces >= 0).all(axis=1)]
        return self._ctrl.copy(), (faces[:, ::-1].copy() if self._param.flipped else faces)

    # ---- editing -----------------------------------------------------------------------
    def with_control_points(self, control_points) -> "TCBSurface":
        """A new surface with other control points (n, 3) (same space; the coefficients of
        the border functions stay); this one is unchanged. All ``space.n_basis`` coefficients
        (as in ``coefficients``) are accepted too. ``errors`` and ``report`` still describe the
        fit (the surface keeps no copy of the data): measure an edited surface against the data
        with :meth:`distances`. The new surface's ``report["edited"]`` is the number of its
        control points (rows of ``coefficients``) that differ from the fit's, and is left out
        when none does (its rms and max had been read as the edited surface's: user test);
        it is kept by :meth:`save`."""
        c = _as_control_points(control_points)
        if c.shape == (len(self._active), 3):
            full = np.array(self._c)
            full[self._active] = c
        elif c.shape == self._c.shape:
            full = c
        else:
            raise InvalidInputError(
                f"control_points must have shape ({len(self._active)}, 3), got {c.shape}"
            )
        report = copy.deepcopy(self._report)
        report.pop("edited", None)
        moved = _moved_rows(full, self._fitted_c)
        if moved:
            report["edited"] = moved
        edited = TCBSurface(
            self._space, full, self._param, self._errors, report,
            self._n_interior, self._options, active=self._active,
        )
        edited._fitted_c = self._fitted_c
        return edited

    # ---- distances ---------------------------------------------------------------------
    def closest_parameters(self, points, iterations: int = 8, callback=None) -> np.ndarray:
        """Parameters (m, 2) of the surface points closest to ``points`` (m, 3).

        Start at the nearest vertex of a fine tessellation (and, for clouds, also at the point's
        projection on the best-fit plane), take Gauss-Newton steps on ``|S(x) - p|^2`` (2x2
        normal equations per point, vectorized; a step that does not improve is retried
        shorter), kept in the data's domain (the trimmed surface: a point beyond its edge gets
        a closest point on the edge; a cloud's domain is its convex hull, so in a concave
        cloud's notch, which :meth:`tessellate` leaves out, there is surface too); the better
        result is returned. A point whose descent ends on the domain's edge also descends
        along the edge (:meth:`_edge_closest`), from the nearest of CLOSEST_EDGE_SAMPLES
        surface points per edge. A point that ended off the surface also descends from those of
        its CLOSEST_STARTS nearest starts that lie on its side of the tangent plane at its foot
        (another part of the surface, a fold or the other flank of a crease, may be closer:
        the nearest start alone had ended in a local minimum), and again from its foot when
        the ``iterations`` rounds ran out before it stopped; the nearest result is kept
        (:meth:`_other_starts`).

        ``callback``, if given, is called with ``{"points_done": k, "points": m}`` before the
        first chunk of :data:`CLOSEST_CHUNK` points and after each (k of the m points done);
        if it returns True the computation stops with :class:`CancelledError` (nothing
        partial is returned). The chunks do not change the result: every point is computed
        on its own.
        """
        return self._closest(points, iterations, callback)[0]

    def closest_points(self, points, iterations: int = 8, callback=None) -> np.ndarray:
        """The surface points (m, 3) closest to ``points`` (m, 3): ``S`` at
        :meth:`closest_parameters` (the feet of the points on the trimmed surface; their
        distances are :meth:`distances`). ``callback``: as for :meth:`closest_parameters`."""
        return self._closest(points, iterations, callback)[2]

    def _closest(self, points, iterations: int = 8, callback=None):
        """:meth:`closest_parameters`, the distances ``|S(x) - p|`` and the surface points ``S(x)``
        there: (m, 2), (m,), (m, 3), in chunks of :data:`CLOSEST_CHUNK` points."""
        steps = _whole(iterations)
        if steps is None or steps < 0:
            raise InvalidInputError(
                f"iterations must be a nonnegative whole number, got {iterations!r}"
            )
        check_callback(callback)
        try:
            p = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            p = points  # _as_points says what is wrong with them
        else:
            p = p.reshape(1, 3) if p.shape == (3,) else p
        p = _as_points(p)
        bad = np.flatnonzero(~np.isfinite(p).all(axis=1))
        if len(bad):
            rows = ", ".join(map(str, bad[:10])) + (", ..." if len(bad) > 10 else "")
            raise InvalidInputError(
                f"{len(bad)} of {len(p)} points have NaN or infinite coordinates (rows {rows}); "
                "closest points need finite ones: leave those out, e.g. "
                "points[np.isfinite(points).all(axis=1)]"
            )
        huge = np.flatnonzero(np.abs(p).max(axis=1, initial=0.0) > 1e150)
        if len(huge):  # (squared distances overflow: an IndexError from the KD-tree, user test)
            raise InvalidInputError(
                f"{len(huge)} of {len(p)} points have coordinates beyond 1e150 (the first: row "
                f"{huge[0]}), whose squared distances overflow: leave those out")
        uv_t, tri = self.tessellation_uv(96)
        lo, hi = uv_t.min(axis=0), uv_t.max(axis=0)
        # starts: the nearest of the tessellation's vertices and of the surface points at (up
        # to 20 000 of) the data's own parameters, which stay close to the data where the map
        # is stretched (a data point is then at most its fit error from its start)
        data, _ = self._data_parameters()
        starts = np.vstack([uv_t, np.clip(data[:: max(1, len(data) // 20_000)], lo, hi)])
        at = self(starts)
        tree = cKDTree(at)
        # the size of the surface (for when a step no longer changes a distance) and its
        # tessellation's longest edge (no surface point is farther from a start)
        size = float(np.linalg.norm(np.ptp(at, axis=0)))
        edge = float(np.linalg.norm(at[tri] - at[tri[:, [1, 2, 0]]], axis=2).max())
        m = len(p)
        x, d, S = np.empty((m, 2)), np.empty(m), np.empty((m, 3))
        edge_starts = None  # (made for the first chunk with points on the edge)
        for s in range(0, m, CLOSEST_CHUNK):
            # (True cancels, None or False go on, anything else is refused as by the fit:
            # 1 or "no" had cancelled here; user test)
            if callback is not None and _cancel_requested(callback, {"points_done": s,
                                                                     "points": m}):
                raise CancelledError(f"closest points cancelled after {s} of {m} points")
            c = slice(s, s + CLOSEST_CHUNK)
            near, nearest = tree.query(p[c], k=CLOSEST_STARTS, workers=-1)
            near, nearest = near.reshape(len(near), -1), nearest.reshape(len(near), -1)
            xc, dc, Sc, left = self._descend_in(p[c], starts[nearest[:, 0]], lo, hi, steps,
                                                size, near[:, 0], edge)
            self._other_starts(p[c], xc, dc, Sc, left, starts, at, near, nearest, lo, hi, steps,
                               size, edge)
            # a step pushed back onto the edge (of the box or the domain) stalls short of the
            # closest point along it (user test: 286 of 2000 points around patch-01's edge
            # came out up to 33% farther than a known surface point): those that ended on the
            # edge also descend along it
            rim = np.flatnonzero(self._on_edge(xc))
            if len(rim):
                if edge_starts is None:
                    edge_starts = self._edge_starts()
                xe, de, Se = self._edge_closest(p[c][rim], edge_starts, steps)
                b = de < dc[rim]
                xc[rim[b]], dc[rim[b]], Sc[rim[b]] = xe[b], de[b], Se[b]
            x[c], d[c], S[c] = xc, dc, Sc
        if callback is not None:
            callback({"points_done": m, "points": m})
        return x, d, S

    def _descend_in(self, p, x0, lo, hi, steps, size, near, edge, plane=True):
        """:meth:`_descend` from the starts ``x0`` with the steps kept in the domain's box;
        the few that ended outside the domain (on the extension over the border rings) are
        redone from the same starts with every step kept in the domain (clamping all points'
        steps to the polygon made points outside a 596-edge mesh 9x slower). Returns the
        parameters, distances, surface points and the mask of the points still stepping when
        the rounds ran out (``left`` of :meth:`_newton_closest`)."""
        left = np.zeros(len(p), dtype=bool)
        x, d, S = self._descend(p, x0, lo, hi, steps, None, size, near, edge, plane, left)
        out = np.flatnonzero(~self._in_domain(x))
        if len(out):
            still = np.zeros(len(out), dtype=bool)
            x[out], d[out], S[out] = self._descend(p[out], x0[out], lo, hi, steps,
                                                   self._into_domain, size, near[out], edge,
                                                   plane, still)
            left[out] = still
        return x, d, S, left

    def _other_starts(self, p, x, d, S, left, starts, at, near, nearest, lo, hi, steps,
                      size, edge):
        """Multi-start: the points whose first descent ended at ``x`` (distances ``d``, surface
        points ``S``, updated in place where better) farther than CLOSEST_ON_SURFACE times
        ``size`` from the surface (a point on it is at its global minimum) descend again from
        (1) those of their next nearest ``starts`` (``nearest[:, 1:]``, surface points ``at``,
        at distances ``near``) that lie on the point's side of the tangent plane at its foot,
        at an angle of more than asin(CLOSEST_OTHER_SHEET) from it: the ball around the point
        through its foot lies on that side, so another part of the surface that enters it (a
        fold, the other flank of a crease, a ripple finer than the starting tessellation) has
        starts there, while the starts of the foot's own sheet lie near the plane; and (2)
        their foot, when they were still stepping as the rounds ran out (a descent that took
        short retried steps round a bend). Each point keeps the nearest of its results. All
        pairs of points and starts in one vectorized descent, without the cloud's projection
        start (:meth:`_descend_in`); not in method.md. Own tessellation vertices (resolutions
        64 to 300) of four 6 x 7 quad meshes of random heights fitted with 600-700 control
        points measured up to 8.9e-3 of its diagonal from the surface with the nearest start
        alone, at most 4.2e-8 with these (the test of the wiggly fit); 1.34x the surface
        evaluations at 1e5 points scattered 2e-3 of the diagonal around one, none more at
        points on it or at a cloud's data. Fits that fold over themselves (heights three times
        larger, RMS 1-2% of the diagonal) still measured up to 1.5e-2 at some points."""
        far = d > CLOSEST_ON_SURFACE * size
        pi, xs0, ns = [], [], []
        if nearest.shape[1] > 1:
            n = (p - S) / np.maximum(d, 1e-300)[:, None]
            w = at[nearest[:, 1:]] - S[:, None, :]  # (m, K - 1, 3)
            up = np.einsum("mkj,mj->mk", w, n)
            i, j = np.nonzero(far[:, None]
                              & (up > CLOSEST_OTHER_SHEET * np.linalg.norm(w, axis=2)))
            pi.append(i)
            xs0.append(starts[nearest[i, j + 1]])
            ns.append(near[i, j + 1])
        i = np.flatnonzero(left & far)
        pi.append(i)
        xs0.append(x[i])
        ns.append(d[i])
        i, x0, nr = np.concatenate(pi), np.vstack(xs0), np.concatenate(ns)
        if len(i) == 0:
            return
        xs, ds, Ss, _ = self._descend_in(p[i], x0, lo, hi, steps, size, nr, edge, plane=False)
        order = np.lexsort((ds, i))  # each point's nearest result first
        i, xs, ds, Ss = i[order], xs[order], ds[order], Ss[order]
        first = np.r_[True, i[1:] != i[:-1]]
        i, xs, ds, Ss = i[first], xs[first], ds[first], Ss[first]
        b = ds < d[i]
        x[i[b]], d[i[b]], S[i[b]] = xs[b], ds[b], Ss[b]

    def _descend(self, p, x, lo, hi, steps, keep_in, size, near, edge, plane=True,
                 left=None):
        """Gauss-Newton (:meth:`_newton_closest`) from the starts ``x`` (at distances
        ``near``) and, for a cloud, also from the points' projections on its plane; the better
        result of each point (starting from the better start only was 1.6x faster on the DEM
        but 2% of the distances came out larger, by up to 2% of the largest).

        A cloud's points are first taken from their projections, then from ``x`` those that
        may end elsewhere: their start there is more than CLOSEST_SAME_BASIN steps of the
        96-step tessellation from where they ended, or closer than the distance they reached,
        or that distance is above a quarter of the tessellation's longest ``edge`` (points off
        the surface). All of them when the steps are kept in the domain (``keep_in``: a step
        pushed back onto the domain's edge can stall short of the closest point there, and
        the other start may not). Against both descents for every point
        (benchmarks/bench_closest.py): at the data of fits of 2e5 points of Franke's function
        with noise and of the DEM, 2.6x and 2.3x faster, farther at 40 and 218 points, by at
        most 1.1e-8 and 3.7e-5 of the diagonal; at 20 000 points around them 1.0-1.2x, 3e-9.
        At the step tile of the tests 136 of 20 000 points around it came out farther, by up
        to 1.5e-3, beside the step's wall (/tmp/s19/rules.py of the nineteenth session)."""
        keep = np.clip if keep_in is None else keep_in
        x = keep(np.array(x, dtype=np.float64), lo, hi)
        if not (plane and self._param.kind == "plane" and self._param.origin is not None):
            return self._newton_closest(p, x, self._surface_and_gradient(x), lo, hi, steps,
                                        keep_in, size, left)
        y = keep(self._param.project(p), lo, hi)
        y, e, T = self._newton_closest(p, y, self._surface_and_gradient(y), lo, hi, steps,
                                       keep_in, size, left)
        apart = np.max(np.abs(x - y), axis=1) > CLOSEST_SAME_BASIN * float(np.max(hi - lo)) / 96
        apart |= (e > near) | (e > 0.25 * edge) | (keep_in is not None)
        if apart.any():
            a = np.flatnonzero(apart)
            la = None if left is None else np.zeros(len(a), dtype=bool)
            xa, da, Sa = self._newton_closest(p[a], x[a], self._surface_and_gradient(x[a]), lo,
                                              hi, steps, keep_in, size, la)
            b = da < e[a]
            y[a[b]], e[a[b]], T[a[b]] = xa[b], da[b], Sa[b]
            if left is not None:
                left[a[b]] = la[b]
        return y, e, T

    def _on_edge(self, x: np.ndarray) -> np.ndarray:
        """Mask of the parameters ``x`` (in the domain) on its polygon's boundary: outside it
        when moved away from its vertex mean by 1e-9 of its size (a polygon that is not
        convex: within 1e-9 of its size of an edge)."""
        v, c = self._convex_domain()[:2]
        if not self._domain_convex:  # (review: every edge for every point took 2x the search)
            return self._onto_edges(x)[1] <= (1e-9 * float(np.ptp(v, axis=0).max())) ** 2
        away = x - c
        length = np.sqrt(np.einsum("ij,ij->i", away, away))
        nudge = 1e-9 * float(np.ptp(v, axis=0).max()) / np.maximum(length, 1e-300)
        return ~self._in_domain(x + nudge[:, None] * away)

    def _edge_point(self, tau: np.ndarray) -> np.ndarray:
        """The point of the domain polygon's boundary at ``tau`` (its edge ``floor(tau)``, that
        far along it: a parameter along the whole loop, one per edge)."""
        v, _, _, ab, _ = self._convex_domain()
        i = np.floor(tau).astype(np.int64) % len(v)
        return np.take(v, i, axis=0) + (tau - np.floor(tau))[:, None] * np.take(ab, i, axis=0)

    def _edge_starts(self):
        """CLOSEST_EDGE_SAMPLES parameters per edge of the domain polygon and a KD-tree of
        the surface points there, for :meth:`_edge_closest`."""
        n = len(self._convex_domain()[0])
        tau = np.arange(n * CLOSEST_EDGE_SAMPLES) / CLOSEST_EDGE_SAMPLES
        return tau, cKDTree(self(self._edge_point(tau)))

    def _edge_closest(self, p, edge_starts, iterations):
        """The points of the trimmed surface's edge (the boundary of the domain polygon)
        closest to ``p``: from the nearest of ``edge_starts``, Gauss-Newton on
        ``|S(x(tau)) - p|^2`` along the loop (``x(tau)``: :meth:`_edge_point`; a step of at
        most one edge, retried at a quarter when it does not bring the point closer, as in
        :meth:`_newton_closest`). Returns the parameters, distances and surface points."""
        tau_s, tree = edge_starts
        v, _, _, ab, _ = self._convex_domain()
        n = len(v)
        tau = tau_s[tree.query(p, workers=-1)[1]]
        x = self._edge_point(tau)
        S, Su, Sv = self._surface_and_gradient(x)
        dist = np.linalg.norm(S - p, axis=1)
        active, scale = np.arange(len(p)), np.ones(len(p))
        for _ in range(iterations):
            if len(active) == 0:
                break
            e = np.take(ab, np.floor(tau[active]).astype(np.int64) % n, axis=0)
            St = Su[active] * e[:, :1] + Sv[active] * e[:, 1:]  # dS / dtau
            den = np.einsum("ij,ij->i", St, St)
            step = -np.einsum("ij,ij->i", St, S[active] - p[active]) / np.maximum(den, 1e-300)
            step = np.clip(scale[active] * step, -1.0, 1.0)
            moved = np.abs(step) > 1e-12
            active = self._try_steps(p, active[moved], (tau[active] + step)[moved] % n, tau,
                                     dist, (S, Su, Sv), scale, self._edge_point)
        return self._edge_point(tau), dist, S

    def _try_steps(self, p, active, cand, x, dist, state, scale, to_uv=None):
        """One round of the closest-point descents: the surface and its gradient at the
        candidate parameters ``cand`` of the points ``active`` (``to_uv(cand)`` when they are
        no uv), taken where they bring the point no farther (``x``, ``dist`` and ``state`` =
        (S, Su, Sv) updated in place, the step scale back to 1), else the step retried at a
        quarter next round (at most 3 times in a row). Returns the points still active."""
        Sc, Suc, Svc = self._surface_and_gradient(cand if to_uv is None else to_uv(cand))
        dc = np.linalg.norm(Sc - p[active], axis=1)
        better = dc <= dist[active]
        idx = active[better]
        x[idx], dist[idx] = cand[better], dc[better]
        for a, b in zip(state, (Sc, Suc, Svc)):
            a[idx] = b[better]
        scale[idx] = 1.0
        worse = active[~better]
        scale[worse] *= 0.25
        return np.concatenate([idx, worse[scale[worse] >= 0.25**3]])

    def _surface_and_gradient(self, uv):
        return self._space.combine(uv, self._c, [(0, 0), (1, 0), (0, 1)])

    def _convex_domain(self):
        """The domain polygon prepared for :meth:`_in_domain` / :meth:`_into_domain`: mostly
        convex (a cloud's convex hull; a mesh's boundary on the unit circle or a rectangle);
        a mesh's flattened boundary need not be (``self._domain_convex`` says which).
        Vertices ``v`` (CCW, starting at the smallest angle around the vertex mean ``c``),
        their angles, the edges and a KD-tree of the vertices."""
        cached = self._domain_cache
        if cached is None:
            v = np.asarray(self._param.domain_polygon, dtype=np.float64)
            self._domain_convex = _is_convex(v)
            c = v.mean(axis=0)
            ang = np.arctan2(v[:, 1] - c[1], v[:, 0] - c[0])
            start = int(np.argmin(ang))
            v, ang = np.roll(v, -start, axis=0), np.roll(ang, -start)
            ab = np.roll(v, -1, axis=0) - v
            cached = (v, c, ang, ab, cKDTree(v))
            self._domain_cache = cached
        return cached

    def _in_domain(self, x: np.ndarray) -> np.ndarray:
        """Mask of ``x`` in the domain polygon, closed to 1e-12 of its size: for a convex one
        the vertex wedge around ``c`` that holds ``x`` (a binary search by angle) names the
        one edge to test (O(log n) per point instead of every edge); else the even-odd test
        of :meth:`domain_contains`."""
        v, c, ang, ab, _ = self._convex_domain()
        if not self._domain_convex:
            return self._param.contains(x)
        i = (np.searchsorted(ang, np.arctan2(x[:, 1] - c[1], x[:, 0] - c[0]), side="right")
             - 1) % len(v)
        rel = x - np.take(v, i, axis=0)
        e = np.take(ab, i, axis=0)
        tol = 1e-12 * float(np.ptp(v, axis=0).max()) * np.sqrt(np.einsum("ij,ij->i", e, e))
        return e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0] >= -tol

    def _into_domain(self, x: np.ndarray, lo, hi) -> np.ndarray:
        """``x`` clipped to the box ``[lo, hi]`` and then, where outside the data's domain
        polygon, moved to the nearest point of its boundary (:meth:`_onto_edges`): closest
        points lie on the trimmed surface, not on its extension over the border rings."""
        x = np.clip(x, lo, hi)
        out = np.flatnonzero(~self._in_domain(x))
        if len(out) == 0:
            return x
        x[out] = self._onto_edges(x[out])[0]
        return x

    def _onto_edges(self, y: np.ndarray):
        """The nearest points of the domain polygon's boundary to ``y`` (m, 2) and their
        squared distances, over candidate edges: all edges of polygons of at most 32; for a
        convex one the edge whose wedge holds the point and its neighbours, and those at the
        two nearest vertices; else those at the 8 nearest vertices."""
        v, c, ang, ab, tree = self._convex_domain()
        n = len(v)
        if n <= 32:
            cand = np.broadcast_to(np.arange(n), (len(y), n))
        elif not self._domain_convex:  # (no wedges)
            _, near = tree.query(y, k=8)
            cand = np.concatenate([near, near - 1], axis=1) % n
        else:
            w = (np.searchsorted(ang, np.arctan2(y[:, 1] - c[1], y[:, 0] - c[0]),
                                 side="right") - 1)[:, None] + np.arange(-2, 3)
            _, near = tree.query(y, k=2)
            cand = np.concatenate([w, near, near - 1], axis=1) % n
        a, e = np.take(v, cand, axis=0), np.take(ab, cand, axis=0)  # (m, edges, 2)
        t = np.einsum("mej,mej->me", y[:, None, :] - a, e)
        t = np.clip(t / np.maximum(np.einsum("mej,mej->me", e, e), 1e-300), 0.0, 1.0)
        proj = a + t[..., None] * e
        gap = np.einsum("mej,mej->me", y[:, None, :] - proj, y[:, None, :] - proj)
        best = gap.argmin(axis=1)
        rows = np.arange(len(y))
        return proj[rows, best], gap[rows, best]

    def _newton_closest(self, p, x, start, lo, hi, iterations, keep_in=None, size=0.0,
                        left=None):
        """Gauss-Newton from ``x`` (with the surface and its gradient there, ``start``) inside
        the box ``[lo, hi]``, or where ``keep_in(x, lo, hi)`` puts the steps (the data's
        domain: :meth:`_into_domain`); returns the parameters, their distances and the
        surface points there.
        Each step evaluates the surface and its first derivatives once, at the trial points
        only. A step that does not bring the point closer is retried at a quarter of its
        length in the next round (at most 3 times in a row: backtracking; before, the point
        stopped there and distances of points away from the surface came out up to 6e-4 of
        the diagonal too large); points whose step is below 1e-8 of the box drop out, and so
        do those whose step would change their distance by less than CLOSEST_DISTANCE_TOL
        times ``size`` (the surface's size): a step moving the surface point by ``t`` along
        the surface changes a distance ``|r|`` by at most about ``t^2 / (2 |r|)`` (or ``t``
        when ``t`` is most of ``|r|``), so a point stops once ``t^2 <= 2 delta |r|``; its
        distance is then within ``3 delta``. Most points of a fitted cloud stop one step
        sooner (method: Gauss-Newton on the squared distance, not in method.md). ``left``, a
        boolean array (m,) if given, is set to the points still stepping when the
        ``iterations`` rounds ran out (:meth:`_other_starts` descends again from them)."""
        tiny = 1e-8 * float(np.max(hi - lo))
        delta = CLOSEST_DISTANCE_TOL * size
        S, Su, Sv = start
        dist = np.linalg.norm(S - p, axis=1)
        active = np.arange(len(p))
        scale = np.ones(len(p))
        for _ in range(iterations):
            if len(active) == 0:
                break
            r, su, sv = S[active] - p[active], Su[active], Sv[active]
            a, b, c = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
            g1, g2 = (su * r).sum(1), (sv * r).sum(1)
            det = a * c - b * b
            ok = det > 1e-300
            step = np.zeros((len(active), 2))
            step[ok, 0] = (c[ok] * g1[ok] - b[ok] * g2[ok]) / det[ok]
            step[ok, 1] = (a[ok] * g2[ok] - b[ok] * g1[ok]) / det[ok]
            cand = x[active] - scale[active, None] * step
            cand = np.clip(cand, lo, hi) if keep_in is None else keep_in(cand, lo, hi)
            moved = np.abs(cand - x[active]).max(axis=1) > tiny
            if delta > 0:  # and the step changes the distance (docstring)
                t = su * step[:, :1] + sv * step[:, 1:]  # (the whole step's, not retried)
                moved &= np.einsum("ij,ij->i", t, t) > 2.0 * delta * dist[active]
            active = self._try_steps(p, active[moved], cand[moved], x, dist, (S, Su, Sv),
                                     scale)
        if left is not None:  # (the points still stepping when the rounds ran out)
            left[:] = False
            left[active] = iterations > 0
        return x, dist, S

    def distances(self, points, callback=None) -> np.ndarray:
        """Distance (m,) of ``points`` (m, 3) to the surface (closest point, see above;
        ``callback`` as for :meth:`closest_parameters`)."""
        return self._closest(points, callback=callback)[1]

    # ---- refinement --------------------------------------------------------------------
    def fitted_to(self, points, rounding: float = 0.0) -> bool:
        """Whether ``points`` are the data this surface's fit was made from (an edited surface,
        :meth:`with_control_points`, keeps its fit's data, and ``report["edited"]`` says that
        its control points moved since; it is not a measure of how well the surface fits
        them, which :meth:`distances` gives): the same count and (for
        surfaces that keep ``report["data_digest"]``; older files do not) the same values in
        the same order, or values that differ from them only by rounding. :meth:`refine` needs
        them.

        Rounding: each point's distance to the fitted surface (before any
        :meth:`with_control_points` edit) at its own parameters is its fitted error within
        :data:`ROUNDING_RTOL` of the diagonal or ``rounding`` of each coordinate (so
        ``sqrt(3) rounding`` of a point; in the data's units: what the
        caller knows its values were rounded by since the fit; Blender passes 4 float32 steps
        of the largest coordinate, for its float32 coordinates rounded again by Apply Rotation
        & Scale, which had been refused: user test). The allowance is not guessed from the
        values: float64 data at UTM northings got 1.2 m of it, and data shifted by 0.8 m
        passed (user test, review). A point that moved by more changes that distance unless it
        moved on a sphere around its surface point; another order of the points does not
        pass (:meth:`reordered` takes it, and :meth:`refine`).
        Points left out of the fit (outliers, loose vertices) are not compared."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or len(points) != len(self._param.uv):
            return False
        stored = self._report.get("data_digest")
        if stored is None or data_digest(points) == stored:
            return True
        if points.shape[1] != 3 or not np.isfinite(points).all():
            return False
        if not max(ROUNDING_RTOL * float(self._report.get("diagonal", 0.0)), float(rounding)) > 0:
            return False
        return not self.moved_points(points, rounding).any()

    def moved_points(self, points, rounding: float = 0.0) -> np.ndarray | None:
        """Per point of ``points`` (as many as the fit's data, in its order), whether it is off
        the data the fit was made from by more than :meth:`fitted_to` allows (a point the fit
        left out: False), or None for another count. Which of several sources fitted together
        changed (user test: Refine named both of two when one was moved)."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) != len(self._param.uv):
            return None
        fitted = np.asarray(self._param.used, dtype=bool)
        moved = fitted & ~np.isfinite(points).all(axis=1)  # (a left-out point: False; review)
        used = fitted & ~moved
        # (``rounding`` of each coordinate: a point moves by up to sqrt(3) times it; data
        # rounded to the millimetre had needed rounding=0.001, not its 0.0005: user test)
        tol = max(ROUNDING_RTOL * float(self._report.get("diagonal", 0.0)),
                  np.sqrt(3.0) * float(rounding))
        A = self._space.evaluate(np.asarray(self._param.uv)[used])
        far = np.linalg.norm(A @ self._fitted_c - points[used], axis=1)
        moved[used] = ~(np.abs(far - self._errors[used]) <= tol)
        return moved

    def same_data_set(self, points) -> bool:
        """Whether ``points`` are the values this surface was fitted to in any order, exactly
        (``report["data_set_digest"]``, :func:`data_set_digest`; False for files saved before
        it), or rounded to 32-bit floats as Blender keeps a file's values
        (``report["data_set_digest32"]``, :func:`rounded_set_digest`: a spline fitted to a text
        file's points and a scan imported from it and sorted had been refused; user test).
        Cheap: a sort and a digest (:meth:`reordered` checks more)."""
        key = self._report.get("data_set_digest")
        key32 = self._report.get("data_set_digest32")
        points = np.asarray(points, dtype=np.float64)
        if not (points.ndim == 2 and len(points) == len(self._param.uv)):
            return False
        return bool(key is not None and data_set_digest(points) == key
                    or key32 is not None and rounded_set_digest(points) == key32)

    def same_faces(self, faces, points=None) -> bool:
        """Whether ``faces`` are the faces this surface was fitted to: the same rows in the
        same order (``report["faces_digest"]``; True for surfaces that keep none: point
        clouds, files saved before it) or, with ``points`` (the data, in the order the faces
        index) and for a surface that keeps ``report["faces_set_digest"]``, the same faces in
        any order, a triangle's corners also turned (:func:`faces_set_digest`; also on the
        points rounded to 32-bit floats, :func:`rounded_faces_digest`)."""
        stored = self._report.get("faces_digest")
        if stored is None or faces_digest(faces) == stored:
            return True
        return points is not None and self._same_face_set(faces, points)

    def _same_face_set(self, faces, points) -> bool:
        """``faces`` on ``points`` are the fit's faces as a set (:func:`faces_set_digest`), or
        on the points rounded to 32-bit floats (:func:`rounded_faces_digest`)."""
        key = self._report.get("faces_set_digest")
        key32 = self._report.get("faces_set_digest32")
        return bool(key is not None and faces_set_digest(faces, points) == key
                    or key32 is not None
                    and rounded_faces_digest(faces, points, checked=True) == key32)

    def same_mesh(self, points, faces) -> bool:
        """Whether ``faces`` on ``points`` are the mesh this surface was fitted to, whatever
        vertices are in no face: the same polygons of the same vertex positions, in any order
        (``report["mesh_digest"]``, :func:`mesh_digest`, kept for data of 32-bit values such as
        Blender's; False for surfaces fitted before it was kept, and for clouds), or of the
        positions rounded to 32-bit floats (``report["faces_set_digest32"]``, kept for other
        data; the values given are then fitted, as :meth:`fitted_to` allows rounding). A loose
        vertex deleted in Blender renumbers the vertices after it: Refine had refused the
        mesh (user test). Cheap: hashes of the corners, no sort. :meth:`refine` and
        :meth:`reordered` then parameterize the mesh again."""
        if self._param.faces is None or faces is None:
            return False
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            return False
        key = self._report.get("mesh_digest")
        key32 = self._report.get("faces_set_digest32")
        return bool(key is not None and mesh_digest(faces, points) == key
                    or key32 is not None
                    and rounded_faces_digest(faces, points, checked=True) == key32)

    def reordered(self, points, faces=None) -> Parameterization | None:
        """The parameterization of ``points`` (and ``faces``) when they are the data this
        surface was fitted to stored in another order (Blender's Sort Elements: the vertices,
        the faces; a triangle's corners turned; a cloud's points), else None.

        The surface keeps no order of its data, only digests of them as sets: the points must
        be the same values exactly (:meth:`same_data_set`) and a mesh's ``faces`` (needed: the
        fit's faces index the old order) the same faces on them (:meth:`same_faces`). The data
        are then parameterized again as :func:`fit_surface` did (Drop Outliers when the fit
        left any out, Fill Holes when it filled any; a cloud along the direction found afresh,
        else along the fit's): the map does not depend on the order of the data (a renumbered
        mesh's parameters agree to about 2e-15, a cloud's are the same values). The result is
        checked against the surface's own: the same kind and counts, and each column of the
        parameters and of the domain polygon, sorted, within :data:`REORDERED_UV_TOL` (else
        None). Parameters that were stored in 32-bit floats (a compact file) are rounded so
        too. Files saved before the set digests take no other order; values both reordered
        and rounded are found when rounded to 32-bit floats (Blender's), by surfaces fitted
        since the thirty-seventh session. A mesh with vertices in no face added or deleted
        (:meth:`same_mesh`; surfaces fitted since the forty-first session) is taken too: the
        parameterization returned is of the points given, their count. Costs a
        parameterization (1e5 points: a cloud 0.4 s, a
        grid mesh 3.7 s; docs/benchmarks.md)."""
        return self._reordered(points, faces)[0]

    def _reordered(self, points, faces=None,
                   mesh: bool | None = None) -> tuple[Parameterization | None, str]:
        """:meth:`reordered` and, when None, why: ``"points"`` (other values, or no set digest
        kept), ``"faces"`` (other faces), ``"no faces"`` (a mesh's points without faces) or
        ``"map"`` (the same data mapped to other parameters). ``mesh``: :meth:`same_mesh`
        of them when the caller has it (None: found here if needed)."""
        points = np.asarray(points, dtype=np.float64)
        old = self._param
        # (NaN rows too: a mesh's loose vertices may be NaN, as the fit allowed: review)
        same_set = (points.ndim == 2 and points.shape == (len(old.uv), 3)
                    and self.same_data_set(points))
        # (or the mesh with other vertices in no face: the used ones, their faces, the same)
        loose = not same_set and (self.same_mesh(points, faces) if mesh is None else mesh)
        if not (same_set or loose):
            return None, "points"
        if old.faces is not None:
            if faces is None:
                return None, "no faces"
            # (the set digest, even when the faces are the fit's rows: on other points)
            if not (loose or self._same_face_set(faces, points)):
                return None, "faces"
            # (spike vertices dissolved by drop_outliers: again, else refused)
            tries = [dict(fill_holes=bool(self._report.get("holes_filled", 0)),
                          drop_outliers=bool(self._report.get("outliers", 0)))]
        else:
            if faces is not None:
                return None, "faces"
            drop = bool(self._report.get("outliers", 0))
            tries = [dict(drop_outliers=drop, fill_holes=old.holes is not None)]
            if old.axes is not None:  # (a projection given to the fit: its direction)
                tries.append(dict(tries[0], projection=tuple(float(x) for x in old.axes[2])))
        # a mesh fitted before the canonical winding (no "canonical_winding" in its report)
        # was mapped as its faces were given: mapped so again (a reordered copy of a mesh
        # wound against it was refused as "values both reordered and rounded": review)
        given = old.faces is not None and not self._report.get("canonical_winding", False)
        for options in tries:
            try:
                new = (_parameterize_mesh(points, faces, **options) if given
                       else parameterize(points, faces, **options))
            except TCBError:
                continue
            if _same_map(new, old):
                return _rounded_like(new, old), ""
        return None, "map"

    def refine(self, points, faces=None, callback=None, rounding: float = 0.0, join=None,
               **changes) -> "TCBSurface":
        """Continue the adaptive loop from this surface on the same data.

        ``points`` (and ``faces``) must be the data this surface was fitted to: the same
        values in the same order (a digest of them is kept in ``report["data_digest"]``), or
        values within rounding of them (see :meth:`fitted_to` and its ``rounding``), or the
        same values in another order with the same faces renumbered, in any order of the faces
        (Blender's Sort Elements; a polygon's corners may be turned; the faces must then be
        given): these are parameterized again
        (:meth:`reordered`, which costs a parameterization), and the refined surface is the
        one of the data in their new order.
        ``changes`` override settings (the fields of :class:`RefineOptions`), e.g.
        ``tolerance=``, ``max_control_points=``, ``max_iterations=`` (default: 5 more
        iterations); an unknown name is an :class:`InvalidInputError`.
        ``join``: as :func:`fit_surface`'s, the neighbours the refined surface is joined to
        (a surface fitted with ``join=`` is refined without it unless given again).
        The surface returned is never worse at the data, by the criterion, than this one: if
        the run's is, this one is returned (the fit's control points, its errors at the
        points) with the run's history and stop reason, and ``report["kept_start"]`` (the
        criterion, both errors, the run's returned iteration and control points); not when
        ``changes`` alter the degree, the mode or the smoothness.
        """
        points = np.asarray(points, dtype=np.float64)
        mesh = None  # (same_mesh, when the count differs: a hash of the faces, made once)
        if points.ndim != 2 or len(points) != len(self._param.uv):
            mesh = self.same_mesh(points, faces)
        if mesh is False:
            raise InvalidInputError(
                "refine() needs the points this surface was fitted to "
                f"({len(self._param.uv)} points, got {len(points)}"
                + ("; a mesh's vertices in no face may differ when its faces are given"
                   if faces is None and self._param.faces is not None
                   and (self._report.get("mesh_digest") or self._report.get(
                       "faces_set_digest32")) else "") + ")"
            )
        if faces is not None and self._param.faces is None:  # (ignored once: user test)
            raise InvalidInputError(
                "refine() was given faces, but this surface was fitted to a point cloud: "
                "give its points only (faces=None)")
        # (the same values as a set, in another order, or the fit's order rounded to 32-bit
        # floats as a set digest also takes: fitted_to within rounding tells; refused as
        # "reordered and rounded" when fitted_to took them: user test)
        same_points = self.fitted_to(points, rounding)
        # (None: the fit's faces; no digest kept: a file saved before it)
        same_faces = faces is None or self.same_faces(faces)
        param = self._param
        if not (same_points and same_faces):
            param, why = self._reordered(points, faces, mesh)
            if why == "no faces":
                raise InvalidInputError(
                    f"refine() was given the {len(points)} points this surface was fitted to "
                    "in another order, without faces: give the mesh's faces as they are "
                    "stored now (the fit's index the old order)")
            if param is None and not same_points and why != "faces":
                _check_finite(points)  # the more specific message first
                old = ("another order, which a surface saved before it kept a digest of its "
                       "data as a set does not take"
                       if self._report.get("data_set_digest") is None
                       else "values both reordered and rounded, other than to 32-bit "
                       "floats")
                raise InvalidInputError(
                    f"refine() needs the {len(points)} points this surface was fitted to, in "
                    f"the same order; these differ from them (other values, by more than "
                    f"rounding, or {old}). Values rounded since the fit pass with rounding= "
                    "the largest change of a coordinate (e.g. 0.0005 for millimetres); to fit "
                    "other data, call fit_surface()"
                )
            if param is None:
                raise InvalidInputError(
                    "refine() needs the faces this surface was fitted to (or None for them); "
                    "these differ from them. To fit another mesh, call fit_surface()")
        unknown = sorted(set(changes) - set(_OPTION_NAMES))
        if unknown:
            raise InvalidInputError(
                f"refine() has no option {', '.join(map(repr, unknown))}; the options are "
                f"{', '.join(_OPTION_NAMES)}"
            )
        if not np.array_equal(self._c, self._fitted_c):  # (as Blender's Refine says: user test)
            moved = _moved_rows(self._c, self._fitted_c)
            warnings.warn(
                f"{moved} edited control point{' is' if moved == 1 else 's are'} replaced: "
                "refine() fits the data again from the knots (the edits are not kept)",
                RuntimeWarning, stacklevel=2)
        fields = self._options.__dict__ | {"max_iterations": 5} | changes
        options = RefineOptions(**fields)
        options.validate()
        check_callback(callback)
        # the digests of the faces given (kept from now: a file saved before the set digest
        # gets it), else the fit's
        keys = (self._report.get("faces_digest"), self._report.get("faces_set_digest"),
                self._report.get("faces_set_digest32"), self._report.get("mesh_digest"))
        if faces is not None and keys[0] is not None:
            keys = _faces_keys(faces, points)
        refined = _run(points, param, options, callback, faces_key=keys[0],
                       faces_set_key=keys[1], faces_set_key32=keys[2], mesh_key=keys[3],
                       start=self.knots[: self._n_interior],
                       rings=self.knots[self._n_interior:],
                       history=self._report.get("history", []), start_degree=self.degree,
                       projection_given=bool(self._report.get("projection_given")),
                       seam_list=seams(param, join, points))
        if join:  # (the surface asked for is joined; the start may not be)
            return refined
        return self._start_unless_beaten(refined, points, options)

    def _start_unless_beaten(self, refined: "TCBSurface", points: np.ndarray,
                             options: RefineOptions) -> "TCBSurface":
        """``refined`` (refine()'s run), unless its error at the data by the criterion
        (the RMS, for a cloud of uneven density the larger of it and the RMS over the area as
        in the loop; or the max) is above this surface's (the fit's control points) at the
        same points: then this surface, with its control points and its errors at them, and
        the run's history, stop reason and data digests; ``report["kept_start"]`` says so.
        Not when the run changed the model (its degree, mode or smoothness): the surface asked
        for is another one. A noisy sphere cap (32 x 16 UV sphere, noise 0.002) fitted at
        3e-3 (49 control points, RMS 1.58e-3 of the diagonal) and refined at 1.5e-3 had its
        noise count against the tighter tolerance (``mesh_noise_counts``): the faces' samples
        drawn flat instead of curved (as the noisy meshes' were until their facets' sag was
        weighed: :data:`FACET_SAG_OVER_NOISE`), the refit at the same knots 2.36e-3 and the
        run's choice (lowest estimated error, 65 control points) 1.83e-3, returned as the
        refined surface (user test)."""
        same_model = (options.degree == self.degree and options.mode == self.mode
                      and options.smoothness == self._options.smoothness)
        if not same_model:
            return refined
        mine = refined._report
        crit = options.criterion

        def area_rms(err: np.ndarray, uv: np.ndarray) -> float:
            return float(np.sqrt(np.dot(area_weights(uv), err**2) / len(err)))

        def value(err: np.ndarray, uv: np.ndarray) -> float:
            if crit == "max":
                return float(err.max(initial=0.0))
            rms = float(np.sqrt(np.mean(err**2)))
            return rms if "rms_area" not in mine else max(rms, area_rms(err, uv))

        # the start's errors as its fit kept them (the fit's control points at its data: the
        # same points, maybe in another order or rounded, by far less than these errors), so
        # that a refine that beats it evaluates nothing more
        used = np.asarray(self._param.used, dtype=bool)
        start = value(np.asarray(self._errors)[used], np.asarray(self._param.uv)[used])
        param = refined.parameterization
        kept = np.flatnonzero(np.asarray(param.used, dtype=bool))
        uv = np.asarray(param.uv)[kept]
        new = value(np.asarray(refined.errors)[kept], uv)
        if not new > start:
            return refined
        e = np.empty(len(kept))  # (at the points as given, in their order)
        step = 200_000
        for s in range(0, len(kept), step):
            at = self._space.combine(uv[s: s + step], self._fitted_c)[0]
            e[s: s + step] = np.linalg.norm(at - points[kept[s: s + step]], axis=1)
        start = value(e, uv)
        if not new > start:  # (the kept errors' rounding decided it)
            return refined
        start_area = area_rms(e, uv) if "rms_area" in mine else None
        report = copy.deepcopy(self._report)
        report.pop("edited", None)
        for key in ("history", "iterations", "seconds", "stop_reason", "data_digest",
                    "data_set_digest", "data_set_digest32", "faces_digest", "faces_set_digest",
                    "faces_set_digest32", "mesh_digest", "canonical_winding",
                    "projection_given"):
            if key in mine:
                report[key] = copy.deepcopy(mine[key])
        diagonal = float(mine["diagonal"])
        rms = float(np.sqrt(np.mean(e**2)))
        report.update({"rms": rms, "max": float(e.max(initial=0.0)), "rms_rel": rms / diagonal,
                       "max_rel": float(e.max(initial=0.0)) / diagonal, "diagonal": diagonal})
        if start_area is not None:
            report["rms_area"], report["rms_area_rel"] = start_area, start_area / diagonal
        # the start's iteration in the history it came with (the run's iterations follow)
        report["returned_iteration"] = int(self._report.get(
            "returned_iteration", len(self._report.get("history", []))))
        report["kept_start"] = {"criterion": crit, "start": start, "refined": new,
                                "refined_iteration": int(mine["returned_iteration"]),
                                "refined_control_points": int(mine["control_points"])}
        errors = np.full(len(points), np.nan)
        errors[kept] = e
        return TCBSurface(self._space, self._fitted_c, param, errors, report, self._n_interior,
                          options, active=self._active)

    # ---- files -------------------------------------------------------------------------
    def to_bytes(self, compact: bool = False) -> bytes:
        """The surface as a versioned ``.npz`` archive in memory (see :meth:`save`).

        ``compact``: the data's parameters and fitted errors (and a mesh's vertex stretch) are
        stored in 32-bit floats and a mesh's faces as 32-bit differences, about half the size
        (a point cloud: 11 instead of 23 bytes per point); the knots, configurations, control
        points, domain polygon and the map's frame stay exact. Reading such bytes gives
        float64 arrays of the float32 values (parameters rounded by at most 6e-8 of the
        domain's half-width: below the float32 precision of the coordinates that Blender, or
        most scan files, hold anyway; a mesh's boundary rows are set back to its domain
        polygon), so a compact archive of a compact archive's surface is the same; otherwise
        the round trip is bit-exact.
        Format 3: readers before it refuse compact bytes with "update the add-on". Format 4:
        a surface of a mesh wound against its canonical winding (``param_flipped``), which
        readers before it would tessellate facing the other way, refused by them alike.
        """
        arrays = {
            "format_version": np.array(4 if self._param.flipped else 3 if compact else
                                       2 if self._options.smoothness == "auto" else 1),
            "degree": np.array(self.degree),
            "mode": np.array(self.mode),
            "knots": self.knots,
            "n_interior": np.array(self._n_interior),
            "control_points": self._c,
            "errors": self._errors,
            "report": np.array(json.dumps(self._report)),
            "options": np.array(json.dumps(self._options.__dict__)),
            # the smoothness was left at the default (cross-validated on sparse clouds): JSON
            # stores it as the number; readers that do not know this array ignore it
            "smoothness_is_default": np.array(isinstance(self._options.smoothness,
                                                         DefaultSmoothness)),
            "param_kind": np.array(self._param.kind),
            "param_scale": np.array(np.nan if self._param.scale is None else self._param.scale),
        }
        for lvl, (T, I) in enumerate(zip(self.configurations.triangles, self.configurations.interior)):
            arrays[f"triangles_{lvl}"] = T
            arrays[f"interior_{lvl}"] = I
        arrays["open_links"] = np.array(self.configurations.open_links)
        for name in _PARAM_FIELDS:
            value = getattr(self._param, name)
            if value is not None:
                arrays[f"param_{name}"] = value
        if self._param.flipped:  # (files without it: the faces' winding was the canonical one)
            arrays["param_flipped"] = np.array(True)
        if not np.array_equal(self._c, self._fitted_c):
            # an edited surface (with_control_points) keeps the fit's control points: refine()
            # says it replaces the edits, and fitted_to() and the errors measure the fit (they
            # were forgotten on saving: user test); readers that do not know the array ignore it
            arrays["fitted_control_points"] = self._fitted_c
        if compact:
            for key in _COMPACT_FLOAT:
                if key in arrays:
                    arrays[key] = np.asarray(arrays[key], dtype=np.float32)
            faces = arrays.get("param_faces")
            if faces is not None and len(faces) and faces.max() < 2**31:
                # int32 deltas: the first corner from the previous face's, the others from
                # the first (a mesh's faces are mostly in order: a grid's compress 100x)
                del arrays["param_faces"]
                arrays["param_faces_delta"] = np.column_stack(
                    [np.diff(faces[:, 0], prepend=0), faces[:, 1:] - faces[:, :1]]
                ).astype(np.int32)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes, what: str = "the data") -> "TCBSurface":
        """Inverse of :meth:`to_bytes`; raises :class:`FileFormatError` on bad content."""
        if isinstance(data, (bytearray, memoryview)):
            data = bytes(data)
        if not isinstance(data, bytes):  # (a str raised TypeError: user test)
            raise FileFormatError(
                f"{what} must be the bytes of a TCB surface file (to_bytes(), or a file's "
                f"content read in binary mode), got {type(data).__name__}; to read a file by "
                "its path, use TCBSurface.load(path)")
        if not data.startswith(b"PK"):  # a .npz is a zip archive (a .npy, text, ... is not)
            raise FileFormatError(
                f"{what} is not a TCB surface file (a .npz archive written by save())"
            )
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except Exception as exc:  # zipfile / numpy raise many kinds on corrupt input
            raise FileFormatError(f"{what} is not a readable TCB surface file ({exc})") from None
        try:
            version = int(arrays["format_version"])
        except KeyError:
            if "elevation" in arrays:  # (a DEM grid that core.meshio reads as input)
                raise FileFormatError(
                    f"{what} is a DEM grid ('elevation'), not a TCB surface file: fit it "
                    "(python -m core fit FILE -o OUT --spline SPLINE.npz) to get one") from None
            raise FileFormatError(f"{what} is not a TCB surface file (no format version)") from None
        if version > FORMAT_VERSION:
            raise FileFormatError(
                f"{what} was written by a newer TCB Surface (format {version}; this version "
                f"reads up to {FORMAT_VERSION}): update the add-on"
            )
        if "param_faces_delta" in arrays:
            delta = arrays.pop("param_faces_delta")
            if delta.ndim != 2 or delta.shape[1] != 3 or delta.dtype.kind not in "iu":
                raise FileFormatError(f"{what} is damaged or incomplete (its faces have shape "
                                      f"{delta.shape} and type {delta.dtype})")
            first = np.cumsum(delta[:, 0].astype(np.int64))
            arrays["param_faces"] = np.column_stack([first, first[:, None] + delta[:, 1:]])
        if arrays.get("param_uv") is not None and arrays["param_uv"].dtype == np.float32:
            uv = arrays["param_uv"].astype(np.float64)
            boundary, polygon = arrays.get("param_boundary"), arrays.get("param_domain_polygon")
            if (boundary is not None and polygon is not None and boundary.ndim == 1
                    and polygon.shape == (len(boundary), 2)):
                try:  # a mesh's boundary rows are its domain polygon's corners, exactly
                    uv[boundary] = polygon
                except IndexError:
                    raise FileFormatError(f"{what} is damaged or incomplete (its boundary "
                                          "indices are out of range)") from None
            arrays["param_uv"] = uv
        for key in _COMPACT_FLOAT:  # (compact bytes: float32)
            if key in arrays and arrays[key].dtype == np.float32:
                arrays[key] = arrays[key].astype(np.float64)
        try:
            degree = int(arrays["degree"])
            knots = arrays["knots"]
            configs = Configurations(
                knots=knots,
                triangles=[arrays[f"triangles_{lvl}"] for lvl in range(degree + 1)],
                interior=[arrays[f"interior_{lvl}"] for lvl in range(degree + 1)],
                open_links=[int(v) for v in arrays["open_links"]],
            )
            space = SplineSpace(knots, degree, str(arrays["mode"]), configs)
            scale = float(arrays["param_scale"])
            param = Parameterization(
                kind=str(arrays["param_kind"]),
                scale=None if np.isnan(scale) else scale,
                flipped=bool(arrays.get("param_flipped", False)),
                **{name: arrays.get(f"param_{name}") for name in _PARAM_FIELDS},
            )
            fields = json.loads(str(arrays["options"]))
            if "smoothness_is_default" in arrays and bool(arrays["smoothness_is_default"]):
                fields["smoothness"] = DEFAULT_SMOOTHNESS
            options = RefineOptions(**fields)
            options.validate()
            for lvl in range(degree + 1):  # (out of range: an IndexError at the first use)
                for name in (f"triangles_{lvl}", f"interior_{lvl}"):
                    idx = np.asarray(arrays[name])
                    if idx.size and (idx.dtype.kind not in "iu" or idx.min() < 0
                                     or idx.max() >= len(knots)):
                        raise FileFormatError(f"{what} is damaged or incomplete (its {name} "
                                              "are no indices of its knots)")
            report = json.loads(str(arrays["report"]))
            _check_report(report, what)
            surf = cls(space, arrays["control_points"], param, arrays["errors"], report,
                       int(arrays["n_interior"]), options)
            if "fitted_control_points" in arrays:  # (an edited surface: to_bytes)
                fitted = np.asarray(arrays["fitted_control_points"], dtype=np.float64)
                if fitted.shape != surf._c.shape or not np.isfinite(fitted).all():
                    raise FileFormatError(f"{what} is damaged or incomplete (its fitted control "
                                          f"points have shape {fitted.shape})")
                fitted.setflags(write=False)
                surf._fitted_c = fitted
                if "edited" not in report:  # (saved before the report said so)
                    surf._report["edited"] = _moved_rows(surf._c, fitted)
            if "functions" not in report:  # saved when every basis function counted
                report["functions"] = int(space.n_basis)
                report["control_points"] = len(surf.active)
            return surf
        except FileFormatError:
            raise
        except KeyError as exc:
            raise FileFormatError(f"{what} is damaged or incomplete (it has no {exc} entry)"
                                  ) from None
        except Exception as exc:
            raise FileFormatError(f"{what} is damaged or incomplete ({type(exc).__name__}: {exc})") from None

    def save(self, path, compact: bool = False) -> None:
        """Write a versioned ``.npz`` (the path, a str, bytes or path object in which ``~``
        means the home folder, must end in ``.npz``); atomically (temporary file, then rename),
        with the permissions a new file gets from the umask (an existing file keeps its own).
        ``compact``: the data's per-point arrays in 32 bits, about half the size (see
        :meth:`to_bytes`)."""
        path = _user_path(path)
        if path.suffix.lower() != ".npz":
            raise InvalidInputError(
                f"a surface is saved as a .npz archive: name the file *.npz (got {path.name})"
            )
        if not path.parent.is_dir():
            raise InvalidInputError(
                f"cannot save to {path}: the folder {path.parent} does not exist"
            )
        if path.is_dir():
            raise InvalidInputError(
                f"cannot save to {path}: that is a folder; give the name of a .npz file"
            )
        data = self.to_bytes(compact=compact)
        # the temporary file is created with mode 0666 and the kernel applies the umask (what
        # a plain open() gives; mkstemp makes 0600); an existing file keeps its own mode
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
        while True:
            tmp = str(path.parent / f"{path.name}.{secrets.token_hex(4)}.tmp")
            try:
                fd = os.open(tmp, flags, 0o666)
                break
            except FileExistsError:
                continue
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            if path.exists():
                os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    @classmethod
    def load(cls, path) -> "TCBSurface":
        """Read a surface written by :meth:`save` (``path`` as for :meth:`save`)."""
        path = _user_path(path)
        if path.is_dir():  # (it had said "no such file": user test)
            raise FileFormatError(f"{path} is a folder: give the name of a .npz file")
        if not path.is_file():
            raise FileFormatError(f"no such file: {path}")
        return cls.from_bytes(path.read_bytes(), what=str(path))

    def __repr__(self) -> str:
        r = self._report
        return (
            f"TCBSurface(mode={self.mode!r}, degree={self.degree}, knots={len(self.knots)}, "
            f"control_points={len(self._active)}, rms_rel={r.get('rms_rel', float('nan')):.3g}"
            + (f" of the fit, {r['edited']} edited" if r.get("edited") else "") + ")"
        )


# a stored report's entries that are numbers (floats) and whole numbers, when present: a file
# whose report had a string there loaded, and Blender's import failed on it (user test)
_REPORT_FLOATS = ("rms", "max", "rms_rel", "max_rel", "diagonal", "seconds", "smoothness",
                  "rms_area", "noise", "noise_rel", "folded")
_REPORT_WHOLE = ("knots", "control_points", "functions", "iterations", "edited", "holes_filled",
                 "outliers", "loose_vertices", "net_capped")


def _check_report(report, what: str) -> None:
    """A :class:`FileFormatError` when a stored ``report`` is no dict or one of its
    :data:`_REPORT_FLOATS` is no number (NaN is one), or of its :data:`_REPORT_WHOLE` no
    nonnegative whole number."""
    if not isinstance(report, dict):
        raise FileFormatError(f"{what} is damaged or incomplete (its report is no dictionary)")
    for key in _REPORT_FLOATS + _REPORT_WHOLE:
        value = report.get(key)
        if value is None:
            continue
        whole = key in _REPORT_WHOLE
        ok = isinstance(value, int) and value >= 0 if whole else isinstance(value, (int, float))
        if not ok or isinstance(value, bool):
            raise FileFormatError(f"{what} is damaged or incomplete (its report's {key!r} is "
                                  f"{value!r})")


def _moved_rows(coefficients: np.ndarray, fitted: np.ndarray) -> int:
    """How many rows of ``coefficients`` differ from the fit's ``fitted`` (report["edited"])."""
    return int(np.count_nonzero(np.any(coefficients != fitted, axis=1)))


def _as_control_points(value) -> np.ndarray:
    """Control points given by a user as a float64 array, or an :class:`InvalidInputError`
    for what numpy would refuse or silently change (sparse matrices, ragged lists, complex
    numbers, strings); the shape is checked by the caller."""
    what = "control points must be a dense (n, 3) array of real numbers"
    if sp.issparse(value):
        raise InvalidInputError(f"{what}, got a scipy sparse matrix (use .toarray())")
    try:
        a = np.asarray(value)
    except ValueError:  # ragged nested lists
        raise InvalidInputError(f"{what}; the rows have different lengths") from None
    if np.iscomplexobj(a):
        raise InvalidInputError(f"{what}, got complex numbers (take .real if that is meant)")
    try:
        return np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{what}, got {a.dtype} values") from None


def _user_path(path) -> Path:
    """A file name given by a user (str, bytes or path object) as a Path, ``~`` expanded."""
    try:
        name = os.fspath(path)
    except TypeError:
        raise InvalidInputError(
            f"a file name must be a str, bytes or path object, got {path!r}"
        ) from None
    return Path(os.fsdecode(name)).expanduser()


# data that differ from the data a surface was fitted to by at most this share of its diagonal
# (per point, in its distance to the surface) count as the same for refine(): float32 coordinates
# rounded again (Blender's Apply Rotation & Scale; about 17 float32 steps of the data's extent;
# Blender also passes 4 steps of the largest coordinate to fitted_to, for data far from the
# origin)
ROUNDING_RTOL = 1e-6

# TCBSurface.reordered: the data parameterized again must give the surface's parameters to
# this (each column sorted; the domain spans [-1, 1]); a renumbered mesh's agree to about
# 2e-15, and a compact file's are rounded by at most 6e-8
REORDERED_UV_TOL = 1e-6


def _same_map(new: Parameterization, old: Parameterization) -> bool:
    """Whether ``new`` (the data parameterized again, in another order) gives the parameters of
    ``old`` as a set: the same kind and counts (of the used points, faces, boundary, holes),
    and each column of the used points' ``uv`` and
    of the domain polygon, sorted, within :data:`REORDERED_UV_TOL`."""
    # (the count of all points may differ: a mesh's vertices in no face; TCBSurface.same_mesh)
    if new.kind != old.kind or new.flipped != old.flipped:
        return False  # (the other canonical winding: the mirrored map)
    if int(np.count_nonzero(new.used)) != int(np.count_nonzero(old.used)):
        return False
    # (a cloud's holes are not its map: the lattice of cloud_holes, where a hole at the
    # threshold may come and go with the rounding of a compact file's parameters)
    pairs = ((new.faces, old.faces), (new.boundary, old.boundary)) + (
        ((new.holes, old.holes),) if new.kind == "disk" else ())
    for a, b in pairs:
        if (a is None) != (b is None) or (a is not None and len(a) != len(b)):
            return False
    if np.shape(new.domain_polygon) != np.shape(old.domain_polygon):
        return False
    for a, b in ((np.asarray(new.uv)[np.asarray(new.used, dtype=bool)],
                  np.asarray(old.uv)[np.asarray(old.used, dtype=bool)]),
                 (new.domain_polygon, old.domain_polygon)):
        a = np.sort(np.asarray(a, dtype=np.float64), axis=0)  # (each column: a set of values
        b = np.sort(np.asarray(b, dtype=np.float64), axis=0)  # moved by e moves by <= e sorted)
        if not np.all(np.abs(a - b) <= REORDERED_UV_TOL):
            return False
    return True


def _rounded_like(new: Parameterization, old: Parameterization) -> Parameterization:
    """``new`` with its ``uv`` (but a mesh's boundary rows, which a compact file keeps exact)
    and ``stretch`` rounded to float32 where ``old``'s are float32 values (read from a compact
    file), so that a refine of the data in another order fits the same parameters."""
    def float32(x):
        x = np.asarray(x, dtype=np.float64)
        x = x[np.isfinite(x)]
        return x.size > 0 and np.array_equal(x, x.astype(np.float32))

    changes = {}
    rows = np.asarray(old.used, dtype=bool).copy()
    if old.boundary is not None:
        rows[old.boundary] = False
    if float32(np.asarray(old.uv)[rows]):
        uv = np.asarray(new.uv, dtype=np.float64).astype(np.float32).astype(np.float64)
        if new.boundary is not None:
            uv[new.boundary] = new.uv[new.boundary]
        changes["uv"] = _readonly(uv)
    if old.stretch is not None and new.stretch is not None and float32(old.stretch):
        changes["stretch"] = _readonly(
            np.asarray(new.stretch, dtype=np.float64).astype(np.float32).astype(np.float64))
    return dataclasses.replace(new, **changes) if changes else new


def faces_digest(faces) -> str | None:
    """A digest (BLAKE2b, 128 bits, hex) of the faces as given (int64, in their order), or None
    when they are no integer array: ``refine()`` compares it, not the fit's own faces, which
    are the given ones cleaned (degenerate and repeated faces dropped, orientation made
    consistent: review)."""
    f = _int_faces(faces)
    if f is None:
        return None
    return hashlib.blake2b(str(f.shape).encode() + f.tobytes(), digest_size=16).hexdigest()


def _int_faces(faces) -> np.ndarray | None:
    """``faces`` as a contiguous int64 array (float values that are whole numbers too), or None
    when they are no such array."""
    try:
        f = np.asarray(faces)
        if f.dtype.kind == "f" and np.isfinite(f).all() and (f == np.round(f)).all():
            f = f.astype(np.int64)
        if f.dtype.kind not in "iu":
            return None
        return np.ascontiguousarray(f, dtype=np.int64)
    except (TypeError, ValueError, OverflowError):
        return None


def _sorted_points(points) -> tuple[np.ndarray, np.ndarray]:
    """``points`` (n, d) as float64 in an order of their coordinates
    (:func:`core.geometry.coordinate_order`) and that order."""
    p = np.asarray(points, dtype=np.float64)
    order = coordinate_order(p) if p.ndim == 2 and p.shape[1] else None
    order = np.arange(len(p)) if order is None else order
    return p[order], order


def point_labels(points) -> np.ndarray:
    """A label (n,) int64 of each of ``points`` (n, d) that follows its coordinates alone: its
    place among the distinct points in an order of their coordinates (equal points, -0.0 and
    0.0 alike, get the same label). :func:`faces_set_digest` numbers a mesh's vertices so."""
    q, order = _sorted_points(points)
    labels = np.empty(len(q), dtype=np.int64)
    if len(q):
        new = np.r_[True, np.any(q[1:] != q[:-1], axis=1)]
        labels[order] = np.cumsum(new) - 1
    return labels


def faces_set_digest(faces, points) -> str | None:
    """A digest (BLAKE2b, 128 bits, hex) of ``faces`` (f, k) on ``points`` as a set of
    polygons of labelled vertices: each index ``i`` replaced by the :func:`point_labels` of
    ``points`` (which follow the vertices' coordinates), each polygon turned to its least
    rotation (a reversed winding is another face) and the rows sorted. The same mesh stored in
    another order (its vertices, its faces: Blender's Sort Elements; a polygon's corners
    turned: the fit cuts polygons by their shape, core.geometry.polygon_triangles) has the
    same digest; ``refine()`` compares it when :func:`faces_digest` differs. (Until the
    thirty-fourth session only triangles and quads were turned: polygons of more corners
    were split into fans from their first corner.)
    None when the faces are no integer (f, k) array of indices into ``points``."""
    f = _int_faces(faces)
    n = len(points)
    if f is None or f.ndim != 2 or (f.size and (f.min() < 0 or f.max() >= n)):
        return None
    lab = point_labels(points)[f]
    k = lab.shape[1]
    if len(lab) and k >= 3:
        turns = lab[:, (np.arange(k)[:, None] + np.arange(k)) % k]  # (f, k rotations, k)
        least = np.ones(turns.shape[:2], dtype=bool)
        for c in range(k):  # the lexicographically least rotation
            col = np.where(least, turns[:, :, c], np.iinfo(np.int64).max)
            least &= col == col.min(axis=1, keepdims=True)
        lab = turns[np.arange(len(lab)), np.argmax(least, axis=1)]
    if len(lab) and k > 1:
        lab = lab[np.lexsort(lab.T[::-1])]
    lab = np.ascontiguousarray(lab)
    return hashlib.blake2b(str(lab.shape).encode() + lab.tobytes(), digest_size=16).hexdigest()


def _row_hashes(values: np.ndarray) -> np.ndarray:
    """Two 64-bit hashes (n, 2) uint64 of each row of the float64 ``values`` (n, d): its words
    (-0.0 as 0.0) mixed in turn by splitmix64's finalizer, from two seeds."""
    v = np.ascontiguousarray(np.asarray(values, dtype=np.float64) + 0.0)
    words = v.reshape(len(v), -1).view(np.uint64)
    out = np.empty((len(v), 2), dtype=np.uint64)
    for lane, seed in enumerate((0x9E3779B97F4A7C15, 0xD1B54A32D192ED03)):
        h = np.full(len(v), seed, dtype=np.uint64)
        for j in range(words.shape[1]):
            h = _mix64(h ^ words[:, j])
        out[:, lane] = h
    return out


def _mix64(h: np.ndarray) -> np.ndarray:
    """splitmix64's finalizer on uint64 values (wrapping products)."""
    h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


def _multiset_text(hashes: np.ndarray) -> str:
    """The sums (mod 2^64) of both lanes of ``hashes`` (n, 2) and n: one text for the same rows
    in any order."""
    total = hashes.sum(axis=0, dtype=np.uint64)
    return f"{len(hashes)}:{int(total[0]):016x}{int(total[1]):016x}"


def _rounded(points) -> np.ndarray:
    """``points`` rounded to 32-bit floats, as float64 (what Blender keeps of them)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(points, dtype=np.float64).astype(np.float32).astype(np.float64)


def rounded_set_digest(points) -> str:
    """A digest of ``points`` (n, d) rounded to 32-bit floats, as a multiset of rows: the sums
    of two 64-bit hashes of each row (:func:`_row_hashes`), so that the same values in any
    order, before or after Blender's rounding of a file's 64-bit values, have the same one;
    ``report["data_set_digest32"]``. Linear, no sort: 1e6 points in about 0.1 s (a sort
    digest of them, :func:`data_set_digest`, took 0.9 s)."""
    return _multiset_text(_row_hashes(_rounded(points)))


def _float32_values(points) -> bool:
    """Whether ``points`` are 32-bit float values (Blender's: their rounded digests are the
    exact ones)."""
    p = np.asarray(points, dtype=np.float64)
    return bool(np.array_equal(_rounded(p), p, equal_nan=True))


def rounded_faces_digest(faces, points, checked: bool = False) -> str | None:
    """A digest of ``faces`` (f, k) on ``points`` rounded to 32-bit floats as a multiset of
    polygons of vertex positions: each polygon hashed from its corners' row hashes from the
    corner of least hash on (a reversed winding is another face), the sums over polygons
    (``report["faces_set_digest32"]``; the rounded twin of :func:`faces_set_digest`; 2e6
    triangles in 0.5-1 s). None when the faces are no integer (f, k) array of indices into
    ``points``, and (unless ``checked``: a comparison) when the points are 32-bit values,
    whose exact digest is the one to keep."""
    if not checked and _float32_values(points):
        return None
    return _polygon_multiset(faces, _rounded(points))


def _faces_keys(faces, points) -> tuple:
    """The digests of a mesh's ``faces`` on ``points`` that a fit's report keeps:
    :func:`faces_digest`, :func:`faces_set_digest`, :func:`rounded_faces_digest` (None for
    32-bit values) and :func:`mesh_digest` (only for 32-bit values: otherwise the rounded one
    is the same digest of the rounded positions, and :meth:`TCBSurface.same_mesh` takes it;
    one digest less, 1.3 s for 2e6 triangles)."""
    key32 = rounded_faces_digest(faces, points)
    return (faces_digest(faces), faces_set_digest(faces, points), key32,
            mesh_digest(faces, points) if key32 is None else None)


def mesh_digest(faces, points) -> str | None:
    """A digest of ``faces`` (f, k) on ``points`` as a multiset of polygons of the float64
    vertex positions (:func:`rounded_faces_digest` unrounded; ``report["mesh_digest"]``): it
    holds the vertices in faces and their values, not their numbers, so a vertex in no face
    added or deleted (which renumbers the others) leaves it as it is; :meth:`TCBSurface.refine`
    takes such a mesh (:meth:`TCBSurface.same_mesh`). None when the faces are no integer
    (f, k) array of indices into ``points``."""
    return _polygon_multiset(faces, points)


def _polygon_multiset(faces, values) -> str | None:
    """The multiset digest of ``faces`` (f, k) as polygons of the rows of ``values`` (n, d):
    each polygon hashed from its corners' :func:`_row_hashes` from the corner of least hash on
    (a reversed winding is another polygon), the sums over polygons (:func:`_multiset_text`).
    None when the faces are no integer (f, k) array of indices into ``values``."""
    f = _int_faces(faces)
    n = len(values)
    if f is None or f.ndim != 2 or (f.size and (f.min() < 0 or f.max() >= n)):
        return None
    corner = _row_hashes(values)[f]  # (f, k, 2)
    k = f.shape[1]
    out = np.zeros((len(f), 2), dtype=np.uint64)
    if k and len(f):
        # each polygon from its corner of least hash on: the same for its corners turned
        start = np.argmin(corner[:, :, 0], axis=1)
        corner = np.take_along_axis(corner, ((start[:, None] + np.arange(k)) % k)[..., None],
                                    axis=1)
        for lane in range(2):
            h = np.full(len(f), 0x2545F4914F6CDD1D + lane, dtype=np.uint64)
            for c in range(k):
                h = _mix64(h ^ corner[:, c, lane])
            out[:, lane] = h
    return _multiset_text(out)


def data_set_digest(points: np.ndarray) -> str:
    """A digest (BLAKE2b, 128 bits, hex) of the float64 values of ``points`` as a set of rows:
    the :func:`data_digest` of the rows in an order of their coordinates
    (:func:`core.geometry.coordinate_order`). The same data stored in another order (Blender's
    Sort Elements) has the same digest: ``refine()`` compares it when ``data_digest`` differs,
    and then parameterizes the data again (:meth:`TCBSurface.reordered`). 1e6 points: 0.1 s
    when their first coordinates have no ties, about 0.5 s otherwise."""
    return data_digest(_sorted_points(points)[0])


def data_digest(points: np.ndarray) -> str:
    """A digest (BLAKE2b, 128 bits, hex) of the float64 values of ``points`` in their order:
    ``refine()`` uses it to refuse data other than the data a surface was fitted to."""
    p = np.asarray(points, dtype=np.float64)
    h = hashlib.blake2b(str(p.shape).encode(), digest_size=16)
    for s in range(0, len(p), 65536):  # in chunks: no copy of a large input
        h.update(np.ascontiguousarray(p[s : s + 65536] + 0.0).data)  # -0.0 and 0.0 alike
    return h.hexdigest()


# _lattice_frame: a domain's smallest enclosing rectangle is used when its area is under this
# share of the axis-aligned box's
LATTICE_FRAME_GAIN = 0.9


def _lattice_frame(poly: np.ndarray) -> np.ndarray | None:
    """The rotation ``R`` (2, 2; columns: the new axes) of the smallest rectangle enclosing the
    convex polygon ``poly`` (one of its sides lies along an edge of the polygon), turned by
    at most 45 degrees, or None when its area is at least LATTICE_FRAME_GAIN times that of
    the axis-aligned box (not in method.md). A tessellation's grid in that frame covers the
    domain as it would if the data were turned to the axes: the parameters of a cloud follow
    its principal directions, which for a square are arbitrary (Franke's square turned 45
    degrees got half the vertices of the same square along the axes at one resolution)."""
    e = np.roll(poly, -1, axis=0) - poly
    length = np.linalg.norm(e, axis=1)
    e = e[length > 0] / length[length > 0, None]
    if len(e) < 3:
        return None
    n = np.c_[-e[:, 1], e[:, 0]]
    area = np.ptp(poly @ e.T, axis=0) * np.ptp(poly @ n.T, axis=0)
    k = int(np.argmin(area))
    box = float(np.prod(np.ptp(poly, axis=0)))
    if not area[k] < LATTICE_FRAME_GAIN * box:
        return None
    angle = np.arctan2(e[k, 1], e[k, 0])
    angle -= 0.5 * np.pi * np.round(angle / (0.5 * np.pi))  # (a rectangle: modulo 90 degrees)
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def _is_convex(v: np.ndarray) -> bool:
    """Whether the CCW polygon ``v`` (b, 2) turns left (or goes straight) at every vertex, to
    1e-12 of its size squared."""
    e = np.roll(v, -1, axis=0) - v
    f = np.roll(e, -1, axis=0)
    turn = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
    return bool((turn >= -1e-12 * float(np.ptp(v, axis=0).max()) ** 2).all())


def convex_domain(polygon) -> np.ndarray:
    """The CCW polygon (b, 2) itself when it is convex, else its convex hull (a mesh's
    flattened boundary, :mod:`.parameterize`)."""
    v = np.asarray(polygon, dtype=np.float64)
    return v if _is_convex(v) else v[ConvexHull(v).vertices]


def tessellation_step(param, resolution: int) -> float:
    """The grid step of ``tessellation_uv(resolution)`` over the domain of ``param``: the longer
    side ``L`` of the grid frame (:func:`grid_frame`) over ``resolution``, times
    ``sqrt(A / (TESSELLATION_FULL_SHARE L^2))`` when the domain polygon's area ``A`` is under
    TESSELLATION_FULL_SHARE of the square on that side (so that a long or ragged domain holds
    about ``TESSELLATION_FULL_SHARE resolution^2`` grid cells, as a domain filling that share
    of its square does, rather than a few of them), and at most the shorter side over
    TESSELLATION_MIN_ACROSS."""
    _, lo, hi = grid_frame(param)
    side, across = float(np.max(hi - lo)), float(np.min(hi - lo))
    return min(side / resolution * tessellation_fill(param), across / TESSELLATION_MIN_ACROSS)


def tessellation_fill(param) -> float:
    """``sqrt(A / (TESSELLATION_FULL_SHARE L^2))`` for a domain polygon of area ``A`` filling
    less than TESSELLATION_FULL_SHARE of the square on the longer side ``L`` of its grid frame,
    else 1: how much finer than ``L / resolution`` :func:`tessellation_step` is."""
    _, lo, hi = grid_frame(param)
    side = float(np.max(hi - lo))
    poly = np.asarray(param.domain_polygon, dtype=np.float64)
    area = 0.5 * abs(float(np.dot(poly[:, 0], np.roll(poly[:, 1], -1))
                           - np.dot(poly[:, 1], np.roll(poly[:, 0], -1))))
    if side > 0 and area < TESSELLATION_FULL_SHARE * side * side:
        return float(np.sqrt(area / (TESSELLATION_FULL_SHARE * side * side)))
    return 1.0


def grid_frame(param) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """``(rot, lo, hi)``: the frame of a tessellation's grid over the domain of ``param`` (a
    :class:`Parameterization`) and the domain polygon's box in it: the smallest rectangle
    enclosing a cloud's domain, or a mesh's flattened boundary (not on the unit circle; a
    rectangle is axis-aligned already), when its area is under LATTICE_FRAME_GAIN of the
    box's (:func:`_lattice_frame`; a square whose parameter axes ran along its diagonals got
    half the vertices: user test), else the uv axes (``rot`` None)."""
    poly = np.asarray(param.domain_polygon, dtype=np.float64)
    circle = param.kind == "disk" and np.allclose(np.hypot(poly[:, 0], poly[:, 1]), 1.0,
                                                  rtol=0, atol=1e-12)
    rot = None if circle else _lattice_frame(convex_domain(poly))
    w = poly if rot is None else poly @ rot
    return rot, w.min(axis=0), w.max(axis=0)


def _lattice(deep: np.ndarray, number: np.ndarray, origin, d: float):
    """The structured part of a tessellation grid: ``(cells, rest, in_cells)``.

    ``deep`` (rows, cols) flags grid points more than ``2 d`` inside the domain, ``number`` is
    their vertex index (-1 if not a vertex), ``origin`` the parameters of grid point (0, 0) and
    ``d`` the grid step. A cell whose four corners are deep is split into two CCW triangles
    (``cells``, (2 c, 3)) instead of being Delaunay-triangulated: qhull's Delaunay of a lattice
    costs seconds at resolution 500 (co-circular points), this costs milliseconds. ``rest``
    are the vertex numbers of the other grid points (a corner of some other cell), and
    ``in_cells(x)`` flags parameters inside the split cells. The split cells' outline edges
    are Gabriel edges of ``rest`` plus the boundary samples (their diametral disks hold no
    other grid point, and boundary samples are over 1.5 d away), hence Delaunay edges."""
    rows, cols = deep.shape
    whole = np.zeros((max(rows - 1, 0), max(cols - 1, 0)), dtype=bool)
    if rows > 1 and cols > 1:
        whole = deep[:-1, :-1] & deep[:-1, 1:] & deep[1:, :-1] & deep[1:, 1:]
    j, i = np.nonzero(whole)
    a, b = number[j, i], number[j, i + 1]
    c, e = number[j + 1, i + 1], number[j + 1, i]
    cells = np.stack([np.c_[a, b, c], np.c_[a, c, e]], axis=1).reshape(-1, 3)
    # grid points all of whose cells are split are interior to the split region
    pad = np.zeros((rows + 1, cols + 1), dtype=bool)
    pad[1:-1, 1:-1] = whole
    interior = pad[:-1, :-1] & pad[:-1, 1:] & pad[1:, :-1] & pad[1:, 1:]
    rest = number[(number >= 0) & ~interior]

    def in_cells(x):
        k = np.floor((x - origin) / d).astype(np.int64)
        ok = (k[:, 0] >= 0) & (k[:, 0] < cols - 1) & (k[:, 1] >= 0) & (k[:, 1] < rows - 1)
        out = np.zeros(len(x), dtype=bool)
        out[ok] = whole[k[ok, 1], k[ok, 0]]
        return out

    return cells.astype(np.intp), rest.astype(np.intp), in_cells if len(cells) else None


def _same_rows(known: np.ndarray, x: np.ndarray) -> np.ndarray:
    """For each row of ``x`` (m, 2) the index of a row of ``known`` (k, 2) with the same bits,
    -1 where there is none (float64 parameters: a hash of both words, sorted and looked up,
    then the bits compared)."""
    kb = np.ascontiguousarray(known, dtype=np.float64).view(np.int64)
    xb = np.ascontiguousarray(x, dtype=np.float64).view(np.int64)
    if not len(kb) or not len(xb):
        return np.full(len(xb), -1)
    mix = np.int64(-7046029254386353131)  # (0x9E3779B97F4A7C15: products wrap around)
    hk, hx = kb[:, 0] * mix + kb[:, 1], xb[:, 0] * mix + xb[:, 1]
    order = np.argsort(hk)
    pos = np.minimum(np.searchsorted(hk[order], hx), len(hk) - 1)
    at = order[pos]
    return np.where((kb[at] == xb).all(axis=1), at, -1)


def _split_edges(uv: np.ndarray, tri: np.ndarray, marked) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """One round of conforming edge splits: every edge for which ``marked(length, midpoint)``
    holds gets its midpoint, and each triangle is split by the number of its marked edges
    (red-green refinement): 1 -> 2 triangles (the midpoint joined to the opposite corner),
    2 -> 3 (the corner between them cut off, the rest along the shorter diagonal), 3 -> 4
    (the midpoint triangle). Both triangles of an edge see the same midpoint, so the mesh
    stays conforming; CCW triangles stay CCW. Returns the parameters with the midpoints
    appended, the triangles left as they were, and the new ones (none: nothing was split).
    The mark depends on the edge alone, so a later round needs only the new triangles: the
    others' edges stay unmarked."""
    n = len(uv)
    # each triangle's edges, column by column (the two triangles of an edge see the same
    # sorted ends, hence the same midpoint and length, to the bit, and the same mark); only
    # the marked ones are numbered (np.unique of every edge cost ~1 s at resolution 1024)
    key = np.empty(tri.shape, dtype=np.int64)
    hit = np.empty(tri.shape, dtype=bool)
    for k in range(3):
        a, b = np.minimum(tri[:, k], tri[:, (k + 1) % 3]), np.maximum(tri[:, k], tri[:, (k + 1) % 3])
        key[:, k] = a * n + b
        hit[:, k] = marked(np.linalg.norm(uv[a] - uv[b], axis=1), 0.5 * (uv[a] + uv[b]))
    if not hit.any():
        return uv, tri, tri[:0]
    split = np.unique(key[hit])
    i, j = split // n, split % n
    mid = 0.5 * (uv[i] + uv[j])
    m = np.full(tri.shape, -1)  # (T, 3) midpoint of edge k = (v_k, v_k+1), or -1
    m[hit] = n + np.searchsorted(split, key[hit])
    count = np.count_nonzero(hit, axis=1)
    out = []
    rows = np.arange(len(tri))[:, None]
    # one split edge: rotate it to (v0, v1); triangles (v0, m, v2), (m, v1, v2)
    t1 = count == 1
    r = np.argmax(m[t1] >= 0, axis=1)
    rot = (r[:, None] + np.arange(3)) % 3
    v, mm = tri[t1][rows[: len(r)], rot], m[t1][rows[: len(r)], rot][:, 0]
    out += [np.c_[v[:, 0], mm, v[:, 2]], np.c_[mm, v[:, 1], v[:, 2]]]
    # two split edges: rotate the unsplit one to (v2, v0); corner (m01, v1, m12), and the
    # quad (v0, m01, m12, v2) along its shorter diagonal
    t2 = count == 2
    u = np.argmax(m[t2] < 0, axis=1)
    rot = (u[:, None] + 1 + np.arange(3)) % 3
    v, mm = tri[t2][rows[: len(u)], rot], m[t2][rows[: len(u)], rot]
    allp = np.vstack([uv, mid])
    a, m01, m12, c = v[:, 0], mm[:, 0], mm[:, 1], v[:, 2]
    first = (np.linalg.norm(allp[a] - allp[m12], axis=1)
             <= np.linalg.norm(allp[m01] - allp[c], axis=1))[:, None]
    out += [np.c_[m01, v[:, 1], m12],
            np.where(first, np.c_[a, m01, m12], np.c_[a, m01, c]),
            np.where(first, np.c_[a, m12, c], np.c_[m01, m12, c])]
    # three: the midpoint triangle and the three corners
    t3 = count == 3
    v, mm = tri[t3], m[t3]
    out += [np.c_[v[:, 0], mm[:, 0], mm[:, 2]], np.c_[mm[:, 0], v[:, 1], mm[:, 1]],
            np.c_[mm[:, 2], mm[:, 1], v[:, 2]], mm]
    return allp, tri[count == 0], np.vstack(out)


def _gridded(f, lo: np.ndarray, hi: np.ndarray, cells: int):
    """``f`` (parameters (m, 2) -> (m,)) evaluated once at the centres of a grid over the box
    ``lo``-``hi`` with ``cells`` square cells along its longer side; returns the lookup ``x ->
    f(centre of the cell holding x)`` (clamped to the grid)."""
    step = float(np.max(hi - lo)) / cells
    shape = np.maximum(np.ceil((hi - lo) / step - 1e-9).astype(np.int64), 1)  # (u cells, v cells)
    gu = lo[0] + step * (np.arange(shape[0]) + 0.5)
    gv = lo[1] + step * (np.arange(shape[1]) + 0.5)
    values = np.asarray(f(np.stack(np.meshgrid(gu, gv), -1).reshape(-1, 2)), dtype=np.float64)
    values = values.reshape(shape[1], shape[0])

    def lookup(x):
        k = np.clip(np.floor((np.asarray(x) - lo) / step).astype(np.int64), 0, shape - 1)
        return values[k[:, 1], k[:, 0]]

    return lookup


def _distance_to_polygon(x: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (m,) from points to the boundary of a polygon (vectorized over edges, in
    chunks of points so that memory stays bounded)."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    ab2 = np.maximum((ab * ab).sum(-1), 1e-300)
    out = np.empty(len(x))
    step = max(1, 2_000_000 // max(len(a), 1))
    for s in range(0, len(x), step):
        xs = x[s : s + step, None, :]
        t = np.clip(((xs - a[None]) * ab[None]).sum(-1) / ab2, 0.0, 1.0)
        proj = a[None] + t[..., None] * ab[None]
        out[s : s + step] = np.sqrt(((xs - proj) ** 2).sum(-1)).min(axis=1)
    return out


def mesh_samples(points, uv, faces, count: int, seed: int = 0, curved: bool = True,
                 vertex_normals=None, area_table=None, smooth=None, with_faces=False,
                 prepared=None):
    """Points sampled on the triangles of a parameterized mesh, with their parameters.

    ``count`` samples, allotted to the faces in proportion to their 3D area; each at random
    barycentric coordinates ``b`` (seeded), where the parameterization is linear: ``uv = sum
    b_i uv_i``. The point is on the C^1 surface through the vertices that
    :func:`smooth_points` makes (``curved``; on a dense mesh, with fewer than
    :data:`SMOOTH_SAMPLES_PER_FACE` samples per face, on the point-normal triangles of
    :func:`curved_points`), or on the flat face, ``p = sum b_i p_i``.
    Fitting these as well as the vertices fits the mesh as a surface instead of interpolating
    a few hundred vertices (not in method.md: section 5 fits the data points as given). On
    the flat faces a coarse mesh was fitted as its facets, creases between them and all: a cap
    of a sphere of 55 vertices took 743 control points and ended 4.7e-3 of its diagonal (RMS)
    from the sphere; on point-normal triangles (:func:`curved_points`, C^0 across the edges in
    the parameters) 146 and 1.0e-3; on the C^1 surface 146 and 3.6e-4
    (benchmarks/coarse_meshes.py). ``vertex_normals``: :func:`_vertex_normals` of ``(points,
    faces)`` and ``area_table``: :func:`_area_table` when known (the fit's fold check uses
    them too). ``smooth``: on the C^1 surface or the point-normal triangles whatever the count
    (default: by the count, as above); ``prepared``: :func:`smooth_corners` when made already;
    ``with_faces``: the face of each sample too (a third array).
    """
    face, bary = _area_samples(points, faces, count, seed, area_table)
    if smooth is None:
        smooth = count >= SMOOTH_SAMPLES_PER_FACE * len(faces)
    p, x = _face_points(points, uv, faces, face, bary, curved, smooth, vertex_normals, prepared)
    return (p, x, face) if with_faces else (p, x)


def _face_points(points, uv, faces, face, bary, curved, smooth, vertex_normals=None,
                 prepared=None):
    """The points at barycentric coordinates ``bary`` (n, 3) in the faces ``face`` (n,) and
    their parameters, on the surface :func:`mesh_samples` describes (``curved``, ``smooth``)."""
    tri = faces[face]
    x = np.einsum("nk,nkj->nj", bary, uv[tri])
    if curved and len(face):
        p = (smooth_points(points, uv, faces, face, bary, vertex_normals=vertex_normals,
                           prepared=prepared) if smooth else
             curved_points(points, faces, face, bary, vertex_normals=vertex_normals))
    else:
        p = np.einsum("nk,nkj->nj", bary, points[tri])
    return p, x


def border_edges(points, faces):
    """The mesh's border edges (those of one face), in the order of their ends' coordinates,
    each from its end of least coordinates (:func:`core.geometry.coordinate_order`): the face
    (e,) of each, the corner (e,) its edge starts at (it ends at the next), whether its end of
    least coordinates is the next corner's (e,) bool, and its 3D length (e,). Neither the order
    of the vertices or faces nor the corner a face starts at changes them (as
    :func:`_area_samples`)."""
    faces = np.asarray(faces)
    # (a face stored twice would count its edges twice: once each)
    kept = np.sort(np.unique(np.sort(faces, axis=1), axis=0, return_index=True)[1])
    faces = faces[kept]
    a, b = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    _, inverse, counts = np.unique(np.sort(np.c_[a, b], axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    once = np.flatnonzero(counts[inverse.ravel()] == 1)
    rank = np.empty(len(points), dtype=np.int64)
    order = coordinate_order(points)  # (None: already in that order)
    rank[np.arange(len(points)) if order is None else order] = np.arange(len(points))
    ra, rb = rank[a[once]], rank[b[once]]
    flip = rb < ra
    along = np.lexsort((np.maximum(ra, rb), np.minimum(ra, rb)))
    once, flip = once[along], flip[along]
    length = np.linalg.norm(points[a[once]] - points[b[once]], axis=1)
    return kept[once // 3], once % 3, flip, length


def _border_samples(edges, count: int, seed: int = 0):
    """``count`` random points (seeded) on the border ``edges`` (:func:`border_edges`), in
    proportion to their length: the face (count,) of each and its barycentric coordinates
    (count, 3), 0 at the face's corner off the edge; none if the edges have no length."""
    face, corner, flip, length = edges
    if count <= 0 or not length.sum() > 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(length), size=count, p=length / length.sum())
    t = rng.random(count)  # from the edge's end of least coordinates
    first = np.where(flip[pick], t, 1.0 - t)  # the weight of the corner the edge starts at
    bary = np.zeros((count, 3))
    rows = np.arange(count)
    bary[rows, corner[pick]] = first
    bary[rows, (corner[pick] + 1) % 3] = 1.0 - first
    return face[pick], bary


# mesh_samples puts the samples on the C^1 surface (smooth_points) when there are at least this
# many per face: its gradients cost 0.2 s for a mesh of 1e4 vertices and 2.0 s for one of 1e5
# (the point-normal triangles 0.05 and 0.15 s), whose fit then took 5.7 s instead of 3.9;
# dense meshes, whose faces are small, gain nothing from it (benchmarks/coarse_meshes.py: the
# 917-vertex cap and the 41 x 41 grid level) and get a sample on a face in two or fewer
# (mesh_sample_count's cap)
SMOOTH_SAMPLES_PER_FACE = 2


def mesh_sample_count(vertices: int, max_control_points: int) -> int:
    """How many points a mesh's fit samples on its faces (:func:`mesh_samples`): 20 per vertex,
    at least 5000, and at most 25 per control point of the budget (at least 50 000) and
    200 000. A dense mesh's vertices hold its net already: a 100 x 100 grid mesh took 2.4 s
    with 200 000 samples and 0.9 s with 50 000, as close to its true surface (1.3e-4 and 1.1e-4
    of the diagonal), a 200 x 200 one 3.0 s and 1.7 s (1.3e-4, 1.7e-4; /tmp/s31/samplecap.py,
    thirty-first session; Blender's Fit of the 100 x 100 grid: 3.9-4.5 s, its vertices as a
    cloud 0.8 s: user test)."""
    cap = min(200_000, max(50_000, 25 * int(max_control_points)))
    return int(np.clip(20 * vertices, 5_000, cap))


# the face check of a mesh's fits (FaceCheck): each fit is checked at this many samples per
# control point of its space (at least STRAY_CHECK_MIN), new ones each time until the pool
# holds STRAY_POOL_PER_CONTROL per control point of the budget (within STRAY_POOL), then again
# from its start; a sample strays when its error is above STRAY_RATIO times the largest of
# its STRAY_NEIGHBOURS nearest fitted points' (in the parameters) and above the floor: the
# tolerance, and at least STRAY_FLOOR of the diagonal
STRAY_CHECK_PER_CONTROL = 5
STRAY_CHECK_MIN = 2_000
STRAY_POOL_PER_CONTROL = 20
STRAY_POOL = (5_000, 100_000)
STRAY_RATIO = 3.0
STRAY_NEIGHBOURS = 6
STRAY_FLOOR = 1e-5
STRAY_SEED = 0x5EED  # the pool's draws are seeded with the fit's seed plus this (and a count)
FACE_CHECK = True  # (off: benchmarks/fins.py's peer, the loop before the check)
BORDER_SAMPLES = True  # (off: fins.py's peer, the check on the faces only, as before)
BORDER_SHARE = 0.25  # border samples per draw of the pool: at most this times its count


class FaceCheck:
    """Where a fit of a mesh strays from it between the points it fitted, and more samples
    there (not in method.md; :func:`core.refine.adaptive_fit`'s ``stray_check``).

    A coarse mesh is fitted through its vertices and :func:`mesh_samples` on its faces, at a
    density that does not follow the net. Near a crease, where the knots crowd, a net of
    ~1000 control points had fewer than 3 fitted points each, and between them the surface
    swung off the mesh as a fin: a sheet of 231 vertices bent by 90 degrees, fitted at 1e-4,
    was 2.6 off it (of a diagonal of 173) where the report said 0.074 at the vertices and
    0.23 at the samples, all it measured (user test; benchmarks/fins.py).

    Each call draws samples of the same surface as the fit's (``mesh_samples`` of the same
    kind, other seeds; ``smooth`` as the fit's were) into a pool, and evaluates the fit at
    them. The pool also holds samples on the mesh's border edges (:func:`border_edges`), as far
    apart along them as the faces' samples: a random point inside a face is never on its edge,
    and a fin where a crease meets the border went unseen (a bent sheet at seed 2: 1.6 off the
    mesh there, 0.30 with them; benchmarks/fins.py). A sample strays when its error is more than
    :data:`STRAY_RATIO` times the largest error at its :data:`STRAY_NEIGHBOURS` nearest fitted
    points and above ``floor`` (normalized units). The pool's samples on the faces that hold a
    stray one are returned to be fitted as well (and leave the pool). ``added`` keeps what was
    returned, in order. :meth:`errors` gives a fit's errors at the pool's samples not fitted
    (the report's errors on the faces count them)."""

    def __init__(self, points, uv, faces, budget: int, floor: float, seed: int = 0,
                 curved: bool = True, smooth: bool = True, vertex_normals=None,
                 area_table=None, prepared=None):
        self.mesh = (points, uv, faces)
        self.cap = int(np.clip(STRAY_POOL_PER_CONTROL * int(budget), *STRAY_POOL))
        self.floor = float(floor)
        self.seed, self.curved, self.smooth = int(seed) + STRAY_SEED, curved, smooth
        self.vertex_normals, self.area_table = vertex_normals, area_table
        self.prepared = prepared  # smooth_corners (made at the first draw if not given)
        self.border = None  # border_edges (made at the first draw)
        self.uv, self.points = np.zeros((0, 2)), np.zeros((0, 3))
        self.face, self.free = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
        self.start = 0  # where the next check starts in the pool
        self.draws = 0
        self.added: list = []

    def _draw(self, count: int) -> None:
        """``count`` more samples into the pool on the faces, and with them samples on the
        border edges, as far apart along the border as the draw's are on the faces
        (``ceil(length sqrt(count / area))``: a check takes about a draw's worth of the pool
        at a time), at most BORDER_SHARE times ``count`` (a long strip's border would
        outnumber its faces). (Taken out of ``count`` instead, the bent sheet's fins at
        seeds 0-5 were 0.93 / 0.51 / 0.28 / 0.18 / 0.29 / 0.17 off its mesh, against 0.15 /
        0.27 / 0.30 / 0.34 / 0.35 / 0.26: /tmp/s45/fin2.py.)"""
        points, uv, faces = self.mesh
        if self.curved and self.smooth and self.prepared is None:
            self.prepared = smooth_corners(points, uv, faces, self.vertex_normals)
        if self.area_table is None:
            self.area_table = _area_table(points, faces)
        if self.border is None:
            self.border = border_edges(points, faces)
        area, length = self.area_table[2].sum(), self.border[3].sum()
        along = 0
        if BORDER_SAMPLES and area > 0 and length > 0:
            along = int(min(np.ceil(length * np.sqrt(count / area)), BORDER_SHARE * count))
        p, x, f = mesh_samples(points, uv, faces, count, seed=self.seed + self.draws,
                               curved=self.curved, vertex_normals=self.vertex_normals,
                               area_table=self.area_table, smooth=self.smooth,
                               with_faces=True, prepared=self.prepared)
        fb, bary = _border_samples(self.border, along, seed=self.seed + self.draws)
        pb, xb = _face_points(points, uv, faces, fb, bary, self.curved, self.smooth,
                              self.vertex_normals, self.prepared)
        self.draws += 1
        self.uv = np.vstack([self.uv, x, xb])
        self.points = np.vstack([self.points, p, pb])
        self.face = np.concatenate([self.face, f, fb])
        self.free = np.concatenate([self.free, np.ones(len(x) + len(xb), dtype=bool)])

    def errors(self, space, control_points) -> np.ndarray:
        """The errors of the surface at the pool's samples not fitted (normalized units)."""
        keep = np.flatnonzero(self.free)
        return _distances(space, control_points, self.uv[keep], self.points[keep])

    def __call__(self, space, control_points, uv, errors):
        m = min(self.cap, max(STRAY_CHECK_MIN, STRAY_CHECK_PER_CONTROL * space.n_basis))
        if self.start + m > len(self.uv) and len(self.uv) < self.cap:
            self._draw(min(self.start + m, self.cap) - len(self.uv))
        if not len(self.uv) or not len(uv):
            return None
        pick = (self.start + np.arange(min(m, len(self.uv)))) % len(self.uv)
        # (the border samples of the last draw can take the pool past its cap, by at most
        # BORDER_SHARE of that draw: those are not checked. Wrapping after them instead made a
        # wiggly test fit's surface one whose own tessellation measured 1.2e-3 of the diagonal
        # from it at a fold, a closest-point miss: test_a_wiggly_fit_s_own_tessellation...)
        self.start = int(pick[-1] + 1) % self.cap
        pick = pick[self.free[pick]]
        if not len(pick):
            return None
        x = self.uv[pick]
        e = _distances(space, control_points, x, self.points[pick])
        k = min(STRAY_NEIGHBOURS, len(uv))
        near = cKDTree(uv).query(x, k=k, workers=-1)[1].reshape(len(x), k)
        stray = e > np.maximum(STRAY_RATIO * errors[near].max(axis=1), self.floor)
        if not stray.any():
            return None
        take = np.flatnonzero(self.free & np.isin(self.face, self.face[pick[stray]]))
        self.free[take] = False
        self.added.append((self.uv[take], self.points[take]))
        return self.added[-1]


def _distances(space, control_points, uv, points) -> np.ndarray:
    """``|S(uv_j) - p_j|`` in chunks (the basis of 2e5 points is ~16 MB)."""
    out = np.empty(len(uv))
    for s in range(0, len(uv), 200_000):
        A = space.evaluate(uv[s : s + 200_000])
        out[s : s + 200_000] = np.linalg.norm(A @ control_points - points[s : s + 200_000],
                                              axis=1)
    return out


# a corner of a face whose vertex normal turns more than this many degrees from the face's own
# normal is a crease's (or a fold's): curved_points takes the face's normal there, so that the
# facets meeting at a crease stay flat across it (90-degree creases turn the vertex normal
# 45 degrees from both faces; the facets of a sphere cap of 55 vertices, 10 degrees)
CREASE_ANGLE = 20.0
# ... and a face with a corner whose vertex normal turns less than this from each of the
# vertex's faces is in a flat region (a CAD mesh's planes) and stays flat: a
# long plane triangle of an STL file next to a tangent fillet of 4 facets sagged with the
# tilted normals along the fillet's edge (5e-3 of the diagonal off the plane), and plates
# creased by 20-40 degrees were rounded off (review of the curved samples). Faces of a coarse
# mesh of a smooth shape turn at every corner (a sphere cap of 55 vertices: 3-10 degrees),
# though one face around a vertex can share its normal (a grid of a saddle z = xy, by
# symmetry: with that face deciding, the curved samples of a 7 x 7 grid were 2.5x farther from
# the saddle).
FLAT_ANGLE = 0.1


# what a sparse cloud's warning tells the user to do with the smoothness (Blender says it in its
# own words: tcb_addon.operators._engine_notes)
SMOOTHNESS_ADVICE = ("leave the smoothness at its default or make it 'auto' to have it chosen "
                     "by cross-validation")


# a noisy mesh's faces are sampled flat (mesh_samples) where the RMS sag of its point-normal
# triangles from its faces (facet_sag) is under this share of its noise
# (core.parameterize.local_noise), curved where it is not. The curved samples interpolate the
# noise between the vertices with the turns of their normals, the flat ones take the facets'
# sag. Measured against the true surface at 1e-3 and 1e-4, with the net's cap
# (refine.NOISY_NET_PER_VERTEX; /tmp/s38/f8.py and f8b.py of the thirty-eighth session; the
# sag over the noise as the fit measures them, /tmp/s38/ratios.py, then the curved fit's
# distance as a share of the flat one's): sphere caps of UV spheres with noise along the
# normals 0.42: 0.61-0.72 (64 x 32 segments, noise 0.3% of the radius), 0.27: 0.73, 0.16:
# 0.96, 0.51: 0.98 (32 x 16, 1%), and 2.53 and 1.01 (32 x 16: benchmarks/noisy_meshes.py);
# wave grids with noise on every coordinate 0.39: 0.85-0.89 (21 x 21), 0.23: 0.91-1.05, 0.21:
# 1.10 (15 x 15), 0.15: 0.82, 0.14: 1.12-1.17 (41 x 41), 0.10: 1.06 (81 x 81); three_peaks.off
# (against its clean vertices' curved triangles) 0.33: 1.01, 0.22: 1.05. Without the cap the
# curved samples had chased the noise at 0.27 (722 control points instead of 147, 1.64x the
# distance), and a threshold of 0.5 was taken; with it 0.5 left the 64 x 32 cap with noise 0.3%
# flat, 1.4-1.6x farther from the sphere (user test)
FACET_SAG_OVER_NOISE = 0.25
FACET_SAG_SAMPLES = 4000  # ... at this many points drawn on the faces by area


def facet_sag(points, faces, seed: int = 0, vertex_normals=None, area_table=None) -> float:
    """The RMS distance between a mesh's point-normal triangles (:func:`curved_points`) and
    its flat faces at :data:`FACET_SAG_SAMPLES` seeded points drawn on them by area
    (:func:`_area_samples`): ``sqrt(mean |PN(b) - sum b_i P_i|^2)``; 0 for faces of no area.
    The sag of a coarse mesh of a curved shape, the turns of a noisy mesh's normals (not in
    method.md). ``vertex_normals``, ``area_table``: as for :func:`mesh_samples`."""
    face, bary = _area_samples(points, faces, FACET_SAG_SAMPLES, seed, area_table)
    if not len(face):
        return 0.0
    flat = np.einsum("nk,nkj->nj", bary, points[faces[face]])
    bent = curved_points(points, faces, face, bary, vertex_normals=vertex_normals) - flat
    return float(np.sqrt(np.mean(np.einsum("nj,nj->n", bent, bent))))


def curved_points(points, faces, face, bary, vertex_normals=None):
    """Points at barycentric coordinates ``bary`` (n, 3) on the faces ``face`` (n,) of the
    mesh ``(points, faces)``, on its curved point-normal triangles (PN triangles, Vlachos,
    Peters, Boyd and Mitchell 2001): the cubic Bezier triangle through the face's corners
    ``P_i`` that is tangent there to the planes across the vertex normals ``N_i`` (the
    corner-angle weighted sums of :func:`_vertex_normals`, a face's own normal at a corner
    beyond :data:`CREASE_ANGLE`, and at every corner of a face with a corner whose faces are
    all within :data:`FLAT_ANGLE` of its normal): control points ``b_300 = P_1`` (and the
    other corners),
    ``b_210 = (2 P_1 + P_2 - ((P_2 - P_1) . N_1) N_1) / 3`` (and the other five along the
    edges), ``b_111 = E + (E - V) / 2`` with ``E`` the mean of the six and ``V`` of the
    corners; the point is ``sum 3! / (i! j! k!) w^i u^j v^k b_ijk`` with ``(w, u, v)`` the
    barycentric coordinates of ``P_1, P_2, P_3``. Flat faces (all their normals the face's)
    stay flat; a face of no area, or a vertex whose normals cancel, has straight edges there.
    Adjacent faces share each edge's curve where neither end is a crease corner.
    ``vertex_normals``: :func:`_vertex_normals` when known."""
    own_corner, normal, unit = flat_corners(points, faces, normals=True,
                                            vertex_normals=vertex_normals)
    own = unit[face]
    tri = faces[face]
    P = points[tri]  # (n, 3 corners, 3)
    N = np.where(own_corner[face][..., None], own[:, None, :], normal[tri])

    def edge(i, j):  # b at 2/3 of P_i and 1/3 of P_j, pulled into P_i's tangent plane
        d = np.einsum("nj,nj->n", P[:, j] - P[:, i], N[:, i])[:, None]
        return (2.0 * P[:, i] + P[:, j] - d * N[:, i]) / 3.0

    b210, b120, b021, b012, b102, b201 = edge(0, 1), edge(1, 0), edge(1, 2), edge(2, 1), \
        edge(2, 0), edge(0, 2)
    E = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0
    b111 = E + (E - P.mean(axis=1)) / 2.0
    w, u, v = bary[:, 0:1], bary[:, 1:2], bary[:, 2:3]
    return (P[:, 0] * w**3 + P[:, 1] * u**3 + P[:, 2] * v**3
            + 3.0 * (b210 * w * w * u + b120 * w * u * u + b201 * w * w * v
                     + b021 * u * u * v + b102 * w * v * v + b012 * u * v * v)
            + 6.0 * b111 * w * u * v)


def flat_corners(points, faces, normals: bool = False, vertex_normals=None):
    """The corners (f, 3) bool of the faces that keep the face's own plane in the curved
    samples (:func:`curved_points`, :func:`smooth_points`): a corner whose vertex normal (unit,
    :func:`_vertex_normals`) turns more than :data:`CREASE_ANGLE` from the face's normal, and
    every corner of a face with a corner whose faces are all within :data:`FLAT_ANGLE` of the
    vertex's normal (a flat region). With ``normals``, also the vertices' unit normals (n, 3)
    and the faces' (f, 3). ``vertex_normals``: :func:`_vertex_normals` when known."""
    corner, normal = (_vertex_normals(points, faces) if vertex_normals is None
                      else vertex_normals)
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    unit = corner / np.maximum(np.linalg.norm(corner, axis=1, keepdims=True), 1e-300)
    turn = np.einsum("fkj,fj->fk", normal[faces], unit)
    own = turn < np.cos(np.radians(CREASE_ANGLE))
    least = np.ones(len(points))
    np.minimum.at(least, faces.ravel(), turn.ravel())
    own |= (least[faces] > np.cos(np.radians(FLAT_ANGLE))).any(axis=1, keepdims=True)
    return (own, normal, unit) if normals else own


def smooth_points(points, uv, faces, face, bary, vertex_normals=None, prepared=None):
    """Points at barycentric coordinates ``bary`` (n, 3) in the faces ``face`` (n,) of the mesh
    ``(points, faces)`` parameterized by ``uv``, on the C^1 Clough-Tocher interpolant of its
    map (:mod:`core.smooth_faces`). The gradient at a face's corner is the face's own linear
    one at the corners of :func:`flat_corners` (creases and flat regions keep their facets);
    the area-weighted mean of the faces' gradients (:func:`core.smooth_faces.mean_gradients`)
    at the vertices within two edges of such corners (the quadratic through two rings of
    neighbours reaches across a crease or a plane's edge: it tilted a plane's long STL
    triangle next to a fillet, its samples 8.7e-4 of the diagonal (RMS) off the part, 1.9e-4
    so, point-normal triangles 2.7e-4; /tmp/s32/fp_dbg.py); elsewhere the vertex's quadratic
    fit (:func:`core.smooth_faces.vertex_gradients`). An edge with such a corner at an end, in
    either of its faces, starts along its chord there in both (``straight``), so the faces
    meet: they had parted, up to 1.1e-3 of the diagonal on patch-01.off and 2.9e-2 on a
    5 x 5 bump (review); giving all faces at such a vertex their own gradients closed that
    too but faceted coarse meshes (an 8 x 8 grid of waves: 502 control points instead of
    180). ``vertex_normals``: :func:`_vertex_normals` when known; ``prepared``:
    :func:`smooth_corners` of the mesh when made already (they depend on the mesh alone)."""
    gradients, straight = (smooth_corners(points, uv, faces, vertex_normals)
                           if prepared is None else prepared)
    return clough_tocher_points(points, uv, faces, face, bary, gradients, straight)


def smooth_corners(points, uv, faces, vertex_normals=None):
    """The gradients (f, 3, 2, 3) at the faces' corners and the edges that start along their
    chords (f, 3, 3) or None, of :func:`smooth_points` (its docstring says which)."""
    own = flat_corners(points, faces, vertex_normals=vertex_normals)
    n = len(points)
    mean = mean_gradients(points, uv, faces)
    gradients = vertex_gradients(points, uv, faces, mean=mean)
    if own.any():  # the vertices within two edges of flagged corners (the quadratic's reach)
        A = vertex_adjacency(faces, n)
        near = np.zeros(n)
        near[faces[own]] = 1.0
        near = near + A @ near
        near = (near + A @ near) > 0
        gradients[near] = mean[near]
    gradients = np.where(own[..., None, None], face_gradients(points, uv, faces)[:, None],
                         gradients[faces])
    straight = None
    if own.any():
        # (vertex k, vertex m) of each face's corners k, m: flagged at k in any face of the edge
        k_of = np.repeat(np.arange(3), 3).reshape(3, 3)
        m_of = k_of.T
        key = faces[:, k_of] * np.int64(n) + faces[:, m_of]  # (f, 3, 3)
        flagged = np.broadcast_to(own[:, :, None], key.shape)
        keys, inverse = np.unique(key.ravel(), return_inverse=True)
        any_own = np.zeros(len(keys), dtype=bool)
        np.logical_or.at(any_own, inverse, flagged.ravel())
        straight = any_own[inverse].reshape(key.shape) & (k_of != m_of)
    return gradients, straight


def _area_table(points, faces):
    """The faces as :func:`_area_samples` draws from them: ``order`` (f,), the faces in the
    order of their corners' coordinates, ``first`` (f,), each face's corner of least
    coordinates (x first), and ``area`` (f,), the 3D areas of the faces in that order. The
    same for every draw on a mesh (the fit's samples and its fold check's, 1-1.5 s each at
    2e6 faces): made once there."""
    faces = np.asarray(faces)
    rank = np.empty(len(points), dtype=np.int64)
    order = coordinate_order(points)  # (the lexicographic order; None: already in it)
    rank[np.arange(len(points)) if order is None else order] = np.arange(len(points))
    first = np.argmin(rank[faces], axis=1)
    turn = (first[:, None] + np.arange(3)) % 3  # the corners from the least one on
    rows = np.arange(len(faces))[:, None]
    ranks = rank[faces[rows, turn]]
    order = np.lexsort(ranks.T[::-1])
    canon = faces[rows, turn][order]
    a, b, c = (points[canon[:, j]] for j in range(3))
    return order, first, 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def _area_samples(points, faces, count: int, seed: int = 0, table=None):
    """``count`` random points (seeded) on the triangles ``faces`` of ``points``, in proportion
    to their 3D area: the face (count,) of each and its barycentric coordinates (count, 3)
    (``s = sqrt(r_1)``: ``(1 - s, s (1 - r_2), s r_2)``, uniform on the triangle); none if
    the faces have no area. The draws do not depend on the order of the vertices, of the faces
    or of a face's corners (each face is started at its corner of least coordinates, x first,
    and the faces are drawn from in the order of their corners' coordinates): the same mesh
    stored another way gets the same points (a half sphere of 65 vertices, its faces shuffled
    as Blender's Sort Elements does, had got nets of 184 to 494 control points: user test).
    ``table``: :func:`_area_table` of the mesh when made already."""
    rng = np.random.default_rng(seed)
    order, first, area = _area_table(points, faces) if table is None else table
    if not area.sum() > 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    pick = rng.choice(len(area), size=count, p=area / area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    drawn = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)  # of the turned corners
    face = order[pick]
    bary = np.empty_like(drawn)
    bary[np.arange(count)[:, None], (first[face][:, None] + np.arange(3)) % 3] = drawn
    return face, bary


# the fold check of a mesh's fit (mesh_folds): points sampled on its faces, and the share of
# its area above which the surface is warned of. Measured on the benchmarks/mesh_maps.py
# meshes (/tmp/s29/shares2.py of the twenty-ninth session): 0 at the default tolerance, at
# most 0.04% at 1e-4 (three_peaks.off); at 1e-2 three_peaks.off 0.45% (a coarse fit, 5.4% of
# the diagonal off, turning over near a peak; 0 at 3e-3). The ragged patch with noise of
# 0.5% of its diagonal 0.20% at the default tolerance, of 1% 1.4% (and 2.1% at 1e-2); a
# V-groove between faces of unequal sizes 0-0.01% (review).
FOLD_SAMPLES = 10_000
FOLDED_SHARE = 1e-3


def mesh_folds(space, control_points, points, uv, faces, seed: int = 0,
               count: int = FOLD_SAMPLES, smooth: np.ndarray | None = None,
               vertex_normals=None, area_table=None) -> float:
    """The share of a mesh's area where the surface ``space`` with ``control_points`` faces
    against the mesh (``points``, ``uv`` its parameters, ``faces`` counter-clockwise in
    ``uv``): at ``count`` points sampled on the faces by area (:func:`_area_samples`, seed
    ``seed + 1``: not the fit's own samples), the share where ``S_u x S_v`` points against
    both the face's normal ``(b - a) x (c - a)`` and the mesh's smooth normal there, ``n =
    sum b_k n_k`` interpolated from the vertices' (``n_k``: the faces' unit normals at ``k``
    weighted by their corner angles, :func:`_vertex_normals`). The mesh's own piecewise
    linear map has ``S_u x S_v`` along ``(b - a) x (c - a)`` on each face, as the uv
    triangles are counter-clockwise. A surface that folds over itself (its normal turned
    against the data's) is wrong, however close to the data its points are: the fit of a
    mesh whose map crushes its faces (a comb of narrow fingers on the circle) can fold
    between the data where the tolerance is met at them; a noisy mesh chased by knots
    crumples (method.md section 4 asks to report folds, not silently return them). Against
    the interpolated normal alone, with area-weighted vertex normals, a V-shaped crease
    turning 135 degrees between faces 5 and 60 columns wide counted 0.6-0.75% of its own
    piecewise linear map as folded (the big faces' normals swamp the crease's vertices: a
    warning on a clean mesh; review); now 0-0.01%. Against the face's normal alone a
    wrinkled (noisy) mesh's faces would count as folds of a smooth surface.

    ``smooth`` (a noisy mesh's vertex normals, smooth over the noise, (n, 3), oriented:
    :func:`smooth_normals`): a fold faces against those, interpolated alike, instead. Where the
    noise is comparable to the vertices' spacing, the faces' and vertices' own normals turn
    with it. Against the noise-free surface's normals (/tmp/s30/foldtruth2.py of the thirtieth
    session):
    - a grid mesh of 120 x 120 vertices with noise of 1% of its diagonal reported 18.6% where
      the surface turned on none (user test), now 9.3%; that noise is 1.2 times the spacing,
      and the planes of 25 vertices turn with it too;
    - with noise 0.3-0.5%, 0.6-1.0% reported where the surface turned on none; now 0;
    - a fit of a 41 x 41 grid with noise 1% that does turn over on 2.0%: 1.6%, now 1.9%.
    Requiring the faces' and vertices' normals as well missed most of that last one (0.35%).
    ``vertex_normals``: :func:`_vertex_normals` of ``(points, faces)`` and ``area_table``:
    :func:`_area_table` when known."""
    face, bary = _area_samples(points, faces, count, seed + 1, area_table)
    if not len(face):
        return 0.0
    tri = faces[face]
    su, sv = space.combine(np.einsum("nk,nkj->nj", bary, uv[tri]), control_points,
                           derivatives=((1, 0), (0, 1)))
    surface_normal = np.cross(su, sv)
    if smooth is not None:  # (a noisy mesh: its faces' and vertices' normals are its noise's)
        against = np.einsum("ij,ij->i", surface_normal,
                            np.einsum("nk,nkj->nj", bary, smooth[tri])) < 0.0
        return float(np.mean(against))
    corner, normal = (_vertex_normals(points, faces) if vertex_normals is None
                      else vertex_normals)
    n = np.einsum("nk,nkj->nj", bary, normal[tri])
    against = ((np.einsum("ij,ij->i", surface_normal, n) < 0.0)
               & (np.einsum("ij,ij->i", surface_normal, corner[face]) < 0.0))
    return float(np.mean(against))


def smooth_normals(points, faces, used, planes, vertex_normals=None) -> np.ndarray:
    """Vertex normals (n, 3) of a noisy mesh, smooth over the noise: the normals of the planes
    fitted to each used vertex and its nearest (``planes``: :func:`_local_planes` of the used
    vertices ``points[used]``, ``used`` a mask or indices), each turned to agree with the sum of
    the angle-weighted vertex normals (:func:`_vertex_normals`) over its neighbourhood; 0 at
    the vertices not used. ``vertex_normals``: :func:`_vertex_normals` when known."""
    normal, _, _, idx = planes
    used = np.asarray(used)
    pick = np.flatnonzero(used) if used.dtype == bool else used
    summed = (_vertex_normals(np.asarray(points, dtype=np.float64), faces)
              if vertex_normals is None else vertex_normals)[1][pick][idx].sum(axis=1)
    out = np.zeros((len(points), 3))
    out[pick] = normal * np.where(np.einsum("ij,ij->i", normal, summed) < 0, -1.0, 1.0)[:, None]
    return out


def _vertex_normals(points, faces) -> tuple[np.ndarray, np.ndarray]:
    """The faces' normals ``(b - a) x (c - a)`` (f, 3) and the vertices' normals (n, 3): the
    sum over the faces at each vertex of their unit normals times their corner angles there
    (which a crease's two sides share alike, whatever their triangles' sizes)."""
    corner = np.cross(points[faces[:, 1]] - points[faces[:, 0]],
                      points[faces[:, 2]] - points[faces[:, 0]])
    unit = corner / np.maximum(np.linalg.norm(corner, axis=1, keepdims=True), 1e-300)
    angle = corner_angles(points, faces)
    normal = np.zeros((len(points), 3))
    for j in range(3):
        for d in range(3):
            normal[:, d] += np.bincount(faces[:, j], weights=angle[:, j] * unit[:, d],
                                        minlength=len(points))
    return corner, normal


# how far (in grid steps) the tessellation's points are moved for qhull (_domain_triangles)
TESSELLATION_JITTER = 1e-7


def _run(points, param, options, callback, start=None, rings=None, history=(), checked=False,
         start_degree=None, faces_key=None, spikes=False, faces_set_key=None,
         projection_given=False, faces_set_key32=None, seam_list=(), mesh_key=None):
    """Fit ``points`` over ``param``; ``checked``: ``parameterize_points`` has just accepted
    these very points (a cloud), so :func:`normalize` need not check them again.
    ``faces_key``, ``faces_set_key``, ``faces_set_key32``, ``mesh_key``: the digests of the
    given faces (:func:`faces_digest`, :func:`faces_set_digest`, :func:`rounded_faces_digest`,
    :func:`mesh_digest`) that the report keeps. ``projection_given``: the cloud was
    projected along a direction the user gave (``report["projection_given"]``).
    ``seam_list``: the neighbours to join (:func:`core.join.seams`): the best fit is joined
    to them (:func:`core.join.join_fit`)."""
    t0 = time.perf_counter()
    used = np.asarray(param.used, dtype=bool)
    # the used points, in an order of their coordinates alone (coordinate_order): the fit's
    # seeded draws (the start's knots, subsets) pick the same points of the same data stored
    # in another order (a half sphere of 65 vertices, its vertices or faces shuffled as
    # Blender's Sort Elements does and bmesh edits leave them, had got nets of 184 to 494
    # control points: user test; a cloud of 3000 points shuffled 499 to 507)
    kept = np.flatnonzero(used)
    order = coordinate_order(np.asarray(points)[kept])
    if order is not None:
        kept = kept[order]
    lo, hi = column_bounds(np.asarray(param.uv)[kept])
    extent = hi - lo
    # (a strip holding several spacings of its points across is a surface: a road corridor
    # 5 km long and 4 m wide, 14 spacings across, had been refused: user test)
    across = np.sqrt(used.sum() * extent.min() / max(extent.max(), 1e-300))
    if extent.min() < MIN_ASPECT * extent.max() and (
            across < MIN_ACROSS or _on_lines(np.asarray(param.uv)[kept])):
        # (longitude and latitude in degrees and heights in metres: a thin upright strip,
        # said only with --projection z before: user test)
        raise InvalidInputError(
            f"the points lie almost on a curve: their parameter domain is "
            f"{extent.min() / extent.max():.1e} times as wide as it is long; a surface needs "
            "points spread in two directions" + _degrees_note(np.asarray(points)[kept])
        )
    if checked and param.faces is None:
        cloud = points[kept]
        norm = box_normalization(cloud)
        q = norm.apply(cloud)
    else:
        q, norm = normalize(points[kept])
    diag_norm = 2.0  # normalize() maps the bounding box to half-diagonal 1
    uv = np.asarray(param.uv)[kept]
    fit_uv, fit_q = uv, q
    subsampled = len(uv) > MAX_FIT_POINTS
    if subsampled:
        # the fit needs far fewer points than a huge scan has: a seeded random subset is fitted,
        # the errors below are still those of every point
        warnings.warn(
            f"{len(uv)} points: fitting a random subset of {MAX_FIT_POINTS} (errors are reported "
            "for all points)", RuntimeWarning, stacklevel=3,
        )
        pick = np.sort(np.random.default_rng(options.seed).choice(len(uv), MAX_FIT_POINTS, replace=False))
        fit_uv, fit_q = uv[pick], q[pick]
    domain = np.asarray(param.domain_polygon, dtype=np.float64)
    # a mesh's noise (its vertices' scatter across a smooth surface through them): where it is
    # not small against the tolerance, the loop counts the vertices alone against the net's size
    # (mesh_noise_counts)
    noise = (local_noise(q, seed=options.seed)
             if param.faces is not None and options.tolerance > 0 else None)
    noisy = noise is not None and mesh_noise_counts(noise, options, diag_norm, norm.scale)
    counts = noisy and not subsampled
    # a mesh's vertex normals (on its normalized vertices) and the table its faces are drawn
    # from by area, once for its samples and its fold check (0.8-1.7 and 1-1.5 s each at 1e6
    # vertices)
    at = vertex_normals = area_table = None
    if param.faces is not None:
        at = norm.apply(points)
        vertex_normals = _vertex_normals(at, np.asarray(param.faces))
        area_table = _area_table(at, np.asarray(param.faces))
    # the tolerance in normalized units (the face check's floor; the smoother fit's limit)
    tol_norm = max(options.tolerance, 0.0) * (diag_norm if options.relative else 1.0 / norm.scale)
    curved = face_check = None
    if param.faces is not None:
        # fit the mesh's surface: vertices plus points sampled on its faces, curved through the
        # vertices unless the vertices' noise outweighs the facets' sag (facet_sag)
        # (of the vertices in faces: loose ones had changed the draws, review)
        curved = not noisy or (facet_sag(at, np.asarray(param.faces), options.seed,
                                         vertex_normals, area_table)
                               >= FACET_SAG_OVER_NOISE * noise)
        count = mesh_sample_count(len(kept), options.max_control_points)
        faces = np.asarray(param.faces)
        smooth = count >= SMOOTH_SAMPLES_PER_FACE * len(faces)
        prepared = (smooth_corners(at, np.asarray(param.uv), faces, vertex_normals)
                    if curved and smooth else None)  # (for the samples and the face check)
        sp_, su_ = mesh_samples(at, np.asarray(param.uv), faces, count, seed=options.seed,
                                curved=curved, vertex_normals=vertex_normals,
                                area_table=area_table, smooth=smooth, prepared=prepared)
        fit_uv, fit_q = np.vstack([uv, su_]), np.vstack([q, sp_])
        if FACE_CHECK and len(fit_uv) <= ITERATION_POINTS and not subsampled:
            # each fit checked between its points, on samples of the same surface (FaceCheck)
            face_check = FaceCheck(
                at, np.asarray(param.uv), faces, options.max_control_points,
                max(tol_norm, STRAY_FLOOR * diag_norm), options.seed, curved, smooth,
                vertex_normals=vertex_normals, area_table=area_table, prepared=prepared)
    # the vertices' normals, smooth over the noise: the errors across the surface, and the
    # fold check's
    planes = _local_planes(q, NOISE_NORMAL_NEIGHBOURS) if counts else None
    if not subsampled:  # the swing check's triangles, made while the loop runs
        prefetch_swing_triangles(uv, options.seed)
    best, hist, reason = adaptive_fit(
        fit_uv, fit_q, options, diagonal=diag_norm, start_knots=start, ring_knots=rings,
        callback=callback, history_offset=len(history), unit=norm.scale,
        n_measured=None if subsampled else len(uv), domain=domain,
        balance=param.faces is None, start_degree=start_degree, measured_only=counts,
        normals=None if planes is None else planes[0], stray_check=face_check,
    )
    later = None  # samples the face check added to the fits after the best one
    sampled_first = len(fit_uv)  # (the face check's samples come after these)
    if face_check is not None and face_check.added:  # (the samples the loop added, in order;
        # the best fit's are those it was fitted to, the first len(best.fit.errors))
        fit_uv = np.vstack([fit_uv, *(a for a, _ in face_check.added)])
        fit_q = np.vstack([fit_q, *(b for _, b in face_check.added)])
        n_fit = len(best.fit.errors)
        later = fit_uv[n_fit:], fit_q[n_fit:]
        fit_uv, fit_q = fit_uv[:n_fit], fit_q[:n_fit]

    def data_checks(fit_state, errs):
        """The layers and spikes checks of a fit (below), for a cloud: the layers' gap and
        the spikes' (found, largest, more) or None (``spikes`` off), given the fit's errors
        at the points (``errs``), and None; for a mesh (None, None, the share of its area
        where the surface folds over: :func:`mesh_folds`). Made on another thread while the
        swing check runs: they read the fit's control points and errors only."""
        if param.faces is not None:  # (a mesh's faces hold one layer)
            faces = np.asarray(param.faces)
            return None, None, mesh_folds(
                fit_state.space, fit_state.fit.control_points, at, np.asarray(param.uv), faces,
                options.seed,
                smooth=None if planes is None else smooth_normals(at, faces, kept, planes,
                                                                  vertex_normals),
                vertex_normals=vertex_normals, area_table=area_table)
        if param.axes is None:
            return None, None, None
        C = norm.undo(fit_state.fit.control_points)
        sub = np.random.default_rng(options.seed).permutation(len(uv))[:LAYER_POINTS]
        across = ((points[kept][sub] - fit_state.space.combine(uv[sub], C)[0])
                  @ np.asarray(param.axes)[2])
        gap = data_layers(uv[sub], across, options.seed)
        return gap, (data_spikes(points[kept], errs, np.asarray(param.axes)[2])
                     if spikes else None), None

    if not subsampled:
        early = background(lambda state=best: data_checks(
            state, state.fit.errors[: len(uv)] * norm.scale))
        # what the smoother fit must still meet when the loop reached the tolerance
        limit = tol_norm if reason == "tolerance reached" and options.tolerance > 0 else None
        looped = best
        best, swings = _smoother_if_swinging(
            best, fit_uv, fit_q, len(uv), options.seed, limit, options.criterion,
            margin=tol_norm, default=isinstance(options.smoothness, DefaultSmoothness))
        checks = early() if best is looped else None
    else:
        swings = checks = None
    joined = None
    if seam_list:
        best, joined = join_fit(
            best, seam_list, np.asarray(param.uv), fit_uv, fit_q, norm, options, domain,
            folds=None if param.faces is None else lambda state: data_checks(state, None)[2],
            n_measured=len(uv), mesh=None if param.faces is None else (points, param.faces),
            fold_allowance=FOLDED_SHARE)
        checks = swings = None  # (the fold and swing checks made again, of the joined fit)
    # back to the user's units (affine, exact up to rounding: partition of unity)
    C = norm.undo(best.fit.control_points)
    errors = np.full(len(points), np.nan)
    if subsampled:
        errors[kept] = _distances(best.space, best.fit.control_points, uv, q) * norm.scale
    else:
        errors[kept] = best.fit.errors[: len(uv)] * norm.scale
    if checks is None:
        checks = data_checks(best, errors[kept])
    diagonal = 2.0 * norm.scale
    # a mesh's spike vertices dissolved by drop_outliers (unused, as its loose vertices are)
    dissolved = 0 if param.outliers is None else int(len(param.outliers))
    report = {
        "mode": options.mode,
        "degree": options.degree,
        "points": int(used.sum()),
        # points of a cloud left out as outliers, spike vertices dissolved out of a mesh
        # (drop_outliers=True); NaN in ``errors``
        "outliers": int(len(used) - used.sum()) if param.faces is None else dissolved,
        # vertices of a mesh that are in no face: a mesh is fitted through its faces
        "loose_vertices": int(len(used) - used.sum()) - dissolved if param.faces is not None
        else 0,
        # holes of a mesh that the surface spans, of a cloud that its tessellation covers
        # (fill_holes=True)
        "holes_filled": 0 if param.holes is None else int(len(param.holes))
        if param.kind == "disk" else gaps_beyond(param),
        "knots": int(len(best.knots)),
        "interior_knots": int(best.n_interior),
        "control_points": int(best.n_control),
        "functions": int(best.space.n_basis),
        "smoothness": float(best.fit.smoothness),  # the value used (chosen, for "auto")
        "iterations": len(history) + len(hist),
        # the iteration returned: the one that met the tolerance, else the lowest (estimated)
        # error within the budget; not always the last (history[i]["iteration"])
        "returned_iteration": int(best.iteration),
        # errors at the user's points (for meshes the fit also used samples on the faces)
        "rms": float(np.sqrt(np.mean(errors[kept] ** 2))),
        "max": float(errors[kept].max()),
        "rms_rel": float(np.sqrt(np.mean(errors[kept] ** 2)) / diagonal),
        "max_rel": float(errors[kept].max() / diagonal),
        "diagonal": float(diagonal),
        "seconds": time.perf_counter() - t0,
        "stop_reason": reason,
        "subsampled": bool(subsampled),
        "history": list(history) + hist,
        # refine() checks that it is given the same points (values and order)
        "data_digest": data_digest(points),
        # or the same values in another order (Sort Elements): refine() parameterizes them again
        "data_set_digest": data_set_digest(points),
    }
    if faces_key is not None:  # (and the same faces: faces_digest)
        report["faces_digest"] = faces_key
    if faces_set_key is not None:  # (or the same stored in another order: faces_set_digest)
        report["faces_set_digest"] = faces_set_key
    # ... or in another order and rounded to 32-bit floats, as Blender keeps a file's values
    # (not for 32-bit values: the digests above are theirs)
    if faces_set_key32 is not None:
        report["faces_set_digest32"] = faces_set_key32
    if mesh_key is not None:  # (or with vertices in no face added or deleted: mesh_digest)
        report["mesh_digest"] = mesh_key
    if not _float32_values(points):
        report["data_set_digest32"] = rounded_set_digest(points)
    if param.faces is not None:  # (the map is of the canonical winding: reordered() maps a
        report["canonical_winding"] = True  # file's without it as its faces were given)
    if noise is not None:  # a mesh's noise (local_noise), in the user's units (a cloud's: below)
        report["noise"] = noise * norm.scale
        report["noise_rel"] = noise / diag_norm
    if curved is not None:  # a mesh's faces sampled on its curved triangles or flat
        report["face_samples"] = "curved" if curved else "flat"
    if joined is not None:  # (the gaps in the user's units, and over the diagonal)
        report["join"] = joined | {
            k + "_rel": joined[k] / diagonal for k in ("gap_max", "gap_rms", "gap_max_unjoined",
                                                       "gap_rms_unjoined")}
        words = join_warning(report)
        if words:
            warnings.warn(words, RuntimeWarning, stacklevel=3)
    if hist and hist[-1].get("net_capped"):  # a noisy mesh's net stopped at its vertex count
        report["net_capped"] = int(hist[-1]["net_capped"])  # (core.refine.NOISY_NET_PER_VERTEX)
    if param.faces is not None and not subsampled and len(best.fit.errors) > len(uv):
        # the errors at the points the fit sampled on the mesh's faces: between the vertices
        # of a coarse mesh the surface can be far from the faces where the errors at the
        # vertices are small (a CAD plate of 34 vertices: max 0.019 mm at them, 0.81 mm on a
        # face at a crease, and the report said only the first: user test)
        on_faces = best.fit.errors[len(uv):] * norm.scale
        if face_check is not None:  # (and at the face check's samples not fitted)
            on_faces = np.concatenate([
                on_faces, face_check.errors(best.space, best.fit.control_points) * norm.scale,
                _distances(best.space, best.fit.control_points, *later) * norm.scale
                if later is not None else []])
        report["faces_rms"] = float(np.sqrt(np.mean(on_faces**2)))
        report["faces_max"] = float(on_faces.max())
        report["faces_rms_rel"] = report["faces_rms"] / diagonal
        report["faces_max_rel"] = report["faces_max"] / diagonal
        if face_check is not None:  # the face check's samples the surface was fitted to
            report["stray_samples"] = int(len(fit_uv) - sampled_first)
        # (above rounding: a planar mesh is fitted to 1e-16 at its vertices and its faces)
        # (criterion "max": a bound the user asked for, so over it on the faces is said too;
        # patch-01.off at 3e-3 reached it at the vertices, 1.9x it on the faces: user test)
        # (met at the vertices: a run that missed it there says so otherwise; review)
        asked = tol_norm * norm.scale * (1 + 1e-9)
        bound = (options.criterion == "max" and options.tolerance > 0
                 and report["max"] <= asked < report["faces_max"])
        if bound or (report["faces_max"] > FACES_MAX_RATIO * report["max"]
                     and report["faces_max_rel"] > FACES_MIN_REL):
            warnings.warn(faces_warning(report, tol_norm * norm.scale if bound else None),
                          RuntimeWarning, stacklevel=3)
    if param.faces is not None and report["control_points"] > COARSE_MESH_RATIO * report["points"]:
        # (the largest bend between its faces, which says whether creases made the net big)
        report["coarse_mesh_crease"] = largest_crease(points, np.asarray(param.faces))
        warnings.warn(coarse_mesh_warning(report), RuntimeWarning, stacklevel=3)
    if param.faces is None:
        # the RMS over the parameter area (core.refine.area_weights): a cloud of uneven density
        # meets the tolerance by it too; equal to "rms" within ~10% for an even one
        e2 = errors[kept] ** 2
        report["rms_area"] = float(np.sqrt(np.dot(area_weights(uv), e2) / len(e2)))
        report["rms_area_rel"] = report["rms_area"] / diagonal
    if report["loose_vertices"]:
        warnings.warn(
            f"{report['loose_vertices']} of the {len(used)} vertices "
            + ("is in no face and was" if report["loose_vertices"] == 1 else
               "are in no face and were")
            + " left out: a mesh is fitted through its faces (fit the vertices without faces "
            "to use them as a point cloud)", RuntimeWarning, stacklevel=3,
        )
    if (param.faces is None and best.selection is None
            and SPARSE_POINTS_PER_CONTROL * report["control_points"] > used.sum()):
        # a mesh is fitted on samples of its faces too; a sparse cloud has nothing between
        # its points but the fairing (60 points of Franke's function: the surface swung to
        # twice the data's height range with smoothness 1e-4). The default and "auto" are
        # cross-validated there (core.refine.adaptive_fit); a number given is used as given.
        chosen_later = isinstance(options.smoothness, DefaultSmoothness) or options.smoothness == "auto"
        advice = ("the run was cancelled before the smoothness was cross-validated"
                  if reason == "cancelled" and chosen_later else SMOOTHNESS_ADVICE)
        warnings.warn(
            f"{report['points']} points for {report['control_points']} control points: between "
            f"the points only the smoothness {report['smoothness']:g} holds the surface, and it "
            f"may overshoot; {advice}",
            RuntimeWarning, stacklevel=3,
        )
    # a surface that swings far from the data between neighbouring points (where the knots
    # crowd closer than the data: a sharp step, a gap), which the errors at the data cannot show
    # (swings within the tolerance are no matter, as in the loop)
    if swings is None:
        at, near, off = uv, points[kept], errors[kept]
        if param.faces is not None and not subsampled:
            # a mesh's samples on its faces are data too: between the vertices of a coarse
            # curved mesh (half a cylinder of 34 vertices) the vertices' neighbourhoods are
            # no slab, and 636 places were flagged up to 0.23 where the surface was within
            # 0.002 of the faces; the smoother refit then went 10x off them (user test)
            at, near = fit_uv, norm.undo(fit_q)
            off = best.fit.errors * norm.scale
        places, checked, largest = data_swings(
            best.space, C, at, near, off, seed=options.seed,
            margin=max(options.tolerance, 0.0) * (diagonal if options.relative else 1.0))
    else:  # the same check, made on the returned fit in the normalized units
        places, checked, largest = swings[0], swings[1], swings[2] * norm.scale
    report["swings"] = {"places": places, "checked": checked, "largest": largest,
                        "largest_rel": largest / diagonal}
    if places:
        warnings.warn(swing_warning(report), RuntimeWarning, stacklevel=3)
    report["layers"] = 0.0
    gap, spiky, folded = checks
    if folded is not None:
        report["folded"] = folded
        if folded > FOLDED_SHARE:
            warnings.warn(folds_warning(report), RuntimeWarning, stacklevel=3)
    # (layers closer than twice the tolerance are within it: no matter, as for swings)
    if gap is not None and gap > 2.0 * max(options.tolerance, 0.0) * (
            diagonal if options.relative else 1.0):
        report["layers"] = gap
        warnings.warn(layers_warning(report), RuntimeWarning, stacklevel=3)
    if spiky is not None:
        # a few points far off the surface that drop_outliers would have left out (10 stray
        # returns 50-200 m up among 4e4 lidar points: 127 m spikes in the surface, no word;
        # user test)
        found, largest, more = spiky
        report["spikes"] = found
        if found:
            warnings.warn(spikes_warning(found, largest, more), RuntimeWarning, stacklevel=3)
    if best.refit is not None:  # iterations on a subset, the chosen space fitted to all points
        report["refit"] = best.refit
    if best.selection is not None:  # smoothness="auto"
        report["smoothness_selection"] = best.selection
    if (noise is None and options.tolerance > 0 and not reason.startswith("tolerance reached")
            and reason != "cancelled"):  # a cloud's noise, to say what kept the tolerance off
        report["noise"] = local_noise(points[kept], seed=options.seed)
        report["noise_rel"] = report["noise"] / diagonal
    if projection_given:
        report["projection_given"] = True
    surf = TCBSurface(best.space, C, param, errors, report, best.n_interior, options,
                      active=best.active)
    if reason == STALLED and param.faces is None and report["rms_rel"] > FAR_STALL_RMS:
        # the error stopped falling far above the data's own scatter: not noise. A cloud
        # folded over its projection plane stops so (Renka's F7 on a noisy 5000-point grid,
        # turned: 36% of its triangles flipped, the fold check passed it under the noise; RMS
        # 12.6% of the diagonal, and no word). The errors at the data's parameters are no
        # measure of that: on a steep surface they are the noise across it over the cosine
        # of the slope (the same grid with the noise, not turned: RMS 15 times the scatter);
        # the distances of (a sample of) the data to their closest surface points are (1.8
        # times there, 8.1 times folded)
        far_stall_check(surf, points[kept], options.seed)
    return surf


# A mesh's points sampled on its faces are its vertices interpolated: where its noise
# (core.parameterize.local_noise) is at least this share of an RMS tolerance (a third of a max
# one), the loop's estimate of the error at new points and its stall test count its vertices
# alone against the net's size (core.refine.adaptive_fit's measured_only). Counting all the
# samples, a grid mesh of 41 x 41 vertices with noise of 0.2-0.5% of its diagonal took the
# budget of 2000 control points at the default tolerance, more than it has vertices, to follow
# its noise (0.5% of the diagonal at 81 x 81: 1.3% of its area folded over); with the vertices
# (and NOISE_NORMAL_NEIGHBOURS) 148-152 (140-150 at 81 x 81), as its vertices alone fitted as a
# cloud (143-150). Clean meshes
# mostly score 0 and keep the samples' count: a fit that counted its vertices stopped early as
# if stalled at a tight tolerance (a half cylinder of 961 vertices at 1e-4: 160 control points
# and 3.0e-4 instead of 1891 and 1.0e-4; /tmp/s30/cmp.py of the thirtieth session). Not all:
# a clean corrugated sheet of 41 x 41 vertices, folded every 4 of them, scores 1.7e-3 of its
# diagonal and at 1e-4 stops at 940 control points and 2.1e-4, where counting the samples took
# 1765 and 1.3e-4 (both missing it; a review).
NOISE_COUNTS = 0.3
# ... and there the loop weighs the errors' components along the vertices' normals, of the
# planes fitted to each and this many nearest (core.parameterize._local_planes)
NOISE_NORMAL_NEIGHBOURS = 24


# a run whose error stopped falling (core.refine.STALLED) with the data's noise
# (report["noise"], core.parameterize.local_noise) at least this share of the RMS reached, and
# at most that RMS over this share, stopped at the noise: the CLI and Blender say so and give
# it. Noise the same in all three directions, none of it followed by a mesh's map, leaves
# sqrt(3) times itself at the vertices (noisy grid meshes of 81 x 81 and 120 x 120 vertices
# with noise 0.5% and 0.3% of the diagonal: 0.59 and 0.53; the noisy meshes of
# benchmarks/noisy_meshes.py 0.7-1.05; clouds of 4000 and 10 000 points with noise 0.01 on
# their heights: 0.93 and 0.88; a clean cosine peak, whose cone point the knots cannot resolve,
# on 3000 points: 0)
NOISE_OF_STALL = 0.4


# a cloud whose bounding-box diagonal is over this many times its height range along its
# projection is told that a relative tolerance is of the diagonal, not of the heights
FLAT_HEIGHT_FIELD = 10.0


def flat_height_field(surf, points: np.ndarray):
    """``(diagonal, height range)`` of a point cloud fitted as a height field (projected on
    a plane: a DEM raster or a cloud) whose bounding-box diagonal is over FLAT_HEIGHT_FIELD
    times its range of heights along the projection, else None. Such data (terrain: km
    across, tens or hundreds of m high) has a relative tolerance of the diagonal that is a
    large share of its relief (the command line's and Blender's note: a relative tolerance
    of 1e-3 was 42.7 m on 840 m of relief; user tests). Not in method.md."""
    param = surf.parameterization
    if param.kind != "plane" or not len(points):
        return None
    heights = np.asarray(points, dtype=np.float64) @ np.asarray(param.axes[2], dtype=np.float64)
    height = float(np.ptp(heights))
    diagonal = float(surf.report["diagonal"])
    if height > 0 and diagonal > FLAT_HEIGHT_FIELD * height:
        return diagonal, height
    return None


def stopped_at_noise(report: dict) -> bool:
    """Whether the error of the fit of ``report`` stopped falling at the data's noise
    (:data:`NOISE_OF_STALL`)."""
    noise, rms = report.get("noise", 0.0), report.get("rms", 0.0)
    # (a fit that went well below what was measured as noise did not stop at noise)
    return (report.get("stop_reason") == STALLED
            and 0 < NOISE_OF_STALL * rms <= noise <= rms / NOISE_OF_STALL)


# a fit that stopped short of its tolerance for another reason (the budget, the iteration
# limit) with the data's noise at least this share of the tolerance (a third of a max one),
# and between NOISE_OF_STALL of the RMS reached and that RMS over NOISE_OF_STALL (as
# stopped_at_noise), was held off by the noise: the CLI and Blender say so, and that more
# control points would mostly fit it. (An RMS somewhat below the noise is a fit that has begun
# to follow it: a noisy cap mesh of 921 vertices, noise 0.29% of its diagonal, met 3e-3 with
# 104 control points; Refine to half of that took the budget, 198, to an RMS of 0.27%, 1.2x
# farther from the shape without noise, and was told to raise the budget; user test. Well
# below it is no such fit: a coarse scanned face's curvature scores 3.5e-3 of its diagonal as
# noise, and fits reach 4.3e-4.) (Against the RMS
# too: a clean 16 x 16 grid mesh of a quadric measured 3.9e-5 of its diagonal before
# local_noise's rule on the growth, above half a tolerance of 1e-9, where its budget of 60 left
# an RMS of 2.1e-4.) A noisy grid mesh of 317 x 317 vertices (noise 0.1% of the diagonal) at
# 1e-3 took the budget to RMS 1.43e-3 with the advice "raise Max Control Points"; a budget of
# 5000 stopped at 4292 and 1.31e-3, the error no longer falling (its tangential noise, which the
# map of so noisy a mesh does not follow, is in the errors at the vertices; the surface was
# 1.5e-4 off the mesh without noise). Since the loop weighs a noisy mesh's errors across the
# surface (adaptive_fit's normals) that mesh stalls at 714 control points, 1.1e-4 off.
NOISE_NEAR = 0.5


def _noise_tolerance(tolerance: float, relative: bool, criterion: str, diagonal: float,
                     unit: float = 1.0) -> float:
    """A tolerance as given (relative to the ``diagonal``, or absolute in units ``unit``
    times those of the diagonal) as an RMS to weigh a noise against: a third of a max
    tolerance (the largest of many errors of noise is about 3 times their RMS)."""
    tol = tolerance * (diagonal if relative else 1.0 / unit)
    return tol if str(criterion).lower() == "rms" else tol / 3.0


# a run stopped short of its tolerance by the budget or the iteration limit whose best RMS was
# still falling at least like knots^-this over its last 1.5x the knots: the scatter measured
# as noise may be fine detail of the shape, and the advice says both (the Jacksboro DEM, every
# 8th node, at 800 control points: RMS 38 m, "noise" 18 m, falling like knots^-0.39 to -0.52
# by the start, and 3000 control points halved the error at the held-out nodes; it had been
# told that more would mostly fit the noise: user test). Noisy meshes and clouds stopped by
# their budget: 0.07-0.39 (/tmp/s43/noise_budget.py), so the advice is two-sided for some
# of them too, and leads with the budget
STILL_FALLING = 0.3


def fall_rate(report: dict) -> float | None:
    """How fast the best RMS of the run of ``report`` fell at its end: ``r`` of ``rms ~
    knots^-r`` between the last fit and the last one with at most 2/3 of its interior knots
    (the best RMS so far at both; fits taken back left out), or None without such a fit (not
    in method.md; the window of ``core.refine._stalled``)."""
    kept = [h for h in report.get("history", ()) if "knots_taken_back" not in h]
    if len(kept) < 2:
        return None
    n = np.array([h["interior_knots"] for h in kept], dtype=np.float64)
    best = np.minimum.accumulate([h["rms"] for h in kept])
    earlier = np.flatnonzero(n[:-1] <= n[-1] / 1.5)
    if not len(earlier) or not best[-1] > 0:
        return None
    j = earlier[-1]
    return float(np.log(best[j] / best[-1]) / np.log(n[-1] / n[j]))


def noise_near_tolerance(report: dict, tolerance: float, relative: bool, criterion: str) -> bool:
    """Whether the data's noise (``report["noise"]``) kept the fit of ``report`` from a
    tolerance it missed (:data:`NOISE_NEAR`); ``tolerance`` as given to the fit."""
    noise, rms = report.get("noise", 0.0), report.get("rms", 0.0)
    tol = _noise_tolerance(tolerance, relative, criterion, report["diagonal"])
    return (0 < NOISE_OF_STALL * rms <= noise <= rms / NOISE_OF_STALL
            and noise >= NOISE_NEAR * tol > 0)


def mesh_noise_counts(noise: float, options, diagonal: float, unit: float) -> bool:
    """Whether a mesh's ``noise`` (normalized units: ``diagonal`` the bounding box's there,
    ``unit`` the user's per normalized one) is at least :data:`NOISE_COUNTS` of the tolerance
    of ``options`` (RMS; a third of a max tolerance)."""
    return noise >= NOISE_COUNTS * _noise_tolerance(options.tolerance, options.relative,
                                                     options.criterion, diagonal, unit)


# a mesh's fit is warned of when on its faces the largest error is over this many times the
# largest at its vertices (the bundled meshes: 1.2-2.7x; a coarse CAD plate with a crease: 44x)
FACES_MAX_RATIO = 4.0
FACES_MIN_REL = 1e-6  # ... and that error is above this share of the diagonal


# a mesh's fit is warned of when its net has over this many control points per vertex: a
# coarse mesh's flat faces are data (method.md section 5), and the fit chases the creases
# between them (a 4 x 4 grid of a smooth function: 581 control points, the 21 x 21 grid of
# the same function 149; nefertiti.off 2.8 per vertex; user test)
COARSE_MESH_RATIO = 4.0


# a mesh whose faces bend by at most this many degrees between neighbours has no creases for
# coarse_mesh_warning to blame (a flat grid's or n-gon's bends are rounding, ~1e-6 degrees)
CREASE_MIN_DEGREES = 0.01


def largest_crease(points: np.ndarray, faces: np.ndarray) -> float:
    """The largest angle in degrees between the normals of two triangles of ``faces`` ((F, 3)
    int, into ``points`` (N, 3)) that share an edge: 0 for a flat mesh. Degenerate triangles
    (no normal) are left out."""
    p = np.asarray(points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)[:, :3]
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    length = np.linalg.norm(n, axis=1)
    ok = length > 1e-12 * max(float(length.max(initial=0.0)), 1e-300)
    n, f = n[ok] / length[ok, None], f[ok]
    if len(f) < 2:
        return 0.0
    edges = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)  # face by face
    edge_id = np.unique(edges[:, 0] * len(p) + edges[:, 1], return_inverse=True)[1].ravel()
    h1, h2 = _edge_pairs(edge_id)  # the two halves of each shared edge
    if not len(h1):
        return 0.0
    cos = np.clip(np.einsum("ij,ij->i", n[h1 // 3], n[h2 // 3]), -1.0, 1.0)
    return float(np.degrees(np.arccos(cos.min())))


def coarse_mesh_warning(report: dict, budget: str = "max_control_points",
                        subdivide: str = "subdivide the mesh first",
                        cloud: str = "fit its vertices as a point cloud (faces=None)") -> str:
    """The words for a net much larger than its mesh (``_run``): what made it large, by the
    largest bend between the mesh's faces (``report["coarse_mesh_crease"]``, degrees), and
    what gives a smaller net. ``budget``, ``subdivide``, ``cloud``: how the caller asks for a
    smaller control-point budget, a subdivided mesh and the vertices alone (Blender words
    them its way)."""
    head = (f"the net has {report['control_points']} control points for a mesh of "
            f"{report['points']} vertices")
    crease = float(report.get("coarse_mesh_crease", 180.0))
    if crease <= CREASE_MIN_DEGREES:  # (a flat grid, a flat n-gon: no creases to blame)
        return (f"{head}, more than it needs: the mesh is flat (no creases between its faces), "
                f"and a net of any size fits it; for a smaller net, lower {budget}")
    return (f"{head}: the surface follows the mesh's flat faces, and the creases between them "
            f"(up to {crease:.3g} degrees) take many control points to meet the tolerance at "
            f"the vertices. For a smooth surface with a small net, {subdivide}; or, if it is a "
            f"height field over a plane, {cloud}")


def folds_warning(report: dict) -> str:
    """The words for ``report["folded"]`` (:func:`mesh_folds`), with what to do: first what
    most likely helps. Where the mesh's noise was measured (``report["noise"]``,
    :func:`core.parameterize.local_noise`), it tells: noise at least NOISE_OF_STALL of the RMS
    reached is what the knots chase (a crushed map second), and none is no cause (the three
    causes in a message of up to 1150 characters, which Blender's console cut at about 1000:
    user test). Without it, by how the fit stopped (at the tolerance: a coarse fit over steep
    slopes; short of it: noise). The map's distortion does not tell a crushed map from a
    noisy mesh (a ragged patch with noise of 1% of its diagonal kept the circle, with a
    distortion above 10, as a comb's on the circle, 83-96), so a crushed map is named
    second."""
    noise = report.get("noise")
    causes = {
        "loose": "on a smooth mesh with steep slopes, a tolerance too loose for them, which "
                 "the surface cuts across (tighten it)",
        "crushed": "narrow fingers or slits along the border, which the parameter map crushes "
                   "(cut the mesh into simpler pieces and fit each; in Blender select one's "
                   "faces in Edit Mode and press Fit Surface)",
        "noise": "on a noisy mesh (its faces wrinkled at the scale of the tolerance or "
                 "finer), knots that chase the noise (loosen the tolerance or smooth the mesh "
                 "first; in Blender a Smooth or Corrective Smooth modifier)",
    }
    met = report.get("stop_reason") == "tolerance reached"
    if noise is None:
        order = ("loose", "crushed", "noise") if met else ("noise", "crushed", "loose")
    elif 0 < NOISE_OF_STALL * report.get("rms", np.inf) <= noise:
        causes["noise"] = (f"the mesh's noise (its vertices scatter {report['noise_rel']:.2%} "
                           "of the diagonal across a smooth surface), which the knots chase "
                           "(loosen the tolerance or smooth the mesh first; in Blender a Smooth "
                           "or Corrective Smooth modifier)")
        order = ("noise", "crushed")
    else:  # (measured: not noisy enough to chase)
        order = ("loose", "crushed") if met else ("crushed", "loose")
    return (f"the surface folds over itself on {report['folded']:.1%} of the mesh's area (its "
            "normal turns against the mesh's there, which the errors at the vertices do not "
            "show); the likely causes: " + "; ".join(causes[k] for k in order))


def faces_warning(report: dict, bound: float | None = None) -> str:
    """The words for a mesh fitted far from its faces between the vertices (``_run``); with
    ``bound`` (criterion "max": the tolerance in the data's units) for one over that bound."""
    ratio = report["faces_max"] / max(report["max"], 1e-300)
    times = (f"{report['faces_max'] / bound:.1f} times the max error asked for ({bound:.4g}; it "
             f"holds at the vertices, up to {report['max']:.4g})" if bound is not None else
             f"{ratio:.0f} times the largest error at the vertices ({report['max']:.4g}; the "
             "errors reported are those at the vertices)")
    return (f"at the points the fit sampled on the mesh's faces, between its vertices, the "
            f"surface is up to {report['faces_max']:.4g} off ({report['faces_max_rel']:.2e} of "
            f"the diagonal), {times}, and it may be farther between those points: the spline "
            "does not follow long faces there, as at a sharp crease of a coarse CAD mesh; a "
            "finer mesh (subdivided or remeshed) holds the surface to the faces"
            + ("; so may a tighter tolerance" if bound is not None else ""))


def far_stall_check(surf: "TCBSurface", points: np.ndarray, seed: int = 0) -> None:
    """Adds ``"distance_rms"`` (of up to FAR_STALL_SAMPLE of ``points``, seeded, to their
    closest surface points), ``"scatter"`` and ``"scatter_disks"``
    (:func:`core.parameterize.local_scatter` of ``points``) to the surface's report, and warns
    when the first is above FAR_STALL_RMS of the diagonal and FAR_STALL_SCATTER times the
    second, with at least FAR_STALL_DISKS of the neighbourhoods thin disks, unless the report
    counts spikes (not in method.md)."""
    report = surf._report
    sub = np.random.default_rng(seed).permutation(len(points))[:FAR_STALL_SAMPLE]
    d = surf.distances(points[sub])
    report["distance_rms"] = float(np.sqrt(np.mean(d * d)))
    report["scatter"], report["scatter_disks"] = local_scatter(points, seed=seed)
    if far_stall(report) and not report.get("spikes"):
        # (spikes pull the surface away from the points around them too: their warning says
        # what to do; the fold's advice was wrong for 10 spikes among 3000 points: user test)
        given = surf.options.smoothness
        value = None if isinstance(given, DefaultSmoothness) else check_smoothness(given)
        stiff = (value if isinstance(value, float)
                 and value > STIFF_SMOOTHNESS * DEFAULT_SMOOTHNESS else None)
        warnings.warn(far_stall_warning(report, stiff), RuntimeWarning, stacklevel=4)


def far_stall(report: dict) -> bool:
    """Whether :func:`far_stall_check` found the data far from a surface whose error stopped
    falling (its warning was given)."""
    d = report.get("distance_rms")
    return d is not None and d > FAR_STALL_RMS * report["diagonal"] and (
        d > FAR_STALL_SCATTER * report["scatter"]) and (
        report["scatter_disks"] >= FAR_STALL_DISKS)


def _on_lines(uv: np.ndarray, sample: int = 2000, k: int = 16) -> bool:
    """Whether the points' neighbourhoods are lines, not patches: the median over a seeded
    sample of the ratio of the smaller to the larger eigenvalue of the covariance of each
    point's ``k`` nearest parameters is under 0.05 (a 5 km track wiggling 4 m wide, 40 000
    points on one curve, had passed the count of spacings across the strip: review). Not in
    method.md."""
    if len(uv) <= k:
        return True
    pick = np.random.default_rng(0).permutation(len(uv))[:sample]
    nb = cKDTree(uv).query(uv[pick], k=k, workers=-1)[1]
    d = uv[nb] - uv[nb].mean(axis=1, keepdims=True)
    ev = np.linalg.eigvalsh(np.einsum("mki,mkj->mij", d, d))
    return bool(np.median(ev[:, 0] / np.maximum(ev[:, 1], 1e-300)) < 0.05)


def _in_faces(faces, n: int) -> np.ndarray:
    """Which of ``n`` vertices ``faces`` holds (all of them when the faces are not an array of
    valid indices: the mesh checks then say what is wrong)."""
    try:
        f = np.asarray(faces).ravel()
    except (TypeError, ValueError):
        return np.ones(n, dtype=bool)
    if not (np.issubdtype(f.dtype, np.integer) and len(f) and f.min() >= 0 and f.max() < n):
        return np.ones(n, dtype=bool)
    used = np.zeros(n, dtype=bool)
    used[f] = True
    return used


def fit_surface(
    points,
    faces=None,
    degree: int = 2,
    mode: str = "tcb",
    tolerance: float = 1e-3,
    relative: bool = True,
    max_control_points: int = 2000,
    max_iterations: int = 20,
    smoothness: float | str = DEFAULT_SMOOTHNESS,
    callback=None,
    *,
    criterion: str = "rms",
    initial_knots: int | None = None,
    knots_per_iteration: int | None = None,
    feature_sensitive: bool = True,
    seed: int = 0,
    drop_outliers: bool = False,
    projection=None,
    fill_holes: bool = False,
    join=None,
) -> TCBSurface:
    """Fit a TCB-spline surface to a point cloud or a disk-like mesh (method.md sections 4-6).

    Parameters
    ----------
    points : (N, 3) float
        Scanned points, or mesh vertices.
    faces : (F, 3) int, optional
        Triangles of a disk-topology mesh ((F, k) polygons, or a list of polygons of any
        lengths, are split by their shape, whatever corner they start at: quads along their
        shorter diagonal, larger polygons by their best ears;
        then the mesh is parameterized over the unit disk,
        or a rectangle when its boundary has four corners, or its own boundary flattened
        when that distorts the triangles less;
        otherwise the cloud is projected on its best-fit plane). Either winding of the faces
        gives the same surface: the map is made in a winding the geometry chooses
        (``core.parameterize.winding_flipped``), and the tessellation, control net and
        normals face the way of the faces given.
    degree : 2 (C^1, default) or 3 (C^2)
    mode : "tcb" (feature-sensitive configurations) or "dcb" (Delaunay configurations); any case
    tolerance : float
        Stop when the RMS (or max, see ``criterion``) error is at most this; relative to the
        bounding-box diagonal when ``relative`` is True, else in the data's units. A point
        cloud of uneven density (a scanner that dwelt in one place) must also meet an RMS
        tolerance over its area (``report["rms_area"]``, ``core.refine.area_weights``).
    max_control_points : int
        Budget of control points; knot insertion stops before exceeding it.
    max_iterations : int
        Fits at most this many times.
    smoothness : float or "auto"
        Fairing weight relative to the data term (method.md section 5); default 1e-4, except
        on sparse clouds (fewer than 2 points per control point) and when a tolerance run
        stops because the error stopped falling, where the default is replaced by the
        cross-validated choice among 100 ... 1e-7 (``report["smoothness_selection"]["why"]``
        says so; pass ``1e-4`` explicitly to keep it). ``"auto"``: the
        iterations use 1e-4 and the surface returned is refitted with the weight chosen by
        5-fold cross-validation among 1e-2 ... 1e-7 (on sparse clouds and after such a stop
        also 1e-1 ... 100;
        one-standard-error rule; the value used is
        ``report["smoothness"]``, the scores ``report["smoothness_selection"]``; a mesh is
        scored at its vertices). On dense samples (50 points per control point) it changed the
        held-out error 0.73-1.14x (geometric mean 0.94) in docs/smoothness.md; on sparse ones
        it is mixed. It costs up to 30 extra sparse factorizations; a cancelled run is not
        refitted.
    callback : callable, optional
        ``callback(report: dict) -> bool``: called after every iteration with keys
        ``iteration, knots, control_points, rms, max, rms_rel, max_rel, seconds``; return True to
        cancel (the best surface so far is returned, ``report["stop_reason"] == "cancelled"``;
        no exception), None or False to go on. Above 200 000 points (criterion "rms")
        the iterations fit a seeded random subset of 200 000 (their reports add
        ``sampled_points`` and their errors are those of the subset) and the chosen knots are
        fitted to all points at the end (``report["refit"]``); ``surf.errors`` and the final
        ``rms``/``max`` are always those of all points.
    criterion : "rms" or "max"; any case
    initial_knots, knots_per_iteration : int >= 1, optional
        Override the automatic sizes (15% more knots per iteration; the start: about 1/12 of
        the budget in interior knots, and with a tolerance a probe fit with a quarter of those
        first, whose error sets the knots of the next start, so that the net follows the
        tolerance: ``core.refine.next_start``); None (the default) keeps them automatic. An
        ``initial_knots`` given is the first fit's knot count, with no probe (at most one knot
        per 8 points: more is cut to that, with a warning). The probe and
        the fresh starts count towards ``max_iterations``. Each iteration's report says
        whether its knots were placed ``"afresh"``, ``"continued"`` (the first fit of
        ``refine()``) or ``"inserted"`` (``knots_placed``).
    feature_sensitive : bool
        TCB only: choose ``Gamma_0`` and the link triangulations from the data (default) or use
        Delaunay ones.
    seed : int >= 0
        Seed of the random choices (knot sampling, jitter): same input, same surface.
    drop_outliers : bool
        Points far from all others (stray returns, spikes; see
        ``core.parameterize.isolated_points``) are refused with an error that names them
        (default), or, with True, left out of the fit, and so are spikes and pits inside the
        cloud (``core.parameterize.spike_points``) and up to 5% of points over the surface
        that the fold check sees as another layer (a power line over terrain): their
        ``errors`` are NaN and ``report["outliers"]`` counts them. A mesh's spike vertices
        (``core.parameterize.mesh_spikes``: one raised far out of its neighbours' plane) are
        refused the same way (OutlierError), or with True dissolved out of the mesh (each
        with its faces, the hole filled by triangles of its neighbours) and left out like
        loose vertices: NaN in ``errors``, counted in ``report["outliers"]``.
    projection : None, "x", "y", "z" or three numbers
        Point clouds only: the direction to project the cloud along (a height field over the
        plane across it). None (default) chooses it (the best-fit plane, or a direction over
        which the cloud is less steep; ``core.parameterize.parameterize_points``). A given
        direction is still checked for folds; it also lets through clouds too noisy for the
        check to be trusted, which are otherwise refused.
    fill_holes : bool
        Meshes only: a mesh with holes (boundary loops besides the outer one, each at most half
        its size) is refused by default (HolesError, a TopologyError); with True it is mapped
        as if each hole were closed by a fan around its border's mean, and the surface spans
        them, held by the fairing (``core.parameterize._with_holes_filled``;
        ``report["holes_filled"]`` counts them). A hole whose fan would overlap the mesh (a
        C- or L-shaped gap) is refused with advice (ParameterizationError).
        Point clouds: the fit is the same; the tessellation, which otherwise leaves out the
        parts of the domain far from all points, covers the gaps inside the cloud that do not
        reach its outline (occlusions, dropouts; at most half its size:
        ``core.parameterize.cloud_holes``), where the surface is held by the fairing;
        ``report["holes_filled"]`` counts those reaching farther from the points than the
        reach of a cloud's tessellation (``core.parameterize.gaps_beyond``).
    join : (TCBSurface, shared) or a list of them, optional
        Meshes: the surfaces of neighbouring patches of the same mesh to join along the
        border this mesh shares with each (``core.join``): ``shared`` is ``(k, 2)`` vertex
        pairs ``(i, j)``, vertex ``i`` of these ``points`` the same as vertex ``j`` of the data
        that surface was fitted to (``core.join.shared_vertices(points, other_points)`` finds
        them by their coordinates). The run is the same; its surface's control points are then
        fitted again with the neighbours' surfaces along the shared border edges as pins
        (the neighbours are not changed), so the patches meet there to a small share of their
        errors (``report["join"]``: the gaps before and after, in the data's units and over
        the diagonal). Two patches of a UV sphere fitted at 1e-3: gaps up to 2.7e-3 of the
        diagonal left, 3e-5 joined (``benchmarks/join.py``).
        Point clouds: the surfaces of neighbouring clouds fitted along the same projection
        (DEM tiles along z), each a TCBSurface (or ``(surface, None)``): this cloud's border
        is pinned where it lies on a neighbour's fitted surface (``core.join.cloud_seam``:
        tiles sharing their edge row of nodes, or overlapping), to that surface's height
        there (``report["join"]["shared_length"]``, ``"pins"``). The Jacksboro DEM in 2 x 2
        tiles at 1e-3: their seams up to 105 m apart alone, 6.38 m joined
        (``benchmarks/dem_tiles.py``).

    Counts (``degree``, ``max_control_points``, ...) are whole numbers (``2.0`` is 2), flags
    (``relative``, ``feature_sensitive``) Python or numpy bools; anything else is refused.

    Raises
    ------
    InvalidInputError, TopologyError, ParameterizationError
        Bad input, with a message that says what to do.
    SingularSystemError, BorderError
        The fit cannot be trusted (never returns NaN).
    """
    options = RefineOptions(
        degree=degree, mode=mode, tolerance=tolerance, relative=relative, criterion=criterion,
        max_control_points=max_control_points, max_iterations=max_iterations,
        smoothness=smoothness, initial_knots=initial_knots,
        knots_per_iteration=knots_per_iteration, feature_sensitive=feature_sensitive, seed=seed,
    )
    options.validate()
    check_callback(callback)
    for name, flag in (("drop_outliers", drop_outliers), ("fill_holes", fill_holes)):
        if not isinstance(flag, (bool, np.bool_)):
            raise InvalidInputError(f"{name} must be True or False, got {flag!r}")
    coarse = float32_rounding(points, "pass float64 coordinates, or subtract an offset before "
                                      "rounding them to fewer bits")
    points = _as_points(points)  # (says what is wrong; complex numbers refused, user test)
    fill = fill_value_rows(points if faces is None else points[_in_faces(faces, len(points))])
    if fill is not None:  # (fitted as terrain 10 km deep, with no word: user test)
        if faces is None:
            raise InvalidInputError(
                fill_value_words(fill, len(points)) + f"; leave those rows out (points["
                f"points[:, {fill[1]}] != {fill[2]:g}])")
        # (a mesh's vertices in faces: NaN or dropped rows would break it; review)
        raise InvalidInputError(fill_value_words(fill, len(fill[0]), "vertices in faces")
                                + "; repair those vertices or cut them out of the mesh")
    held = points if faces is None else points[_in_faces(faces, len(points))]
    huge = huge_rows(held)
    if huge.any():
        raise InvalidInputError(
            huge_words(huge, held, "points" if faces is None else "vertices in faces")
            + ("; leave those rows out" if faces is None
               else "; repair those vertices or cut them out of the mesh"))
    try:
        param = parameterize(points, faces, drop_outliers=drop_outliers, projection=projection,
                             fill_holes=bool(fill_holes))
    except TCBError as exc:
        if coarse is None:
            raise
        exc.args = (f"{exc} (note: {coarse})",)  # (the same error: its fields, such as
        raise exc from None  # an OutlierError's indices, stay; review)
    if coarse is not None:
        warnings.warn(coarse, RuntimeWarning, stacklevel=2)
    return _run(points, param, options, callback, checked=faces is None,
                seam_list=seams(param, join, points),
                **dict(zip(("faces_key", "faces_set_key", "faces_set_key32", "mesh_key"),
                           (None,) * 4 if faces is None else _faces_keys(faces, points))),
                spikes=faces is None and not drop_outliers,
                projection_given=faces is None and projection is not None)


def default_swung(selection: dict | None) -> bool:
    """Whether ``report["smoothness_selection"]`` says the default smoothness was replaced by
    a smoother one because its surface swung (:func:`_smoother_if_swinging`): a
    ``"smoother"`` entry without cross-validation scores."""
    return bool(selection) and "smoother" in selection and "cross_validated_rms" not in selection


def _smoother_if_swinging(best, uv, points, n_measured: int, seed: int, limit=None,
                          criterion: str = "rms", margin: float = 0.0, default: bool = False):
    """``best`` (an IterationState of adaptive_fit), or, when its smoothness was chosen by
    cross-validation and the surface swings away from the data between points
    (:func:`data_swings`, by more than ``margin``), refitted with the next larger candidate
    that does not (the selection says so in ``"smoother"``). Held-out data points cannot see
    a swing in a gap between them: 30 points of sin(3x) got 1e-5, 1.2 off the function, where
    1e-4 is about 0.2 off (user test). ``uv``/``points``: what was fitted (normalized), the
    first ``n_measured`` the user's. With ``limit`` (the tolerance the loop reached,
    normalized) a smoother fit must meet it too; a default kept because the choice missed the
    tolerance (``"kept"``) is left alone.

    ``default``: the smoothness is the default 1e-4, not chosen by the user. When the fit
    with it swings, the larger candidates of AUTO_SMOOTHNESS and SPARSE_SMOOTHNESS are tried
    the same way (the selection's ``"chosen"`` is then the default, and it has no scores):
    the step tile of the tests, with the loop's take-backs switched off, swung 39 m off the
    true shape beyond 3 m of the step with 1e-4 and 2.9 m with 1.0. A value the user gave is
    kept (the final check warns). Without a tolerance reached the smoother fit's error at the
    data (by ``criterion``) must stay within SMOOTHER_MAX_LOSS times the choice's.

    Returns the state and :func:`data_swings` of its fit (normalized units), or ``None`` when
    nothing was checked: the final check reuses it (the check is scale-covariant; 0.1-0.2 s
    of a 1e5-point fit)."""
    sel = best.selection
    if sel and "cross_validated_rms" in sel and "kept" not in sel:
        candidates = [float(k) for k in sel["cross_validated_rms"]]
    elif not sel and default:
        candidates = list(AUTO_SMOOTHNESS) + list(SPARSE_SMOOTHNESS)
    else:
        return best, None

    def swings(fit):  # (all the points fitted: a mesh's samples on its faces are data too)
        return data_swings(best.space, fit.control_points, uv, points, fit.errors, seed=seed,
                           margin=margin)

    first = swings(best.fit)
    if first[0] == 0:
        return best, first
    chosen = float(best.fit.smoothness)

    def error(fit):
        e = fit.errors[:n_measured]
        return float(np.sqrt(np.mean(e * e)) if criterion == "rms" else e.max(initial=0.0))

    bound = limit if limit is not None else SMOOTHER_MAX_LOSS * error(best.fit)
    for s in sorted(candidates):
        if s <= chosen:
            continue
        fit = fit_control_points(best.space, uv, points, None, s)
        if error(fit) > bound:
            # smoother ones miss the tolerance the loop reached, or (none reached) lose too
            # much at the data: keep the choice (the final check warns of its swings)
            break
        found = swings(fit)
        if found[0] == 0:
            fit.basis = None
            if not sel:  # (the default)
                return dataclasses.replace(best, fit=fit, selection={
                    "chosen": chosen, "smoother": f"{s:g} (with the default {chosen:g} the "
                    "surface swung away from the data between points)"}), found
            return dataclasses.replace(best, fit=fit, selection={
                **sel, "smoother": f"{s:g} (with {chosen:g}, the cross-validated choice, the "
                                   "surface swung away from the data between points)"}), found
    return best, first


def data_swings(space, C, uv, points, errors, seed: int = 0,
                margin: float = 0.0) -> tuple[int, int, float]:
    """Where the surface swings away from the data between neighbouring data points: a check
    after the fit (not in method.md; :func:`core.refine.swing_places`, which says how, gives
    the places too). ``space`` with control points ``C`` (all functions), the data's
    parameters ``uv``, ``points`` and fit errors ``errors`` (one unit); a place counts when
    its excess is above ``margin``. Returns (places flagged, places checked, the largest
    excess). The points are taken in an order of their coordinates (``coordinate_order``):
    the check's seeded sample does not depend on the order they are stored in, and the
    report's check (made in that order by the fit) is what this call says."""
    order = coordinate_order(points)
    if order is not None:
        uv, points, errors = (np.asarray(a)[order] for a in (uv, points, errors))
    where, checked, largest = swing_places(space, C, uv, points, errors, seed, margin,
                                           domain=True)
    return len(where), checked, largest


# a smoother fit taken for one that swings (:func:`_smoother_if_swinging`) when the loop reached
# no tolerance may miss the data by at most this many times the choice's error: the step tile
# of the tests needed 2.1x (smoothness 1 for 1e-4, its swing of 39 m down to 2.9 m); F7 with 3x
# its heights, flagged by a check since corrected, went to 100 at 33x (31x in cross-validation,
# 1.0 off the function instead of 0.03)
SMOOTHER_MAX_LOSS = 3.0
# a cloud whose error stopped falling (core.refine.STALLED) with its data, at their closest
# surface points (a sample of FAR_STALL_SAMPLE), farther than FAR_STALL_RMS of the diagonal
# (RMS) and FAR_STALL_SCATTER times their scatter about their local planes (local_scatter) is
# warned of: that is not noise (far_stall_check). Measured on 135 fits of benchmarks/
# fold_check.py's functions and caps (up to 5000 points; as given, with noise of 0.5% of the
# extent, and turned with it; /tmp/s20/scatter2.py of the twentieth session): the 65 stalled
# ones other than the folded one at most 0.65% of the diagonal and 1.9x their scatter (clean
# data: 0.07% at most, though up to 21x), the folded one 3.2% and 8.1x
# Noise larger than the data's spacing makes the scatter too small (local_scatter): it is
# trusted when at least FAR_STALL_DISKS of the neighbourhoods are thin disks. The review's
# noise clouds (a plane and Franke's function, 3000-20 000 points, noise 1-5% of the extent,
# and a DEM tile with 2%; those with 3-5% and the tile had set off the warning at 4.1-5.8x)
# have 5-9%; the folded one 31%, the same grid not turned 32%, Franke 3000 with 1% noise 48%
# (/tmp/s20/rel.py)
FAR_STALL_RMS = 0.01
FAR_STALL_SCATTER = 4.0
FAR_STALL_DISKS = 0.2
FAR_STALL_SAMPLE = 2000

# the spikes check (:func:`data_spikes`): the share of points looked at (those the fit misses
# most), how much more than the RMS of the others they must miss, and how steep a spike must
# be (2: 63 degrees; F10's cone point, sampled at its tip, is a spike at 45). A share of 1e-3
# counted 10 of 30 spikes in 1e4 points, each missed by 5 m (user test)
SPIKE_SHARE = 1e-2
SPIKE_FACTOR = 10.0
SPIKE_SLOPE = 2.0


def data_spikes(points, errors, direction) -> tuple[int, float, bool]:
    """The points of a cloud that stick out of their neighbours' surface like spikes, among
    those the fit misses most (not in method.md): the worst SPIKE_SHARE of the points that
    miss it by more than SPIKE_FACTOR times the RMS of the others, tested by
    :func:`core.parameterize.spike_points` (steeper than SPIKE_SLOPE) across ``direction``
    (the projection's), and alone at their height among their 24 nearest points. For a cloud
    fitted without ``drop_outliers``, which would have left them out: they pull the surface.
    Returns (how many, the largest error among them, whether there may be more: all of the
    worst SPIKE_SHARE were tested)."""
    e = np.asarray(errors, dtype=np.float64)
    n = len(e)
    top = max(1, int(SPIKE_SHARE * n))
    if n < 20:
        return 0, 0.0, False
    order = np.argsort(e)[::-1]
    rest = float(np.sqrt(np.mean(e[order[top:]] ** 2)))
    cand = order[:top][e[order[:top]] > SPIKE_FACTOR * rest]
    if len(cand) == 0:
        return 0, 0.0, False
    norm = box_normalization(points)
    q = norm.apply(points)
    found = spike_points(q, direction, only=cand, slope=SPIKE_SLOPE)
    if len(found):
        # alone at its height: no two of its 24 nearest across the direction within a quarter
        # of its error of it (a point of the lower level where a 20 m step meets the tile's
        # border, its 11 nearest all on the upper level, passed the spike test: suite)
        w = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
        h = q @ w
        flat = q - np.outer(h, w)
        nb = cKDTree(flat).query(flat[found], k=min(25, len(q)), workers=-1)[1][:, 1:]
        level = np.abs(h[nb] - h[found][:, None]) * norm.scale < 0.25 * e[found][:, None]
        found = found[level.sum(axis=1) < 2]
    return int(len(found)), float(e[found].max(initial=0.0)), len(cand) == top


def spikes_warning(found: int, largest: float, more: bool = False) -> str:
    """The warning of :func:`data_spikes`, with what to do (``more``: at least so many)."""
    return (f"{'at least ' if more else ''}{found} point{'s' if found != 1 else ''} "
            f"stick{'s' if found == 1 and not more else ''} out of "
            f"the surface of {'their' if found != 1 else 'its'} neighbours like "
            f"{'spikes' if found != 1 else 'a spike'} (missed by up to {largest:.4g}): stray "
            "returns? They pull the surface towards them; drop_outliers=True (--drop-outliers, "
            "in Blender Drop Outliers) leaves such points out")


# the layers check (:func:`data_layers`): points checked, share of them near the surface
# below which the residuals are two-layered (clean fits of 30 clouds: 0.15-0.25; two copies
# 6 noise sigmas apart: 0.02), share of each side and of opposite-side neighbours at least
LAYER_POINTS = 5000
LAYER_NEAR = 0.06
LAYER_SIDE = 0.15
LAYER_MIXED = 0.25
LAYER_LOCAL = 24  # ... or around LAYER_PART of the points at least, among their 24 nearest
LAYER_PART = 0.1
# ... in clouds of at least this many (sample) points: pure noise gave an alarm in 8-10 of 100
# draws of 100-200 points, none of 500-5000; uniform residuals 1 of 50 draws of 1000, none of
# 2000 or 5000 (/tmp/s24/lnoise.py, lnoise2.py)
LAYER_LOCAL_MIN = 2000


def data_layers(uv, residuals, seed: int = 0) -> float:
    """The distance between two layers of points that the surface runs between, or 0.0 (not
    in method.md). ``residuals`` are the signed distances of the data points from the surface
    across the projection plane, ``uv`` their parameters.

    Two scans of one surface that are not aligned (an offset below the 3D neighbourhoods of
    the fold check, which refuses larger ones) are fitted between them: the errors are half
    the offset everywhere and look like noise (user test L2: two copies of a terrain 0.1
    apart, RMS 0.05, "the error stopped falling"). Noise leaves residuals near 0: of a
    random sample of LAYER_POINTS, ``|r| < 0.3 median |r|`` holds at 15-25% of the points on
    30 clean clouds (the benchmarks' 12 at two tolerances, the DEM, quantized terrain, Gaussian
    and Laplace noise), at 8% for two layers 4 noise sigmas apart and 2% at 6. Layers count
    when under LAYER_NEAR are that near, both sides hold at least LAYER_SIDE of the points,
    and the median point has LAYER_MIXED of its 8 nearest neighbours (in uv) on the other
    side (interleaved layers, not a smooth misfit). The distance is ``median(r | r > 0) -
    median(r | r < 0)``. Layers over part of the surface (overlapping strips; in clouds of
    LAYER_LOCAL_MIN points or more) are found by the same near and side tests on each
    point's LAYER_LOCAL nearest, where they hold around LAYER_PART of the points; their
    distance is the median of the neighbourhoods'. No false alarm on benchmarks/layers.py's
    48 fits, nor on the DEM with its heights rounded to 1 or 5 m or with Laplace noise, or
    terrain rounded to 0.1-1 (scratch /tmp/s24/quant.py); two strips overlapping by 40%, 0.1
    apart: 0.1 (the tests)."""
    r = np.asarray(residuals, dtype=np.float64)
    uv = np.asarray(uv, dtype=np.float64)
    if len(r) > LAYER_POINTS:
        pick = np.random.default_rng(seed).choice(len(r), LAYER_POINTS, replace=False)
        uv, r = uv[pick], r[pick]
    if len(r) < 20:
        return 0.0
    a = np.abs(r)
    up = r > 0
    tree = cKDTree(uv)
    if (np.mean(a < 0.3 * np.median(a)) < LAYER_NEAR
            and LAYER_SIDE <= np.mean(up) <= 1.0 - LAYER_SIDE):
        _, nb = tree.query(uv, k=9, workers=-1)
        if np.median(np.mean(up[nb[:, 1:]] != up[:, None], axis=1)) >= LAYER_MIXED:
            return float(np.median(r[up]) - np.median(r[~up]))
    if len(r) < LAYER_LOCAL_MIN:  # (150 noisy points: 4 of 30 fits were alarms; review)
        return 0.0
    # layers over part of the surface (strips of a scan overlapping by a third, the second
    # 0.15 above the first, noise 0.02: the whole passed as noise, user test): the same test
    # on each point's LAYER_LOCAL nearest (in uv; the sign test: both sides hold LAYER_SIDE),
    # counted where half of a point's neighbours pass too, when they are LAYER_PART of all
    _, nb = tree.query(uv, k=LAYER_LOCAL + 1, workers=-1)
    rn = r[nb[:, 1:]]
    an = np.abs(rn)
    side = np.mean(rn > 0, axis=1)
    local = ((np.mean(an < 0.3 * np.median(an, axis=1, keepdims=True), axis=1) < LAYER_NEAR)
             & (side >= LAYER_SIDE) & (side <= 1.0 - LAYER_SIDE))
    local &= np.mean(local[nb[:, 1:]], axis=1) >= 0.5
    if np.mean(local) < LAYER_PART:
        return 0.0
    up_n = rn[local] > 0
    above = np.nanmedian(np.where(up_n, rn[local], np.nan), axis=1)
    below = np.nanmedian(np.where(~up_n, rn[local], np.nan), axis=1)
    return float(np.median(above - below))


# a smoothness given over this many times the default is named as the cause of a far stall
STIFF_SMOOTHNESS = 100.0

# what the command line and Blender say of a run that missed its tolerance with spike points
# in the cloud (report["spikes"], whose warning names them), before the option to leave them out
SPIKES_HELD_OFF = ("the points that stick out like spikes (the warning above) pull the "
                   "surface")


def far_stall_warning(report: dict, stiff: float | None = None) -> str:
    """The warning of an error that stopped falling far above the data's scatter (``_run``);
    ``stiff``: a smoothness given that is over STIFF_SMOOTHNESS times the default, named first
    as the likely cause (smoothness=1000 on clean Franke was told of folds only: user test)."""
    d = report["distance_rms"]
    given = bool(report.get("projection_given"))
    cause = ("" if stiff is None else
             f" The smoothness given ({stiff:g}, {stiff / DEFAULT_SMOOTHNESS:.0f} times the "
             "default) likely holds the surface off the data: lower it, or leave it to the "
             "default. Otherwise the cloud may ")
    return (f"the error stopped falling with the data {d:.4g} from the surface (RMS of their "
            f"distances, {100 * d / report['diagonal']:.1f}% of the diagonal), "
            f"{d / max(report['scatter'], 1e-300):.0f} times their scatter about their local "
            f"planes ({report['scatter']:.3g}): that is not noise."
            + (cause or " The cloud may ")
            + ("not be a height field along the direction given (parts of it seen edge-on "
               "along it, or overlapping): split it into patches that each face one "
               "direction, give another direction, "
               if given else
               "fold over the plane it was projected on (parts of it seen edge-on, or "
               "overlapping in projection): give the direction it faces (projection=, on the "
               "command line "
               "--projection, in Blender the Projection option), split it into patches that "
               "each face one direction, ")
            + "or supply a mesh of disk topology (with faces)")


def layers_warning(report: dict) -> str:
    """The warning for ``report["layers"]`` (:func:`data_layers`), with what to do."""
    return (f"the points lie in two layers about {report['layers']:.4g} apart across the "
            "surface, which runs between them (scans that are not aligned to each other, "
            "both sides of a thin object, or a scanner's double returns): align the scans, or "
            "fit each layer on its own")


def swing_warning(report: dict) -> str:
    """The warning for ``report["swings"]`` (:func:`data_swings`), with what to change."""
    sw = report["swings"]
    return (f"the surface swings away from the data between neighbouring points at "
            f"{sw['places']} of the {sw['checked']} places checked, by up to {sw['largest']:.4g} "
            f"({sw['largest_rel']:.2e} of the diagonal), which the errors at the data do not "
            "show: more knots crowd there than the data hold (a sharp step, or a gap in the "
            "data); a looser tolerance, or fewer control points, keeps the surface closer to "
            "the data there")
