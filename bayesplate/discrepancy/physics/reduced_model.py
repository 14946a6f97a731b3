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
import scipy.sparse

from ...plate.model import ModalResult

__all__ = [
    "CandidatePencil",
    "RegionProjection",
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
#: Eigenvalues of an element matrix below this fraction of its largest (in magnitude) are
#: taken as round-off in its factors (:class:`RegionProjection`).
FACTOR_TOL = 1e-13
#: Sets of whole elements whose sums a :class:`RegionProjection` keeps (each T r^2 numbers:
#: 0.45 MB for a hole's seven matrices at r = 90), and the fewest elements worth keeping.
WHOLE_KEPT, WHOLE_MIN = 8, 4
#: An area fraction this close to 1 is an element wholly inside a region.
WHOLE_TOL = 1e-12
#: Runs of consecutive elements at least this long are summed as one matrix-vector product;
#: the shorter ones' elements by one sparse product (:meth:`RegionProjection._sum`).
RUN_MIN = 8
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
        return tuple(np.tensordot(phi, c, axes=(0, 0)) for c in coefficients)

    return matrices


class RegionProjection:
    """``sum_e w_e V_e^T A_t V_e``: element matrices shared by every element, weighted, projected.

    ``V_e`` (32, r) are the rows of the basis at element ``e``'s unknowns and ``A_t`` the
    element matrices (a damaged patch's lost stiffness terms, a hole's stiffness and mass).
    Each element's ``V_e^T A_t V_e`` is computed the first time a weighting reaches it and
    kept, so that a weighting costs a weighted sum over its elements, and a difference of two
    weightings (the edge of a region that moved) over its few edge elements.

    An element's products come from the factors ``A_t = F_t S_t F_t^T`` (eigenvectors scaled
    by the square roots of the nonzero ``|eigenvalues|``, ``S_t`` their signs): ``V_e^T A_t
    V_e = G_t^T S_t G_t`` with ``G_t = F_t^T V_e``. A plate's element stiffness terms have rank
    10 to 12 of 32 (its mass 28): a new element costs about 2.5 times less than by ``A_t``
    whole. Eigenvalues below :data:`FACTOR_TOL` of the largest are round-off (the 50 x 50
    Frederiksen plate's: kept ones 8e-11 or more of the largest, dropped ones 4e-15 or less).

    Parameters
    ----------
    model : PlateModel
    basis : numpy.ndarray, shape (n_dofs, r)
    element_matrices : numpy.ndarray, shape (T, 32, 32)
    """

    def __init__(self, model, basis, element_matrices):
        self.dofs = model.mesh.element_dofs
        self.basis = basis
        factors, signs, self._slices = [], [], []
        for A in np.asarray(element_matrices, dtype=float):
            w, U = np.linalg.eigh(0.5 * (A + A.T))
            keep = np.abs(w) > FACTOR_TOL * np.abs(w).max(initial=0.0)
            start = sum(f.shape[1] for f in factors)
            factors.append(U[:, keep] * np.sqrt(np.abs(w[keep])))
            signs.append(np.sign(w[keep]))
            self._slices.append(slice(start, start + int(keep.sum())))
        self._factors_t = np.ascontiguousarray(np.hstack(factors).T)  # (sum of ranks, 32)
        self._signs = np.concatenate(signs)
        shape = (len(self.dofs), len(self._slices), basis.shape[1], basis.shape[1])
        self._projected = np.empty(shape)  # filled element by element (pages on first touch)
        self._done = np.zeros(len(self.dofs), dtype=bool)
        self._whole = {}  # sums of sets of whole elements, by the set; least recently used first
        self._last = None  # (fractions, result) of the last call of ``inside``

    def __call__(self, weights):
        """The weighted sum, shape (T, r, r); ``weights`` shape (n_elements,)."""
        weights = np.asarray(weights, dtype=float)
        inside = np.flatnonzero(weights)
        self._fill(inside)
        return self._sum(inside, weights).reshape(self._projected.shape[1:])

    def inside(self, fractions):
        """The weighted sum for a region's area ``fractions`` (each in [0, 1]), (T, r, r).

        The same sum as ``self(fractions)`` to round-off, in another order: the elements
        wholly inside (fraction 1 within :data:`WHOLE_TOL`, the round-off of an area's closed
        form) summed once per set of them with weight 1 and kept (:data:`WHOLE_KEPT` sets),
        the cut ones weighted as in ``__call__``. A fit moves a region by small steps: its whole
        elements change seldom, and the sum at each step visits the cut ones alone (a patch of
        120 elements of the 50 x 50 Frederiksen plate, 100 of them whole, r = 90: 1.4 ms by
        every element, 0.7 ms by the cut ones). The last result is kept as well: a difference
        in a factor that multiplies the region asks for the same sum again at the same point.
        """
        fractions = np.asarray(fractions, dtype=float)
        if self._last is not None and np.array_equal(self._last[0], fractions):
            return self._last[1].copy()
        inside = np.flatnonzero(fractions)
        self._fill(inside)
        cut = np.abs(fractions[inside] - 1.0) > WHOLE_TOL
        whole = inside[~cut]
        if whole.size < WHOLE_MIN:
            out = self._sum(inside, fractions)
        else:
            key = whole.tobytes()
            kept = self._whole.pop(key, None)
            if kept is None:
                kept = self._sum(whole, np.ones(len(self.dofs)))
            self._whole[key] = kept  # the most recently used last
            while len(self._whole) > WHOLE_KEPT:
                self._whole.pop(next(iter(self._whole)))
            out = kept + self._sum(inside[cut], fractions)
        out = out.reshape(self._projected.shape[1:])
        self._last = (fractions.copy(), out)
        return out.copy()

    def _fill(self, inside):
        """Project the elements of ``inside`` not yet projected."""
        new = inside[~self._done[inside]]
        if new.size:
            G = self._factors_t @ self.basis[self.dofs[new]]  # (n, sum of ranks, r)
            SG = G * self._signs[:, None]
            for t, part in enumerate(self._slices):
                self._projected[new, t] = SG[:, part].transpose(0, 2, 1) @ G[:, part]
            self._done[new] = True

    def _sum(self, inside, weights):
        """``sum_e weights_e P_e`` over ``inside`` (sorted, projected), flat (T r r,)."""
        # a region's elements are a few runs of consecutive numbers (one per row of the
        # mesh it crosses): each long run's sum is one matrix-vector product on a view, where
        # gathering the elements first copied all their projected matrices (4-5 times
        # slower for a patch of 12 x 12 elements, r = 90); the elements of short runs (a
        # region's left and right edges: one element per row) are summed by one sparse
        # product, which adds each row into the one result (a product per run of one read
        # and wrote the whole result once per element: 1.5 ms against 0.3 ms for the 20
        # elements of two edges, r = 90; for a hole's rim, runs of two or three, both take
        # about the same: reading the elements' matrices is the cost)
        flat = self._projected.reshape(len(self.dofs), -1)
        runs = list(_runs(inside))
        short = [np.arange(start, stop) for start, stop in runs if stop - start < RUN_MIN]
        if short:
            short = np.concatenate(short)
            row = scipy.sparse.csr_matrix(
                (weights[short], short, [0, short.size]), shape=(1, len(self.dofs))
            )
            out = np.asarray(row @ flat).ravel()
        else:
            out = np.zeros(flat.shape[1])
        for start, stop in runs:
            if stop - start >= RUN_MIN:
                out += weights[start:stop] @ flat[start:stop]
        return out


def _runs(indices):
    """``(start, stop)`` of each run of consecutive integers in sorted ``indices``."""
    if indices.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(indices) != 1) + 1
    starts = indices[np.r_[0, breaks]]
    stops = indices[np.r_[breaks - 1, indices.size - 1]] + 1
    return zip(starts.tolist(), stops.tolist(), strict=True)


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
        terms, constant, mass = self.matrices(theta)
        K = np.tensordot(b, terms, axes=(0, 0)) + constant
        values, X = scipy.linalg.eigh(0.5 * (K + K.T), 0.5 * (mass + mass.T))
        rigid_share = np.sum((mass[:6] @ X) * X[:6], axis=0)
        rigid = (rigid_share > RIGID_SHARE) | (np.abs(values) <= 1e-8 * np.abs(values).max())
        elastic = np.flatnonzero(~rigid)[:n_modes]
        lam, X = values[elastic], X[:, elastic]
        sens = np.sum(X * (terms @ X), axis=1).T  # x_i^T K_j x_i, shape (n, 6)
        d_theta = np.zeros((lam.size, self.steps.size))
        for i, h in enumerate(self.steps):
            d_terms, d_constant, dM = self.difference(theta, i, h)
            dK = np.tensordot(b, d_terms, axes=(0, 0)) + d_constant
            d_theta[:, i] = np.sum(X * (dK @ X), axis=0) - lam * np.sum(X * (dM @ X), axis=0)
        modal = ModalResult(np.asarray(b, dtype=float), lam, X, sens, values[rigid])
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
        return self.solve(b, theta, n_modes)[0].eigenvalues


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
