"""Lamina and laminate mechanics of Reddy's third-order theory (Daghia et al. 2007, eqs. 16-25).

Everything here is SI (Pa, m, kg/m^3) and pure array computation.

The lamina is described by its six stiffness coefficients in material axes,
``b = (C11, C22, C12, C66, C44, C55)`` (eqs. 20-21), the parameters the estimators work on.
The engineering constants are ``e = (E1, E2, nu12, G12, G13, G23)`` in the order of
:data:`bayesplate.quantities.ENGINEERING_NAMES`; names, units and covariance
transforms live in :mod:`bayesplate.quantities`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "LaminateMatrices",
    "higher_order_coefficient",
    "stiffness_from_engineering",
    "engineering_from_stiffness",
    "stiffness_jacobian",
    "is_physical",
    "lamina_matrices",
    "rotate_lamina",
    "ply_interfaces",
    "laminate_matrices",
    "inertias",
    "constitutive_matrix",
    "inertia_matrix",
]


def higher_order_coefficient(h):
    """Return Reddy's ``c = -4 / (3 h^2)`` (eq. 14) for thickness ``h`` in m."""
    return -4.0 / (3.0 * np.asarray(h, dtype=float) ** 2)


def stiffness_from_engineering(e):
    """Reduced lamina stiffnesses from engineering constants (eqs. 20-21).

    Parameters
    ----------
    e : array_like, shape (..., 6)
        ``(E1, E2, nu12, G12, G13, G23)`` in Pa (nu12 dimensionless).

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa, with ``C44 = G23`` and ``C55 = G13``.
    """
    e = np.asarray(e, dtype=float)
    E1, E2, nu12, G12, G13, G23 = np.moveaxis(e, -1, 0)
    nu21 = nu12 * E2 / E1
    denom = 1.0 - nu12 * nu21
    return np.stack([E1 / denom, E2 / denom, nu12 * E2 / denom, G12, G23, G13], axis=-1)


def engineering_from_stiffness(b):
    """Engineering constants from reduced lamina stiffnesses (inverse of eqs. 20-21).

    Parameters
    ----------
    b : array_like, shape (..., 6)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa.

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        ``(E1, E2, nu12, G12, G13, G23)``; nu12 = C12 / C22, nu21 = C12 / C11.
    """
    b = np.asarray(b, dtype=float)
    C11, C22, C12, C66, C44, C55 = np.moveaxis(b, -1, 0)
    factor = 1.0 - C12**2 / (C11 * C22)
    return np.stack([C11 * factor, C22 * factor, C12 / C22, C66, C55, C44], axis=-1)


def stiffness_jacobian(e):
    """Jacobian ``d b / d e`` of :func:`stiffness_from_engineering`.

    Used for first-order propagation of the prior deviations of the engineering constants
    to the stiffness coefficients, and for the chain rule of the sensitivities.

    Parameters
    ----------
    e : array_like, shape (..., 6)
        Engineering constants in Pa.

    Returns
    -------
    numpy.ndarray, shape (..., 6, 6)
        ``J[..., i, j] = d b_i / d e_j``.
    """
    e = np.asarray(e, dtype=float)
    E1, E2, nu12 = e[..., 0], e[..., 1], e[..., 2]
    r = E2 / E1
    denom = 1.0 - nu12**2 * r
    # d(1/denom)/dE1 = -nu12^2 E2 / E1^2 / denom^2 ; d/dE2 = nu12^2 / E1 / denom^2
    dinv_dE1 = -(nu12**2) * E2 / E1**2 / denom**2
    dinv_dE2 = nu12**2 / E1 / denom**2
    dinv_dnu = 2.0 * nu12 * r / denom**2
    J = np.zeros(e.shape + (6,))
    J[..., 0, 0] = 1.0 / denom + E1 * dinv_dE1
    J[..., 0, 1] = E1 * dinv_dE2
    J[..., 0, 2] = E1 * dinv_dnu
    J[..., 1, 0] = E2 * dinv_dE1
    J[..., 1, 1] = 1.0 / denom + E2 * dinv_dE2
    J[..., 1, 2] = E2 * dinv_dnu
    J[..., 2, 0] = nu12 * E2 * dinv_dE1
    J[..., 2, 1] = nu12 / denom + nu12 * E2 * dinv_dE2
    J[..., 2, 2] = E2 / denom + nu12 * E2 * dinv_dnu
    J[..., 3, 3] = 1.0  # C66 = G12
    J[..., 4, 5] = 1.0  # C44 = G23
    J[..., 5, 4] = 1.0  # C55 = G13
    return J


