"""Submatrices on a fixed set of unknowns, straight from assembled CSR data.

Every matrix of a mesh shares one sparsity pattern (:class:`bayesplate.fem.assembly.Assembler`),
so the submatrix on a fixed, ordered set of unknowns (the free ones, say, in a fill-reducing
order) has a fixed pattern too: one index map per format, built once, turns the assembled
``data`` array into the submatrix's with a single gather, with no slicing, conversion or
sorting per matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["SubPattern"]


class SubPattern:
    """Index maps from assembled CSR data to the submatrix on ``dofs``.

    Parameters
    ----------
    assembler : bayesplate.fem.assembly.Assembler
        The shared pattern.
    dofs : numpy.ndarray of int, shape (k,)
        The unknowns kept, in the order wanted (8 per node in the mesh numbering).

    Attributes
    ----------
    dofs : numpy.ndarray of int, shape (k,)
    node_size : int or None
        Unknowns per node when every node in ``dofs`` has the same number of them, one
        after the other (the submatrix then has square node blocks); None otherwise.
    """

    def __init__(self, assembler, dofs, dofs_per_node=8):
        self.dofs = np.asarray(dofs)
        self.shape = (len(self.dofs), len(self.dofs))
        nnz = assembler.nnz
        # the positions in the data, as values (exact in float64 below 2^53), moved by
        # scipy's own slicing and conversions: what lands where is the map
        sub = assembler.matrix(np.arange(1.0, nnz + 1.0))[self.dofs][:, self.dofs]
        sub.sort_indices()
        csc = sub.tocsc()
        csc.sort_indices()
        self._csr = (sub.data.astype(np.int64) - 1, sub.indices, sub.indptr)
        self._csc = (csc.data.astype(np.int64) - 1, csc.indices, csc.indptr)
        self._bsr = None
        nodes = self.dofs // dofs_per_node
        size = int(np.sum(nodes == nodes[0])) if len(nodes) else 0
        self.node_size = None
        if size and len(nodes) % size == 0:
            if np.all(nodes.reshape(-1, size) == nodes[::size, None]):
                self.node_size = size
                bsr = sub.tobsr(blocksize=(size, size))
                # padding inside the blocks reads index -1: a zero appended to the data
                self._bsr = (bsr.data.astype(np.int64) - 1, bsr.indices, bsr.indptr)

    def csr(self, data):
        """The submatrix of the assembled ``data`` (shape (nnz,)), CSR."""
        index, indices, indptr = self._csr
        return sp.csr_matrix((data[index], indices, indptr), shape=self.shape)

    def csc(self, data):
        """The submatrix of the assembled ``data`` (shape (nnz,)), CSC."""
        index, indices, indptr = self._csc
        return sp.csc_matrix((data[index], indices, indptr), shape=self.shape)

    def blocked(self, data):
        """The submatrix in node blocks (BSR, faster products) if it has them, else CSR."""
        if self._bsr is None:
            return self.csr(data)
        index, indices, indptr = self._bsr
        padded = np.append(data, 0.0)
        return sp.bsr_matrix((padded[index], indices, indptr), shape=self.shape)
