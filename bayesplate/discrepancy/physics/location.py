"""Location maps: where on the plate a local change would explain the misfit.

Everything here is linearised at the nominal fit and pure array computation. Residuals and
effect columns are whitened by the observation deviations, and the part of every effect
that the six elastic constants can absorb is projected out first: only what the constants
cannot explain points at missing physics.

The maps of the located candidates are built here from the derivative columns each
candidate computes in its :meth:`~.base.Physics.location_map` (:func:`effect_map`); the
kinds of the modes and the best place over the maps are the search's
(:mod:`..search.locate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "LocationMap",
    "absorbable_projector",
    "explained_chi2",
    "effect_map",
]


def absorbable_projector(sensitivity_whitened):
    """Projector onto what the elastic constants cannot absorb, shape (m, m).

    Parameters
    ----------
    sensitivity_whitened : numpy.ndarray, shape (m, p)
        ``V_Y^(-1/2) S``: whitened sensitivities of the observations to the parameters.
    """
    Q, _ = np.linalg.qr(sensitivity_whitened)
    return np.eye(Q.shape[0]) - Q @ Q.T


def explained_chi2(residual_whitened, effects_whitened, projector):
    """Chi-square explained by each single effect column after projection.

    For each column ``g`` the best amplitude is ``alpha = g~ . r~ / g~ . g~`` and the drop in
    chi-square ``(g~ . r~)^2 / g~ . g~`` (tilde: projected by ``projector``).

    Parameters
    ----------
    residual_whitened : numpy.ndarray, shape (m,)
    effects_whitened : numpy.ndarray, shape (m, n)
    projector : numpy.ndarray, shape (m, m)

    Returns
    -------
    drop : numpy.ndarray, shape (n,)
    amplitude : numpy.ndarray, shape (n,)
    """
    r = projector @ residual_whitened
    G = projector @ effects_whitened
    norm = np.einsum("mn,mn->n", G, G)
    # a column the constants absorb entirely is left with rounding only: it explains nothing
    visible = norm > 1e-20 * np.einsum("mn,mn->n", effects_whitened, effects_whitened)
    safe = np.where(visible, norm, 1.0)
    dot = G.T @ r
    return np.where(visible, dot**2 / safe, 0.0), np.where(visible, dot / safe, 0.0)


@dataclass(frozen=True)
class LocationMap:
    """How well a local change at each place explains the residuals.

    Attributes
    ----------
    points_mm : numpy.ndarray, shape (n, 2)
        Where (element centres or nodes), mm.
    chi2_drop : numpy.ndarray, shape (n,)
        Chi-square explained by a local change there (after the constants took their share).
    amplitude : numpy.ndarray, shape (n,)
        Best-fitting size of the change (stiffness lost as a fraction, or mass in kg).
    physical : numpy.ndarray of bool, shape (n,)
        Whether that size has the physical sign (a loss, a positive mass).
    shape : tuple of int
        Grid shape ``(ny, nx)`` of the points, for drawing.
    """

    points_mm: np.ndarray
    chi2_drop: np.ndarray
    amplitude: np.ndarray
    physical: np.ndarray
    shape: tuple

    def best(self):
        """Index of the best physical location, or None when no location helps."""
        score = np.where(self.physical, self.chi2_drop, -np.inf)
        i = int(np.argmax(score))
        return None if not np.isfinite(score[i]) or score[i] <= 0 else i


def effect_map(derivatives, sigma_lambda, residual_whitened, projector, points_mm, shape):
    """The location map of an effect from its derivative columns, one per place.

    Parameters
    ----------
    derivatives : numpy.ndarray, shape (m, n)
        ``d lambda_i / d alpha`` at each of the ``n`` places (rad^2/s^2 per unit of the
        effect's size ``alpha``), signed so that a physical effect has ``alpha > 0``.
    sigma_lambda : numpy.ndarray, shape (m,)
        Deviations of the measured eigenvalues, rad^2/s^2.
    residual_whitened : numpy.ndarray, shape (m,)
    projector : numpy.ndarray, shape (m, m)
    points_mm : numpy.ndarray, shape (n, 2)
        The places, mm.
    shape : tuple of int
        Grid shape ``(ny, nx)`` of the places.

    Returns
    -------
    LocationMap
        ``physical`` where the best amplitude is positive.
    """
    effects = derivatives / sigma_lambda[:, None]
    drop, amp = explained_chi2(residual_whitened, effects, projector)
    return LocationMap(points_mm, drop, amp, amp > 0, shape)
