"""Baselines the TCB fit is measured against (issue 5); kept out of the main path.

numpy and scipy only; never imports bpy. ::

    from core.baselines import fit_tensor
    surf = fit_tensor(uv, points, max_control_points=400, tolerance=1e-3)
    xyz = surf(uv_new)
"""

from .tensor import TensorSurface, averaged_knots, fit_tensor

__all__ = ["fit_tensor", "TensorSurface", "averaged_knots"]
