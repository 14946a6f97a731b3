"""Closed-form Navier solution for free vibration of SS-1 cross-ply plates under Reddy's TSDT.

Independent test reference: it does not import ``bayesplate``.

Displacement field (Reddy 1984), with ``c = -4 / (3 h^2)``::

    u = u0 + z psi_x + c z^3 (psi_x + w0_x)
    v = v0 + z psi_y + c z^3 (psi_y + w0_y)
    w = w0

Generalised strains, 11 of them, in the order used by the constitutive matrix::

    eps0  = [u0_x, v0_y, u0_y + v0_x]                                  (membrane)
    chi   = [psi_x,x, psi_y,y, psi_x,y + psi_y,x]                      (curvature)
    chi_h = [psi_x,x + w_xx, psi_y,y + w_yy, psi_x,y + psi_y,x + 2 w_xy]
    gam0  = [w_y + psi_y, w_x + psi_x]                                 (yz, xz)

In-plane strain ``eps0 + z chi + c z^3 chi_h``; transverse shear ``(1 + 3 c z^2) gam0``.
All through-thickness integrals are done exactly, ply by ply, on monomials ``z^k``.
"""

import numpy as np
from scipy.linalg import eigh


def _ply_stiffness(angle_deg, E1, E2, nu12, G12, G13, G23):
    """Reduced stiffnesses of a 0 or 90 degree ply in plate axes.

    Returns
    -------
    Q : ndarray, shape (3, 3)
        In-plane stiffness for strains ``[xx, yy, xy]``.
    Qs : ndarray, shape (2, 2)
        Transverse shear stiffness for strains ``[yz, xz]``.
    """
    nu21 = nu12 * E2 / E1
    d = 1.0 - nu12 * nu21
    q11, q22, q12 = E1 / d, E2 / d, nu12 * E2 / d
    q44, q55 = G23, G13
    angle = float(angle_deg) % 180.0
    if np.isclose(angle, 90.0):
        q11, q22, q44, q55 = q22, q11, q55, q44
    elif not (np.isclose(angle, 0.0) or np.isclose(angle, 180.0)):
        raise ValueError(f"only 0/90 plies give a Navier solution, got {angle_deg}")
    Q = np.array([[q11, q12, 0.0], [q12, q22, 0.0], [0.0, 0.0, G12]])
    return Q, np.diag([q44, q55])


def _z_moments(z_bottom, z_top, kmax=6):
    """Return ``int z^k dz`` over ``[z_bottom, z_top]`` for ``k = 0..kmax``."""
    k = np.arange(kmax + 1)
    return (z_top ** (k + 1) - z_bottom ** (k + 1)) / (k + 1)


def laminate_abdefh(layup_deg, ply_thickness, E1, E2, nu12, G12, G13, G23):
    """Laminate stiffness integrals of a cross-ply laminate.

    Parameters
    ----------
    layup_deg : sequence of float
        Ply angles in degrees (0 or 90), listed from the bottom face ``z = -h/2`` upward.
    ply_thickness : float
        Thickness of every ply.
    E1, E2, nu12, G12, G13, G23 : float
        Lamina engineering constants (1 = fibre direction).

    Returns
    -------
    dict
        ``A, B, D, E, F, H`` (3x3, ``int Qbar z^k dz`` for ``k = 0, 1, 2, 3, 4, 6``),
        ``As, Ds, Fs`` (2x2, ``int Qs z^k dz`` for ``k = 0, 2, 4``), ``h`` and ``c``.
    """
    n_ply = len(layup_deg)
    h = n_ply * ply_thickness
    z = -h / 2 + ply_thickness * np.arange(n_ply + 1)
    Zk = np.zeros((7, 3, 3))
    Zs = np.zeros((7, 2, 2))
    for i, angle in enumerate(layup_deg):
        Q, Qs = _ply_stiffness(angle, E1, E2, nu12, G12, G13, G23)
        mom = _z_moments(z[i], z[i + 1])
        Zk += mom[:, None, None] * Q
        Zs += mom[:, None, None] * Qs
    out = dict(zip("ABDEF", Zk[:5], strict=True))
    out.update(H=Zk[6], As=Zs[0], Ds=Zs[2], Fs=Zs[4], h=h, c=-4.0 / (3.0 * h**2))
    return out


def constitutive_matrix(lam):
    """Return the 11x11 matrix ``C`` with strain energy density ``1/2 e^T C e``.

    ``e = [eps0, chi, chi_h, gam0]`` as in the module docstring; the factors ``c`` of the
    displacement field are included, so ``C`` pairs directly with the generalised strains.
    """
    c = lam["c"]
    A, B, D, E, F, H = (lam[k] for k in "ABDEFH")
    C = np.zeros((11, 11))
    C[:9, :9] = np.block([[A, B, c * E], [B, D, c * F], [c * E, c * F, c**2 * H]])
    C[9:, 9:] = lam["As"] + 6 * c * lam["Ds"] + 9 * c**2 * lam["Fs"]
    return C


