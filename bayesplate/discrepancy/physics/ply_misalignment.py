"""Every ply turned by the same small angle (a laminate cut or laid up off-axis)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics
from .reduced_model import interpolated_ritz, local_ritz

__all__ = ["PlyMisalignment"]


class PlyMisalignment(Physics):
    """The layup ``theta_L + delta`` for every ply ``L`` (eqs. 24-25 with rotated plies).

    For a plate whose layup is symmetric under ``y -> -y`` (0 and 90 degree plies), ``delta``
    and ``-delta`` give the same frequencies: only ``|delta|`` is identified.
    """

    name = "ply_misalignment"
    description = "every ply turned by the same angle delta"

    def parameters(self, model, b):
        """``delta_deg``: prior 0 +- 5 degrees, within +-45 degrees."""
        return (Parameter("delta_deg", 0.0, 5.0, -45.0, 45.0),)

    def apply(self, model, theta):
        """The plate with turned plies; ``theta = (delta_deg,)``."""
        (delta,) = theta
        terms = model.element_stiffness_terms(angle_offset_deg=delta)
        return model.modified(stiffness_terms=model.assembler.uniform_data(terms))

    def ritz(self, model, b, basis, near=None):
        """Exact: a turned ply's stiffness holds the harmonics 0, 2 and 4 of the angle.

        ``near`` given: a quadratic exact there (:func:`~.reduced_model.local_ritz`, nodes a tenth
        of the prior deviation apart), three plates instead of five.
        """
        if near is not None:
            step = 0.1 * self.parameters(model, b)[0].sd
            return local_ritz(lambda t: self.apply(model, t), basis, near, step)

        def features(theta):
            d = np.radians(np.atleast_1d(theta)[0])
            return np.array([1.0, np.cos(2 * d), np.sin(2 * d), np.cos(4 * d), np.sin(4 * d)])

        nodes = np.array([[-40.0], [-20.0], [0.0], [20.0], [40.0]])
        return interpolated_ritz(lambda t: self.apply(model, t), basis, nodes, features)

    def image(self, model, theta, symmetry):
        """``-delta`` under a reflection, ``delta`` under the half-turn.

        A reflection turns every ply's angle, and so its error, into its negative.
        """
        theta = np.asarray(theta, dtype=float)
        return theta if symmetry == "xy" else -theta
