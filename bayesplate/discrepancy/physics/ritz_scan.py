"""Ritz scans: where, and how large, a located effect could be, beyond first order.

The location maps of :mod:`.location` are linear in the effect's size. A large effect (a
sensor of a few percent of the plate's mass, a patch that lost half its stiffness) shifts
the eigenvalues far beyond that, reorders modes, and a local fit started from the map's
peak stops in a false minimum. A scan solves the modified plate exactly in the Ritz basis
of the nominal modes instead: with ``Phi`` the M-orthonormal rigid-body motions and the
lowest elastic modes at the nominal fit, ``Lambda`` their eigenvalues,

* a point mass ``m`` at node ``p``: ``Lambda q = lambda (I + m w_p w_p^T) q`` with
  ``w_p = Phi[w dof of p]``;
* a patch keeping ``factor`` of the matrix-dominated stiffness:
  ``(Lambda - (1 - factor) Phi^T K_loss Phi) q = lambda q``;

a few dozen unknowns, solved for thousands of places and sizes at once. The scan's
chi-square is taken after projecting out what the six constants absorb (as in the maps);
its best distinct places and sizes are starting points for the joint fit.

This module is the machinery every located candidate shares (the basis, the scan's result,
the misfit of batched Ritz eigenvalues); each candidate writes its own pencil in its
:meth:`~.base.Physics.scan`, in its own module, over the grid it declares.
Pure array computation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import mirror_positions

__all__ = ["RitzBasis", "Scan", "misfit"]


@dataclass(frozen=True)
class RitzBasis:
    """Rigid-body motions and elastic modes of the nominal plate.

    Attributes
    ----------
    vectors : numpy.ndarray, shape (n_dofs, r + n)
        M-orthonormal: the ``r`` rigid-body motions, then the elastic modes.
    eigenvalues : numpy.ndarray, shape (r + n,)
        Zero for the rigid motions, rad^2/s^2.
    n_rigid : int
    """

    vectors: np.ndarray
    eigenvalues: np.ndarray
    n_rigid: int

    @classmethod
    def from_modes(cls, model, modal):
        """The basis of a free plate's ``ModalResult`` (its rigid motions added)."""
        R = model.rigid_body_modes()
        R = R @ np.linalg.inv(np.linalg.cholesky(R.T @ (model.mass @ R))).T
        vectors = np.hstack([R, modal.vectors])
        eigenvalues = np.concatenate([np.zeros(R.shape[1]), modal.eigenvalues])
        return cls(vectors, eigenvalues, R.shape[1])


@dataclass(frozen=True)
class Scan:
    """Chi-square of a located effect over a grid of its parameters.

    Attributes
    ----------
    theta : numpy.ndarray, shape (n, k)
        Parameter values in the physics' units (as ``Physics.parameters`` orders them).
    chi2 : numpy.ndarray, shape (n,)
        Whitened misfit after the constants took their share.
    position : tuple of int
        Columns of ``theta`` holding ``(x_mm, y_mm)``.
    """

    theta: np.ndarray
    chi2: np.ndarray
    position: tuple

    def best(self, model, n=3, separation=0.1):
        """The ``n`` best parameter sets at distinct places, best first.

        Places closer than ``separation`` of the plate's sides to a better one, or to one of
        its mirror images (which fit equally), are skipped.

        Returns
        -------
        list of numpy.ndarray, each shape (k,)
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        chosen, taken = [], []
        for i in np.argsort(self.chi2):
            if not np.isfinite(self.chi2[i]):
                break
            x, y = self.theta[i, list(self.position)]
            near = any(
                abs(x - px) < separation * a_mm and abs(y - py) < separation * b_mm
                for px, py in taken
            )
            if near:
                continue
            chosen.append(self.theta[i].copy())
            taken += [(x, y), *mirror_positions(model, x, y)]
            if len(chosen) == n:
                break
        return chosen


def misfit(eigenvalues, basis, Y, sigma, modes, projector):
    """Projected chi-square of batched Ritz eigenvalues.

    Parameters
    ----------
    eigenvalues : numpy.ndarray, shape (..., r + n)
        Eigenvalues of the modified plate in ``basis`` (any order), rad^2/s^2.
    basis : RitzBasis
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations, rad^2/s^2.
    modes : numpy.ndarray of int, shape (m,)
        0-based elastic modes paired with the measured ones.
    projector : numpy.ndarray, shape (m, m)
        Onto what the constants cannot absorb.

    Returns
    -------
    numpy.ndarray, shape (...,)
    """
    elastic = np.sort(eigenvalues, axis=-1)[..., basis.n_rigid :]
    r = (Y - elastic[..., modes]) / sigma
    r = r @ projector.T
    return np.einsum("...i,...i->...", r, r)
