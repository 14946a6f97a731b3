"""A plate's likelihood Gaussian in its stiffness and shear compliance: the population marginal.

A plate's likelihood is close to Gaussian in the coordinates

    y = (C11, C22, C12, C66, 1 / C44, 1 / C55)

(:func:`coordinates`): the eigenvalues are linear in the in-plane stiffness along fixed mode
shapes (``K`` is linear in it), and a transverse shear modulus lowers them roughly as a
compliance in series with the bending stiffness. With the sensitivities ``S_y`` taken at the
plate's linearisation point ``y0`` (:func:`bayesplate.sampling.plate_laplace.linearise`),

    ln L_p(y) = -1/2 y^T A y + a^T y + const,   A = S_y^T V_Y^-1 S_y,
    a = S_y^T V_Y^-1 (Y - g0 + S_y y0).

It is far from Gaussian in ``z = ln c``: the eigenvalues move with ``nu12`` through
``C12 = nu12 E2 / D`` (as ``e^z``) and with a shear modulus as ``e^-z``. Measured on
synthetic plates 0.6 away in ``ln G23`` from the point, the exact log-likelihood fell by 4.0,
this form's by 3.8, a Gaussian in ``z``'s by 5.8 and a Gaussian in the stiffness ``b``'s by
9.2; a Gaussian in ``z`` fitted at one point over-penalises one side and under-penalises the
other, and ten plates that barely identify ``nu12`` and ``G23`` gave the population's
``nu12`` biased high and its ``G23`` low.

With ``z ~ N(m, diag s^2)`` from the population (``s = tau``, or an outlier component's
wider spreads), write ``z = m + s u``; the plate's marginal is a Laplace approximation at
the conditional mode ``u*`` of

    F(u) = ln L_p(y(m + s u)) - 1/2 |u|^2,

reached by :data:`NEWTON_STEPS` Gauss-Newton steps from ``u = 0`` (``M = I + s J^T A J s``,
``J = d y / d z``):

    ln int L_p(y(z)) N(z; m, s^2) dz  ~  F(u*) - 1/2 ln det M(u*).

As ``s -> 0`` it is ``ln L_p(y(m))``, the shared-constants likelihood at ``m``; where the
plate identifies a constant well its conditional is narrow and the Laplace accurate; where
it does not, the conditional is the population's narrow ``N(m, s^2)`` and ``y(z)`` nearly
linear over it. The plate's constants given the population are ``N(m + s u*, s M^-1 s)``
(:func:`conditional_y`). Everything is vectorised over walkers, plates and mixture
components.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from .. import laminate
from .population import component_log_weights, component_spreads, marginal_log_likelihood

__all__ = [
    "NEWTON_STEPS",
    "Plates",
    "conditional_y",
    "coordinates",
    "coordinates_jacobian",
    "marginal_y",
    "mixture_y",
]

#: Gauss-Newton steps from ``u = 0`` to the conditional mode (a fixed number: the density
#: stays a smooth function of the population parameters).
NEWTON_STEPS = 3
#: Largest step in ``u`` (population deviations) of one Gauss-Newton iteration.
MAX_STEP = 3.0


def coordinates(c):
    """``y = (C11, C22, C12, C66, 1 / C44, 1 / C55)`` of engineering constants `c` (..., 6), SI."""
    return _of_stiffness(laminate.stiffness_from_engineering(c))


def _of_stiffness(b):
    """``y`` of stiffness coefficients `b` (..., 6)."""
    return np.concatenate([b[..., :4], 1.0 / b[..., 4:]], axis=-1)


def coordinates_jacobian(c, b=None):
    """``d y / d z`` at engineering constants `c` (``z = ln c``), shape (..., 6, 6).

    `b`: their stiffness coefficients, when the caller has them already.
    """
    c = np.asarray(c, dtype=float)
    J = laminate.stiffness_jacobian(c) * c[..., None, :]
    b = laminate.stiffness_from_engineering(c) if b is None else b
    dy_db = np.concatenate([np.ones(c.shape[:-1] + (4,)), -1.0 / b[..., 4:] ** 2], axis=-1)
    return J * dy_db[..., :, None]


def stiffness_per_coordinate(b):
    """``d b / d y`` (diagonal) at stiffness `b` (..., 6): 1, and ``-C^2`` for the shears."""
    b = np.asarray(b, dtype=float)
    return np.concatenate([np.ones(b.shape[:-1] + (4,)), -(b[..., 4:] ** 2)], axis=-1)


def _terms(m, s, u, A, a):
    """``F(u)``, its gradient in ``u`` and ``M = I + s J^T A J s`` (broadcast (..., 6))."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # far points: -inf
        return _terms_at(m, s, u, A, a)


