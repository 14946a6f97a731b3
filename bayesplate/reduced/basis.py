"""Growth of the reduced basis: snapshots M-orthogonalised, split by class and compressed.

Each batch of full-model mode shapes (snapshots) is scaled to unit strain energy at a
reference ``b``, split into symmetry classes, M-orthogonalised against the basis of its class
and compressed by a proper orthogonal decomposition in the energy norm; the projected terms
``V^T K_j V`` (and ``V^T K_0 V``) are extended with the new columns only.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..parallel import available_cores, fork_map
from .symmetry import _SIGN_SEED, _by_class

# Parts of snapshots with less energy than this fraction of rank_tol**2 (the components of
# a mode in the other symmetry classes, the remainder of a mode already in the basis) are
# rounding noise; they are left out of the compression.
_NEGLIGIBLE = 1e-2
# A class's part of a snapshot whose energy before the projection is below this fraction of
# the negligible energy is noise the projection cannot lift above it: it is set aside before
# any product with the model's matrices. (Taking out its M-projection on the basis raises a
# part's energy by at most (1 + sqrt(lambda_max / lambda_1))**2 of the basis, a few hundred
# for the modes of a fast model; a mode's parts in other classes are 1e-16 to 1e-6 of its
# norm, measured on the Frederiksen plate at 24 x 24.)
_UNLIFTABLE = 1e-4


def _rigid_basis(model, symmetries):
    """M-orthonormal rigid-body motions of a free plate by class; none if supported.

    Returns
    -------
    basis : numpy.ndarray, shape (n_dofs, 6) or (n_dofs, 0)
    classes : numpy.ndarray of int, shape (6,) or (0,)
    """
    if model.boundary != "free":
        return np.zeros((model.mesh.n_dofs, 0)), np.zeros(0, dtype=int)
    M, R = model.mass, model.rigid_body_modes()
    R = _m_orthonormal(M, R)
    basis, classes = [], []
    for label, part in _by_class(R, symmetries):
        # each rigid motion (about the centre) lies in one class: keep the rank of the part
        w, U = np.linalg.eigh(part.T @ (M @ part))
        keep = w > 1e-8
        if keep.any():
            basis.append(_m_orthonormal(M, part @ U[:, keep]))
            classes += [label] * int(keep.sum())
    return _fix_signs(np.hstack(basis)), np.array(classes, dtype=int)


def _m_orthonormal(M, X):
    """Columns of ``X`` made M-orthonormal by Cholesky QR, twice."""
    for _ in range(2):
        G = X.T @ (M @ X)
        L = np.linalg.cholesky(0.5 * (G + G.T))
        X = sla.solve_triangular(L, X.T, lower=True).T
    return X


def _project_out(M, V, X):
    """``X`` minus its M-orthogonal projection on the M-orthonormal ``V``, twice."""
    for _ in range(2):
        X = X - V @ (V.T @ (M @ X))
    return X


def _grow(model, symmetries, basis, classes, terms, constant, snapshots, reference, rank_tol):
    """Basis, classes and projected terms with the new directions of ``snapshots`` appended.

    Returns
    -------
    basis : numpy.ndarray, shape (n_dofs, r + q)
    classes : numpy.ndarray of int, shape (r + q,)
    terms : numpy.ndarray, shape (6, r + q, r + q)
    constant : numpy.ndarray, shape (r + q, r + q), or None
    """
    new, labels = [], []
    K = model.stiffness(reference)
    S, KS = _energy_normalised(K, snapshots)
    # a symmetry commutes with K: the class parts of K S are K times the class parts of S,
    # and the energies of the parts of one snapshot add up to its own
    for (label, part), (_, k_part) in zip(
        _by_class(S, symmetries), _by_class(KS, symmetries), strict=True
    ):
        live = np.einsum("di,di->i", part, k_part) > _UNLIFTABLE * _NEGLIGIBLE * rank_tol**2
        D = _new_directions(model, K, basis[:, classes == label], part[:, live], rank_tol)
        new.append(D)
        labels += [label] * D.shape[1]
    new = np.hstack(new)
    basis = np.hstack([basis, new])
    classes = np.concatenate([classes, np.array(labels, dtype=int)])
    terms = _extend(terms, _project_terms(model, basis, new))
    if constant is not None:
        constant = _extend(constant[None], _project_constant(model, basis, new)[None])[0]
    return basis, classes, terms, constant


def _energy_normalised(K, snapshots):
    """Snapshots scaled to unit strain energy ``s^T K s``, and ``K`` times them."""
    KS = K @ snapshots
    scale = 1.0 / np.sqrt(np.einsum("di,di->i", snapshots, KS))
    return snapshots * scale, KS * scale


def _new_directions(model, K, V, S, rank_tol):
    """New M-orthonormal basis vectors of one class, compressed in the energy norm.

    Parameters
    ----------
    model : PlateModel
    K : scipy.sparse matrix, shape (n_dofs, n_dofs)
        The stiffness of the energy inner product (at the basis's reference ``b``).
    V : numpy.ndarray, shape (n_dofs, r_c)
        The M-orthonormal basis vectors of the class so far.
    S : numpy.ndarray, shape (n_dofs, k)
        The class's parts of snapshots of unit strain energy.
    rank_tol : float
        Directions with less than ``rank_tol**2`` of a snapshot's energy are dropped.

    Returns
    -------
    numpy.ndarray, shape (n_dofs, q)
    """
    M = model.mass
    if S.shape[1] == 0:
        return np.zeros((V.shape[0], 0))
    S = _project_out(M, V, S)
    KS = K @ S
    keep = np.einsum("di,di->i", S, KS) > _NEGLIGIBLE * rank_tol**2
    if not keep.any():
        return np.zeros((V.shape[0], 0))
    S, KS = S[:, keep], KS[:, keep]
    w, U = np.linalg.eigh(S.T @ KS)  # proper orthogonal decomposition in the energy norm
    keep = w > rank_tol**2
    if not keep.any():
        return np.zeros((V.shape[0], 0))
    D = _project_out(M, V, S @ (U[:, keep] / np.sqrt(w[keep])))
    return _fix_signs(_m_orthonormal(M, D))


def _fix_signs(D):
    """Flip columns so that each has a positive product with a fixed random vector."""
    g = np.random.default_rng(_SIGN_SEED).standard_normal(D.shape[0])
    return D * np.where(g @ D < 0, -1.0, 1.0)


def _project_terms(model, basis, new):
    """``basis.T @ K_j @ new`` for the six terms, shape (6, r, q)."""
    return np.array([basis.T @ (model.stiffness_term(j) @ new) for j in range(6)])


def _project_constant(model, basis, new):
    """``basis.T @ K_0 @ new`` for the stiffness independent of ``b``, or None.

    ``K_0`` is the model's :attr:`~bayesplate.plate.model.PlateModel.extra_stiffness_data` (None for
    the bare plate).
    """
    K0 = model.extra_stiffness
    if K0 is None:
        return None
    return basis.T @ (K0 @ new)


def _extend(terms, columns):
    """Symmetric ``(t, r + q, r + q)`` from ``(t, r, r)`` and new columns ``(t, r + q, q)``."""
    t, r, _ = terms.shape
    n = columns.shape[1]
    out = np.empty((t, n, n))
    out[:, :r, :r] = terms
    out[:, :, r:] = columns
    out[:, r:, :r] = np.transpose(columns[:, :r, :], (0, 2, 1))
    out[:, r:, r:] = 0.5 * (out[:, r:, r:] + np.transpose(out[:, r:, r:], (0, 2, 1)))
    return out


# ----------------------------------------------------------------------------- full solves


def _solve_many(model, points, n_modes, workers=None):
    """Full-model solutions at several points, in order, on ``workers`` forked processes.

    Processes, not threads: ARPACK's reverse communication and SuperLU's solves hold the
    GIL, so threads gave no speed-up (4 solves at 32 x 32: 4.9 s on two threads, 3.9 s
    serial). Each solve runs at one BLAS thread in any case, so the results do not depend
    on ``workers`` (default: every available core), to the last bit.
    """
    workers = available_cores() if workers is None else workers
    return fork_map(lambda p: model.solve(p, n_modes), points, workers)
