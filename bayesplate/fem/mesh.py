"""Uniform rectangular mesh of the plate mid-plane and its degree-of-freedom numbering."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["DOFS_PER_NODE", "DOF_NAMES", "RectangularMesh"]

#: Nodal unknowns, in the order they are numbered at every node.
DOF_NAMES = ("u", "v", "w", "w_x", "w_y", "w_xy", "psi_x", "psi_y")
DOFS_PER_NODE = len(DOF_NAMES)


@dataclass(frozen=True)
class RectangularMesh:
    """``nx`` x ``ny`` equal rectangles on ``[0, a] x [0, b]``.

    Nodes are numbered row by row (x fastest); element nodes counter-clockwise from the
    lower-left corner. Node ``k`` carries the unknowns of :data:`DOF_NAMES` at global
    indices ``8 k .. 8 k + 7``.

    Parameters
    ----------
    a, b : float
        Plate length (x) and width (y) in m.
    nx, ny : int
        Elements along x and y.
    """

    a: float
    b: float
    nx: int
    ny: int

    def __post_init__(self):
        if self.nx < 1 or self.ny < 1:
            raise ValueError(f"mesh = [{self.nx}, {self.ny}]: needs at least one element each way")

    @property
    def dx(self):
        """Element length along x, m."""
        return self.a / self.nx

    @property
    def dy(self):
        """Element length along y, m."""
        return self.b / self.ny

    @property
    def n_nodes(self):
        """Number of nodes."""
        return (self.nx + 1) * (self.ny + 1)

    @property
    def n_elements(self):
        """Number of elements."""
        return self.nx * self.ny

    @property
    def n_dofs(self):
        """Number of unknowns."""
        return DOFS_PER_NODE * self.n_nodes

    @cached_property
    def nodes(self):
        """Node coordinates, shape (n_nodes, 2), m."""
        x = np.linspace(0.0, self.a, self.nx + 1)
        y = np.linspace(0.0, self.b, self.ny + 1)
        X, Y = np.meshgrid(x, y)
        return np.column_stack([X.ravel(), Y.ravel()])

    @cached_property
    def elements(self):
        """Element connectivity, shape (n_elements, 4), counter-clockwise."""
        i, j = np.meshgrid(np.arange(self.nx), np.arange(self.ny))
        n0 = (j * (self.nx + 1) + i).ravel()
        return np.column_stack([n0, n0 + 1, n0 + self.nx + 2, n0 + self.nx + 1])

    @cached_property
    def element_dofs(self):
        """Global unknowns of each element, shape (n_elements, 32), node-major."""
        base = DOFS_PER_NODE * self.elements[:, :, None] + np.arange(DOFS_PER_NODE)
        return base.reshape(self.n_elements, -1)

    @cached_property
    def centroids(self):
        """Element centres, shape (n_elements, 2), m."""
        return self.nodes[self.elements].mean(axis=1)

    def nested_dissection(self, leaf=4):
        """Fill-reducing order of the unknowns by geometric nested dissection.

        The node grid is split recursively across its longer side by a line of nodes that
        is numbered last, down to blocks of about ``leaf`` x ``leaf`` nodes.

        Returns
        -------
        numpy.ndarray of int, shape (n_dofs,)
            A permutation of the global unknowns.
        """
        order = []
        _dissect(0, self.nx + 1, 0, self.ny + 1, self.nx + 1, leaf, order)
        nodes = np.concatenate(order)
        return (DOFS_PER_NODE * nodes[:, None] + np.arange(DOFS_PER_NODE)).ravel()

    def dofs(self, name, nodes=None):
        """Global indices of one unknown at the given nodes (all nodes by default)."""
        nodes = np.arange(self.n_nodes) if nodes is None else np.asarray(nodes)
        return DOFS_PER_NODE * nodes + DOF_NAMES.index(name)

    def edge_nodes(self, edge):
        """Nodes on an edge: ``"x0"`` (x = 0), ``"xa"`` (x = a), ``"y0"``, ``"yb"``."""
        tol = 1e-9 * max(self.a, self.b)
        x, y = self.nodes.T
        where = {"x0": x < tol, "xa": x > self.a - tol, "y0": y < tol, "yb": y > self.b - tol}
        return np.flatnonzero(where[edge])

    def locate(self, points):
        """Element index and local coordinates of points on the plate.

        Parameters
        ----------
        points : array_like, shape (p, 2)
            ``(x, y)`` in m, inside ``[0, a] x [0, b]``.

        Returns
        -------
        element : numpy.ndarray of int, shape (p,)
        local : numpy.ndarray, shape (p, 2)
            ``(xi, eta)`` in ``[-1, 1]``.
        """
        p = np.atleast_2d(np.asarray(points, dtype=float))
        i = np.clip(np.floor(p[:, 0] / self.dx).astype(int), 0, self.nx - 1)
        j = np.clip(np.floor(p[:, 1] / self.dy).astype(int), 0, self.ny - 1)
        xi = 2.0 * (p[:, 0] - (i + 0.5) * self.dx) / self.dx
        eta = 2.0 * (p[:, 1] - (j + 0.5) * self.dy) / self.dy
        return j * self.nx + i, np.column_stack([xi, eta])


def _dissect(i0, i1, j0, j1, row, leaf, order):
    """Append the nodes of the block [i0, i1) x [j0, j1) in nested-dissection order."""
    ni, nj = i1 - i0, j1 - j0
    if ni * nj <= leaf * leaf or min(ni, nj) < 3:
        order.append((np.arange(j0, j1)[:, None] * row + np.arange(i0, i1)).ravel())
    elif ni >= nj:
        mid = (i0 + i1) // 2
        _dissect(i0, mid, j0, j1, row, leaf, order)
        _dissect(mid + 1, i1, j0, j1, row, leaf, order)
        order.append(np.arange(j0, j1) * row + mid)
    else:
        mid = (j0 + j1) // 2
        _dissect(i0, i1, j0, mid, row, leaf, order)
        _dissect(i0, i1, mid + 1, j1, row, leaf, order)
        order.append(mid * row + np.arange(i0, i1))