def _terms_at(m, s, u, A, a):
    c = np.exp(m + s * u)
    b = laminate.stiffness_from_engineering(c)
    y = _of_stiffness(b)
    Js = coordinates_jacobian(c, b) * s[..., None, :]  # d y / d u
    JsT = np.swapaxes(Js, -1, -2)
    Ay = (A @ y[..., None])[..., 0]
    log_l = np.sum(y * (a - 0.5 * Ay), axis=-1)
    grad = (JsT @ (a - Ay)[..., None])[..., 0] - u
    M = np.eye(6) + JsT @ A @ Js
    ok = laminate.is_physical(b) & np.isfinite(log_l) & np.all(np.isfinite(grad), axis=-1)
    return np.where(ok, log_l - 0.5 * np.sum(u * u, axis=-1), -np.inf), grad, M, ok


def _mode(m, s, A, a, steps=NEWTON_STEPS):
    """``u*`` and ``F``, ``M`` there, after `steps` Gauss-Newton steps from ``u = 0``.

    No line search and a fixed number of steps, each no longer than :data:`MAX_STEP`: the
    result is a smooth function of ``m`` and ``s``, as a sampler and a finite-difference
    Hessian need.
    """
    shape = np.broadcast_shapes(m.shape, s.shape, a.shape)
    u = np.zeros(shape)
    for _ in range(steps):
        F, grad, M, ok = _terms(m, s, u, A, a)
        du = np.linalg.solve(np.where(ok[..., None, None], M, np.eye(6)), grad[..., None])
        size = np.maximum(np.max(np.abs(du[..., 0]), axis=-1, keepdims=True), 1e-300)
        u = u + np.where(ok[..., None], du[..., 0], 0) * np.minimum(1.0, MAX_STEP / size)
    F, _, M, ok = _terms(m, s, u, A, a)
    return u, F, M, ok


def marginal_y(log_mu, tau, A, a, steps=NEWTON_STEPS):
    """``ln int L_p(y(z)) N(z; ln mu, diag tau^2) dz`` up to the plate's constant (docstring).

    Parameters
    ----------
    log_mu, tau : numpy.ndarray, shape (..., 6)
        Population means (``ln`` of SI values) and spreads (of ``ln c``, >= 0).
    A : numpy.ndarray, shape (..., 6, 6)
        The plate's precision in ``y`` (:func:`coordinates`, SI).
    a : numpy.ndarray, shape (..., 6)
        Its information vector.
    steps : int
        Gauss-Newton steps to the conditional mode.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``-inf`` where the population's mean is not a physical lamina.
    """
    m, s = np.asarray(log_mu, dtype=float), np.asarray(tau, dtype=float)
    _, F, M, ok = _mode(m, s, A, a, steps)
    sign, logdet = np.linalg.slogdet(np.where(ok[..., None, None], M, np.eye(6)))
    return np.where(ok & (sign > 0), F - 0.5 * logdet, -np.inf)


