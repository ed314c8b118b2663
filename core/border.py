"""Auxiliary border knots and the partition-of-unity check (method.md section 3).

The TCB basis sums to one only where every link that a configuration needs has closed. Rings of
jittered auxiliary knots outside the data's parameter domain keep the data strictly inside that
region: ring ``j`` lies on the border of the domain's bounding box grown by ``j * h``, with knots
about ``h`` apart along it. Method.md section 3 measured that two rings are needed for
quadratics and three for cubics, which :func:`default_ring_count` returns; the fit asserts the
sum at every data parameter anyway and adds a ring when it fails.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import BorderError

__all__ = ["border_rings", "default_ring_count", "PartitionReport", "check_partition_of_unity"]


def default_ring_count(degree: int) -> int:
    """Rings of auxiliary knots for a degree: two up to quadratics, three for cubics (method.md
    section 3)."""
    return 2 if degree <= 2 else 3


def border_rings(
    lower,
    upper,
    spacing: float,
    rings: int = 3,
    jitter: float = 0.2,
    seed: int = 0,
) -> np.ndarray:
    """Jittered knots on the borders of the box ``[lower, upper]`` grown by ``h, 2h, ...``.

    Parameters
    ----------
    lower, upper : (2,) float
        Corners of the domain's bounding box.
    spacing : float
        ``h``, about the interior knot spacing; also the spacing along each ring.
    rings : int
        Number of rings.
    jitter : float
        Random displacement (fraction of ``h``, both along and across the ring) that keeps
        the ring knots in general position (no three collinear).
    seed : int
        Seed of the jitter: the same input gives the same knots.

    Returns
    -------
    (r, 2) float64 knots.
    """
    lower = np.asarray(lower, dtype=np.float64)
    upper = np.asarray(upper, dtype=np.float64)
    h = float(spacing)
    if not (h > 0 and np.isfinite(h)):
        raise ValueError("the ring spacing must be a positive number")
    rng = np.random.default_rng(seed)
    out = []
    for j in range(1, rings + 1):
        lo, hi = lower - j * h, upper + j * h
        w, ht = hi - lo
        perimeter = 2 * (w + ht)
        count = max(int(np.ceil(perimeter / h)), 8)
        s = (np.arange(count) + 0.5 * (j % 2)) / count * perimeter
        s = s + rng.uniform(-jitter, jitter, count) * h
        s = np.mod(s, perimeter)
        # walk the rectangle counter-clockwise from the lower-left corner
        pts = np.empty((count, 2))
        e1, e2, e3 = w, w + ht, 2 * w + ht
        m = s < e1
        pts[m] = np.c_[lo[0] + s[m], np.full(m.sum(), lo[1])]
        m = (s >= e1) & (s < e2)
        pts[m] = np.c_[np.full(m.sum(), hi[0]), lo[1] + s[m] - e1]
        m = (s >= e2) & (s < e3)
        pts[m] = np.c_[hi[0] - (s[m] - e2), np.full(m.sum(), hi[1])]
        m = s >= e3
        pts[m] = np.c_[np.full(m.sum(), lo[0]), hi[1] - (s[m] - e3)]
        # move across the ring too, so that knots on one side are not collinear
        center = 0.5 * (lo + hi)
        outward = np.sign(pts - center) * (np.abs(pts - center) >= 0.5 * (hi - lo) - 1e-12 * h)
        pts += outward * rng.uniform(-jitter, jitter, (count, 1)) * h
        out.append(pts)
    return np.concatenate(out)


@dataclass(frozen=True)
class PartitionReport:
    """Where ``sum_I B_I(x) = 1`` holds: max deviation, mask of failing points, tolerance."""

    max_deviation: float
    bad: np.ndarray
    tolerance: float

    @property
    def ok(self) -> bool:
        return not self.bad.any()


def check_partition_of_unity(space, uv: np.ndarray, tol: float = 1e-9, raise_error: bool = False):
    """Check ``|sum_I B_I(x_j) - 1| < tol`` at every parameter ``x_j`` (method.md section 3).

    Returns a :class:`PartitionReport`; with ``raise_error`` a failure raises
    :class:`~core.errors.BorderError` saying how many points fail and by how much.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    total = np.asarray(space.evaluate(uv).sum(axis=1)).ravel()
    dev = np.abs(total - 1.0)
    bad = ~(dev < tol)
    report = PartitionReport(float(dev.max()) if len(dev) else 0.0, bad, tol)
    if raise_error and not report.ok:
        raise BorderError(
            f"the spline basis does not sum to one at {int(bad.sum())} of {len(uv)} parameters "
            f"(worst deviation {report.max_deviation:.3g}); more auxiliary border rings are needed"
        )
    return report
