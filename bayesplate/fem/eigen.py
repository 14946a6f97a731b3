"""Lowest natural modes of ``K a = lambda M a`` by shift-invert Lanczos."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

__all__ = ["EigenSolution", "lowest_modes"]

log = logging.getLogger(__name__)

#: Eigenvalues with ``|lambda| <= RIGID_TOL * max |lambda|`` are rigid-body modes.
RIGID_TOL = 1e-7


@dataclass(frozen=True)
class EigenSolution:
    """Elastic modes of a generalised eigenproblem (rigid-body modes removed).

    Attributes
    ----------
    eigenvalues : numpy.ndarray, shape (n,)
        ``lambda = omega^2`` in rad^2/s^2, ascending.
    vectors : numpy.ndarray, shape (n_dofs, n)
        Mass-normalised: ``vectors.T @ M @ vectors = I``.
    rigid_eigenvalues : numpy.ndarray, shape (n_rigid,)
        The near-zero eigenvalues that were detected and dropped.
    """

    eigenvalues: np.ndarray
    vectors: np.ndarray
    rigid_eigenvalues: np.ndarray


def lowest_modes(K, M, n_modes, shift, n_rigid_max=6, ordering=None, rigid_basis=None):
    """Lowest ``n_modes`` elastic modes, detecting and dropping rigid-body modes.

    Parameters
    ----------
    K, M : scipy.sparse matrix, shape (n_dofs, n_dofs)
        Symmetric stiffness (positive semi-definite) and mass (positive definite).
    n_modes : int
        Number of elastic modes wanted.
    shift : float
        Negative shift ``sigma`` of the spectral transformation, of the order of a tenth of
        the lowest elastic eigenvalue: ``K - sigma M`` is then positive definite.
    n_rigid_max : int
        Largest number of rigid-body modes expected (6 for a free plate, 0 if supported).
    ordering : numpy.ndarray of int, optional
        Fill-reducing symmetric permutation of the unknowns for the factorisation of
        ``K - sigma M`` (for example nested dissection); SuperLU's own ordering otherwise.
    rigid_basis : numpy.ndarray, shape (n_dofs, r), optional
        M-orthonormal rigid-body motions. A mode whose mass-weighted projection on them
        exceeds one half is also counted as rigid, even if its eigenvalue is not near zero
        (a plate on a soft support bounces at a small but finite frequency).

    Returns
    -------
    EigenSolution
    """
    if shift >= 0:
        raise ValueError(f"shift = {shift}: must be negative so that K - shift M is definite")
    k = min(n_modes + n_rigid_max + 2, K.shape[0] - 1)
    # BLAS threads only contend here (SuperLU and ARPACK work on vectors and small blocks):
    # measured 3x to 7x slower with OpenBLAS's default threads on a loaded 2-core machine
    with threadpool_limits(limits=1, user_api="blas"):
        op = _shift_invert(K - shift * M, ordering)
        # a fixed pseudo-random start: the same matrices give the same numbers every time
        v0 = np.random.default_rng(0).standard_normal(K.shape[0])
        vals, vecs = spla.eigsh(K, k=k, M=M, sigma=shift, OPinv=op, which="LM", tol=1e-10, v0=v0)
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    rigid = np.abs(vals) <= RIGID_TOL * np.max(np.abs(vals))
    if rigid_basis is not None:
        projection = np.sum((rigid_basis.T @ (M @ vecs)) ** 2, axis=0)
        rigid |= projection > 0.5 * np.einsum("di,di->i", vecs, M @ vecs)
    if rigid.sum() > n_rigid_max:
        log.warning("%d near-zero eigenvalues found, at most %d expected", rigid.sum(), n_rigid_max)
    elastic = np.flatnonzero(~rigid)[:n_modes]
    vecs = vecs[:, elastic]
    # Rayleigh quotients: eigenvalues to second order in the residual of the Lanczos vectors
    vecs /= np.sqrt(np.einsum("di,di->i", vecs, M @ vecs))
    refined = np.einsum("di,di->i", vecs, K @ vecs)
    return EigenSolution(refined, vecs, vals[rigid])


def _shift_invert(A, ordering):
    """``x -> A^-1 x`` by a sparse LU of the symmetric positive definite ``A``."""
    if ordering is None:
        lu = spla.splu(A.tocsc(), permc_spec="MMD_ATA")
        return spla.LinearOperator(A.shape, matvec=lu.solve, dtype=float)
    A = A.tocsr()[ordering][:, ordering].tocsc()
    # symmetric positive definite: no pivoting needed, keep the given order
    lu = spla.splu(A, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    inverse = np.empty_like(ordering)
    inverse[ordering] = np.arange(len(ordering))

    def solve(x):
        return lu.solve(x[ordering])[inverse]

    return spla.LinearOperator(A.shape, matvec=solve, dtype=float)
