"""Checks of the linearised covariance without sampling, and of a sampled one against it.

:func:`curvature_covariance` (the full Hessian at the MAP, against B's Gauss-Newton ``P``),
:func:`linearisation_band` (how much ``P``'s deviations change over one deviation) and
:func:`covariance_agreement` (sampled deviations and correlations against a Gaussian
approximation's, within Monte Carlo bands).
"""

from __future__ import annotations

import numpy as np

from .. import laminate
from ..estimators import b_step
from ..quantities import engineering_covariance

__all__ = ["covariance_agreement", "curvature_covariance", "linearisation_band"]


def _engineering_covariance(b, covariance_b):
    """First-order ``J^-1 cov_b J^-T`` with ``J = d b / d e`` at the constants of `b` (Pa)."""
    return engineering_covariance(laminate.engineering_from_stiffness(b), covariance_b)


def curvature_covariance(problem, b, covariance, step=0.05):
    """Laplace covariance with the full Hessian of ``ln f(b | Y)`` at ``b`` (the MAP).

    B's ``P`` (eq. 9) is the Gauss-Newton inverse curvature: it drops the term
    ``sum_i r_i (V_Y^-1)_ii d^2 g_i / db^2`` of the residuals ``r = Y - g``, which matters
    when the residuals are large (a prior that pulls the fit away from the data). Here the
    Hessian is taken by central differences of :meth:`GaussianProblem.log_posterior` along
    ``b = b_MAP + L y`` with ``L L^T = covariance``, where it is close to the identity: the
    truncation error is O(``step``^2) relative (~2e-3 for 0.05) and the rounding
    ~1e-16 |ln f| / step^2. An independent check of ``P``, no sampling involved.

    Parameters
    ----------
    problem : GaussianProblem
        E.g. :meth:`SamplingSetup.problem_on_fast_model`.
    b : array_like, shape (6,)
        The MAP, Pa.
    covariance : array_like, shape (6, 6)
        ``P``, Pa^2: sets the directions and scale of the steps.
    step : float
        Difference step in units of ``L``.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        Covariance of ``b``, Pa^2.
    """
    b = np.asarray(b, dtype=float)
    L = np.linalg.cholesky(np.asarray(covariance, dtype=float))
    eye = step * np.eye(6)

    def f(y):
        return problem.log_posterior(b + L @ y)

    H = np.zeros((6, 6))
    for i in range(6):
        for j in range(i, 6):
            a, c = eye[i], eye[j]
            H[i, j] = H[j, i] = -(f(a + c) - f(a - c) - f(c - a) + f(-a - c)) / (4 * step**2)
    return L @ np.linalg.inv(H) @ L.T


def linearisation_band(problem, b, covariance_b):
    """How much B's deviations change over one deviation around the MAP, per constant.

    ``P`` of eq. 9 is recomputed at ``b +- L_k`` (the columns of ``chol(P)``, 12 points)
    and carried to the engineering constants; the largest relative change of each
    deviation measures the nonlinearity of the problem over the bulk of the posterior, an
    error of the linearised covariance that needs no sampling.

    Parameters
    ----------
    problem : GaussianProblem
        On a model with sensitivities (e.g. :meth:`SamplingSetup.problem_on_fast_model`).
    b : array_like, shape (6,)
        The MAP, Pa.
    covariance_b : array_like, shape (6, 6)
        ``P`` at the MAP, Pa^2.

    Returns
    -------
    numpy.ndarray, shape (6,)
        ``max_k |sd_i(b +- L_k) / sd_i(b) - 1|`` for ``(E1, E2, nu12, G12, G13, G23)``.
    """
    b = np.asarray(b, dtype=float)
    L = np.linalg.cholesky(np.asarray(covariance_b, dtype=float))
    sd0 = np.sqrt(np.diag(_engineering_covariance(b, covariance_b)))
    change = []
    for k in range(6):
        for sign in (1.0, -1.0):
            point = b + sign * L[:, k]
            p = problem.predict(point)
            P = b_step(point, problem.mu_b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)[1]
            change.append(np.sqrt(np.diag(_engineering_covariance(point, P))) / sd0 - 1)
    return np.max(np.abs(change), axis=0)


def covariance_agreement(result, covariance, n_mc=4.0):
    """Sampled deviations and correlations against a Gaussian approximation's, with bands.

    The Monte Carlo error of a sampled deviation is ``sd / sqrt(2 ESS)`` and of a
    correlation ``(1 - rho^2) / sqrt(ESS)`` (the Gaussian formulas, ESS the bulk ESS, the
    smaller of the pair); they agree when the difference is within ``n_mc`` of them.

    Parameters
    ----------
    result : SamplingResult
    covariance : array_like, shape (6, 6)
        Engineering covariance to compare with (e.g. ``EstimateResult.covariance``), SI.
    n_mc : float
        Monte Carlo errors allowed.

    Returns
    -------
    dict
        ``sd_sampled``, ``sd_linear``, ``ratio``, ``band`` (allowed ``|ratio - 1|``),
        ``sd_agrees`` (6,); ``corr_sampled``, ``corr_linear``, ``corr_band``,
        ``corr_agrees`` (6, 6).
    """
    ess = np.asarray(result.ess_bulk, dtype=float)
    cov = np.asarray(covariance, dtype=float)
    sd_s = np.sqrt(np.diag(result.covariance))
    sd_l = np.sqrt(np.diag(cov))
    ratio = sd_s / sd_l
    band = n_mc / np.sqrt(2 * ess)
    corr_s = result.covariance / np.outer(sd_s, sd_s)
    corr_l = cov / np.outer(sd_l, sd_l)
    corr_band = n_mc * (1 - corr_l**2) / np.sqrt(np.minimum.outer(ess, ess))
    np.fill_diagonal(corr_band, 0.0)
    return {
        "sd_sampled": sd_s,
        "sd_linear": sd_l,
        "ratio": ratio,
        "band": band,
        "sd_agrees": np.abs(ratio - 1) <= band,
        "corr_sampled": corr_s,
        "corr_linear": corr_l,
        "corr_band": corr_band,
        "corr_agrees": np.abs(corr_s - corr_l) <= corr_band + 1e-12,
    }
