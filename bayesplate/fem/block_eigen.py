"""Block shift-invert Lanczos for the lowest modes of ``K a = lambda M a``.

The method
----------
With a factorisation of ``A = K - sigma M`` (``sigma < 0``), the operator
``T = A^-1 M`` is self-adjoint in the mass inner product ``<x, y> = x^T M y`` and has the
eigenvalues ``mu = 1 / (lambda - sigma)``: the lowest ``lambda`` are its largest ``mu``,
well separated from the rest. A block of ``p`` M-orthonormal vectors ``V_1`` generates the
block Krylov space ``span{V_1, T V_1, T^2 V_1, ...}``, built one block at a time:

1. ``W = A^-1 (M V_j)``: ONE multi-right-hand-side solve with the LU factors (SuperLU
   works on supernodes with level-3 BLAS: a block of 24 vectors costs about 3x one);
2. full M-reorthogonalisation of ``W`` against every basis vector, twice (classical
   Gram-Schmidt, two passes), with the products ``M V`` kept from the previous steps;
   one sparse product ``M W`` of what is left (the only one per block); then an
   M-orthonormal basis of what is left, from the eigen-decomposition of its M-Gram
   matrix, dropping directions whose M-norm fell below ``DEFLATION`` of the block's
   (deflation: an exactly invariant direction, such as a rigid-body motion put in the
   start block, ends its chain there); the coefficients of both steps are the columns
   of the projected operator ``H = V^T M T V`` (``T V_m = V_m H_m + V_{m+1} S_m E_m^T``);
3. Rayleigh-Ritz: ``H_m y = mu y``; the Ritz pair ``(mu, V_m y)`` has the residual
   ``||T x - mu x||_M = ||S_m y_last||`` (no further product needed); stop when the
   ``n_wanted`` largest Ritz values have ``||S_m y_last|| <= tol * mu``.

The start block is the caller's rigid-body basis (if any: for a free plate ``K R = 0``, so
these are eigenvectors at once and deflate in the first step) and seeded pseudo-random
vectors, so the same matrices give the same numbers every time.

Returns ``None`` when the basis cap is reached before convergence: the caller falls back
to another method.
"""

from __future__ import annotations

import numpy as np

__all__ = ["block_lanczos"]

#: An orthogonalised direction whose M-norm is below this fraction of the block's
#: largest M-norm before orthogonalisation is dropped (it lies in the basis already).
DEFLATION = 1e-10


def _orthonormal_block(W, Z, scale):
    """M-orthonormal basis of ``span W`` (``Z = M W``), small directions dropped.

    Parameters
    ----------
    W, Z : numpy.ndarray, shape (n, p)
        The block and its mass product.
    scale : float
        Reference M-norm for the deflation test.

    Returns
    -------
    Q, MQ : numpy.ndarray, shape (n, q)
        ``Q^T M Q = I``, ``MQ = M Q``, ``q <= p``.
    S : numpy.ndarray, shape (q, p)
        ``W = Q S`` up to the dropped directions.
    """
    G = W.T @ Z
    d, U = np.linalg.eigh((G + G.T) / 2)
    keep = d > (DEFLATION * scale) ** 2
    d, U = d[keep], U[:, keep]
    F = U / np.sqrt(d)
    S = np.sqrt(d)[:, None] * U.T
    return W @ F, Z @ F, S


