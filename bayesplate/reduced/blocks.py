"""The reduced eigenproblem as independent small dense blocks, one per packed symmetry class.

Each evaluation of the reduced model solves ``(sum_j b_j T_j + T_0) x = lambda x`` block by
block, with LAPACK's symmetric solvers, and takes the lowest pairs over all blocks.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

# syevr (some pairs) beats syevd (all pairs) when fewer than 1/_SUBSET_FRACTION are wanted.
_SUBSET_FRACTION = 6


class _Blocks:
    """The reduced eigenproblem as independent blocks, small groups packed together.

    Groups of basis vectors that no term couples (the symmetry classes) are packed, largest
    first, into bins no larger than the largest group; each bin is one dense symmetric
    eigenproblem.

    Parameters
    ----------
    groups : list of numpy.ndarray of int
        Column indices of each group.
    terms : numpy.ndarray, shape (6, r, r)
    constant : numpy.ndarray, shape (r, r), or None
    n_rigid : int
        The first ``n_rigid`` columns are the rigid-body motions.
    """

    def __init__(self, groups, terms, constant, n_rigid):
        self.group_sizes = tuple(len(g) for g in groups)
        self.cols = _pack(groups)
        label = np.empty(terms.shape[1], dtype=int)
        for i, g in enumerate(groups):
            label[g] = i
        # groups packed into one bin are exactly decoupled: drop the rounding between them
        same = [label[c][:, None] == label[c][None, :] for c in self.cols]
        self.terms = [terms[:, c][:, :, c] * m for c, m in zip(self.cols, same, strict=True)]
        self.stacked = [T.reshape(6, -1) for T in self.terms]
        self.constant = [
            None if constant is None else constant[np.ix_(c, c)] * m
            for c, m in zip(self.cols, same, strict=True)
        ]
        self.on_rigid = [c < n_rigid for c in self.cols]
        # without a stiffness independent of b, K_j r = 0 for every rigid-body motion r: the
        # rigid modes are the near-zero eigenvalues, found without eigenvectors
        self.rigid_at_zero = constant is None

    @property
    def bin_sizes(self):
        """Sizes of the dense eigenproblems solved per evaluation."""
        return tuple(len(c) for c in self.cols)

    def lowest(self, b, k):
        """The ``k`` lowest eigenpairs over all bins, ascending.

        Returns
        -------
        values : numpy.ndarray, shape (k,)
        where, index : numpy.ndarray of int, shape (k,)
            Bin of each pair and its column in that bin's eigenvectors.
        vectors : list of numpy.ndarray, shape (size_c, k_c)
            Eigenvectors of each bin.
        rigid : numpy.ndarray of bool, shape (k,)
            Mostly rigid: M-projection on the rigid-body motions above one half.
        """
        values, where, index, vectors, rigid = [], [], [], [], []
        for c, (cols, S, C, on_rigid) in enumerate(
            zip(self.cols, self.stacked, self.constant, self.on_rigid, strict=True)
        ):
            A = (b @ S).reshape(len(cols), len(cols))
            if C is not None:
                A += C
            w, x = _lowest_eigh(A, min(k, len(cols)))
            values.append(w)
            where.append(np.full(len(w), c))
            index.append(np.arange(len(w)))
            vectors.append(x)
            rigid.append(np.sum(x[on_rigid] ** 2, axis=0) > 0.5)
        values = np.concatenate(values)
        order = np.argsort(values, kind="stable")[:k]
        return (
            values[order],
            np.concatenate(where)[order],
            np.concatenate(index)[order],
            vectors,
            np.concatenate(rigid)[order],
        )

    def lowest_values(self, b, k):
        """The ``k`` lowest eigenvalues over all bins, ascending, shape (k,)."""
        values = []
        for cols, S, C in zip(self.cols, self.stacked, self.constant, strict=True):
            A = (b @ S).reshape(len(cols), len(cols))
            if C is not None:
                A += C
            w, _, info = lapack.dsyev(A.T, compute_v=0, overwrite_a=1)
            if info != 0:
                raise np.linalg.LinAlgError(f"symmetric eigensolver failed (info = {info})")
            values.append(w[:k])
        return np.sort(np.concatenate(values))[:k]

    def modes(self, where, index, vectors, r):
        """Coefficients in the whole basis and sensitivities of some eigenpairs.

        Parameters
        ----------
        where, index : numpy.ndarray of int, shape (n,)
            Bin and column of each pair, as from :meth:`lowest`.
        vectors : list of numpy.ndarray
            Eigenvectors of each bin, as from :meth:`lowest`.
        r : int
            Basis size.

        Returns
        -------
        coefficients : numpy.ndarray, shape (r, n)
        sensitivities : numpy.ndarray, shape (n, 6)
            ``x^T T_j x`` (eq. 28 in the basis).
        """
        n = len(where)
        coefficients = np.zeros((r, n))
        sensitivities = np.empty((n, 6))
        for c in np.unique(where):
            sel = np.flatnonzero(where == c)
            x = vectors[c][:, index[sel]]
            size = len(x)
            Tx = (self.terms[c].reshape(6 * size, size) @ x).reshape(6, size, -1)
            sensitivities[sel] = np.einsum("jai,ai->ij", Tx, x)
            coefficients[np.ix_(self.cols[c], sel)] = x
        return coefficients, sensitivities


def _lowest_eigh(A, k):
    """Lowest ``k`` eigenpairs of a small dense symmetric matrix.

    LAPACK through SciPy (NumPy's ``eigh`` spawns threads that cost ten times the work on a
    busy machine): syevr for a few pairs of a larger matrix, syevd for all pairs otherwise
    (faster from about a sixth of the spectrum on).
    """
    # A is symmetric, so its transpose is the Fortran-ordered array LAPACK wants
    if k * _SUBSET_FRACTION <= len(A):
        w, x, m, _, info = lapack.dsyevr(A.T, compute_v=1, range="I", il=1, iu=k, overwrite_a=1)
    else:
        w, x, info = lapack.dsyevd(A.T, compute_v=1, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"symmetric eigensolver failed (info = {info})")
    return w[:k], x[:, :k]


def _pack(groups):
    """Groups of columns packed first-fit, largest first, into bins of the largest size."""
    capacity = max(len(g) for g in groups)
    bins = []
    for g in sorted(groups, key=len, reverse=True):
        for b in bins:
            if len(b) + len(g) <= capacity:
                b.extend(g.tolist())
                break
        else:
            bins.append(g.tolist())
    return [np.array(b) for b in bins]
