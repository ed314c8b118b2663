"""TCB Surface engine: surface reconstruction with triangle configuration B-splines.

numpy and scipy only; never imports bpy. See ``method.md`` (shipped alongside the project) for
the mathematics. Public API::

    from core import build_space, fit_surface, TCBSurface
    space = build_space(knots, degree=2, mode="tcb")
    surf = fit_surface(points, faces=None, degree=2, mode="tcb", tolerance=1e-3)
"""

from .border import border_rings, check_partition_of_unity, default_ring_count
from .configurations import (
    RandomTriangulator,
    constrained_delaunay,
    ear_clipping,
    link_triangulation_procedure,
)
from .errors import (
    BorderError,
    FileFormatError,
    HolesError,
    InvalidInputError,
    InvalidKnotsError,
    OutlierError,
    ParameterizationError,
    CancelledError,
    SingularSystemError,
    TCBError,
    TopologyError,
)
from .refine import RefineOptions
from .simplex import SimplexBatch, simplex_spline
from .spline_space import SplineSpace, build_space
from .surface import TCBSurface, fit_surface

__version__ = "0.1.0"

__all__ = [
    "fit_surface",
    "TCBSurface",
    "RefineOptions",
    "build_space",
    "SplineSpace",
    "simplex_spline",
    "SimplexBatch",
    "link_triangulation_procedure",
    "constrained_delaunay",
    "ear_clipping",
    "RandomTriangulator",
    "border_rings",
    "default_ring_count",
    "check_partition_of_unity",
    "TCBError",
    "InvalidInputError",
    "InvalidKnotsError",
    "TopologyError",
    "ParameterizationError",
    "OutlierError",
    "HolesError",
    "FileFormatError",
    "BorderError",
    "SingularSystemError",
    "CancelledError",
]
