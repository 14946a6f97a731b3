"""A plate's Gaussian likelihood in ``z = ln c`` against the population: information form.

Each plate's likelihood is approximated (:mod:`bayesplate.sampling.plate_laplace`) as

    ln L_p(z) = -1/2 z^T H_p z + h_p^T z + const,

``H_p`` (6, 6) its Gauss-Newton precision in ``z = ln c`` and ``h_p`` (6,) its information
vector. ``H_p`` may be singular or nearly so (G13 and G23 of a thin plate): nothing here
inverts it. With the plate's constants drawn from the population, ``z ~ N(m, T)``,
``m = ln mu``, ``T = diag(tau^2)``, the plate's marginal likelihood is (``s = diag(tau)``,
``r = h - H m``, ``M = I + s H s``, symmetric positive definite for any ``H >= 0``)

    ln int L_p(z) N(z; m, T) dz = q(m) - 1/2 ln det M + 1/2 (s r)^T M^-1 (s r),

``q(m) = -1/2 m^T H m + h^T m`` (expand ``z = m + s u``, ``u ~ N(0, I)``, and integrate
``u``). It is ``N(H^-1 h; m, H^-1 + T)`` up to a constant when ``H`` is invertible and tends
to ``q(m)`` (the plate's own likelihood at ``m``) as ``tau -> 0``, without the ``1 / tau``
cancellations of the textbook form. The plate's constants given ``(m, tau)`` and its data are
Gaussian: mean ``m + s M^-1 s r``, covariance ``s M^-1 s`` (:func:`conditional`).

Outliers: a plate is from the population with probability ``1 - OUTLIER_PRIOR``; otherwise
one constant (or all six, a plate of another material) scatters with an extra spread
:data:`OUTLIER_SCALE` on ``ln c``: seven wide components of equal prior weight
(:func:`component_spreads`). A mixture rather than a leave-one-out check because it gives
what the issue asks, a posterior probability, and keeps the odd plate from widening the
spreads ``tau`` of the rest; one constant at a time because a flawed coupon is usually off
in one constant (a 15 % low E1), and a component widening all six pays an Occam factor
``tau_k / OUTLIER_SCALE`` for each constant it does not need.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

__all__ = [
    "OUTLIER_PRIOR",
    "OUTLIER_SCALE",
    "component_log_weights",
    "component_spreads",
    "conditional",
    "marginal_log_likelihood",
    "mixture_log_likelihood",
]

#: Prior probability that a plate is not of the population (one test in twenty flawed).
OUTLIER_PRIOR = 0.05
#: Extra spread of an outlying plate's constants on ``ln c`` (a factor of about e^0.5).
OUTLIER_SCALE = 0.5
#: Components: 0 the population, 1..6 constant k-1 widened, 7 all six widened.
N_COMPONENTS = 8


def _gradient(log_mu, H, h):
    """``q(m) = -1/2 m^T H m + h^T m`` and ``r = h - H m``, broadcast: (...), (..., 6)."""
    Hm = np.sum(H * np.asarray(log_mu, dtype=float)[..., None, :], axis=-1)
    return np.sum((h - 0.5 * Hm) * log_mu, axis=-1), h - Hm


def _integrated(q, r, tau, H):
    """``q - 1/2 ln det M + 1/2 g^T M^-1 g``, ``M = I + s H s``, ``g = s r`` (broadcast)."""
    tau = np.asarray(tau, dtype=float)
    t = [tau[..., i] for i in range(6)]

    def entry(i, j):
        return (i == j) + t[i] * t[j] * H[..., i, j]

    logdet, w = _cholesky_solve(entry, [t[i] * r[..., i] for i in range(6)])
    return q - 0.5 * logdet + 0.5 * sum(x * x for x in w)


def marginal_log_likelihood(log_mu, tau, H, h):
    """``ln int L_p(z) N(z; ln mu, diag tau^2) dz`` up to the plate's constant (docstring).

    Parameters
    ----------
    log_mu, tau : numpy.ndarray, shape (..., 6)
        Population means (``ln`` of SI values) and spreads (of ``ln c``, >= 0).
    H : numpy.ndarray, shape (..., 6, 6)
        Plate precision in ``z`` (symmetric, positive semi-definite; may be singular).
    h : numpy.ndarray, shape (..., 6)
        Plate information vector.

    Returns
    -------
    numpy.ndarray, shape (...)
    """
    q, r = _gradient(log_mu, H, h)
    return _integrated(q, r, tau, H)


def _cholesky_solve(entry, g):
    """``ln det M`` and ``L^-1 g`` (``M = L L^T``) of many small systems at once.

    Parameters
    ----------
    entry : callable
        ``entry(i, j)`` the ``(i, j)`` entries (``i >= j``) of the 6 x 6 symmetric positive
        definite matrices, an array of the batch's shape.
    g : list of 6 numpy.ndarray
        The right-hand sides' entries, each of the batch's shape.

    Returns
    -------
    logdet : numpy.ndarray
    w : list of 6 numpy.ndarray

    Notes
    -----
    The factorisation unrolled over the 6 x 6 entries, each a vector operation over the
    batch (walkers, plates, mixture components): :func:`numpy.linalg.cholesky` pays a
    per-matrix overhead several times larger on thousands of 6 x 6 matrices, at every step.
    """
    n = len(g)
    L = [[None] * n for _ in range(n)]
    w = [None] * n
    logdet = 0.0
    for j in range(n):
        L[j][j] = np.sqrt(entry(j, j) - sum(L[j][k] ** 2 for k in range(j)))
        logdet = logdet + np.log(L[j][j])
        for i in range(j + 1, n):
            L[i][j] = (entry(i, j) - sum(L[i][k] * L[j][k] for k in range(j))) / L[j][j]
        w[j] = (g[j] - sum(L[j][k] * w[k] for k in range(j))) / L[j][j]
    return 2.0 * logdet, w


def conditional(log_mu, tau, H, h):
    """Mean and covariance of a plate's ``z = ln c`` given the population and its data.

    Parameters
    ----------
    log_mu, tau, H, h
        As for :func:`marginal_log_likelihood`.

    Returns
    -------
    mean : numpy.ndarray, shape (..., 6)
    cov : numpy.ndarray, shape (..., 6, 6)
    """
    log_mu = np.asarray(log_mu, dtype=float)
    tau = np.asarray(tau, dtype=float)
    _, r = _gradient(log_mu, H, h)
    M = np.eye(6) + tau[..., :, None] * H * tau[..., None, :]
    g = tau * r
    Minv = np.linalg.inv(M)
    mean = log_mu + tau * np.einsum("...ij,...j->...i", Minv, g)
    cov = tau[..., :, None] * Minv * tau[..., None, :]
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def component_spreads(tau, scale=OUTLIER_SCALE):
    """Each mixture component's spreads: ``tau``, then one constant widened, then all.

    Parameters
    ----------
    tau : numpy.ndarray, shape (..., 6)
    scale : float
        The outliers' extra spread on ``ln c``.

    Returns
    -------
    numpy.ndarray, shape (..., 8, 6)
        ``sqrt(tau^2 + scale^2 * mask_c)`` with ``mask_0 = 0``, ``mask_k = e_k``,
        ``mask_7 = 1``.
    """
    mask = np.vstack([np.zeros(6), np.eye(6), np.ones(6)])
    tau = np.asarray(tau, dtype=float)[..., None, :]
    return np.sqrt(tau**2 + scale**2 * mask)


def component_log_weights(prior=OUTLIER_PRIOR):
    """``ln`` prior weights of the components, shape (8,): ``1 - prior``, then ``prior / 7``."""
    if prior <= 0:
        return np.concatenate([[0.0], np.full(N_COMPONENTS - 1, -np.inf)])
    return np.log(np.concatenate([[1 - prior], np.full(N_COMPONENTS - 1, prior / 7)]))


def mixture_log_likelihood(log_mu, tau, H, h, prior=OUTLIER_PRIOR, scale=OUTLIER_SCALE):
    """Each plate's marginal under the outlier mixture, and the components' responsibilities.

    Parameters
    ----------
    log_mu, tau : numpy.ndarray, shape (n, 6)
        Population points (walkers).
    H : numpy.ndarray, shape (P, 6, 6)
    h : numpy.ndarray, shape (P, 6)
    prior, scale : float
        :data:`OUTLIER_PRIOR` and :data:`OUTLIER_SCALE`; ``prior = 0``: no mixture.

    Returns
    -------
    loglik : numpy.ndarray, shape (n, P)
    resp : numpy.ndarray, shape (n, P, 8)
        Posterior probability of each component given the point.
    """
    spreads = component_spreads(tau, scale)[:, None, :, :]  # (n, 1, 8, 6)
    q, r = _gradient(np.asarray(log_mu, dtype=float)[:, None, :], H[None], h[None])  # (n, P)
    each = _integrated(q[..., None], r[:, :, None, :], spreads, H[None, :, None])
    each = each + component_log_weights(prior)  # (n, P, 8)
    total = logsumexp(each, axis=-1)
    return total, np.exp(each - total[..., None])
