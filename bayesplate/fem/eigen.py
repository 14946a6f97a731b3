"""Lowest natural modes of ``K a = lambda M a`` by shift-invert Lanczos.

Two methods share one factorisation of ``K - sigma M`` and one set of rules (rigid-body
modes detected and dropped, mass-normalised vectors, Rayleigh-quotient eigenvalues):

- ``"block"`` (default): block Lanczos with full M-reorthogonalisation
  (:mod:`bayesplate.fem.block_eigen`): a few multi-right-hand-side solves, which SuperLU does
  with level-3 BLAS, instead of many single ones; rigid-body motions seed the start block;
- ``"arpack"``: ARPACK's implicitly restarted Lanczos (``scipy.sparse.linalg.eigsh``), one
  vector at a time; the block method falls back to it, with a warning, if it does not
  converge within its basis cap.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla
from threadpoolctl import ThreadpoolController

from .block_eigen import block_lanczos

__all__ = ["METHODS", "EigenSolution", "lowest_modes"]

log = logging.getLogger(__name__)

#: Eigenvalues with ``|lambda| <= RIGID_TOL * max |lambda|`` are rigid-body modes.
RIGID_TOL = 1e-7
METHODS = ("block", "arpack")
#: Pseudo-random vectors in the block method's start block (the width of its blocks).
BLOCK_SIZE = 4
#: Relative residual ``||T x - mu x||_M / mu`` of the block method's Ritz pairs, with
#: ``T = (K - sigma M)^-1 M``: eigenvalues then agree with ARPACK's to about 1e-12.
BLOCK_TOL = 1e-8
#: BLAS threads during the solve: SuperLU and the Lanczos work on vectors and small blocks,
#: where threads only contend (benchmarks/bench_forward.py measures 1 against 2).
BLAS_THREADS = 1


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


def lowest_modes(
    K,
    M,
    n_modes,
    shift,
    n_rigid_max=6,
    ordering=None,
    rigid_basis=None,
    method="block",
    shifted=None,
    max_dim=None,
):
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
    ordering : numpy.ndarray of int or "given", optional
        Fill-reducing symmetric permutation of the unknowns for the factorisation of
        ``K - sigma M`` (for example nested dissection); ``"given"`` if the unknowns are in
        such an order already; SuperLU's own ordering otherwise.
    rigid_basis : numpy.ndarray, shape (n_dofs, r), optional
        M-orthonormal rigid-body motions. A mode whose mass-weighted projection on them
        exceeds one half is also counted as rigid, even if its eigenvalue is not near zero
        (a plate on a soft support bounces at a small but finite frequency). The block
        method also starts from them.
    method : {"block", "arpack"}
        Block Lanczos (default) or ARPACK; see the module docstring.
    shifted : scipy.sparse.csc_matrix, shape (n_dofs, n_dofs), optional
        ``K - shift M`` if the caller has it already (it is formed otherwise).
    max_dim : int, optional
        Basis cap of the block method (default ``max(8 (n_modes + n_rigid_max), 80)``);
        past it the block method gives up and ARPACK runs instead.

    Returns
    -------
    EigenSolution
    """
    if shift >= 0:
        raise ValueError(f"shift = {shift}: must be negative so that K - shift M is definite")
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {METHODS}")
    n = K.shape[0]
    A = K - shift * M if shifted is None else shifted
    # ARPACK with OpenBLAS's default threads: measured 3x to 7x slower on a loaded 2-core
    # machine
    with _blas().limit(limits=BLAS_THREADS, user_api="blas"):
        solve = _shift_invert(A, ordering)
        found = None
        if method == "block":
            wanted = min(n_modes + n_rigid_max, n - 1)
            cap = min(n, max_dim or max(8 * wanted, 80))
            found = block_lanczos(solve, M, wanted, BLOCK_SIZE, cap, BLOCK_TOL, rigid_basis)
            if found is None:
                log.warning("block Lanczos did not converge within %d vectors: ARPACK instead", cap)
            else:
                mu, vecs, _ = found
                vals = shift + 1.0 / mu
        if found is None:
            k = min(n_modes + n_rigid_max + 2, n - 1)
            op = spla.LinearOperator(A.shape, matvec=solve, dtype=float)
            # a fixed pseudo-random start: the same matrices give the same numbers every time
            v0 = np.random.default_rng(0).standard_normal(n)
            vals, vecs = spla.eigsh(
                K, k=k, M=M, sigma=shift, OPinv=op, which="LM", tol=1e-10, v0=v0
            )
        order = np.argsort(vals, kind="stable")
        vals, vecs = vals[order], vecs[:, order]
        rigid = np.abs(vals) <= RIGID_TOL * np.max(np.abs(vals))
        if rigid_basis is not None:
            projection = np.sum((rigid_basis.T @ (M @ vecs)) ** 2, axis=0)
            rigid |= projection > 0.5 * np.einsum("di,di->i", vecs, M @ vecs)
        if rigid.sum() > n_rigid_max:
            log.warning(
                "%d near-zero eigenvalues found, at most %d expected", rigid.sum(), n_rigid_max
            )
        elastic = np.flatnonzero(~rigid)[:n_modes]
        vecs = vecs[:, elastic]
        # Rayleigh quotients: eigenvalues to second order in the residual of the Ritz vectors
        vecs /= np.sqrt(np.einsum("di,di->i", vecs, M @ vecs))
        refined = np.einsum("di,di->i", vecs, K @ vecs)
    return EigenSolution(refined, vecs, vals[rigid])


def _blas():
    """One thread-pool controller for the process (making one inspects the libraries, ~5 ms)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


_CONTROLLER = None


def _shift_invert(A, ordering):
    """``X -> A^-1 X`` (one vector or a block) by a sparse LU of the definite ``A``."""
    if ordering is None:
        lu = spla.splu(A.tocsc(), permc_spec="MMD_ATA")
        return lu.solve
    # symmetric positive definite: no pivoting needed, keep the given order
    options = {"permc_spec": "NATURAL", "diag_pivot_thresh": 0.0}
    if isinstance(ordering, str):
        if ordering != "given":
            raise ValueError(f"ordering = {ordering!r}: an array or 'given'")
        return spla.splu(A.tocsc(), **options, options={"SymmetricMode": True}).solve
    lu = spla.splu(
        A.tocsr()[ordering][:, ordering].tocsc(), **options, options={"SymmetricMode": True}
    )
    inverse = np.empty_like(ordering)
    inverse[ordering] = np.arange(len(ordering))

    def solve(x):
        return lu.solve(x[ordering])[inverse]

    return solve
