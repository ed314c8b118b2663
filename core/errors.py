"""Exceptions raised by the TCB Surface engine.

Every error a user can cause derives from :class:`TCBError`; those caused by bad input also
derive from :class:`ValueError`, so ``except ValueError`` keeps working for library users.
Messages say what is wrong *and* what to do about it: the Blender add-on shows them verbatim.
"""

from __future__ import annotations


class TCBError(Exception):
    """Base class of all errors raised on purpose by ``core``."""


class InvalidInputError(TCBError, ValueError):
    """Input data that cannot be used (NaN/inf, too few points, wrong shape, ...)."""


class InvalidKnotsError(InvalidInputError):
    """A knot set from which no spline space can be built (too few, collinear, non-finite)."""


class TopologyError(InvalidInputError):
    """A mesh whose topology is not a disk (closed, several boundary loops, non-manifold)."""


class HolesError(TopologyError):
    """A mesh with holes (boundary loops besides its outer one), given without ``fill_holes``.
    ``loops``: its number of boundary loops (callers with their own spelling of the option
    word the message again with :func:`core.parameterize.holes_error`)."""

    def __init__(self, message: str, loops: int = 2):
        super().__init__(message)
        self.loops = loops


class ParameterizationError(InvalidInputError):
    """The data cannot be mapped to a plane without folds (e.g. a strongly curved cloud)."""


class OutlierError(InvalidInputError):
    """A cloud with points far from all others, or a mesh with spike vertices. ``indices`` are
    their rows in the points given (callers that merged or filtered the input re-number them
    with :func:`core.parameterize.outlier_error`, or for a mesh's spikes, whose ``heights``
    above their neighbours' plane are given, :func:`core.parameterize.spike_error`)."""

    def __init__(self, message: str, indices=(), heights=None):
        super().__init__(message)
        self.indices = indices
        self.heights = heights


class FileFormatError(InvalidInputError):
    """A file that cannot be read: unknown extension, malformed content, truncated data."""


class BorderError(TCBError):
    """The basis does not sum to one at some data parameters (the border rings are too thin)."""


class SingularSystemError(TCBError):
    """The least-squares system is singular or too ill-conditioned to give a trustworthy fit."""


class CancelledError(TCBError):
    """A callback of ``TCBSurface.closest_points`` (``closest_parameters``, ``distances``)
    returned True: the computation stopped and has no result.

    A fit's callback that returns True ends the fit early without an exception:
    ``fit_surface`` and ``TCBSurface.refine`` return the best surface so far, with
    ``report["stop_reason"] == "cancelled"``.
    """
