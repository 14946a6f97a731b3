"""The 4-node rectangle of Reddy's third-order theory (Daghia et al. 2007, section 3.5).

``u0, v0, psi_x, psi_y`` are bilinear (Lagrange); ``w0`` is the bicubic Hermite
(Bogner-Fox-Schmit) field with ``w, w_x, w_y, w_xy`` at each node, so that ``w0`` is C1 across
element edges. Shape functions are written in local coordinates ``(xi, eta)`` in
``[-1, 1]^2``, never through a global Vandermonde inverse.

The element matrices are contractions of material matrices with geometric kernels:

    K_e = int_e B^T C B dA = sum_ab C_ab G_ab,   G_ab = int_e B_a^T B_b dA
    M_e = int_e N^T R N dA = sum_ab R_ab H_ab,   H_ab = int_e N_a^T N_b dA

with ``B`` the generalised-strain operator (11 rows, eq. 15), ``N`` the generalised
displacement operator (7 rows) and ``C``, ``R`` from :mod:`bayesplate.laminate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .mesh import DOF_NAMES, DOFS_PER_NODE

__all__ = ["CORNERS", "TSDTRectangle", "gauss_rule"]

#: Local coordinates of the element's nodes, counter-clockwise from the lower-left corner.
CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_N_LOCAL = 4 * DOFS_PER_NODE
_U, _V, _W, _WX, _WY, _WXY, _PX, _PY = range(DOFS_PER_NODE)
assert DOF_NAMES[_PY] == "psi_y"


def gauss_rule(n):
    """Tensor Gauss-Legendre rule on ``[-1, 1]^2``: points (n^2, 2) and weights (n^2,)."""
    s, w = np.polynomial.legendre.leggauss(n)
    S, T = np.meshgrid(s, s, indexing="ij")
    return np.column_stack([S.ravel(), T.ravel()]), np.outer(w, w).ravel()


def _hermite(s, s_node):
    """1-D cubic Hermite functions of the node at ``s_node`` = +-1, in local units.

    Returns an array (2, 3, p): [value function, slope function] x [f, df/ds, d2f/ds2].
    """
    one = np.ones_like(s)
    value = [
        (2 + 3 * s_node * s - s_node * s**3) / 4,
        3 * s_node * (1 - s**2) / 4,
        -6 * s_node * s / 4,
    ]
    slope = [
        (-s_node - s + s_node * s**2 + s**3) / 4,
        (-1 + 2 * s_node * s + 3 * s**2) / 4,
        (2 * s_node + 6 * s) / 4 * one,
    ]
    return np.array([value, slope])


@dataclass(frozen=True)
class TSDTRectangle:
    """Rectangle of size ``dx`` x ``dy`` (m) for the third-order plate theory.

    Parameters
    ----------
    dx, dy : float
        Element sides in m.
    order : int
        Gauss points per direction; 4 integrates every term exactly.
    shear_order : int, optional
        Gauss points per direction for the transverse-shear terms; default ``order``
        (exact integration, as the paper's displacement element).
    """

    dx: float
    dy: float
    order: int = 4
    shear_order: int | None = None

    def fields(self, local, names=None):
        """Values and physical derivatives of every field at local points.

        Parameters
        ----------
        local : array_like, shape (p, 2)
        names : collection of str, optional
            Only these fields (default: all).

        Returns
        -------
        dict of numpy.ndarray, each shape (p, 32)
            Keys ``u, u_x, u_y, v, ..., w, w_x, w_y, w_xx, w_yy, w_xy, psi_x, psi_x_x, ...``:
            the field (or derivative) produced by a unit value of each local unknown.
        """
        local = np.atleast_2d(local)
        xi, eta = local[:, 0], local[:, 1]
        hx, hy = self.dx / 2, self.dy / 2
        p = len(xi)
        if names is None:
            names = [
                name + suffix
                for name in ("u", "v", "psi_x", "psi_y")
                for suffix in ("", "_x", "_y")
            ]
            names += ["w", "w_x", "w_y", "w_xx", "w_yy", "w_xy"]
        out = {name: np.zeros((p, _N_LOCAL)) for name in names}
        lagrange = any(not name.startswith("w") for name in out)
        hermite = any(name.startswith("w") for name in out)
        for node, (sx, sy) in enumerate(CORNERS):
            base = DOFS_PER_NODE * node
            if lagrange:
                lag = (1 + sx * xi) * (1 + sy * eta) / 4
                lag_x = sx * (1 + sy * eta) / 4 / hx
                lag_y = sy * (1 + sx * xi) / 4 / hy
                for name, k in (("u", _U), ("v", _V), ("psi_x", _PX), ("psi_y", _PY)):
                    for suffix, value in (("", lag), ("_x", lag_x), ("_y", lag_y)):
                        if name + suffix in out:
                            out[name + suffix][:, base + k] = value
            if not hermite:
                continue
            Hx, Hy = _hermite(xi, sx), _hermite(eta, sy)
            # (x function, y function, scale of the unknown in local units)
            for k, ix, iy, scale in (
                (_W, 0, 0, 1.0),
                (_WX, 1, 0, hx),
                (_WY, 0, 1, hy),
                (_WXY, 1, 1, hx * hy),
            ):
                fx, fy = Hx[ix], Hy[iy]
                col = base + k
                values = {  # (each product in the order it always had: the same bits)
                    "w": scale * fx[0] * fy[0],
                    "w_x": scale * fx[1] * fy[0] / hx,
                    "w_y": scale * fx[0] * fy[1] / hy,
                    "w_xx": scale * fx[2] * fy[0] / hx**2,
                    "w_yy": scale * fx[0] * fy[2] / hy**2,
                    "w_xy": scale * fx[1] * fy[1] / (hx * hy),
                }
                for name, value in values.items():
                    if name in out:
                        out[name][:, col] = value
        return out

    def strain_operator(self, local):
        """Generalised strains of eq. (15) per unit local unknown, shape (p, 11, 32).

        Rows: ``eps0 (x, y, xy), chi (x, y, xy), chih (x, y, xy), gamma (yz, xz)``.
        """
        f = self.fields(local)
        rows = [
            # eps0 (x, y, xy)
            f["u_x"],
            f["v_y"],
            f["u_y"] + f["v_x"],
            # chi (x, y, xy)
            f["psi_x_x"],
            f["psi_y_y"],
            f["psi_x_y"] + f["psi_y_x"],
            # chih (x, y, xy)
            f["psi_x_x"] + f["w_xx"],
            f["psi_y_y"] + f["w_yy"],
            f["psi_x_y"] + f["psi_y_x"] + 2 * f["w_xy"],
            # gamma (yz, xz)
            f["w_y"] + f["psi_y"],
            f["w_x"] + f["psi_x"],
        ]
        return np.stack(rows, axis=1)

    def displacement_operator(self, local):
        """Generalised displacements per unit local unknown, shape (p, 7, 32).

        Rows: ``u0, psi_x, psi_x + w_x, v0, psi_y, psi_y + w_y, w0`` (see
        :func:`bayesplate.laminate.inertia_matrix`).
        """
        f = self.fields(local)
        rows = [
            f["u"],
            f["psi_x"],
            f["psi_x"] + f["w_x"],
            f["v"],
            f["psi_y"],
            f["psi_y"] + f["w_y"],
            f["w"],
        ]
        return np.stack(rows, axis=1)

    def _kernel(self, operator, n):
        points, weights = gauss_rule(n)
        Bq = operator(points)
        jac = self.dx * self.dy / 4
        return np.einsum("q,qai,qbj->abij", weights * jac, Bq, Bq)

    @cached_property
    def stiffness_kernel(self):
        """``G_ab = int B_a^T B_b dA``, shape (11, 11, 32, 32), in m^2 x strain units."""
        G = self._kernel(self.strain_operator, self.order)
        if self.shear_order is not None and self.shear_order != self.order:
            G[9:, 9:] = self._kernel(self.strain_operator, self.shear_order)[9:, 9:]
        return G

    @cached_property
    def mass_kernel(self):
        """``H_ab = int N_a^T N_b dA``, shape (7, 7, 32, 32)."""
        return self._kernel(self.displacement_operator, self.order)

    def stiffness(self, C):
        """Element stiffness for constitutive matrices ``C`` of shape (..., 11, 11)."""
        return np.einsum("...ab,abij->...ij", C, self.stiffness_kernel, optimize=True)

    def mass(self, R):
        """Element mass for inertia matrices ``R`` of shape (..., 7, 7)."""
        return np.einsum("...ab,abij->...ij", R, self.mass_kernel, optimize=True)
