"""The working mesh's own error on each frequency, and the part of it the deviations carry.

The element converges as ``h^2``; with the mesh of half as many elements each way, Richardson
extrapolation estimates the working mesh's error ``e = (f_coarse - f_fine) / 3``. Most of it
is what a slightly stiffer plate does (a mesh too stiff is much like a plate a little
stiffer), and the nominal fit's six constants absorb that part; what they cannot absorb is

    e_left = sigma * P (e / sigma),   P = I - Q Q^T,   Q R = S_f / sigma,

``S_f`` the sensitivities of the frequencies to the stiffness coefficients (``d f / d b =
f / (2 lambda) d lambda / d b``) at the same point, whitened like ``e`` (the projector of
:func:`..physics.location.absorbable_projector`). ``"whole"`` adds ``e`` to the deviations
in quadrature where it is not well under them (diagnose's default); ``"unabsorbed"`` adds ``e_left``
instead, so that what the constants take is not counted twice, once by the fit and once in
the deviations.
"""

from __future__ import annotations

import numpy as np

from ...quantities import hz_from_eigenvalue
from ..physics.location import absorbable_projector

__all__ = ["MESH_ERROR_PARTS", "coarse_model", "mesh_error", "unabsorbed"]

#: What of the mesh's estimated error :func:`..diagnose.diagnose` adds to the deviations.
MESH_ERROR_PARTS = ("whole", "unabsorbed")


def coarse_model(model):
    """The same plate on a mesh with half as many elements each way."""
    return model.on_mesh((max(model.mesh.nx // 2, 2), max(model.mesh.ny // 2, 1)))


def mesh_error(model, b, n_modes, coarse=None):
    """Richardson estimate of each frequency's discretisation error on ``model``'s mesh.

    The mesh is compared with one of half as many elements each way; with the element's
    ``h^2`` rate the error of the finer one is ``(f_coarse - f_fine) / 3``.

    Returns
    -------
    numpy.ndarray, shape (n_modes,)
        Estimated ``f_mesh - f_converged`` in Hz (positive: the mesh is too stiff).
    """
    coarse = coarse or coarse_model(model)
    fine = model.solve(b, n_modes).frequency_Hz
    return (coarse.solve(b, n_modes).frequency_Hz - fine) / 3.0


def unabsorbed(error_Hz, sigma_Hz, eigenvalues, sensitivities):
    """The part of a frequency error that a change of the six constants cannot mimic.

    Parameters
    ----------
    error_Hz, sigma_Hz : numpy.ndarray, shape (m,)
        The error and the deviations it is compared with, Hz.
    eigenvalues : numpy.ndarray, shape (m,)
        The modes' eigenvalues where the error was estimated, rad^2/s^2.
    sensitivities : numpy.ndarray, shape (m, 6)
        ``d lambda / d b`` there (rad^2/s^2 per Pa).

    Returns
    -------
    numpy.ndarray, shape (m,)
        ``e_left`` in Hz (linearised; ``m <= 6`` leaves nothing).
    """
    error_Hz, sigma_Hz = np.asarray(error_Hz, float), np.asarray(sigma_Hz, float)
    lam = np.asarray(eigenvalues, dtype=float)
    frequency = hz_from_eigenvalue(lam)
    S = np.asarray(sensitivities, dtype=float) * (frequency / (2.0 * lam))[:, None]
    whitened = S / sigma_Hz[:, None]
    whitened = whitened / np.linalg.norm(whitened, axis=0)  # (the span is what counts)
    return sigma_Hz * (absorbable_projector(whitened) @ (error_Hz / sigma_Hz))