def conditional_y(log_mu, tau, A, a, steps=NEWTON_STEPS):
    """Mean and covariance of a plate's ``z = ln c`` given the population and its data.

    Parameters
    ----------
    log_mu, tau, A, a, steps
        As for :func:`marginal_y`.

    Returns
    -------
    mean : numpy.ndarray, shape (..., 6)
        ``ln mu + tau u*``.
    cov : numpy.ndarray, shape (..., 6, 6)
        ``s M^-1 s`` at ``u*``.
    """
    m, s = np.asarray(log_mu, dtype=float), np.asarray(tau, dtype=float)
    u, _, M, ok = _mode(m, s, A, a, steps)
    Minv = np.linalg.inv(np.where(ok[..., None, None], M, np.eye(6)))
    cov = s[..., :, None] * Minv * s[..., None, :]
    return m + s * u, 0.5 * (cov + np.swapaxes(cov, -1, -2))


@dataclass(frozen=True, eq=False)
class Plates:
    """The plates' likelihoods, in ``y`` for the population and in ``z`` for the outliers.

    Attributes
    ----------
    A, a : numpy.ndarray, shapes (P, 6, 6), (P, 6)
        Each plate's Gaussian in ``y`` (:func:`coordinates`).
    H, h : numpy.ndarray, shapes (P, 6, 6), (P, 6)
        The same likelihood as a Gaussian in ``z`` at each plate's point ``z0``.
    offset : numpy.ndarray, shape (P,)
        ``ln L(y(z0)) - q(z0)``: puts the ``z`` form on the ``y`` form's level.
    """

    A: np.ndarray
    a: np.ndarray
    H: np.ndarray
    h: np.ndarray
    offset: np.ndarray

    @classmethod
    def of(cls, laplaces):
        """From :class:`~bayesplate.sampling.plate_laplace.PlateLaplace` objects (with ``A``)."""
        A, a = np.array([f.A for f in laplaces]), np.array([f.a for f in laplaces])
        H, h = np.array([f.H for f in laplaces]), np.array([f.h for f in laplaces])
        z0 = np.array([f.z0 for f in laplaces])
        y0 = coordinates(np.exp(z0))
        log_l = np.sum(y0 * (a - 0.5 * (A @ y0[..., None])[..., 0]), axis=-1)
        q = np.sum(z0 * (h - 0.5 * (H @ z0[..., None])[..., 0]), axis=-1)
        return cls(A, a, H, h, np.where(np.isfinite(log_l), log_l - q, 0.0))


def mixture_y(log_mu, tau, plates, prior, scale):
    """Each plate's marginal under the outlier mixture, and the components' responsibilities.

    The population's component by :func:`marginal_y`; the outliers' wide components (which
    only need to say that a plate does not fit) by the closed form in ``z``
    (:func:`bayesplate.sampling.population.marginal_log_likelihood`), put on the same level
    by ``plates.offset``: eight Laplace searches a plate would cost eight times as much.

    Parameters
    ----------
    log_mu, tau : numpy.ndarray, shape (n, 6)
    plates : Plates
    prior, scale : float
        The outliers' prior probability (0: none) and extra spread on ``ln c``.

    Returns
    -------
    loglik : numpy.ndarray, shape (n, P)
    resp : numpy.ndarray, shape (n, P, 8)
    """
    log_mu = np.asarray(log_mu, dtype=float)
    weights = component_log_weights(prior)
    own = marginal_y(log_mu[:, None, :], np.asarray(tau)[:, None, :], plates.A, plates.a)
    each = np.empty(own.shape + (weights.size,))
    each[..., 0] = own + weights[0]
    if np.isfinite(weights[1:]).any():
        wide = component_spreads(tau, scale)[:, None, 1:, :]  # (n, 1, 7, 6)
        H, h = plates.H[None, :, None], plates.h[None, :, None]
        z_form = marginal_log_likelihood(log_mu[:, None, None, :], wide, H, h)
        each[..., 1:] = z_form + plates.offset[None, :, None] + weights[1:]
    else:
        each[..., 1:] = -np.inf
    total = logsumexp(each, axis=-1)
    with np.errstate(invalid="ignore"):
        resp = np.exp(each - total[..., None])
    return total, np.nan_to_num(resp)
