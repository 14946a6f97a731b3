"""Locate a misfit: which modes carry it, what kind they are, where on the plate it sits.

Everything here is linearised at the nominal fit and pure array computation. Residuals and
effect columns are whitened by the observation deviations, and the part of every effect
that the six elastic constants can absorb is projected out first: only what the constants
cannot explain points at missing physics.

The maps of the located candidates are built here from the derivative columns each
candidate computes in its :meth:`~.base.Physics.location_map` (:func:`effect_map`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import mirror_positions

__all__ = [
    "LocationMap",
    "absorbable_projector",
    "best_region",
    "explained_chi2",
    "effect_map",
    "mode_kinds",
]

_KIND_BY_COEFFICIENT = {0: "bending along x", 1: "bending along y", 3: "torsion"}


def mode_kinds(model, result, threshold=0.6):
    """Name each mode by where its energy sits.

    A mode is ``in-plane`` when most of its kinetic energy is in ``u0, v0``; otherwise it is
    named by the stiffness coefficient that carries most of its strain energy (the
    normalised sensitivities of eq. 29 sum to one): C11 -> ``bending along x`` (plate x),
    C22 -> ``bending along y``, C66 -> ``torsion``; ``mixed`` when no share exceeds
    ``threshold``. For angle plies the names refer to the lamina coefficients.

    Parameters
    ----------
    model : PlateModel
    result : ModalResult

    Returns
    -------
    list of str, one per mode
    """
    phi = result.vectors
    inplane = np.zeros(model.mesh.n_dofs)
    inplane[np.concatenate([model.mesh.dofs("u"), model.mesh.dofs("v")])] = 1.0
    kinetic_inplane = np.einsum(
        "di,di->i", phi * inplane[:, None], model.mass @ (phi * inplane[:, None])
    )
    shares = result.normalised_sensitivities()
    kinds = []
    for k, s in zip(kinetic_inplane, shares, strict=True):
        j = int(np.argmax(s))
        if k > 0.5:
            kinds.append("in-plane")
        elif s[j] > threshold and j in _KIND_BY_COEFFICIENT:
            kinds.append(_KIND_BY_COEFFICIENT[j])
        else:
            kinds.append("mixed")
    return kinds


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


def best_region(model, maps):
    """The best located place over all maps (mm), with its mirror images; ``(None, [])``."""
    best = None
    for m in maps.values():
        i = m.best()
        if i is not None and (best is None or m.chi2_drop[i] > best[0]):
            best = (m.chi2_drop[i], tuple(float(v) for v in m.points_mm[i]))
    if best is None:
        return None, []
    return best[1], [tuple(float(v) for v in p) for p in mirror_positions(model, *best[1])]
