"""Joining a mesh's surface to the surfaces of its neighbouring patches (not in method.md).

A mesh cut into patches (faces selected in Edit Mode, a scan split into parts) is fitted one
patch at a time, and each fit meets its own data within its tolerance, not its neighbour's
surface: two patches of a UV sphere fitted at 1e-3 left gaps up to 3e-3 of the diagonal along
their shared border. A patch fitted with ``join=`` is drawn to its neighbours' surfaces along
the border they share:

- the shared border is the mesh edges that are border edges of both patches (each used by
  one of the patch's triangles), between vertices given as the same (``shared`` pairs, or
  :func:`shared_vertices` by their coordinates);
- a parameterization is linear on each triangle, so the point at fraction ``t`` along a shared
  edge is at ``(1 - t) uv_i + t uv_j`` in either patch's parameters; the points at
  :data:`EDGE_PINS` along each edge and at its ends are drawn to the nearest point of the
  neighbour's border along that edge, but not in across the patch's own border
  (:func:`join_pins`, :func:`inward_directions`): where the neighbour's border lies over the
  patch (its fit's error there), the two surfaces overlap rather than the patch's border
  folding back over its own data (it had: thin lips along the seam);
- the patch's control points are fitted again on the knots its own run chose, with the pins
  added to the data term (``core.fit.fit_control_points``'s ``pins``, each worth
  :data:`PIN_WEIGHT` data points), so the neighbour is left as it is; where the pins are
  missed by more than :data:`GAP_SHARE` of the tolerance, knots are inserted in the
  ``Gamma_0`` triangles that hold them (method.md section 6's insertion, ranked by the pins'
  errors), up to :data:`JOIN_ROUNDS` times and within the control-point budget
  (:func:`join_fit`): a patch's knots follow its own data, and its border is often coarser
  than its neighbour's.

The gap that is left (:func:`seam_gaps`, at :data:`GAP_SAMPLES` points per shared edge, the
overlap not counted) is what the patch's spline space cannot follow of its neighbour between
the pins. A joined fit that turns over on the patch's triangles along the seam
(:func:`seam_folds`) is not returned.

Point clouds (:class:`CloudSeam`, forty-seventh session) have no vertices to share: a cloud
fitted along the same projection as its neighbour (DEM tiles along z) is pinned where its
domain's border lies on the neighbour's fitted surface (a shared row of nodes, or an overlap),
each pin to the neighbour's surface on the projection ray through it, so its height there
(:func:`cloud_seam`); the rest is the meshes' loop.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from .errors import BorderError, InvalidInputError, SingularSystemError, TCBError
from .fit import fit_control_points
from .parameterize import data_spacing, in_voids, trim_distance
from .refine import _feature_cost, insertion_points, make_space

# pins inside each shared edge, as fractions along it (its two vertices are pinned too)
EDGE_PINS = (0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875)
# what one pin weighs, in data points of the mean weight (30-1000 tried on benchmarks/join.py's
# cases: 100 met the pins closest with the fewest knots added; at 1000 the knots added folded
# the surface at the seam)
PIN_WEIGHT = 100.0
# the pins are to be met to this share of the tolerance; knots are inserted where they are not,
# in at most JOIN_ROUNDS rounds
GAP_SHARE = 0.3
JOIN_ROUNDS = 10
# ... of the Gamma_0 triangles holding pins missed by more, the worst this share
INSERT_SHARE = 0.25
# points per shared edge at which the gap between the surfaces is measured (ends included)
GAP_SAMPLES = 17
GAP_SEGMENTS = 32
# the seam's fold check (seam_samples): a barycentric grid of this many steps on each of the
# patch's triangles that hold a shared edge (153 points, the triangle's edges included). The
# folds a join made were thin lips along the shared edges that the whole mesh's check
# (core.surface.mesh_folds, 10 000 points drawn by area) missed: the 64 x 32 sphere's rest
# joined to its cap turned its normal over at 23 of 20 800 such points, on 4 of its 64 seam
# triangles, reported "folded 0"
SEAM_FOLD_STEPS = 16
# point clouds (CloudSeam): pins along the shared border this share of the data's spacing
# apart (the gap measured at twice as many points); a neighbour's domain holds points on its
# border to this share of its size (the pins come from this cloud's parameters through 3D,
# rounded at about 1e-16 of the coordinates: UTM's 4e6 m on a tile 500 m across is 1e-12);
# the two projection directions are parallel to this (1 - |cos|)
CLOUD_PIN_SPACING = 0.25
CLOUD_BORDER_TOL = 1e-9
CLOUD_PARALLEL = 1e-9


def border_edges(faces: np.ndarray) -> np.ndarray:
    """``(e, 2)`` sorted vertex pairs of the edges of triangles ``faces`` used by one
    triangle only: the mesh's border (outer loop and holes)."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    u, count = np.unique(e, axis=0, return_counts=True)
    return u[count == 1]