def is_physical(b):
    """Whether stiffness coefficients describe a positive-definite lamina.

    Parameters
    ----------
    b : array_like, shape (..., 6)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa.

    Returns
    -------
    bool or numpy.ndarray of bool, shape (...)
    """
    b = np.asarray(b, dtype=float)
    C11, C22, C12, C66, C44, C55 = np.moveaxis(b, -1, 0)
    ok = (C11 > 0) & (C22 > 0) & (C11 * C22 - C12**2 > 0) & (C66 > 0) & (C44 > 0) & (C55 > 0)
    return ok & np.all(np.isfinite(b), axis=-1)


def lamina_matrices(b):
    """In-plane and transverse-shear stiffness of a lamina in material axes (eq. 22).

    Parameters
    ----------
    b : array_like, shape (6,)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa.

    Returns
    -------
    Q : numpy.ndarray, shape (3, 3)
        Acting on ``(eps_1, eps_2, gamma_12)``.
    Qs : numpy.ndarray, shape (2, 2)
        Acting on ``(gamma_23, gamma_13)``.
    """
    C11, C22, C12, C66, C44, C55 = np.asarray(b, dtype=float)
    Q = np.array([[C11, C12, 0.0], [C12, C22, 0.0], [0.0, 0.0, C66]])
    Qs = np.diag([C44, C55])
    return Q, Qs


def rotate_lamina(Q, Qs, angle_deg):
    """Lamina stiffness in plate axes for a ply at ``angle_deg`` from x.

    Parameters
    ----------
    Q : numpy.ndarray, shape (3, 3)
    Qs : numpy.ndarray, shape (2, 2)
    angle_deg : float
        Fibre (material 1) direction, counter-clockwise from x, in degrees.

    Returns
    -------
    Qbar : numpy.ndarray, shape (3, 3)
        Acting on ``(eps_x, eps_y, gamma_xy)``.
    Qsbar : numpy.ndarray, shape (2, 2)
        Acting on ``(gamma_yz, gamma_xz)``.
    """
    t = np.deg2rad(angle_deg)
    c, s = np.cos(t), np.sin(t)
    # engineering strains in material axes from plate axes
    T = np.array(
        [[c * c, s * s, c * s], [s * s, c * c, -c * s], [-2 * c * s, 2 * c * s, c * c - s * s]]
    )
    R = np.array([[c, -s], [s, c]])  # (gamma_23, gamma_13) from (gamma_yz, gamma_xz)
    return T.T @ Q @ T, R.T @ Qs @ R


def ply_interfaces(thicknesses):
    """Z coordinates of the ply interfaces, from ``-h/2`` upward.

    Parameters
    ----------
    thicknesses : array_like, shape (n_plies,)
        Ply thicknesses in m, bottom ply first.

    Returns
    -------
    numpy.ndarray, shape (n_plies + 1,)
    """
    t = np.asarray(thicknesses, dtype=float)
    z = np.concatenate([[0.0], np.cumsum(t)])
    return z - z[-1] / 2.0


@dataclass(frozen=True)
class LaminateMatrices:
    """Through-thickness stiffness integrals of Reddy's theory (eqs. 24-25).

    Attributes
    ----------
    Cf : numpy.ndarray, shape (7, 3, 3)
        ``Cf[q] = sum_L int Qbar_L z^q dz`` for ``q = 0..6`` (Pa m^(q+1)).
    Cs : numpy.ndarray, shape (5, 2, 2)
        ``Cs[q] = sum_L int Qsbar_L z^q dz`` for ``q = 0..4`` (odd q kept for completeness).
    c : float
        ``-4 / (3 h^2)`` in 1/m^2.
    """

    Cf: np.ndarray
    Cs: np.ndarray
    c: float


