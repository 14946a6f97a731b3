"""Weighted sums of projected element matrices: a region's share of a reduced model.

A local candidate (a damaged patch, a hole, a cut corner) changes the plate inside a region:
its reduced matrices are the nominal ones plus ``sum_e w_e V_e^T A_t V_e`` over the elements
the region touches, ``w_e`` the share of each element inside. :class:`RegionProjection` keeps
each element's projected matrices once computed, so that a new weighting costs a weighted
sum (:mod:`.reduced_model`'s pencils evaluate one at each step of a fit).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

__all__ = ["RegionProjection"]

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
        r = basis.shape[1]
        # an element's products are symmetric: kept as their upper triangles (row by row),
        # which halves what a weighted sum reads: a 12 x 6 patch of the 40 x 20 Frederiksen
        # plate, r = 90, seven matrices, its sum 3.6-4.0 ms by whole matrices and 2.0-2.2 ms
        # by triangles (the unpacking included), a sum over its moved edges 2.0-2.2 and 1.3 ms
        self._upper = np.triu_indices(r)
        unpacking = np.empty((r, r), dtype=np.intp)  # (i, j) -> its triangle's entry
        unpacking[self._upper] = unpacking.T[self._upper] = np.arange(self._upper[0].size)
        self._unpacking = unpacking.ravel()  # row by row, for ``np.take``
        shape = (len(self.dofs), len(self._slices), self._upper[0].size)
        self._projected = np.empty(shape)  # filled element by element (pages on first touch)
        self._done = np.zeros(len(self.dofs), dtype=bool)
        self._whole = {}  # sums of sets of whole elements, by the set; least recently used first
        self._last = None  # (fractions, result) of the last call of ``inside``

    def __call__(self, weights):
        """The weighted sum, shape (T, r, r); ``weights`` shape (n_elements,)."""
        weights = np.asarray(weights, dtype=float)
        inside = np.flatnonzero(weights)
        self._fill(inside)
        return self._unpack(self._sum(inside, weights))

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
        out = self._unpack(out)
        self._last = (fractions.copy(), out)
        return out.copy()

    def _fill(self, inside):
        """Project the elements of ``inside`` not yet projected."""
        new = inside[~self._done[inside]]
        if new.size:
            G = self._factors_t @ self.basis[self.dofs[new]]  # (n, sum of ranks, r)
            SG = G * self._signs[:, None]
            i, j = self._upper
            for t, part in enumerate(self._slices):
                self._projected[new, t] = (SG[:, part].transpose(0, 2, 1) @ G[:, part])[:, i, j]
            self._done[new] = True

    def _unpack(self, flat):
        """The (T, r, r) symmetric matrices of a flat sum of upper triangles (T r (r+1) / 2,)."""
        T, r = self._projected.shape[1], self.basis.shape[1]
        return np.take(flat.reshape(T, -1), self._unpacking, axis=1).reshape(T, r, r)

    def _sum(self, inside, weights):
        """``sum_e weights_e P_e`` over ``inside`` (sorted, projected): upper triangles, flat."""
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
