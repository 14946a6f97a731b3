"""A rectangular region that lost stiffness (impact damage, porosity, a dry patch)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_positions

__all__ = ["LocalStiffnessLoss", "area_fractions"]

#: The matrix-dominated coefficients that the factor multiplies: C22, C12, C66, C44, C55.
_KEPT = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def area_fractions(mesh, centre, size):
    """Fraction of each element's area inside an axis-aligned rectangle.

    Parameters
    ----------
    mesh : RectangularMesh
    centre, size : array_like, shape (2,)
        Rectangle centre and sides in m.

    Returns
    -------
    numpy.ndarray, shape (n_elements,)
    """
    lo = np.asarray(centre) - np.asarray(size) / 2
    hi = np.asarray(centre) + np.asarray(size) / 2
    half = np.array([mesh.dx, mesh.dy]) / 2
    overlap = np.clip(
        np.minimum(mesh.centroids + half, hi) - np.maximum(mesh.centroids - half, lo), 0.0, None
    )
    return overlap[:, 0] * overlap[:, 1] / (mesh.dx * mesh.dy)


class LocalStiffnessLoss(Physics):
    """Inside a rectangle, ``C22, C12, C66, C44, C55`` are multiplied by ``factor``.

    That keeps ``factor`` of E2, G12, G13 and G23 with nu12 unchanged; E1 rises by less than
    ``nu12 nu21 (1 - factor)`` (a fraction of a percent for carbon/epoxy). Elements cut by
    the rectangle's edge take the factor in proportion to the area inside, so the
    frequencies vary smoothly with position and size. Kept linear in the lamina
    coefficients: ``K_j -> K_j + (d_j - 1) sum_e frac_e K_j^e``.
    """

    name = "local_stiffness_loss"
    description = "a rectangular region keeping a fraction of E2, G12, G13, G23"

    def parameters(self, model, b):
        """Centre ``x_mm``, ``y_mm``; sides ``dx_mm``, ``dy_mm``; ``factor`` kept in (0, 1]."""
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        return (
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), 0.0, a_mm),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), 0.0, b_mm),
            Parameter("dx_mm", a_mm / 5, a_mm / 10, 1e3 * model.mesh.dx, a_mm),
            Parameter("dy_mm", b_mm / 5, b_mm / 10, 1e3 * model.mesh.dy, b_mm),
            Parameter("factor", 0.7, 0.3, 0.02, 1.0),
        )

    def apply(self, model, theta):
        """The damaged plate; ``theta = (x_mm, y_mm, dx_mm, dy_mm, factor)``."""
        x, y, dx, dy, factor = theta
        frac = area_fractions(model.mesh, 1e-3 * np.array([x, y]), 1e-3 * np.array([dx, dy]))
        inside = np.flatnonzero(frac > 0)
        if inside.size == 0:
            return model
        multiplier = _KEPT + (1.0 - _KEPT) * factor
        terms = model.element_stiffness_terms()
        region = [
            model.assembler.element_data(inside, frac[inside, None, None] * Ke[None])
            for Ke in terms
        ]
        new = model.stiffness_terms + (multiplier - 1.0)[:, None] * np.array(region)
        return model.modified(stiffness_terms=new)

    def mirror_images(self, model, theta):
        """The same region at the mirror positions of its centre."""
        return [np.array([x, y, *theta[2:]]) for x, y in mirror_positions(model, *theta[:2])]