def inertias(rho, h):
    """Return ``I_k = int rho z^k dz`` for ``k = 0..6`` over ``[-h/2, h/2]`` (uniform ``rho``)."""
    return rho * _z_moments(-h / 2, h / 2)


def navier_matrices(a, b, h, rho, layup_deg, E1, E2, nu12, G12, G13, G23, m, n, drop_inertia=()):
    """Stiffness and mass matrices for the amplitudes ``q = [U, V, W, X, Y]`` of mode (m, n).

    Trial functions: ``u0 = U cos sin``, ``v0 = V sin cos``, ``w0 = W sin sin``,
    ``psi_x = X cos sin``, ``psi_y = Y sin cos`` (arguments ``alpha x``, ``beta y``).
    The common factor ``a b / 4`` of both energies is dropped. ``drop_inertia`` lists the
    ``k`` of inertias ``I_k`` to set to zero (to test other authors' conventions); by
    default all terms are kept. Parameters are those of `navier_frequencies`.

    Returns
    -------
    K, M : ndarray, shape (5, 5)
    """
    if m < 1 or n < 1:
        raise ValueError("m and n must be >= 1 (m = 0 or n = 0 gives spurious roots)")
    al, be = m * np.pi / a, n * np.pi / b
    lam = laminate_abdefh(layup_deg, h / len(layup_deg), E1, E2, nu12, G12, G13, G23)
    c = lam["c"]
    # Amplitudes of the 11 generalised strains; columns are U, V, W, X, Y.
    Bm = np.array(
        [
            [-al, 0, 0, 0, 0],
            [0, -be, 0, 0, 0],
            [be, al, 0, 0, 0],
            [0, 0, 0, -al, 0],
            [0, 0, 0, 0, -be],
            [0, 0, 0, be, al],
            [0, 0, -(al**2), -al, 0],
            [0, 0, -(be**2), 0, -be],
            [0, 0, 2 * al * be, be, al],
            [0, 0, be, 0, 1],
            [0, 0, al, 1, 0],
        ]
    )
    K = Bm.T @ constitutive_matrix(lam) @ Bm
    # Kinetic energy: u = (U + z X + c z^3 (X + alpha W)) cos sin, v likewise, w = W sin sin.
    I0, I1, I2, I3, I4, _, I6 = np.where(np.isin(np.arange(7), drop_inertia), 0.0, inertias(rho, h))
    Mz = np.array([[I0, I1, c * I3], [I1, I2, c * I4], [c * I3, c * I4, c**2 * I6]])
    Bu = np.array([[1, 0, 0, 0, 0], [0, 0, 0, 1, 0], [0, 0, al, 1, 0]])
    Bv = np.array([[0, 1, 0, 0, 0], [0, 0, 0, 0, 1], [0, 0, be, 0, 1]])
    M = Bu.T @ Mz @ Bu + Bv.T @ Mz @ Bv
    M[2, 2] += I0
    return K, M


def navier_frequencies(a, b, h, rho, layup_deg, E1, E2, nu12, G12, G13, G23, m, n, drop_inertia=()):
    """Natural circular frequencies of the SS-1 cross-ply plate for the half-waves (m, n).

    Parameters
    ----------
    a, b, h : float
        Plate side lengths (x, y) and total thickness.
    rho : float
        Mass density (uniform through the thickness).
    layup_deg : sequence of float
        Ply angles (0 or 90 degrees), equal thicknesses, from ``z = -h/2`` upward.
    E1, E2, nu12, G12, G13, G23 : float
        Lamina engineering constants.
    m, n : int
        Half-wave numbers along x and y, both >= 1.
    drop_inertia : sequence of int, optional
        Indices ``k`` of inertias ``I_k = int rho z^k dz`` to neglect; default none.

    Returns
    -------
    ndarray, shape (5,)
        Circular frequencies in rad/s, ascending; the lowest is the flexural mode.
        Degrees of freedom left without inertia (e.g. ``drop_inertia=(2, 4, 6)``) give ``inf``.
    """
    K, M = navier_matrices(a, b, h, rho, layup_deg, E1, E2, nu12, G12, G13, G23, m, n, drop_inertia)
    if not len(drop_inertia):
        return np.sqrt(eigh(K, M, eigvals_only=True))
    # M may be singular once inertias are dropped, K is positive definite for m, n >= 1:
    # solve M q = (1 / omega^2) K q (adequate for the moderate a/h of convention checks).
    lam = eigh(M, K, eigvals_only=True)
    lam = np.where(lam > 1e-12 * lam.max(), lam, 0.0)
    with np.errstate(divide="ignore"):
        return np.sort(1.0 / np.sqrt(lam))


def nondimensional(omega, a, h, rho, E2):
    """Return ``omega a^2 / h sqrt(rho / E2)``."""
    return omega * a**2 / h * np.sqrt(rho / E2)
