"""A glued sensor or lump: a point mass on the plate's mid-plane."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_positions

__all__ = ["PointMass"]


class PointMass(Physics):
    """``M + m N_w(x, y)^T N_w(x, y)``: translational inertia of a mass ``m`` at ``(x, y)``.

    The mass moves with the mid-plane deflection ``w``; its rotary and in-plane inertia are
    neglected (a sensor much smaller than the wavelengths).
    """

    name = "point_mass"
    description = "a point mass (glued sensor) at (x, y)"

    def parameters(self, model, b):
        """``mass_g``, ``x_mm``, ``y_mm``.

        Mass prior 5 +- 10 % of the plate's mass (>= 0); position with the mean and
        deviation of a uniform position over the plate.
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        plate_mass_g = 1e3 * model.density * model.thickness * model.mesh.a * model.mesh.b
        return (
            Parameter("mass_g", 0.05 * plate_mass_g, 0.1 * plate_mass_g, 0.0, plate_mass_g),
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), 0.0, a_mm),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), 0.0, b_mm),
        )

    def apply(self, model, theta):
        """The plate with the mass added; ``theta = (mass_g, x_mm, y_mm)``."""
        mass_g, x_mm, y_mm = theta
        point = np.array([[1e-3 * x_mm, 1e-3 * y_mm]])
        element, local = model.mesh.locate(point)
        n_w = model.element.fields(local)["w"][0]
        added = model.assembler.element_data(element, 1e-3 * mass_g * np.outer(n_w, n_w)[None])
        return model.modified(mass_data=model.mass_data + added)

    def mirror_images(self, model, theta):
        """The same mass at the mirror positions of ``(x, y)``."""
        return [np.array([theta[0], x, y]) for x, y in mirror_positions(model, *theta[1:])]
