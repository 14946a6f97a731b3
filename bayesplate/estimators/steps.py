"""One update of each estimator: B (eq. 9) and MVE (eq. 12), in scaled coordinates."""

from __future__ import annotations

import numpy as np

__all__ = ["b_step", "mve_step"]


def _scaled(S, V, b_scale):
    """Sensitivities and covariance in the dimensionless ``x = b / b_scale``."""
    return S * b_scale[None, :], V / np.outer(b_scale, b_scale)


def b_step(b, mu, g, S, Y, V_Y, V_b):
    """One iteration of the B estimator (eq. 9).

    Parameters
    ----------
    b, mu : numpy.ndarray, shape (6,)
        Current iterate and prior mean, Pa.
    g : numpy.ndarray, shape (m,)
        Model eigenvalues at `b`.
    S : numpy.ndarray, shape (m, 6)
        Sensitivities at `b`.
    Y : numpy.ndarray, shape (m,)
    V_Y : numpy.ndarray, shape (m, m)
    V_b : numpy.ndarray, shape (6, 6)

    Returns
    -------
    b_next : numpy.ndarray, shape (6,)
    P : numpy.ndarray, shape (6, 6)
        ``[S^T V_Y^-1 S + V_b^-1]^-1``.
    """
    scale = np.abs(mu)
    Sx, Vx = _scaled(S, V_b, scale)
    W = np.linalg.inv(V_Y)
    Px = np.linalg.inv(Sx.T @ W @ Sx + np.linalg.inv(Vx))
    rhs = Y - g - S @ (mu - b)
    b_next = mu + scale * (Px @ Sx.T @ W @ rhs)
    return b_next, Px * np.outer(scale, scale)


def mve_step(b, g, S, Y, V_Y, V):
    """One iteration of the minimum variance estimator (eq. 12).

    Parameters
    ----------
    b : numpy.ndarray, shape (6,)
        Current iterate, Pa.
    g, S, Y, V_Y
        As in :func:`b_step`.
    V : numpy.ndarray, shape (6, 6)
        Parameter covariance used in this step.

    Returns
    -------
    b_next : numpy.ndarray, shape (6,)
    V_next : numpy.ndarray, shape (6, 6)
        ``V - V S^T (S V S^T + V_Y)^-1 S V`` (section 2.2).
    """
    scale = np.abs(b)
    Sx, Vx = _scaled(S, V, scale)
    C = Sx @ Vx @ Sx.T + V_Y
    K = np.linalg.solve(C, Sx @ Vx).T  # V S^T C^-1, shape (6, m)
    b_next = b + scale * (K @ (Y - g))
    V_next = Vx - K @ Sx @ Vx
    return b_next, V_next * np.outer(scale, scale)
