"""Reduced candidate models: a modified plate solved in a small Ritz basis.

A candidate's joint fit evaluates the modified plate ``K(b, theta) = sum_j b_j K_j(theta)
(+ K_0(theta))``, ``M(theta)`` hundreds of times. Projected on a fixed basis ``V`` (the
rigid-body motions, the nominal plate's lowest modes and the modified plate's modes at a
few parameter values, orthonormal in the nominal mass), every evaluation is a dense
generalised eigenproblem of a few dozen unknowns (:func:`scipy.linalg.eigh`); its
eigenvalues bound the finite-element ones from above (Courant-Fischer).

What does not change with ``theta`` is projected once; each candidate says how the rest
does in its :meth:`~.base.Physics.ritz` (a point mass is a rank-one mass term, a foundation
is affine in its modulus, a taper's and a misalignment's matrices are exact low-degree
(trigonometric) polynomials of their parameter: :func:`interpolated_ritz`). A candidate
without such a form (``ritz`` returns None) is fitted on the finite-element model.

Derivatives: ``d lambda / d b_j = x^T K_j x`` and ``d lambda / d theta_i = x^T (dK -
lambda dM) x`` with the reduced matrices differenced centrally (no extra eigen solve).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ..model import ModalResult

__all__ = ["CandidatePencil", "candidate_pencil", "interpolated_ritz", "project", "ritz_basis"]

#: Directions whose nominal-mass norm falls below this fraction of the largest are dropped.
BASIS_TOL = 1e-8
#: Share of a mode's mass on the rigid-body motions above which it counts as rigid.
RIGID_SHARE = 0.5


def project(plate, V):
    """Projected matrices of a (modified) plate on ``V``.

    Parameters
    ----------
    plate : PlateModel
    V : numpy.ndarray, shape (n_dofs, r)

    Returns
    -------
    terms : numpy.ndarray, shape (6, r, r)
        ``V^T K_j V``.
    constant : numpy.ndarray, shape (r, r)
        ``V^T K_0 V`` (zero for a plate without a stiffness independent of ``b``).
    mass : numpy.ndarray, shape (r, r)
        ``V^T M V``.
    """
    assemble = plate.assembler.matrix
    terms = np.array([V.T @ (assemble(d) @ V) for d in plate.stiffness_terms])
    constant = np.zeros((V.shape[1], V.shape[1]))
    if plate.extra_stiffness_data is not None:
        constant = V.T @ (assemble(plate.extra_stiffness_data) @ V)
    return terms, constant, V.T @ (plate.mass @ V)


def ritz_basis(model, blocks):
    """Rigid-body motions and the given vectors, orthonormal in the nominal mass.

    Parameters
    ----------
    model : PlateModel
        The nominal plate (its mass defines the inner product).
    blocks : list of numpy.ndarray, each shape (n_dofs, n_i)
        Mode shapes (nominal and modified plates).

    Returns
    -------
    numpy.ndarray, shape (n_dofs, r)
        The six rigid-body motions first (M-orthonormal), then the rest of the span.
    """
    M = model.mass
    R = model.rigid_body_modes()
    R = R @ np.linalg.inv(np.linalg.cholesky(R.T @ (M @ R))).T
    X = np.hstack(blocks)
    X = X - R @ (R.T @ (M @ X))
    G = X.T @ (M @ X)
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > BASIS_TOL * w.max()
    Q = X @ (U[:, keep] / np.sqrt(w[keep]))
    return np.hstack([R, Q])


def interpolated_ritz(plate_at, V, nodes, features):
    """Reduced matrices of a family exactly spanned by a few functions of ``theta``.

    ``A(theta) = sum_f phi_f(theta) G_f`` for every matrix ``A`` (the six stiffness terms,
    ``K_0`` and ``M``): the ``G_f`` are solved from the projected matrices at ``nodes``.

    Parameters
    ----------
    plate_at : callable
        ``plate_at(theta) -> PlateModel``.
    V : numpy.ndarray, shape (n_dofs, r)
    nodes : numpy.ndarray, shape (F, k)
        Parameter values, as many as functions.
    features : callable
        ``features(theta) -> numpy.ndarray, shape (F,)``.

    Returns
    -------
    callable
        ``theta -> (terms (6, r, r), constant (r, r), mass (r, r))``.
    """
    Phi = np.array([features(t) for t in nodes])  # (F, F)
    projected = [project(plate_at(t), V) for t in nodes]
    inv = np.linalg.inv(Phi)
    stacked = [np.array([p[i] for p in projected]) for i in range(3)]
    coefficients = [np.tensordot(inv, s, axes=(1, 0)) for s in stacked]

    def matrices(theta):
        phi = features(theta)
        return tuple(np.tensordot(phi, c, axes=(0, 0)) for c in coefficients)

    return matrices


class CandidatePencil:
    """A candidate's modified plate in a Ritz basis: the forward model of its joint fit.

    Parameters
    ----------
    basis : numpy.ndarray, shape (n_dofs, r)
        From :func:`ritz_basis` (rigid-body motions first).
    matrices : callable
        ``theta -> (terms (6, r, r), constant (r, r), mass (r, r))``.
    steps : numpy.ndarray, shape (k,)
        Difference steps of the parameters (their units).
    """

    def __init__(self, basis, matrices, steps):
        self.basis = basis
        self.matrices = matrices
        self.steps = np.asarray(steps, dtype=float)

    def solve(self, b, theta, n_modes):
        """Lowest elastic modes and their derivatives.

        Parameters
        ----------
        b : numpy.ndarray, shape (6,)
            Pa.
        theta : numpy.ndarray, shape (k,)
        n_modes : int

        Returns
        -------
        modal : ModalResult
            ``vectors`` are the Ritz coefficients, shape (r, n_modes), not mode shapes.
        d_theta : numpy.ndarray, shape (n_modes, k)
            ``d lambda / d theta``, rad^2/s^2 per parameter unit.
        """
        terms, constant, mass = self.matrices(theta)
        K = np.tensordot(b, terms, axes=(0, 0)) + constant
        values, X = scipy.linalg.eigh(0.5 * (K + K.T), 0.5 * (mass + mass.T))
        rigid_share = np.sum((mass[:6] @ X) * X[:6], axis=0)
        rigid = (rigid_share > RIGID_SHARE) | (np.abs(values) <= 1e-8 * np.abs(values).max())
        elastic = np.flatnonzero(~rigid)[:n_modes]
        lam, X = values[elastic], X[:, elastic]
        sens = np.einsum("ri,jrs,si->ij", X, terms, X)
        d_theta = np.zeros((lam.size, self.steps.size))
        for i, h in enumerate(self.steps):
            up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
            up[i] += h
            down[i] -= h
            t_up, c_up, m_up = self.matrices(up)
            t_dn, c_dn, m_dn = self.matrices(down)
            dK = (np.tensordot(b, t_up - t_dn, axes=(0, 0)) + c_up - c_dn) / (2 * h)
            dM = (m_up - m_dn) / (2 * h)
            d_theta[:, i] = np.einsum("ri,rs,si->i", X, dK, X) - lam * np.einsum(
                "ri,rs,si->i", X, dM, X
            )
        modal = ModalResult(np.asarray(b, dtype=float), lam, X, sens, values[rigid])
        return modal, d_theta

    def eigenvalues(self, b, theta, n_modes):
        """Lowest elastic eigenvalues, rad^2/s^2, shape (n_modes,)."""
        return self.solve(b, theta, n_modes)[0].eigenvalues


def candidate_pencil(model, physics, b, thetas, n_modes, nominal_modes=None):
    """A candidate's :class:`CandidatePencil` on ``model``, or None if it has no Ritz form.

    The basis holds the rigid-body motions, the nominal plate's lowest ``n_modes`` modes at
    ``b`` and the modified plate's at each of ``thetas`` (also at ``b``).

    Parameters
    ----------
    model : PlateModel
        The nominal plate (the mesh the pencil lives on).
    physics : Physics or None
        None: the nominal plate, its basis the nominal modes alone.
    b : numpy.ndarray, shape (6,)
        Stiffness coefficients of the snapshots, Pa.
    thetas : sequence of numpy.ndarray, each shape (k,)
        Parameter values of the modified plate's snapshots.
    n_modes : int
        Elastic modes of each snapshot.
    nominal_modes : numpy.ndarray, shape (n_dofs, n), optional
        The nominal plate's modes at ``b`` if already solved.

    Returns
    -------
    CandidatePencil or None
    """
    if physics is not None and not _has_ritz(physics):
        return None
    if nominal_modes is None:
        nominal_modes = model.solve(b, n_modes).vectors
    blocks = [nominal_modes]
    if physics is None:  # the nominal plate itself
        V = ritz_basis(model, blocks)
        projected = project(model, V)
        return CandidatePencil(V, lambda theta: projected, [])
    blocks += [physics.apply(model, np.asarray(t, dtype=float)).solve(b, n_modes).vectors
               for t in thetas]  # fmt: skip
    V = ritz_basis(model, blocks)
    matrices = physics.ritz(model, b, V)
    if matrices is None:
        return None
    steps = 1e-4 * np.array([p.sd for p in physics.parameters(model, b)])
    return CandidatePencil(V, matrices, steps)


def _has_ritz(physics):
    """Whether the candidate overrides :meth:`~.base.Physics.ritz`."""
    from .base import Physics

    return type(physics).ritz is not Physics.ritz
