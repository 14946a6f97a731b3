"""A plate thicker at one end than at the other, its mean thickness kept."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics
from .reduced_model import interpolated_ritz, local_ritz

__all__ = ["ThicknessTaper"]


class ThicknessTaper(Physics):
    """Thickness ``h (1 + e (2 s - 1))`` with ``s`` in [0, 1] along ``direction``.

    The thickness goes from ``h (1 - e)`` to ``h (1 + e)``; every ply scales with it. Each
    element takes the thickness at its centre (piecewise constant), so the effect is
    resolved to the mesh.

    Parameters
    ----------
    direction : {"x", "y"}
    """

    name = "thickness_taper"
    description = "linear thickness taper along x or y, mean thickness kept"

    def __init__(self, direction="x"):
        if direction not in ("x", "y"):
            raise ValueError(f"direction = {direction!r}: must be 'x' or 'y'")
        self.direction = direction

    def settings(self):
        """``{"direction": "x" or "y"}``."""
        return {"direction": self.direction}

    def parameters(self, model, b):
        """``ratio`` e: prior 0 +- 0.05, within +-0.5."""
        return (Parameter("ratio", 0.0, 0.05, -0.5, 0.5),)

    def apply(self, model, theta):
        """The tapered plate; ``theta = (ratio,)``."""
        (ratio,) = theta
        axis, length = (0, model.mesh.a) if self.direction == "x" else (1, model.mesh.b)
        s = model.mesh.centroids[:, axis] / length
        scale = 1.0 + ratio * (2.0 * s - 1.0)
        levels, element_level = np.unique(np.round(scale, 12), return_inverse=True)
        per_level = np.array([model.element_stiffness_terms(thickness_scale=v) for v in levels])
        terms = [model.assembler.data(per_level[element_level, j]) for j in range(6)]
        masses = np.array([model.element_mass(thickness_scale=v) for v in levels])
        mass = model.assembler.data(masses[element_level])
        return model.modified(stiffness_terms=terms, mass_data=mass)

    def ritz(self, model, b, basis, near=None):
        """Exact: every matrix is a polynomial of degree 7 in ``ratio`` (Chebyshev nodes).

        The ply integrals of the third-order theory scale as powers of the thickness up to
        the seventh, with the shear-correction coefficient as its inverse square. ``near``
        given: a quadratic exact there (:func:`~.reduced_model.local_ritz`, nodes a tenth of the
        prior deviation apart), three tapered plates instead of eight.
        """
        if near is not None:
            step = 0.1 * self.parameters(model, b)[0].sd
            return local_ritz(lambda t: self.apply(model, t), basis, near, step)
        half = 0.5
        nodes = half * np.cos(np.pi * (np.arange(8) + 0.5) / 8)

        def features(theta):
            return np.polynomial.chebyshev.chebvander(np.atleast_1d(theta)[0] / half, 7)[0]

        return interpolated_ritz(lambda t: self.apply(model, t), basis, nodes[:, None], features)

    def image(self, model, theta, symmetry):
        """``-e`` when the symmetry turns the plate end for end along the taper, else ``e``."""
        theta = np.asarray(theta, dtype=float)
        return -theta if self.direction in symmetry else theta
