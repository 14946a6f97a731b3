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

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from ...plate.model import ModalResult

__all__ = [
    "CandidatePencil",
    "PencilModes",
    "candidate_pencil",
    "interpolated_ritz",
    "local_ritz",
    "project",
    "ritz_basis",
]

#: Directions whose squared nominal-mass norm falls below this fraction of the largest are
#: dropped. Small: a modified plate's modes differ from the nominal ones by local,
#: high-frequency directions whose mass norm is tiny but whose stiffness is not; at 1e-8 a
#: pencil built at a point was off there by up to 4e-5 in eigenvalue (a local loss) and 5e-3
#: in its sensitivities, at 1e-12 by under 1e-10 and 1e-5 (50 x 50 Frederiksen plate; the
#: eigenvalues and sensitivities of its own snapshot, the exactness its rounds rely on:
#: :mod:`..search.settling`).
BASIS_TOL = 1e-12
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
    terms = np.array([V.T @ (plate.stiffness_term(j) @ V) for j in range(6)])
    constant = np.zeros((V.shape[1], V.shape[1]))
    if plate.extra_stiffness is not None:
        constant = V.T @ (plate.extra_stiffness @ V)
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
    Q = _orthonormal(X, M, BASIS_TOL)
    # again: directions kept near the tolerance come out of one pass orthonormal only to
    # about eps / BASIS_TOL; a second pass on the (well-conditioned) result restores it
    Q = _orthonormal(Q - R @ (R.T @ (M @ Q)), M, 1e-14)
    return np.hstack([R, Q])


def _orthonormal(X, M, tol):
    """An ``M``-orthonormal basis of the span of ``X``, directions below ``tol`` dropped."""
    G = X.T @ (M @ X)
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > tol * w.max()
    return X @ (U[:, keep] / np.sqrt(w[keep]))


def local_ritz(plate_at, V, near, step):
    """A family's reduced matrices as a quadratic in one parameter around ``near``.

    Exact at ``near`` (a node), its first derivative there to ``O(step^2)``: the form of a
    round of :mod:`..search.settling`, whose pencil need only be exact at its snapshot (three plates
    assembled and projected instead of a whole range's nodes).

    Parameters
    ----------
    plate_at : callable
        ``plate_at(theta) -> PlateModel``, ``theta`` shape (1,).
    V : numpy.ndarray, shape (n_dofs, r)
    near : array_like, shape (1,)
    step : float
        Distance of the two other nodes.

    Returns
    -------
    callable
        As :func:`interpolated_ritz`'s.
    """
    t0 = float(np.atleast_1d(near)[0])
    nodes = np.array([[t0 - step], [t0], [t0 + step]])

    def features(theta):
        d = (np.atleast_1d(theta)[0] - t0) / step
        return np.array([1.0, d, d * d])

    return interpolated_ritz(plate_at, V, nodes, features)


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
        return tuple(_combine(phi, c) for c in coefficients)

    return matrices


