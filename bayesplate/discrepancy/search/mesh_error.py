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

``"corrected"`` takes the error out of the model instead of into the deviations. The half
mesh is not yet where the ``h^2`` rate holds (the observed orders between 20 x 10, 40 x 20
and 80 x 40 on the Frederiksen plate run from 1 to 3), so the estimate comes from the mesh
*twice as fine* each way: ``e = 4/3 (f_mesh - f_finer)`` (Richardson, rate 2), and each
computed frequency is taken as ``f_mesh - e`` (:func:`corrected_error`). What the correction
leaves uncertain is the grid convergence index of the finer mesh (Roache 1994: safety factor
1.25 on its estimated error), ``u = 1.25 |f_mesh - f_finer| / 3``, added to the deviations in
quadrature. Against a converged reference (Richardson between 4x and 8x finer meshes) the
corrected frequencies of the bundled plates are within ``u`` (``tests/test_mesh_correction.py``).
"""

from __future__ import annotations

import numpy as np

from ...quantities import hz_from_eigenvalue
from ..physics.location import absorbable_projector

__all__ = [
    "MESH_ERROR_PARTS",
    "GCI_SAFETY",
    "coarse_model",
    "corrected_error",
    "finer_model",
    "mesh_error",
    "unabsorbed",
]

#: What of the mesh's estimated error :func:`..diagnose.diagnose` adds to the deviations.
MESH_ERROR_PARTS = ("whole", "unabsorbed", "corrected")

#: Roache's safety factor of the grid convergence index on a two-mesh estimate.
GCI_SAFETY = 1.25


def coarse_model(model):
    """The same plate on a mesh with half as many elements each way."""
    return model.on_mesh((max(model.mesh.nx // 2, 2), max(model.mesh.ny // 2, 1)))


def finer_model(model):
    """The same plate on a mesh with twice as many elements each way."""
    return model.on_mesh((2 * model.mesh.nx, 2 * model.mesh.ny))


def richardson(working_Hz, finer_Hz):
    """The working mesh's error and the uncertainty its correction leaves, from the finer mesh.

    Parameters
    ----------
    working_Hz, finer_Hz : numpy.ndarray, shape (m,)
        The same modes on the working mesh and on the mesh twice as fine each way, Hz.

    Returns
    -------
    error_Hz, uncertainty_Hz : numpy.ndarray, shape (m,)
        ``e = 4/3 (f_mesh - f_finer)`` (``f_mesh - f_converged``, rate ``h^2``) and
        ``u = 1.25 |f_mesh - f_finer| / 3`` (the finer mesh's grid convergence index).
    """
    step = np.asarray(working_Hz, dtype=float) - np.asarray(finer_Hz, dtype=float)
    return 4.0 * step / 3.0, GCI_SAFETY * np.abs(step) / 3.0


def corrected_error(model, b, n_modes, finer=None):
    """:func:`richardson` on ``model``'s mesh and the one twice as fine, at ``b``.

    Returns
    -------
    error_Hz, uncertainty_Hz : numpy.ndarray, shape (n_modes,)
    """
    finer = finer or finer_model(model)
    return richardson(model.solve(b, n_modes).frequency_Hz, finer.solve(b, n_modes).frequency_Hz)


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
