"""Spatial index: which axis-aligned boxes contain which points (method.md section 1, Support).

A uniform bucket grid over the points. Each box is registered in the cells it overlaps (CSR list
cell -> boxes); each point then looks at the boxes of its own cell only, and the exact
inclusive-bbox test removes the rest. Work and memory are proportional to the number of
candidate pairs, never ``points x boxes``. Results come in chunks so memory stays bounded.

A box may also carry a *diagonal band*: the range of ``u + v`` and of ``u - v`` over the set
it stands for (the knots of a simplex spline, whose support is their convex hull). The box and
its band bound an octagon around that hull; a box is then registered only in the cells that
meet its octagon, and a point must lie in both (not in method.md).
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

__all__ = ["BoxIndex", "support_bands"]


def support_bands(sets: np.ndarray) -> np.ndarray:
    """The diagonal bands ``[smin, smax, dmin, dmax]`` (C, 4) of point sets (C, n, 2), for
    :class:`BoxIndex`: the ranges of ``u + v`` and ``u - v`` over each set, widened by 1e-9
    of the set's size plus its distance from the origin. A point of the closed convex hull
    of a set lies in its band (the rounded sums keep the order of the exact ones); so does
    one that the simplex side tests (``core.simplex``), with their rounding of about 1e-16
    of that size, can take for a point of the hull."""
    V = np.asarray(sets, dtype=np.float64)
    s, d = V[:, :, 0] + V[:, :, 1], V[:, :, 0] - V[:, :, 1]
    size = np.maximum(np.ptp(s, axis=1), np.ptp(d, axis=1)) + np.abs(V).max(axis=(1, 2))
    pad = 1e-9 * size
    return np.stack([s.min(axis=1) - pad, s.max(axis=1) + pad,
                     d.min(axis=1) - pad, d.max(axis=1) + pad], axis=1)


class BoxIndex:
    """Bucket-grid index of boxes (C, 4) ``[umin, vmin, umax, vmax]`` for point queries."""

    def __init__(self, boxes: np.ndarray, cell: float | None = None,
                 diagonals: np.ndarray | None = None, cell_fraction: float = 0.5):
        """``boxes`` (C, 4); ``cell`` the grid step (default ``cell_fraction`` times the median
        box size, see below); ``diagonals`` (C, 4) ``[smin, smax, dmin, dmax]``, the bands of
        ``s = u + v`` and ``d = u - v`` (module docstring), or None. A band should hold its
        set with a margin for the rounding of ``u + v`` and ``u - v`` at points that
        callers count as inside (:meth:`pairs` compares the rounded sums)."""
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        self.boxes = boxes
        # the four bounds as contiguous columns: 1-D gathers and contiguous compares in pairs()
        self._bounds = [np.ascontiguousarray(boxes[:, j]) for j in range(4)]
        self._bands = (None if diagonals is None else
                       [np.ascontiguousarray(np.asarray(diagonals, dtype=np.float64)
                                             .reshape(-1, 4)[:, j]) for j in range(4)])
        if self._bands is not None and len(self._bands[0]) != len(boxes):
            raise ValueError(f"{len(self._bands[0])} diagonal bands for {len(boxes)} boxes")
        if len(boxes) == 0:
            self.origin, self.cell, self.shape = np.zeros(2), 1.0, (1, 1)
            self.ptr = np.zeros(2, dtype=np.int64)
            self.ids = np.zeros(0, dtype=np.int64)
            return
        ext = np.maximum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])
        lo = boxes[:, :2].min(axis=0)
        hi = boxes[:, 2:].max(axis=0)
        span = np.maximum(hi - lo, 1e-300)
        if cell is None:
            # a fraction (default half) of the median box size
            cell = (cell_fraction * float(np.median(ext)) if np.median(ext) > 0
                    else float(span.max()))
        # cap the grid size (about 16 cells per box in total)
        cell = max(cell, float(np.sqrt(span[0] * span[1] / (16.0 * len(boxes) + 1))))
        cell = max(cell, float(span.max()) / 4096)
        self.origin, self.cell = lo, cell
        nx, ny = (np.floor(span / cell).astype(np.int64) + 1).tolist()
        self.shape = (nx, ny)
        i0, j0 = self._cell_coords(boxes[:, :2])
        i1, j1 = self._cell_coords(boxes[:, 2:])
        wi = i1 - i0 + 1
        C = len(boxes)
        # each box's rows of cells i0..i1, and in each row the columns from lo_j to hi_j
        box = np.repeat(np.arange(C), wi)
        ci = i0[box] + (np.arange(len(box)) - np.repeat(np.cumsum(wi) - wi, wi))
        lo_j, hi_j = j0[box], j1[box]
        if self._bands is not None:
            # only the cells that meet the octagon. Cell (i, j) spans u + v in origin_s +
            # cell [i + j, i + j + 2] and u - v in origin_d + cell [i - j - 1, i - j + 1]:
            # integer bounds on i + j and i - j per box (1e-6 of a cell wider, for the
            # rounding of the cells' corners and of the points' cells), so in row i the
            # columns a_lo - i .. a_hi - i and i - b_hi .. i - b_lo
            smin, smax, dmin, dmax = (np.take(b, box) for b in self._bands)
            os_, od, tol = lo[0] + lo[1], lo[0] - lo[1], 1e-6
            big = float(nx + ny + 4)  # (clipped before the cast: a grid of point boxes has a
            # step of 1e-300, and the bounds overflowed; review)

            def whole(x):
                return np.clip(x, -big, big).astype(np.int64)

            lo_j = np.maximum(lo_j, np.maximum(
                whole(np.ceil((smin - os_) / cell - 2 - tol)) - ci,
                ci - whole(np.floor((dmax - od) / cell + 1 + tol))))
            hi_j = np.minimum(hi_j, np.minimum(
                whole(np.floor((smax - os_) / cell + tol)) - ci,
                ci - whole(np.ceil((dmin - od) / cell - 1 - tol))))
        cnt = np.maximum(hi_j - lo_j + 1, 0)
        # sorted by cell, and by box within a cell (the order a point meets its boxes in):
        # one sort of unique keys (cell * C + box), faster than a stable argsort of the cells
        key = np.repeat((ci * ny + lo_j) * C + box, cnt) + C * (
            np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        key.sort()
        self.ids = key % C
        self.ptr = np.concatenate([[0], np.cumsum(np.bincount(key // C, minlength=nx * ny))])

    def _cell_coords(self, p: np.ndarray):
        """Cell of each point, clamped to the grid (NaN coordinates give cell 0: callers
        leave non-finite points out); clamped before the cast, which warns on NaN and inf."""
        g = np.floor((p - self.origin) / self.cell)
        g = np.clip(np.nan_to_num(g), 0, np.subtract(self.shape, 1)).astype(np.int64)
        return g[:, 0], g[:, 1]

    def pairs(self, points: np.ndarray, max_pairs: int = 1 << 17) -> Iterator[tuple]:
        """Yield ``(point_index, box_index)`` arrays, chunked, for all points inside boxes.

        ``points`` (m, 2). A point belongs to a box when ``umin <= u <= umax`` and likewise ``v``
        (and, with diagonal bands, ``smin <= u + v <= smax`` and ``dmin <= u - v <= dmax``).
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(points) == 0 or len(self.boxes) == 0:
            return
        ci, cj = self._cell_coords(points)
        g = np.floor((points - self.origin) / self.cell)
        outside = (g[:, 0] < 0) | (g[:, 1] < 0) | (g[:, 0] >= self.shape[0]) | (
            g[:, 1] >= self.shape[1]
        )
        outside |= ~np.isfinite(points).all(axis=1)
        cid = ci * self.shape[1] + cj
        start = self.ptr[cid]
        count = np.where(outside, 0, self.ptr[cid + 1] - start)
        csum = np.cumsum(count)
        # split the points into chunks of about max_pairs candidates each
        bounds = np.searchsorted(csum, np.arange(max_pairs, int(csum[-1]) + max_pairs, max_pairs))
        bounds = np.unique(np.concatenate([[0], np.minimum(bounds + 1, len(points)), [len(points)]]))
        umin, vmin, umax, vmax = self._bounds
        pu_all, pv_all = points[:, 0].copy(), points[:, 1].copy()
        # np.take and contiguous columns throughout: fancy indexing and strided (n, 4) columns
        # made this 1.2-1.5x slower
        for s, e in zip(bounds[:-1], bounds[1:]):
            cnt = count[s:e]
            tot = int(cnt.sum())
            if tot == 0:
                continue
            pt = np.repeat(np.arange(s, e), cnt)
            local = np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            bx = np.take(self.ids, np.take(start, pt) + local)
            pu = np.repeat(pu_all[s:e], cnt)  # = points[pt, 0]
            pv = np.repeat(pv_all[s:e], cnt)
            inside = np.take(umin, bx) <= pu
            inside &= pu <= np.take(umax, bx)
            inside &= np.take(vmin, bx) <= pv
            inside &= pv <= np.take(vmax, bx)
            if self._bands is not None:
                smin, smax, dmin, dmax = self._bands
                ps, pd = pu + pv, pu - pv
                inside &= np.take(smin, bx) <= ps
                inside &= ps <= np.take(smax, bx)
                inside &= np.take(dmin, bx) <= pd
                inside &= pd <= np.take(dmax, bx)
            sel = np.flatnonzero(inside)
            yield np.take(pt, sel), np.take(bx, sel)