def shared_vertices(points, other_points) -> np.ndarray:
    """``(k, 2)`` int64 pairs ``(i, j)`` with ``points[i] == other_points[j]`` (identical
    coordinates, -0.0 equal to 0.0: the vertices two patches cut from one mesh share), every
    such pair (a coordinate repeated in either array, an unwelded or loose vertex, pairs each
    of its rows), sorted."""
    a = np.asarray(points, dtype=np.float64)
    b = np.asarray(other_points, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != 3 or b.shape[1] != 3:
        raise InvalidInputError("shared_vertices() needs two (N, 3) arrays of points")
    rows = np.dtype((np.void, 24))
    ka = np.ascontiguousarray(a + 0.0).view(rows).ravel()  # (+ 0.0: -0.0 becomes 0.0)
    kb = np.ascontiguousarray(b + 0.0).view(rows).ravel()
    code = np.unique(np.concatenate([ka, kb]), return_inverse=True)[1]
    ca, cb = code[: len(ka)], code[len(ka):]
    ob = np.argsort(cb, kind="stable")
    sorted_b = cb[ob]
    lo = np.searchsorted(sorted_b, ca, side="left")
    count = np.searchsorted(sorted_b, ca, side="right") - lo
    i = np.repeat(np.arange(len(ka)), count)
    j = ob[np.repeat(lo - np.cumsum(count) + count, count) + np.arange(count.sum())]
    return np.column_stack([i, j]).astype(np.int64)


def shared_border_edges(faces, other_faces, pairs) -> tuple[np.ndarray, np.ndarray]:
    """The edges on the border of both meshes (triangles ``faces`` and ``other_faces``)
    between vertices ``pairs`` ``(k, 2)`` gives as the same (this mesh's, the other's):
    ``(mine, theirs)``, ``(e, 2)`` vertex pairs of the same edges in each mesh's numbers."""
    own_border = border_edges(faces)
    other_border = border_edges(other_faces)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    n_own = int(max(own_border.max(initial=-1), pairs[:, 0].max(initial=-1))) + 1
    n_other = int(max(other_border.max(initial=-1), pairs[:, 1].max(initial=-1))) + 1
    # this mesh's border edges whose two ends are shared, with every pair of the other's
    # vertices their ends are paired with (a repeated coordinate pairs several) ...
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    start = np.searchsorted(pairs[:, 0], np.arange(n_own + 1))
    count = np.diff(start)
    na, nb = count[own_border[:, 0]], count[own_border[:, 1]]
    e = np.repeat(np.arange(len(own_border)), na * nb)
    k = np.arange(len(e)) - np.repeat(np.cumsum(na * nb) - na * nb, na * nb)
    mine = own_border[e]
    theirs = np.column_stack([pairs[start[mine[:, 0]] + k // nb[e], 1],
                              pairs[start[mine[:, 1]] + k % nb[e], 1]])
    key = np.array([n_other, 1], dtype=np.int64)  # ... that are the other's border edges too
    on = np.isin(np.sort(theirs, axis=1) @ key, other_border @ key)
    return mine[on], theirs[on]


def shared_faces(faces, other_faces, pairs) -> int:
    """How many triangles of ``faces`` are triangles of ``other_faces`` too, their vertices
    paired by ``pairs`` (the first pair of each vertex): overlapping patches, or a patch and
    itself."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    f = np.asarray(faces, dtype=np.int64)
    g = np.asarray(other_faces, dtype=np.int64)
    if not len(pairs) or not len(f) or not len(g):
        return 0
    to_other = np.full(max(int(f.max()), int(pairs[:, 0].max())) + 1, -1, dtype=np.int64)
    to_other[pairs[::-1, 0]] = pairs[::-1, 1]  # (the first pair of each vertex last: kept)
    mapped = to_other[f]
    mapped = mapped[(mapped >= 0).all(axis=1)]
    rows = np.dtype((np.void, 24))  # (a triangle's sorted corners as one key)
    mine = np.ascontiguousarray(np.sort(mapped, axis=1)).view(rows).ravel()
    theirs = np.ascontiguousarray(np.sort(g, axis=1)).view(rows).ravel()
    return int(np.isin(mine, theirs).sum())


class Seam:
    """The border a patch shares with one neighbouring surface: ``own`` and ``other``
    ``(e, 2)`` vertex pairs of the shared edges (the same edges, in each patch's vertex
    numbers), ``vertices`` ``(k, 2)`` the shared border vertices, and the neighbour
    ``surface``."""

    def __init__(self, surface, own_edges, other_edges, vertices):
        self.surface = surface
        self.own = own_edges
        self.other = other_edges
        self.vertices = vertices
        self._polyline = None

    def polyline(self) -> np.ndarray:
        """The neighbour's surface along each shared edge, ``(e, GAP_SEGMENTS + 1, 3)``
        (made once: the neighbour does not change)."""
        if self._polyline is None:
            theirs = self.along(np.zeros((0, 2)), np.linspace(0.0, 1.0, GAP_SEGMENTS + 1),
                                own=False)[1]
            self._polyline = self.surface(theirs).reshape(len(self.own), GAP_SEGMENTS + 1, 3)
        return self._polyline

    def along(self, own_uv: np.ndarray, fractions, own: bool = True):
        """Parameters ``(own, other)`` of the points at ``fractions`` along every shared
        edge: ``(1 - t) uv_i + t uv_j`` in each patch's parameters (``own`` False: None for
        this patch's)."""
        t = np.asarray(fractions, dtype=np.float64)[None, :, None]
        other_uv = np.asarray(self.surface.parameterization.uv)

        def at(uv, edges):
            return ((1 - t) * uv[edges[:, 0]][:, None]
                    + t * uv[edges[:, 1]][:, None]).reshape(-1, 2)

        return at(own_uv, self.own) if own else None, at(other_uv, self.other)


class CloudSeam:
    """The border a point cloud's surface shares with a neighbouring cloud's surface, both
    projected along the same direction (DEM tiles along z, :func:`cloud_seam`): the pins
    ``uv`` ``(m, 2)`` (this cloud's parameters, on its domain's border where the neighbour's
    surface is fitted) and their ``targets`` ``(m, 3)``, the neighbour's surface on the same
    projection rays (data units); ``gap_uv`` and ``gap_targets`` the same at twice as many
    points, where the gap is measured; ``length`` the length of border they cover (data
    units) and ``neighbour_error`` the neighbour's largest error at its data points nearest
    to the pins. The two surfaces share their projection, so a pin's target lies on the ray
    through the pin: nothing slides along the border, and nothing lies across it."""

    vertices = np.zeros((0, 2), dtype=np.int64)  # (none: a cloud has no vertices to share)
    own = np.zeros((0, 2), dtype=np.int64)

    def __init__(self, surface, uv, targets, gap_uv, gap_targets, length, neighbour_error):
        self.surface = surface
        self.uv, self.targets = uv, targets
        self.gap_uv, self.gap_targets = gap_uv, gap_targets
        self.length = float(length)
        self.neighbour_error = float(neighbour_error)


def _on_border(polygon: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along the closed ``polygon`` ``(b, 2)`` at most ``step`` apart (each edge cut
    into equal pieces, its first end included), in order, and the length of the piece from
    each to the next (the last's to the first)."""
    a = np.asarray(polygon, dtype=np.float64)
    d = np.roll(a, -1, axis=0) - a
    length = np.linalg.norm(d, axis=1)
    k = np.maximum(1, np.ceil(length / step)).astype(np.int64)
    edge = np.repeat(np.arange(len(a)), k)
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / k[edge]
    return a[edge] + t[:, None] * d[edge], (length / k)[edge]


def _fitted_part(param, uv: np.ndarray) -> np.ndarray:
    """Mask of the parameters ``uv`` on the fitted part of a cloud's surface (where its
    tessellation and :meth:`core.surface.TCBSurface.heights` reach): inside its domain (its
    border included, to :data:`CLOUD_BORDER_TOL` of its size), and within the trim distance
    of its data or in a void between its points, or anywhere inside with ``fill_holes``."""
    inside = param.contains(uv, tol=CLOUD_BORDER_TOL)
    if param.holes is not None or not inside.any():
        return inside
    data = np.asarray(param.uv)[np.isfinite(param.uv).all(axis=1)]
    tree = cKDTree(data)
    near = tree.query(uv[inside])[0] <= trim_distance(param, data, tree)
    near[~near] = in_voids(param, uv[inside][~near])
    inside[np.flatnonzero(inside)[~near]] = False
    return inside


def cloud_seam(param, surface, k: int = 0, points=None) -> CloudSeam:
    """The :class:`CloudSeam` of a point cloud (parameterization ``param``, a plane) with the
    neighbouring cloud's ``surface`` (``join[k]``): the points of this cloud's domain border,
    :data:`CLOUD_PIN_SPACING` of its data's spacing apart, that are within the trim distance
    of its data and on the fitted part of the neighbour's surface (:func:`_fitted_part`),
    where the two are to meet. Two DEM tiles sharing a row of nodes share that row; tiles
    that overlap, the part of this one's border inside the other. A clear
    :class:`InvalidInputError` for a neighbour fitted to a mesh or projected along another
    direction, and for one that reaches none of this border, or all of it (the same data,
    or a cloud inside it). ``points`` (the cloud's, ``(n, 3)``, rows as ``param.uv``'s): the
    border is looked for on the other surface at the height of this cloud's nearest points
    (along a direction the other does not share, the border's points on this cloud's plane
    project elsewhere: an adjacent tile fitted 17 degrees off had been told it reached no
    part of the border; review)."""
    other = surface.parameterization
    if other.kind != "plane" or other.axes is None or other.origin is None:
        raise InvalidInputError(f"join[{k}]: that surface was fitted to a mesh; a point "
                                "cloud's surface joins the surfaces of neighbouring clouds")
    finite = np.isfinite(param.uv).all(axis=1)
    data = np.asarray(param.uv)[finite]
    tree = cKDTree(data)
    step = CLOUD_PIN_SPACING * data_spacing(data, tree)[0] / 2.0
    if not step > 0:
        raise InvalidInputError(f"join[{k}]: this cloud's points have no spacing to pin "
                                "its border at")
    uv, piece = _on_border(param.domain_polygon, step)
    dist, nearest = tree.query(uv)
    own = dist <= trim_distance(param, data, tree)
    p = np.asarray(param.origin) + param.scale * (uv @ np.asarray(param.axes[:2]))
    if points is not None:  # (at the height of the nearest data point over the plane)
        normal = np.asarray(param.axes[2], dtype=np.float64)
        near = np.asarray(points, dtype=np.float64)[np.flatnonzero(finite)[nearest]]
        p = p + ((near - np.asarray(param.origin)) @ normal)[:, None] * normal
    theirs = other.project(p)
    shared = own & _fitted_part(other, theirs)
    apart = (f"join[{k}]: that surface reaches no part of this cloud's border: neighbouring "
             "clouds are joined where one's border lies on the other's fitted surface (DEM "
             "tiles sharing their edge row of nodes, or overlapping); tiles whose nodes do not "
             "meet (cut a cell apart) are fitted together instead (several files on the "
             "command line, the tiles selected together in Blender)")
    if not shared.any():  # (said first: the words for any surface apart from this cloud)
        raise InvalidInputError(apart)
    n_own = np.asarray(param.axes[2], dtype=np.float64)
    n_other = np.asarray(other.axes[2], dtype=np.float64)
    if abs(float(n_own @ n_other)) < 1.0 - CLOUD_PARALLEL:
        raise InvalidInputError(
            f"join[{k}]: the two clouds were projected along different directions "
            f"({_direction(n_own)} and {_direction(n_other)}); neighbouring clouds are joined "
            "as heights along one direction: fit both with the same projection (DEM tiles: "
            "projection='z', on the command line --projection z, which it chooses by itself "
            "for DEM rasters and gridded x y z text)")
    targets = np.full((len(uv), 3), np.nan)
    targets[shared] = surface(theirs[shared])
    shared &= np.isfinite(targets).all(axis=1)
    if not shared.any():
        raise InvalidInputError(apart)
    if shared.sum() == own.sum():
        raise InvalidInputError(
            f"join[{k}]: that surface reaches all of this cloud's border (the same data, or a "
            "cloud inside it): join to the surface of a neighbouring cloud, which shares a "
            "part of the border with this one")
    rest = np.asarray(other.uv)
    ok = np.isfinite(rest).all(axis=1)
    nearest = np.flatnonzero(ok)[cKDTree(rest[ok]).query(theirs[shared])[1]]
    worst = np.nanmax(np.asarray(surface.errors, dtype=np.float64)[nearest], initial=0.0)
    pins = shared & (np.arange(len(uv)) % 2 == 0)
    if not pins.any():  # (one shared point: pinned too)
        pins = shared
    return CloudSeam(surface, uv[pins], targets[pins], uv[shared], targets[shared],
                     float(piece[shared & np.roll(shared, -1)].sum()) * param.scale, worst)


def _direction(n: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in n) + ")"


def seams(param, join, points=None) -> list[Seam]:
    """The :class:`Seam` of each ``(surface, shared)`` of ``join`` (one pair, or a list of
    them) with the mesh of parameterization ``param``; ``shared`` ``(k, 2)`` pairs ``(i, j)``:
    vertex ``i`` of this mesh is vertex ``j`` of the data ``surface`` was fitted to (such as
    :func:`shared_vertices` finds). A clear :class:`InvalidInputError` for anything else:
    this data not a mesh, a neighbour fitted to a point cloud, pairs out of range, or none of
    them on both borders."""
    if join is None:
        return []
    if (isinstance(join, tuple) and len(join) == 2 and hasattr(join[0], "parameterization")
            and not hasattr(join[1], "parameterization")):  # (two surfaces: two neighbours)
        join = [join]
    if param.faces is None:
        return _cloud_seams(param, join, points)
    if hasattr(join, "parameterization"):
        raise InvalidInputError("join= for a mesh takes pairs (surface, shared): the "
                                "neighbour's surface and the (k, 2) vertex pairs the two "
                                "meshes share (core.join.shared_vertices finds them)")
    out = []
    for k, item in enumerate(join):
        if not (isinstance(item, (tuple, list)) and len(item) == 2
                and hasattr(item[0], "parameterization")):
            raise InvalidInputError(
                f"join[{k}] must be a pair (surface, shared): a TCBSurface and the (k, 2) "
                "vertex pairs (this mesh's, its data's) the two meshes share "
                "(core.join.shared_vertices finds them by their coordinates)")
        surface, shared = item
        other = surface.parameterization
        if other.faces is None:
            raise InvalidInputError(f"join[{k}]: that surface was fitted to a point cloud; only "
                                    "surfaces of meshes have a border to join to")
        try:
            pairs = np.asarray(shared)
            ok = pairs.ndim == 2 and pairs.shape[1] == 2 and np.issubdtype(pairs.dtype,
                                                                           np.integer)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise InvalidInputError(f"join[{k}]: shared must be a (k, 2) array of whole "
                                    "numbers, vertex pairs (this mesh's, the surface's data's)")
        pairs = pairs.astype(np.int64)
        n_own, n_other = len(param.uv), len(other.uv)
        if len(pairs) and (pairs.min() < 0 or pairs[:, 0].max() >= n_own
                           or pairs[:, 1].max() >= n_other):
            raise InvalidInputError(
                f"join[{k}]: shared pairs out of range: this mesh has {n_own} vertices, the "
                f"surface's data {n_other}")
        overlap = shared_faces(param.faces, other.faces, pairs)
        if overlap:
            raise InvalidInputError(
                f"join[{k}]: the two meshes have {overlap} triangles in common (the same "
                "patch, or overlapping ones): join to the surface of a neighbouring patch, "
                "which shares a border with this one and no faces")
        mine, theirs = shared_border_edges(param.faces, other.faces, pairs)
        if not len(mine):
            raise InvalidInputError(
                f"join[{k}]: the two meshes share no border edge (an edge on the border of "
                f"both, between vertices given as shared; {len(pairs)} pairs given): the "
                "surface to join must be of a neighbouring patch of the same mesh")
        verts = np.unique(np.column_stack([mine.ravel(), theirs.ravel()]), axis=0)
        out.append(Seam(surface, mine, theirs, verts))
    return out


def _cloud_seams(param, join, points=None) -> list[CloudSeam]:
    """:func:`seams` for a point cloud: ``join`` a neighbouring cloud's surface, a pair
    ``(surface, None)`` as for meshes (no vertices are shared: the second is not used), or a
    list of them."""
    if hasattr(join, "parameterization"):
        join = [join]
    if param.kind != "plane" or param.axes is None or param.origin is None:
        raise InvalidInputError("join= joins a point cloud's surface to its neighbours' only "
                                "for a cloud projected on a plane")
    out = []
    for k, item in enumerate(join):
        if (isinstance(item, (tuple, list)) and len(item) == 2
                and not hasattr(item[1], "parameterization")):
            item = item[0]  # (a pair as for meshes: no vertices are shared, the rest unused)
        if not hasattr(item, "parameterization"):
            raise InvalidInputError(
                f"join[{k}] must be the TCBSurface of a neighbouring point cloud (or a pair "
                "(surface, None)); give several neighbours as a list of surfaces")
        out.append(cloud_seam(param, item, k, points))
    return out


def _nearest_on(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """For polylines ``q`` ``(e, 1, k + 1, 3)`` and points ``p`` ``(e, t, 1, 3)``: the
    nearest point of each point's polyline, ``(e, t, 3)``."""
    a, d = q[:, :, :-1], q[:, :, 1:] - q[:, :, :-1]  # pieces a + x d, x in [0, 1]
    x = np.clip(np.einsum("etkc,etkc->etk", p - a, d)
                / np.maximum(np.einsum("etkc,etkc->etk", d, d), 1e-300), 0.0, 1.0)
    near = a + x[..., None] * d
    k = np.linalg.norm(near - p, axis=-1).argmin(axis=2)
    return np.take_along_axis(near, k[..., None, None], axis=2)[:, :, 0]


def _borders(seam, own_uv, evaluate, fractions):
    """The surface ``evaluate`` at ``fractions`` along the seam's edges ``(e, t, 3)``, and
    the nearest points of the neighbour's surface along the same edges (a polyline of
    :data:`GAP_SEGMENTS` pieces) ``(e, t, 3)``, with the own parameters ``(e * t, 2)``."""
    mine, _ = seam.along(own_uv, fractions)
    p = evaluate(mine).reshape(len(seam.own), len(fractions), 3)
    return p, _nearest_on(seam.polyline()[:, None], p[:, :, None]), mine


def inward_directions(seam_list, faces, points) -> list[np.ndarray]:
    """For each seam, unit vectors ``(e, 3)`` from its shared edges into the patch's mesh:
    each in the plane of the triangle holding the edge, across the edge."""
    f = np.asarray(faces, dtype=np.int64)
    p = np.asarray(points, dtype=np.float64)
    n = max(len(p), 1)
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    third = f[:, [2, 0, 1]].ravel()  # (the corner opposite each edge)
    key = e[:, 0] * n + e[:, 1]
    order = np.argsort(key, kind="stable")
    out = []
    for seam in seam_list:
        own = np.sort(seam.own, axis=1)
        at = order[np.searchsorted(key[order], own[:, 0] * n + own[:, 1])]
        a, b, c = p[own[:, 0]], p[own[:, 1]], p[third[at]]
        u = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1), 1e-300)[:, None]
        w = (c - a) - np.einsum("ij,ij->i", c - a, u)[:, None] * u
        out.append(w / np.maximum(np.linalg.norm(w, axis=1), 1e-300)[:, None])
    return out


def _not_inward(targets, at, inward):
    """``targets`` (m, 3) without the part of ``targets - at`` along the unit vectors
    ``inward`` (m, 3) where it points that way (into the patch)."""
    into = np.einsum("ij,ij->i", targets - at, inward)
    return targets - np.maximum(into, 0.0)[:, None] * inward


def join_pins(seam_list, own_uv: np.ndarray, evaluate,
              inward=None) -> tuple[np.ndarray, np.ndarray]:
    """Pins of the seams (``core.fit.fit_control_points``'s ``pins``, in the data's units):
    ``(uv, targets)``: the points :data:`EDGE_PINS` along each shared edge and its ends, to
    the point of the neighbour's
    surface along that edge nearest to the surface ``evaluate(uv) -> (m, 3)`` there (so the
    border is drawn to the neighbour's and may slide along it: the two surfaces' speeds along
    an edge differ, and pinning equal fractions had made the border wiggle between them).
    ``inward`` (:func:`inward_directions`): a target is not taken into the patch, across its
    border (the part of ``target - surface`` along the edge's direction into the patch is
    dropped where positive): where the neighbour's border lies over the patch's own surface
    (its fit's error there), drawing the patch's border in over its data folded the surface
    into a lip along the seam (64 x 32 sphere; the two surfaces overlap there instead). The
    vertices take the pins at their edges' ends, each edge's own: a vertex's target,
    taken back along both its edges' directions, had been pinned apart from its edges' pins
    where the seam zigzags over a grid's triangles (1.3e-3 of the diagonal at a vertex; each
    vertex had had a pin of its own, to the neighbour's surface at it)."""
    uvs, targets = [], []
    fractions = (0.0, *EDGE_PINS, 1.0)
    for k, seam in enumerate(seam_list):
        if isinstance(seam, CloudSeam):
            uvs.append(seam.uv)
            targets.append(seam.targets)
            continue
        p, near, mine = _borders(seam, own_uv, evaluate, fractions)
        near = near.reshape(-1, 3)
        if inward is not None:
            near = _not_inward(near, p.reshape(-1, 3),
                               np.repeat(inward[k], len(fractions), axis=0))
        uvs.append(mine)
        targets.append(near)
    return np.vstack(uvs), np.vstack(targets)


def seam_gaps(seam_list, own_uv: np.ndarray, evaluate, inward=None) -> np.ndarray:
    """Distances from the surface ``evaluate(uv) -> (m, 3)`` (the data's units) along the
    shared edges, at :data:`GAP_SAMPLES` points per edge (ends included), to each neighbour's
    surface along the same edge (a polyline of :data:`GAP_SEGMENTS` pieces of it, the
    distance to the nearest piece): the geometric gap between the two borders, whatever their
    speeds along the edge. ``inward`` (:func:`inward_directions`): the part of the distance
    into the patch, across its border, is not counted (the neighbour's border lies over the
    patch's surface there: the two overlap, as :func:`join_pins` leaves them)."""
    t = np.linspace(0.0, 1.0, GAP_SAMPLES)
    gaps = []
    for k, seam in enumerate(seam_list):
        if isinstance(seam, CloudSeam):
            gaps.append(np.linalg.norm(evaluate(seam.gap_uv) - seam.gap_targets, axis=1))
            continue
        p, near, _ = _borders(seam, own_uv, evaluate, t)
        if inward is not None:
            p, near = p.reshape(-1, 3), near.reshape(-1, 3)
            near = _not_inward(near, p, np.repeat(inward[k], len(t), axis=0))
        gaps.append(np.linalg.norm(p - near, axis=-1).ravel())
    return np.concatenate(gaps) if gaps else np.zeros(0)


def seam_samples(seam_list, faces, own_uv, points) -> tuple[np.ndarray, np.ndarray]:
    """Points of the patch's triangles ``faces`` (counter-clockwise in ``own_uv``, the
    canonical winding) that hold a shared edge of ``seam_list``: their parameters ``(s, 2)``
    (a barycentric grid of :data:`SEAM_FOLD_STEPS` steps on each, edges included) and their
    triangle's normal ``(b - a) x (c - a)`` on the mesh ``points`` ``(s, 3)``, along which the
    mesh's own map has ``S_u x S_v`` (as for ``core.surface.mesh_folds``)."""
    f = np.asarray(faces, dtype=np.int64)
    n = max(len(own_uv), 1)
    own = np.sort(np.vstack([seam.own for seam in seam_list]), axis=1)
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2), axis=2)
    tris = f[np.isin(e[..., 0] * n + e[..., 1], own[:, 0] * n + own[:, 1]).any(axis=1)]
    steps = SEAM_FOLD_STEPS
    i, j = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1), indexing="ij")
    inside = i + j <= steps
    bary = np.c_[i[inside], j[inside], steps - i[inside] - j[inside]] / steps
    uv = np.einsum("sk,tkd->tsd", bary, np.asarray(own_uv, dtype=np.float64)[tris])
    p = np.asarray(points, dtype=np.float64)
    normal = np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]])
    return uv.reshape(-1, 2), np.repeat(normal, len(bary), axis=0)


