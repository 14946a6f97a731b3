"""A delamination: a rectangular region that lost transverse shear stiffness (located)."""

from __future__ import annotations

import numpy as np

from .base import Parameter
from .local_stiffness_loss import LocalStiffnessLoss

__all__ = ["Delamination"]


class Delamination(LocalStiffnessLoss):
    """Inside a rectangle, the transverse shear coefficients ``C44, C55`` times ``factor``.

    The in-plane and bending coefficients ``C11, C22, C12, C66`` and the mass are left as
    they are. A local loss of shear transfer between plies (a disbond, an impact's
    delamination): the plies inside still stretch and bend as before, but slide over one
    another more easily, so the region keeps ``factor`` of G13 and G23. The construction is
    :class:`~.local_stiffness_loss.LocalStiffnessLoss`'s (area fractions for elements cut by
    the rectangle's edge, the same Ritz form, map and scan), with another :attr:`kept`.

    The effect is that of the shear flexibility of the plate: large on a thick plate, small
    on a thin one (to first order as ``(h / wavelength)^2``, times E1 / G13), where the
    bending modes hardly strain the plate in transverse shear.

    Prior on ``factor``: mean 0.3, deviation 0.3, bounds 0.01 to 1. A delamination is a
    separation, not a slight softening: most of the shear transfer across the separated
    interface is lost, so the prior sits well below 1 (a factor near 1 is a plate without
    one, which the nominal model already is). The lower bound keeps the region's shear
    stiffness positive.

    Attributes
    ----------
    kept : numpy.ndarray, shape (6,)
        ``(1, 1, 1, 1, 0, 0)``: only C44 and C55 are multiplied.
    scan_factors : tuple of float
        Fractions of ``C44, C55`` kept that the scan tries: mostly lost to half.
    """

    name = "delamination"
    description = "a rectangular region keeping a fraction of G13, G23 (shear between plies)"
    kept = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0])
    scan_factors = (0.05, 0.2, 0.5)

    def parameters(self, model, b):
        """Centre ``x_mm``, ``y_mm``; sides ``dx_mm``, ``dy_mm``; ``factor`` of C44, C55 kept."""
        *place, _ = super().parameters(model, b)
        return (*place, Parameter("factor", 0.3, 0.3, 0.01, 1.0))