def _moments(z, q):
    """``int z^q dz`` over each ply, shape (n_plies,)."""
    return (z[1:] ** (q + 1) - z[:-1] ** (q + 1)) / (q + 1)


def laminate_matrices(b, angles_deg, thicknesses):
    """Laminate stiffness integrals ``C_f^(q)``, ``C_s^(q)`` (eqs. 24-25).

    Parameters
    ----------
    b : array_like, shape (6,)
        Lamina stiffness coefficients in Pa (all plies share one material).
    angles_deg : array_like, shape (n_plies,)
        Ply angles from the bottom face upward, degrees.
    thicknesses : array_like, shape (n_plies,)
        Ply thicknesses in m.

    Returns
    -------
    LaminateMatrices
    """
    Q, Qs = lamina_matrices(b)
    z = ply_interfaces(thicknesses)
    rotated = [rotate_lamina(Q, Qs, a) for a in angles_deg]
    Qbar = np.array([r[0] for r in rotated])
    Qsbar = np.array([r[1] for r in rotated])
    Cf = np.array([np.einsum("l,lij->ij", _moments(z, q), Qbar) for q in range(7)])
    Cs = np.array([np.einsum("l,lij->ij", _moments(z, q), Qsbar) for q in range(5)])
    return LaminateMatrices(Cf=Cf, Cs=Cs, c=float(higher_order_coefficient(z[-1] - z[0])))


def inertias(density, thicknesses):
    """Mass moments ``I_i = sum_L int rho z^i dz`` for ``i = 0..6``.

    Parameters
    ----------
    density : float
        kg/m^3, shared by all plies.
    thicknesses : array_like, shape (n_plies,)
        Ply thicknesses in m.

    Returns
    -------
    numpy.ndarray, shape (7,)
        ``I0 .. I6`` in kg m^(i-2).
    """
    z = ply_interfaces(thicknesses)
    return np.array([density * _moments(z, i).sum() for i in range(7)])


def constitutive_matrix(lam):
    """Plate constitutive matrix of eq. (23), ``s = C e``.

    The generalised strains are ordered ``(eps0_x, eps0_y, gamma0_xy, chi_x, chi_y, chi_xy,
    chih_x, chih_y, chih_xy, gamma_yz, gamma_xz)``, with the in-plane strain
    ``eps0 + z chi + c z^3 chih`` and the shear strain ``(1 + 3 c z^2) gamma``.

    Parameters
    ----------
    lam : LaminateMatrices

    Returns
    -------
    numpy.ndarray, shape (11, 11)
    """
    A, B, D, E, F, H = (lam.Cf[q] for q in (0, 1, 2, 3, 4, 6))
    c = lam.c
    C = np.zeros((11, 11))
    C[:9, :9] = np.block([[A, B, c * E], [B, D, c * F], [c * E, c * F, c * c * H]])
    C[9:, 9:] = lam.Cs[0] + 6 * c * lam.Cs[2] + 9 * c * c * lam.Cs[4]
    return C


def inertia_matrix(moments, c):
    """Kinetic-energy density matrix of the generalised velocities.

    The generalised displacements are ordered ``(u0, psi_x, psi_x + w_x, v0, psi_y,
    psi_y + w_y, w0)`` so that ``u = u0 + z psi_x + c z^3 (psi_x + w_x)``.

    Parameters
    ----------
    moments : array_like, shape (7,)
        Inertias ``I0 .. I6``.
    c : float
        ``-4 / (3 h^2)``.

    Returns
    -------
    numpy.ndarray, shape (7, 7)
    """
    I0, I1, I2, I3, I4, _, I6 = moments
    block = np.array([[I0, I1, c * I3], [I1, I2, c * I4], [c * I3, c * I4, c * c * I6]])
    R = np.zeros((7, 7))
    R[:3, :3] = block
    R[3:6, 3:6] = block
    R[6, 6] = I0
    return R
