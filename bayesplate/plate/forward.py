"""The forward-model interface: what every model the estimators, sampler and diagnose call offers.

A forward model maps the lamina stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)``
(Pa) to the lowest elastic eigenvalues ``lambda = (2 pi f)^2`` (rad^2/s^2) of the free plate,
with their sensitivities ``d lambda / d b`` when asked for modes. The full finite-element model
(:class:`bayesplate.plate.model.PlateModel`), the reduced-basis model and the certified model (full
where the reduced one is not certified) implement it; code that needs more of one of them (the
mass matrix for MAC tracking, the certified box) asks for it through the interface below, never
by probing attributes.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Modes", "ForwardModel"]


@runtime_checkable
class Modes(Protocol):
    """Modes at one point: what :meth:`ForwardModel.solve` returns.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        Where they were computed, Pa.
    eigenvalues : numpy.ndarray, shape (n,)
        Lowest elastic eigenvalues, ascending, rad^2/s^2.
    sensitivities : numpy.ndarray, shape (n, 6)
        ``d lambda_i / d b_j``, rad^2/s^2/Pa.
    vectors : numpy.ndarray, shape (n_dofs, n)
        Mass-normalised mode shapes on the full model's unknowns (computed on access by a
        reduced model).
    """

    b: np.ndarray
    eigenvalues: np.ndarray
    sensitivities: np.ndarray

    @property
    def vectors(self) -> np.ndarray:
        """Mode shapes, shape (n_dofs, n)."""
        ...


@runtime_checkable
class ForwardModel(Protocol):
    """A model of the plate's free vibration, ``b -> lambda(b)``.

    Attributes
    ----------
    mesh : bayesplate.fem.mesh.RectangularMesh
        The finite-element mesh whose unknowns the mode shapes live on.
    mass : scipy.sparse matrix, shape (n_dofs, n_dofs)
        Mass matrix of those unknowns (the MAC weight between mode shapes).
    """

    @property
    def mesh(self):
        """The mesh the mode shapes live on."""
        ...

    @property
    def mass(self):
        """Mass matrix, shape (n_dofs, n_dofs)."""
        ...

    def solve(self, b, n_modes: int) -> Modes:
        """Lowest `n_modes` elastic modes at `b` with their sensitivities."""
        ...

    def eigenvalues(self, b, n_modes: int) -> np.ndarray:
        """Lowest `n_modes` elastic eigenvalues at `b`, shape (n_modes,); the cheapest path."""
        ...
