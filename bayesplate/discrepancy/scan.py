"""Ritz scans: where, and how large, a located effect could be, beyond first order.

The location maps of :mod:`.locate` are linear in the effect's size. A large effect (a
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
Pure array computation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import mirror_positions

__all__ = ["RitzBasis", "Scan", "point_mass_scan", "stiffness_loss_scan"]


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


def _misfit(eigenvalues, basis, Y, sigma, modes, projector):
    """Projected chi-square of batched Ritz eigenvalues, shape (...,)."""
    elastic = np.sort(eigenvalues, axis=-1)[..., basis.n_rigid :]
    r = (Y - elastic[..., modes]) / sigma
    r = r @ projector.T
    return np.einsum("...i,...i->...", r, r)


def point_mass_scan(model, basis, Y, sigma, modes, projector, masses_g, stride=2):
    """Scan a point mass over the nodes (every ``stride``-th each way) and ``masses_g``.

    Parameters
    ----------
    model : PlateModel
    basis : RitzBasis
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations (rad^2/s^2).
    modes : numpy.ndarray of int, shape (m,)
        0-based elastic modes paired with the measured ones.
    projector : numpy.ndarray, shape (m, m)
        Onto what the constants cannot absorb (:func:`.locate.absorbable_projector`).
    masses_g : array_like
        Masses to try, g.

    Returns
    -------
    Scan
        ``theta = (mass_g, x_mm, y_mm)``.
    """
    mesh = model.mesh
    grid = np.arange(mesh.n_nodes).reshape(mesh.ny + 1, mesh.nx + 1)[::stride, ::stride]
    nodes = grid.ravel()
    w = basis.vectors[mesh.dofs("w", nodes)]  # (p, n)
    s = np.einsum("pn,pn->p", w, w)
    lam = basis.eigenvalues
    xy = 1e3 * mesh.nodes[nodes]
    thetas, chi2 = [], []
    for mass_g in np.asarray(masses_g, dtype=float):
        m = 1e-3 * mass_g
        # (I + m w w^T)^(-1/2) = I - c w w^T: the symmetric form of the pencil
        c = (1.0 - 1.0 / np.sqrt(1.0 + m * s)) / np.where(s > 0, s, 1.0)
        S = np.eye(lam.size) - c[:, None, None] * w[:, :, None] * w[:, None, :]
        A = (S * lam) @ S
        chi2.append(_misfit(np.linalg.eigvalsh(A), basis, Y, sigma, modes, projector))
        thetas.append(np.column_stack([np.full(nodes.size, mass_g), xy]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (1, 2))


def stiffness_loss_scan(model, basis, b, Y, sigma, modes, projector, sizes_mm, factors,
                        stride=2):  # fmt: skip
    """Scan a patch that lost matrix-dominated stiffness over centres, sizes and factors.

    The patch is made of whole elements (those whose centre lies inside); centres are
    element centres (every ``stride``-th each way).

    Parameters
    ----------
    b : array_like, shape (6,)
        Nominal stiffness coefficients, Pa.
    sizes_mm : sequence of (dx_mm, dy_mm)
    factors : array_like
        Fractions of ``C22, C12, C66, C44, C55`` kept inside.

    Other parameters are those of :func:`point_mass_scan`.

    Returns
    -------
    Scan
        ``theta = (x_mm, y_mm, dx_mm, dy_mm, factor)``.
    """
    from .local_stiffness_loss import _KEPT

    mesh = model.mesh
    Ke = np.einsum("j,jab->ab", np.asarray(b) * (1.0 - _KEPT), model.element_stiffness_terms())
    q = basis.vectors[mesh.element_dofs]  # (n_el, 32, n)
    reduced = q.transpose(0, 2, 1) @ (Ke @ q)
    ix = np.floor(mesh.centroids[:, 0] / mesh.dx).astype(int)
    iy = np.floor(mesh.centroids[:, 1] / mesh.dy).astype(int)
    n = basis.eigenvalues.size
    table = np.zeros((mesh.ny + 1, mesh.nx + 1, n, n))  # summed-area table of the elements
    table[iy + 1, ix + 1] = reduced
    table = table.cumsum(axis=0).cumsum(axis=1)
    cy, cx = np.meshgrid(np.arange(0, mesh.ny, stride), np.arange(0, mesh.nx, stride),
                         indexing="ij")  # fmt: skip
    cx, cy = cx.ravel(), cy.ravel()
    thetas, chi2 = [], []
    for dx_mm, dy_mm in sizes_mm:
        # elements either side of the centre one: the patch spans 2 h + 1 elements
        hx = max(int(np.floor((1e-3 * dx_mm / mesh.dx - 1) / 2 + 0.5)), 0)
        hy = max(int(np.floor((1e-3 * dy_mm / mesh.dy - 1) / 2 + 0.5)), 0)
        x0, x1 = np.clip(cx - hx, 0, mesh.nx), np.clip(cx + hx + 1, 0, mesh.nx)
        y0, y1 = np.clip(cy - hy, 0, mesh.ny), np.clip(cy + hy + 1, 0, mesh.ny)
        patch = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        size = 1e3 * np.column_stack([(x1 - x0) * mesh.dx, (y1 - y0) * mesh.dy])
        centre = 1e3 * np.column_stack([(x0 + x1) * mesh.dx, (y0 + y1) * mesh.dy]) / 2
        for factor in np.asarray(factors, dtype=float):
            A = np.diag(basis.eigenvalues) - (1.0 - factor) * patch
            chi2.append(_misfit(np.linalg.eigvalsh(A), basis, Y, sigma, modes, projector))
            thetas.append(np.column_stack([centre, size, np.full(cx.size, factor)]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (0, 1))
