"""A soft support under the whole plate (Winkler foundation)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics
from .reduced_model import interpolated_ritz

__all__ = ["ElasticFoundation"]


class ElasticFoundation(Physics):
    """``K + k int N_w^T N_w dA``: a distributed spring of modulus ``k`` (N/m^3) under ``w``.

    To first order it adds ``k / I0`` to every bending eigenvalue; the three out-of-plane
    rigid-body modes become low bouncing modes, which the eigen solver recognises by their
    shape and drops like the rigid-body modes of the free plate.
    """

    name = "elastic_foundation"
    description = "a soft elastic support under the whole plate"

    def image(self, model, theta, symmetry):
        """``k`` itself: a foundation under the whole plate is turned with it."""
        return np.asarray(theta, dtype=float)

    def parameters(self, model, b):
        """``k_N_m3`` >= 0.

        Prior deviation: the ``k`` that lifts every bending eigenvalue by 10 % of the
        lowest one (its Rayleigh bound,
        :meth:`~bayesplate.plate.model.PlateModel.lowest_eigenvalue_bound`).
        """
        lowest = model.lowest_eigenvalue_bound(b)
        scale = 0.1 * model.density * model.thickness * lowest
        return (Parameter("k_N_m3", 0.0, scale, 0.0, np.inf),)

    def apply(self, model, theta):
        """The plate on the foundation; ``theta = (k_N_m3,)``."""
        (k,) = theta
        w_block = model.element.mass_kernel[6, 6]  # int N_w^T N_w dA of one element
        extra = k * model.assembler.uniform_data(w_block)
        return model.modified(extra_stiffness_data=extra)

    def ritz(self, model, b, basis, near=None):
        """Exact: the stiffness is affine in ``k``."""
        (param,) = self.parameters(model, b)

        def features(theta):
            return np.array([1.0, np.atleast_1d(theta)[0] / param.sd])

        nodes = np.array([[0.0], [param.sd]])
        return interpolated_ritz(lambda t: self.apply(model, t), basis, nodes, features)