def seam_folds(samples, space, control_points) -> int:
    """How many of the seam's ``samples`` (:func:`seam_samples`) the surface ``space`` with
    ``control_points`` turns over at: ``S_u x S_v`` against the triangle's normal."""
    uv, normal = samples
    if not len(uv):
        return 0
    su = space.evaluate(uv, (1, 0)) @ control_points
    sv = space.evaluate(uv, (0, 1)) @ control_points
    return int(np.count_nonzero(np.einsum("ij,ij->i", np.cross(su, sv), normal) < 0))


def join_fit(best, seam_list, own_uv, fit_uv, fit_q, norm, options, domain, folds=None,
             n_measured=None, mesh=None, fold_allowance=0.0):
    """``best`` (a ``core.refine.IterationState`` of the normalized data ``fit_uv``,
    ``fit_q``; ``norm`` their normalization) joined to the neighbours of ``seam_list``: its
    control points fitted again, same points and smoothness, with the pins of
    :func:`join_pins` (each worth :data:`PIN_WEIGHT` points), whose targets along the edges
    are taken again from each fit (a border sliding along its neighbour's); while a pin is
    missed by more than :data:`GAP_SHARE` of the tolerance (``options``), a knot is inserted
    in each ``Gamma_0`` triangle holding such pins (``core.refine.insertion_points`` ranked by
    the pins' misses, at least two per triangle) and the space made again, as long as the
    control points that meet ``domain`` stay within the budget (fewer, worst first, when all
    would not fit); at most :data:`JOIN_ROUNDS` fits after the first. Of the fits that fold
    over the mesh no more than ``best`` or ``fold_allowance`` (``folds(state) -> share of the
    mesh's area``, ``core.surface.mesh_folds``: knots inserted at a coarse mesh's seam had
    folded its surface over 0.3% of its area, a UV sphere of 32 x 16 cut at z = 0.3; the
    surface passes ``core.surface.FOLDED_SHARE``, the share it warns of: a half of
    three_peaks.off folded over 0.04% of its area on its own and 0.07-0.11% joined, and was
    kept unjoined, 0.22 apart, where 0.054 was within it; user test) and, with ``mesh`` (the
    patch's ``(points, faces)``, the faces in the canonical winding), turn over at no more of
    the seam's triangles' points than ``best`` (:func:`seam_folds`), the one with the smallest
    largest gap among those whose error at the first ``n_measured`` points (the criterion's)
    is within the tolerance, or ``best``'s if that is larger, else among all, is returned
    (``tolerance_missed``: the neighbour's surface, fitted to a looser tolerance, is farther
    from the shared vertices than this one's tolerance; review); when every fit folds more,
    ``best`` itself (``kept_unjoined``). Returns the state and what ``report["join"]`` says:
    the neighbours, shared vertices and edges, knots added, the gaps (:func:`seam_gaps`, the
    data's units) before and after, ``tolerance_missed``, ``kept_unjoined`` and the seam's
    points turned over (``seam_folds`` of ``seam_samples``)."""
    def surface_of(state):
        return lambda x: norm.undo(state.space.evaluate(x) @ state.fit.control_points)

    inward = None if mesh is None else inward_directions(seam_list, mesh[1], mesh[0])
    before = seam_gaps(seam_list, own_uv, surface_of(best), inward)
    samples = (np.zeros((0, 2)), np.zeros((0, 3))) if mesh is None else seam_samples(
        seam_list, mesh[1], own_uv, mesh[0])

    def turned(state) -> int:
        return seam_folds(samples, state.space, state.fit.control_points)
    smoothness = float(best.fit.smoothness)
    goal = GAP_SHARE * options.tolerance * (2.0 if options.relative else 1.0 / norm.scale)
    cost = None
    state, fits, worse = best, [], 0
    for round_ in range(JOIN_ROUNDS + 1):
        pin_uv, targets = join_pins(seam_list, own_uv, surface_of(state), inward)
        targets = norm.apply(targets)
        space, knots, n_int, active = state.space, state.knots, state.n_interior, state.active
        if round_:
            miss = np.linalg.norm(state.space.evaluate(pin_uv) @ state.fit.control_points
                                  - targets, axis=1)
            if goal <= 0 or miss.max() <= goal:
                break
            bad = np.where(miss > goal, miss, 0.0)
            new = insertion_points(knots, space.configurations.triangles[0], pin_uv, bad,
                                   max(1, int(INSERT_SHARE * np.count_nonzero(bad))),
                                   min_points=2)
            if len(new):
                n_int = n_int + len(new)
                knots = np.vstack([knots[: state.n_interior], new, knots[state.n_interior:]])
                if cost is None and options.feature_sensitive and options.mode == "tcb":
                    cost = _feature_cost(fit_uv, fit_q, n_int, options.seed)
                while True:  # (fewer knots, worst first, until the space fits the budget)
                    try:
                        space = make_space(knots, options.degree, options.mode, cost, n_int)
                        active = np.flatnonzero(space.meets(domain))
                    except TCBError:  # (a knot on another: the pins' targets only)
                        active = None
                        break
                    if len(active) <= options.max_control_points or len(new) == 1:
                        break
                    new = new[: len(new) // 2]
                    n_int = state.n_interior + len(new)
                    knots = np.vstack([state.knots[: state.n_interior], new,
                                       state.knots[state.n_interior:]])
                if active is None or len(active) > options.max_control_points:
                    space, knots, n_int = state.space, state.knots, state.n_interior
                    active = state.active
        try:
            fit = fit_control_points(space, fit_uv, fit_q, smoothness=smoothness,
                                     pins=(pin_uv, targets, PIN_WEIGHT))
        except (BorderError, SingularSystemError):
            if state is best:
                raise
            break
        if not np.isfinite(fit.control_points).all():  # (never a NaN surface)
            if state is best:
                raise SingularSystemError("joining the surface to its neighbours gave "
                                          "non-finite control points; fit without join=")
            break
        state = dataclasses.replace(state, knots=knots, n_interior=n_int, space=space,
                                    fit=fit, active=active)
        gaps = seam_gaps(seam_list, own_uv, surface_of(state), inward)
        if fits and gaps.max() >= min(g.max() for _, g in fits):
            worse += 1
        else:
            worse = 0
        fits.append((state, gaps))
        if worse >= 2:
            break
    m = len(fit_uv) if n_measured is None else n_measured

    def error(fit):  # the criterion's error at the measured points (normalized units)
        e = fit.errors[:m]
        return float(e.max(initial=0.0) if options.criterion == "max"
                     else np.sqrt(np.mean(e ** 2)))

    allowed = max(options.tolerance * (2.0 if options.relative else 1.0 / norm.scale),
                  error(best.fit))
    limit = None if folds is None else max(folds(best), fold_allowance)
    seam_limit = turned(best)
    fits = [(*f, turns) for f in fits for turns in (turned(f[0]),)
            if turns <= seam_limit and (limit is None or folds(f[0]) <= limit)]
    fits.sort(key=lambda f: (error(f[0].fit) > allowed, f[1].max()))
    state, after, turns = fits[0] if fits else (best, before, seam_limit)
    return state, {
        "surfaces": len(seam_list),
        "shared_vertices": int(sum(len(m.vertices) for m in seam_list)),
        "shared_edges": int(sum(len(m.own) for m in seam_list)),
        "knots_added": int(state.n_interior - best.n_interior),
        "gap_max": float(after.max()), "gap_rms": float(np.sqrt(np.mean(after ** 2))),
        "gap_max_unjoined": float(before.max()),
        "gap_rms_unjoined": float(np.sqrt(np.mean(before ** 2))),
        "tolerance_missed": bool(error(state.fit) > allowed),
        "kept_unjoined": not fits,
        "control_points": int(state.n_control),
        "control_points_unjoined": int(best.n_control),
        "seam_samples": int(len(samples[0])), "seam_folds": int(turns),
        # how far the neighbours' surfaces are from the shared vertices (their errors there)
        "neighbour_error_max": float(max(
            m.neighbour_error if isinstance(m, CloudSeam) else np.nanmax(
                np.asarray(m.surface.errors, dtype=np.float64)[m.vertices[:, 1]], initial=0.0)
            for m in seam_list)),
        # (point clouds: the pins along the border shared, and its length in data units)
        "pins": int(len(join_pins(seam_list, own_uv, surface_of(best), inward)[0])),
        "shared_length": float(sum(m.length for m in seam_list
                                   if isinstance(m, CloudSeam))),
    }


def join_warning(report: dict) -> str | None:
    """What a fit's report says of a join that did not go as asked (``report["join"]``), in
    words, or None: the surface kept unjoined (every joined fit folded over the mesh), or the
    joined surface's error at the data above the tolerance (the neighbour's surface is that
    far from the shared border: fitted to a looser tolerance)."""
    j = report.get("join") or {}
    if j.get("kept_unjoined"):
        return ("the surface could not be joined to its neighbours without folding over its "
                "mesh at the shared border: it is fitted on its own (the borders "
                f"{j['gap_max_unjoined_rel']:.2g} of the diagonal apart)")
    if j.get("tolerance_missed"):
        # (not "fit them to the same tolerance": one that was had run out of control points;
        # user test)
        return ("joined to its neighbours, the surface misses the tolerance at its data (RMS "
                f"{report['rms_rel']:.2g}, max {report['max_rel']:.2g} of the diagonal): the "
                "neighbours' surfaces are up to "
                f"{j['neighbour_error_max'] / report['diagonal']:.2g} of it from their data "
                "along the shared border; refine them to this tolerance first (a larger budget "
                "if they ran out of control points), or fit this one without joining")
    return None