def _combine(weights, stack):
    """``sum_i weights_i stack_i`` over the first axis of ``stack``.

    What ``np.tensordot`` gives with ``axes=(0, 0)``, the same numbers, without its
    overhead: 0.015 ms against 0.028 ms for six terms at r = 90.
    """
    return (weights @ stack.reshape(len(weights), -1)).reshape(stack.shape[1:])


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
    snapshot : ModalResult, optional
        The finite-element solution at the point the pencil was last built at (its
        eigenvalues are the full model's there: the check of an answer the pencil gave).
    """

    def __init__(self, basis, matrices, steps, snapshot=None):
        self.basis = basis
        self.matrices = matrices
        self.steps = np.asarray(steps, dtype=float)
        self.snapshot = snapshot
        self.snapshots = []  # mode shapes of the finite-element solves in the basis

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
        return self.derivatives(self.modes(b, theta, n_modes))

    def modes(self, b, theta, n_modes):
        """The lowest elastic modes alone (:class:`PencilModes`), derivatives not taken.

        What a fit's evaluation of its residuals needs; :meth:`derivatives` completes it
        when the Jacobian is asked for (a trust-region fit asks for it at the steps it
        accepts only: 82 % of a concealed point mass's diagnosis's evaluations).
        """
        b = np.asarray(b, dtype=float)
        terms, constant, mass = self.matrices(theta)
        K = _combine(b, terms) + constant
        values, X = scipy.linalg.eigh(0.5 * (K + K.T), 0.5 * (mass + mass.T))
        rigid_share = np.sum((mass[:6] @ X) * X[:6], axis=0)
        rigid = (rigid_share > RIGID_SHARE) | (np.abs(values) <= 1e-8 * np.abs(values).max())
        elastic = np.flatnonzero(~rigid)[:n_modes]
        return PencilModes(
            b, np.array(theta, dtype=float), values[elastic], X[:, elastic], values[rigid], terms
        )

    def derivatives(self, modes):
        """``(modal, d_theta)`` of :meth:`solve` from the :meth:`modes` of a point."""
        b, theta, lam, X, terms = (
            modes.b,
            modes.theta,
            modes.eigenvalues,
            modes.vectors,
            modes.terms,
        )
        sens = np.sum(X * (terms @ X), axis=1).T  # x_i^T K_j x_i, shape (n, 6)
        d_theta = np.zeros((lam.size, self.steps.size))
        for i, h in enumerate(self.steps):
            d_terms, d_constant, dM = self.difference(theta, i, h)
            dK = _combine(b, d_terms) + d_constant
            d_theta[:, i] = np.sum(X * (dK @ X), axis=0) - lam * np.sum(X * (dM @ X), axis=0)
        modal = ModalResult(b, lam, X, sens, modes.rigid_eigenvalues)
        return modal, d_theta

    def difference(self, theta, i, h):
        """Central difference of the matrices in parameter ``i`` with step ``h``.

        ``(A(theta + h e_i) - A(theta - h e_i)) / 2 h`` for the terms, the constant and the
        mass; by the candidate's own ``matrices.difference`` when its Ritz form has one (a
        cheaper path to the same difference: a region's edge elements only), else by two
        calls of ``matrices``.
        """
        own = getattr(self.matrices, "difference", None)
        if own is not None:
            return own(theta, i, h)
        up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
        up[i] += h
        down[i] -= h
        t_up, c_up, m_up = self.matrices(up)
        t_dn, c_dn, m_dn = self.matrices(down)
        return (t_up - t_dn) / (2 * h), (c_up - c_dn) / (2 * h), (m_up - m_dn) / (2 * h)

    def eigenvalues(self, b, theta, n_modes):
        """Lowest elastic eigenvalues, rad^2/s^2, shape (n_modes,)."""
        return self.modes(b, theta, n_modes).eigenvalues


@dataclass(frozen=True)
class PencilModes:
    """A pencil's lowest elastic modes at one point, before their derivatives.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        Pa.
    theta : numpy.ndarray, shape (k,)
    eigenvalues : numpy.ndarray, shape (n,)
        rad^2/s^2.
    vectors : numpy.ndarray, shape (r, n)
        Ritz coefficients, mass-normalised.
    rigid_eigenvalues : numpy.ndarray
    terms : numpy.ndarray, shape (6, r, r)
        The reduced stiffness terms at ``theta`` (the sensitivities' matrices).
    """

    b: np.ndarray
    theta: np.ndarray
    eigenvalues: np.ndarray
    vectors: np.ndarray = field(repr=False)
    rigid_eigenvalues: np.ndarray
    terms: np.ndarray = field(repr=False)


def candidate_pencil(
    model, physics, b, thetas, n_modes, nominal_modes=None, earlier=(), local=False
):
    """A candidate's :class:`CandidatePencil` on ``model``, or None if it has no Ritz form.

    The basis holds the rigid-body motions, the nominal plate's lowest ``n_modes`` modes at
    ``b``, the modified plate's at each of ``thetas`` (also at ``b``) and the ``earlier``
    snapshots.

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
    earlier : sequence of numpy.ndarray, each shape (n_dofs, n_i)
        Mode shapes of earlier snapshots to keep (an earlier pencil's
        :attr:`~CandidatePencil.snapshots`: they stay exact).
    local : bool
        The pencil need only be exact at the last of ``thetas`` and accurate around it (a
        round of :mod:`..search.settling`): the candidate may build a cheaper local form there
        (:meth:`~.base.Physics.ritz`'s ``near``).

    Returns
    -------
    CandidatePencil or None
        Its :attr:`~CandidatePencil.snapshot` is the finite-element solution of its last
        snapshot (the last of ``thetas``; the nominal plate at ``b`` when ``thetas`` is empty
        and ``nominal_modes`` is not given), or None; its ``snapshots`` the mode shapes of
        ``earlier`` and of its own snapshots.
    """
    if physics is not None and not _has_ritz(physics):
        return None
    if physics is None:  # the nominal plate's own solve at b is its snapshot
        solves = [] if nominal_modes is not None else [model.solve(b, n_modes)]
        blocks = [] if nominal_modes is None else [nominal_modes]
    else:
        if nominal_modes is None:
            nominal_modes = model.solve(b, n_modes).vectors
        solves = [
            physics.apply(model, np.asarray(t, dtype=float)).solve(b, n_modes) for t in thetas
        ]
        blocks = [nominal_modes]
    snapshots = [*earlier, *(s.vectors for s in solves)]
    V = ritz_basis(model, blocks + snapshots)
    last = solves[-1] if solves else None
    if physics is None:  # the nominal plate itself
        projected = project(model, V)
        pencil = CandidatePencil(V, lambda theta: projected, [], last)
    else:
        near = np.asarray(thetas[-1], dtype=float) if local and len(thetas) else None
        matrices = physics.ritz(model, b, V, near)
        if matrices is None:
            return None
        steps = 1e-4 * np.array([p.sd for p in physics.parameters(model, b)])
        pencil = CandidatePencil(V, matrices, steps, last)
    pencil.snapshots = snapshots
    return pencil


def _has_ritz(physics):
    """Whether the candidate overrides :meth:`~.base.Physics.ritz`."""
    from .base import Physics

    return type(physics).ritz is not Physics.ritz
