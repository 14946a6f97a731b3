"""The result of a modal solve: eigenvalues, mode shapes and their sensitivities.

Made by the full model (:meth:`bayesplate.plate.model.PlateModel.solve`) and, in the same form, by
the reduced and candidate models; kept apart from them so that a result needs no model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import laminate
from ..quantities import hz_from_eigenvalue

__all__ = ["ModalResult"]


@dataclass(frozen=True)
class ModalResult:
    """Elastic modes of the plate at one set of stiffness coefficients.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa.
    eigenvalues : numpy.ndarray, shape (n,)
        ``lambda = (2 pi f)^2`` in rad^2/s^2 (eq. 27).
    vectors : numpy.ndarray, shape (n_dofs, n)
        Mass-normalised mode shapes on all unknowns (constrained ones are zero).
    sensitivities : numpy.ndarray, shape (n, 6)
        ``d lambda_i / d b_j`` (eq. 28), in rad^2/s^2 per Pa.
    rigid_eigenvalues : numpy.ndarray
        Near-zero eigenvalues detected and dropped (six for a free plate).
    """

    b: np.ndarray
    eigenvalues: np.ndarray
    vectors: np.ndarray
    sensitivities: np.ndarray
    rigid_eigenvalues: np.ndarray = field(repr=False)

    @property
    def frequency_Hz(self):
        """Natural frequencies in Hz, shape (n,)."""
        return hz_from_eigenvalue(self.eigenvalues)

    @property
    def n_rigid(self):
        """Number of rigid-body modes detected and dropped."""
        return len(self.rigid_eigenvalues)

    def normalised_sensitivities(self):
        """``s_ij = (d lambda_i / d b_j) b_j / lambda_i`` (eq. 29), shape (n, 6)."""
        return self.sensitivities * self.b[None, :] / self.eigenvalues[:, None]

    def engineering_sensitivities(self):
        """``d lambda_i / d e_j`` for ``e = (E1, E2, nu12, G12, G13, G23)``, shape (n, 6)."""
        e = laminate.engineering_from_stiffness(self.b)
        return self.sensitivities @ laminate.stiffness_jacobian(e)