def block_lanczos(solve, M, n_wanted, block_size, max_dim, tol, start=None, seed=0):
    """Largest eigenpairs of ``T = A^-1 M`` by block Lanczos with full reorthogonalisation.

    Parameters
    ----------
    solve : callable
        ``solve(B)`` returns ``A^-1 B`` for a block ``B`` of shape (n, k).
    M : scipy.sparse matrix, shape (n, n)
        Symmetric positive definite mass.
    n_wanted : int
        Number of eigenpairs to converge (the largest ``mu``).
    block_size : int
        Pseudo-random vectors in the start block, ``p``: the width of every later block
        (less any deflated directions).
    max_dim : int
        Largest basis size: past it the iteration stops without a result.
    tol : float
        Relative residual ``||T x - mu x||_M / mu`` every wanted pair must reach.
    start : numpy.ndarray, shape (n, r), optional
        M-orthonormal vectors put first in the start block, before the ``p`` random ones.
    seed : int
        Seed of the pseudo-random rest of the start block.

    Returns
    -------
    tuple or None
        ``(mu, X, n_solves)``: ``mu`` shape (n_wanted,) descending, ``X`` shape
        (n, n_wanted) M-orthonormal Ritz vectors, and the number of vectors solved for;
        None if ``max_dim`` was reached first.
    """
    n = M.shape[0]
    r = 0 if start is None else start.shape[1]
    width = max_dim + r + block_size
    V = np.empty((n, width), order="F")  # columns contiguous: V[:, :k] is one block of memory
    MV = np.empty_like(V)
    H = np.zeros((width, width))
    W = np.empty((n, r + block_size))
    W[:, r:] = np.random.default_rng(seed).standard_normal((n, block_size))
    if r:
        W[:, :r] = start
    Z = M @ W
    if r:
        # the random part M-orthogonal to the given vectors, twice
        for _ in range(2):
            C = Z[:, :r].T @ W[:, r:]
            W[:, r:] -= W[:, :r] @ C
            Z[:, r:] -= Z[:, :r] @ C
    scale = np.sqrt(np.max(np.einsum("di,di->i", W, Z)))
    Q, MQ, _ = _orthonormal_block(W, Z, scale)
    lo, hi = 0, Q.shape[1]
    V[:, lo:hi], MV[:, lo:hi] = Q, MQ
    n_solves = 0
    while True:
        W = solve(MV[:, lo:hi])
        n_solves += hi - lo
        C = np.zeros((hi, hi - lo))
        for _ in range(2):  # classical Gram-Schmidt, twice
            c = MV[:, :hi].T @ W
            W -= V[:, :hi] @ c
            C += c
        Z = M @ W
        # M-norms of the block before orthogonalisation: its coefficients and what is left
        scale = np.sqrt(np.max(np.sum(C**2, axis=0) + np.einsum("di,di->i", W, Z)))
        Q, MQ, S = _orthonormal_block(W, Z, scale)
        singular = np.linalg.svd(S, compute_uv=False) if S.size else np.ones(1)
        if singular[-1] < 1e-3 * singular[0]:
            # much of the block cancelled: its rounding errors along the basis were
            # magnified, one more pass (W = V C + Q S, Q = V c + Q' S')
            c = MV[:, :hi].T @ Q
            Q -= V[:, :hi] @ c
            MQ -= MV[:, :hi] @ c
            C += c @ S
            Q, MQ, S2 = _orthonormal_block(Q, MQ, 1.0)
            S = S2 @ S
        q = Q.shape[1]
        H[:hi, lo:hi] = C
        H[hi : hi + q, lo:hi] = S
        if hi < n_wanted and q > 0 and hi + q <= max_dim:  # too few vectors yet: no Ritz step
            V[:, hi : hi + q], MV[:, hi : hi + q] = Q, MQ
            lo, hi = hi, hi + q
            continue
        Hm = H[:hi, :hi]
        mu, Y = np.linalg.eigh((Hm + Hm.T) / 2)
        mu, Y = mu[::-1][:n_wanted], Y[:, ::-1][:, :n_wanted]
        residual = np.linalg.norm(S @ Y[lo:hi], axis=0)
        if hi >= n_wanted and np.all(residual <= tol * np.abs(mu)):
            return mu, V[:, :hi] @ Y, n_solves
        if q == 0 or hi + q > max_dim:
            return None
        V[:, hi : hi + q], MV[:, hi : hi + q] = Q, MQ
        lo, hi = hi, hi + q
