"""A common, unknown scale of the frequency deviations: its prior, posterior and marginal.

The measured eigenvalues deviate from the model by ``e ~ N(0, s^2 V_Y)``, with ``V_Y`` from
the declared deviations (:func:`bayesplate.likelihood.posterior.observation_covariance`) and one
unknown scale ``s > 0`` (dimensionless; ``s = 1``: the declared deviations are right). The prior is
the conjugate inverse gamma on ``s^2``, ``s^2 ~ InvGamma(a, beta)`` (shape ``a``, scale ``beta``),
stated by a lab as the median and the upper 95 % bound of ``s`` (:class:`ErrorScalePrior`).

Marginal likelihood
    ``s^2`` integrates out in closed form: with ``chi2 = r^T V_Y^-1 r`` (``r = Y - g(b)``) and
    ``m`` paired eigenvalues,
    ``f(Y | b) = Gamma(a + m/2) / Gamma(a) beta^a (2 pi)^(-m/2) |V_Y|^(-1/2)
    (beta + chi2 / 2)^-(a + m/2)``, a multivariate Student-t with ``2 a`` degrees of freedom
    and scale matrix ``(beta / a) V_Y`` (:func:`log_marginal`). The sampler's target stays
    six-dimensional. Given ``b``, ``s^2 | b, Y ~ InvGamma(a + m/2, beta + chi2 / 2)``
    (:func:`draw_scale`: one ``s`` per kept draw).

Linearised (B, MVE)
    :func:`linearised_scale` reports ``s`` at the estimate with the fitted constants'
    degrees of freedom taken off (a restricted-likelihood correction): ``p`` is the trace of
    the hat matrix ``H = S P S^T (s^2 V_Y)^-1`` (about 6 when the data dominate the prior,
    less when the prior holds some constants), ``s^2 | Y ~ InvGamma(a + (m - p)/2,
    beta + chi2 / 2)``, ``s_hat^2 = (beta + chi2/2) / (a + (m - p)/2)`` (a fixed point, as
    ``p`` depends on ``s``). The constants' covariance becomes
    ``nu / (nu - 2) (S^T (s_hat^2 V_Y)^-1 S + W)^-1`` with ``nu = 2 a + m - p`` and ``W``
    the estimator's prior precision (``V_b^-1`` for B): the
    covariance of a Student-t with ``nu`` degrees of freedom around the estimate. Exact for a
    linear model with a flat prior (the normal-inverse-gamma posterior); otherwise a
    linearisation, and the estimate itself is left where the estimator put it (``s = 1``
    weights; it moves only in the balance between prior and data).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, special, stats

__all__ = [
    "HDI_PROB",
    "ErrorScalePrior",
    "LinearisedScale",
    "ScaleSummary",
    "draw_scale",
    "linearised_at",
    "linearised_scale",
    "log_marginal",
    "loo_pointwise",
    "scale_from_draws",
    "summarise_scale",
]

#: Probability of the reported interval of ``s`` (as the posterior tables': 3 % to 97 %).
HDI_PROB = 0.94
#: Shapes ``a`` the quantiles may ask for: upper95 / median from about 102 down to 1.005.
_SHAPE_RANGE = (0.25, 3e4)


def _ratio(a):
    """upper95 / median of ``s`` when ``s^2 ~ InvGamma(a, .)`` (independent of the scale)."""
    return float(np.sqrt(stats.gamma.ppf(0.5, a) / stats.gamma.ppf(0.05, a)))


#: Medians of ``s`` accepted: a factor on the declared deviations, not a unit slip.
MEDIAN_RANGE = (0.01, 100.0)
#: The smallest and largest upper95 / median the shape range allows.
RATIO_RANGE = (_ratio(_SHAPE_RANGE[1]), _ratio(_SHAPE_RANGE[0]))


@dataclass(frozen=True)
class ErrorScalePrior:
    """The prior of the error scale ``s``: ``s^2 ~ InvGamma(shape, scale)`` from two quantiles.

    Parameters
    ----------
    median : float
        Median of ``s`` (dimensionless; 1: the declared deviations are the best guess),
        within ``MEDIAN_RANGE``.
    upper95 : float
        ``s`` is below this with probability 0.95; between ``RATIO_RANGE`` times `median`.

    Attributes
    ----------
    shape, scale : float
        ``a`` and ``beta`` of the inverse gamma on ``s^2``, solved from the two quantiles.

    Raises
    ------
    ValueError
        When a value breaks a rule (the message names the field and the rule).
    """

    median: float
    upper95: float
    shape: float = field(init=False)
    scale: float = field(init=False)

    def __post_init__(self):
        for name in ("median", "upper95"):
            value = getattr(self, name)
            if not (
                isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0
            ):
                raise ValueError(f"{name}: must be a positive number")
        if not MEDIAN_RANGE[0] <= self.median <= MEDIAN_RANGE[1]:
            low, high = MEDIAN_RANGE
            raise ValueError(
                f"median: must be between {low:g} and {high:g} (a factor on the declared sd)"
            )
        low, high = RATIO_RANGE
        ratio = self.upper95 / self.median
        if not low <= ratio <= high:
            raise ValueError(
                f"upper95: must be between {low:.3f} and {high:.3g} times the median "
                f"({self.median:g}); closer, s is known (leave error_scale out)"
            )
        shape = optimize.brentq(lambda a: np.log(_ratio(a) / ratio), *_SHAPE_RANGE, xtol=1e-12)
        object.__setattr__(self, "shape", float(shape))
        scale = self.median**2 * stats.gamma.ppf(0.5, shape)
        object.__setattr__(self, "scale", float(scale))

    def quantile(self, q):
        """Quantile(s) `q` of ``s`` under this prior."""
        return np.sqrt(stats.invgamma.ppf(q, self.shape, scale=self.scale))


def log_marginal(chi2, m, logdet_V, prior):
    """``ln f(Y | b)`` with ``s^2`` integrated out (a multivariate Student-t), normalised.

    Parameters
    ----------
    chi2 : float or numpy.ndarray
        ``r^T V_Y^-1 r`` with the declared ``V_Y`` (dimensionless).
    m : int
        Number of paired eigenvalues.
    logdet_V : float
        ``ln |V_Y|`` (``V_Y`` in rad^4/s^8).
    prior : ErrorScalePrior

    Returns
    -------
    float or numpy.ndarray
    """
    a, beta = prior.shape, prior.scale
    const = (
        special.gammaln(a + m / 2)
        - special.gammaln(a)
        + a * np.log(beta)
        - 0.5 * (m * np.log(2 * np.pi) + logdet_V)
    )
    return const - (a + m / 2) * np.log(beta + 0.5 * np.asarray(chi2))


def loo_pointwise(r, Q, prior):
    """Each eigenvalue's leave-one-out density ``ln f(Y_i | Y_-i, b)`` with ``s`` unknown.

    Given ``Y_-i``, ``s^2 ~ InvGamma(a + (m-1)/2, beta + chi2_-i / 2)`` and ``Y_i`` is normal
    around its conditional mean with variance ``s^2 / Q_ii`` (``Q = V_Y^-1``): a Student-t with
    ``2 a + m - 1`` degrees of freedom. ``chi2 = chi2_-i + (Q r)_i^2 / Q_ii``.

    Parameters
    ----------
    r : numpy.ndarray, shape (m,)
        Residuals ``Y - g``, rad^2/s^2.
    Q : numpy.ndarray, shape (m,) or (m, m)
        ``V_Y^-1`` (its diagonal when ``V_Y`` is diagonal).
    prior : ErrorScalePrior

    Returns
    -------
    numpy.ndarray, shape (m,)
        Summing to :func:`log_marginal` only when ``m = 1`` (the terms are conditionals).
    """
    if Q.ndim == 1:
        q, e2 = Q, Q * r**2
        chi2 = float(np.sum(e2))
    else:
        Qr = Q @ r
        q = np.diag(Q)
        e2 = Qr**2 / q
        chi2 = float(r @ Qr)
    m = r.size
    a1 = prior.shape + (m - 1) / 2
    b1 = prior.scale + 0.5 * (chi2 - e2)
    # Student-t: ln G(a1 + 1/2) - ln G(a1) - ln(2 pi b1 / q)/2 - (a1 + 1/2) ln(1 + e2/(2 b1))
    return (
        special.gammaln(a1 + 0.5)
        - special.gammaln(a1)
        - 0.5 * np.log(2 * np.pi * b1 / q)
        - (a1 + 0.5) * np.log1p(0.5 * e2 / b1)
    )


def draw_scale(chi2, m, prior, rng):
    """One draw of ``s`` from ``s^2 | b, Y ~ InvGamma(a + m/2, beta + chi2/2)`` per ``chi2``.

    Parameters
    ----------
    chi2 : array_like, shape (n,)
        ``r^T V_Y^-1 r`` at each kept draw of ``b``.
    m : int
    prior : ErrorScalePrior
    rng : numpy.random.Generator

    Returns
    -------
    numpy.ndarray, shape (n,)
    """
    chi2 = np.asarray(chi2, dtype=float)
    gamma = rng.gamma(prior.shape + m / 2, size=chi2.shape)
    return np.sqrt((prior.scale + 0.5 * chi2) / gamma)


def scale_from_draws(problem, samples_b, forward, rng=None, max_draws=4000):
    """The posterior of ``s`` from a chain: one ``s`` per kept draw of ``b`` (seeded).

    Each kept ``b`` gets its ``chi2`` (a forward evaluation: the sampler's own model) and one
    ``s`` from ``s^2 | b, Y`` (:func:`draw_scale`); together they are draws of ``s | Y``.

    Parameters
    ----------
    problem : bayesplate.likelihood.posterior.GaussianProblem
        The sampled problem, with ``error_scale`` set.
    samples_b : numpy.ndarray, shape (n, 6)
        Kept draws of ``b``, Pa (``SamplingResult.samples_b``).
    forward : callable
        ``forward(b, n_modes)`` with ``eigenvalues`` (``SamplingSetup.sampling_forward()``).
    rng : int, numpy.random.Generator or None
    max_draws : int
        At most this many draws, a seeded subset without replacement when there are more
        (the forward evaluations cost about a millisecond each on the fast model).

    Returns
    -------
    summary : ScaleSummary
    s : numpy.ndarray, shape (min(n, max_draws),)
    """
    rng = np.random.default_rng(rng)
    samples_b = np.asarray(samples_b, dtype=float)
    n = len(samples_b)
    rows = np.sort(rng.choice(n, max_draws, replace=False)) if n > max_draws else np.arange(n)
    n_modes, modes = problem.pairing.n_modes(), problem.pairing.modes
    chi2 = np.array(
        [problem.chi2(np.asarray(forward(b, n_modes).eigenvalues)[modes]) for b in samples_b[rows]]
    )
    s = draw_scale(chi2, problem.m, problem.error_scale, rng)
    return summarise_scale(s, problem.error_scale), s


@dataclass(frozen=True)
class ScaleSummary:
    """The posterior of ``s``: median and central 94 % interval.

    Attributes
    ----------
    median : float
    interval : tuple of float
        3 % and 97 % quantiles.
    prior : ErrorScalePrior
    source : str
        ``"draws"`` (one per kept posterior draw) or ``"linearised"`` (at the estimate).
    status : str
        ``"ok"``, or ``"wide"`` when the interval's upper end is over 3 times the median
        (too few frequencies to tell the scale).
    """

    median: float
    interval: tuple
    prior: ErrorScalePrior
    source: str
    status: str = "ok"

    def __str__(self):
        lo, hi = self.interval
        return (
            f"error scale s: median {self.median:.3g}, 94 % interval [{lo:.3g}, {hi:.3g}] "
            f"({self.source}; prior median {self.prior.median:g}, upper 95 % "
            f"{self.prior.upper95:g})"
        )


def summarise_scale(s, prior, source="draws"):
    """A :class:`ScaleSummary` of draws of ``s``, shape (n,)."""
    tail = (1 - HDI_PROB) / 2
    lo, med, hi = np.quantile(np.asarray(s, dtype=float), [tail, 0.5, 1 - tail])
    return _summary(med, lo, hi, prior, source)


def _summary(med, lo, hi, prior, source):
    status = "wide" if hi > 3 * med else "ok"
    return ScaleSummary(float(med), (float(lo), float(hi)), prior, source, status)


@dataclass(frozen=True)
class LinearisedScale:
    """``s`` at an estimate and the constants' covariance with it (B, MVE; linearised).

    Attributes
    ----------
    summary : ScaleSummary
        ``s | Y`` (source ``"linearised"``).
    s_hat : float
        ``sqrt((beta + chi2/2) / (a + (m - p)/2))``.
    chi2 : float
        At the estimate, declared deviations.
    n_effective : float
        ``p``: the trace of the hat matrix at ``s_hat``.
    dof : float
        ``nu = 2 a + m - p``.
    covariance_b : numpy.ndarray, shape (6, 6)
        ``nu / (nu - 2) (S^T (s_hat^2 V_Y)^-1 S + W)^-1``, Pa^2.
    status : str
        ``"ok"``; ``"few_dof"`` when ``nu <= 2`` (no finite variance: the covariance is then
        the Gaussian one at ``s_hat``, unscaled by ``nu / (nu - 2)``).
    """

    summary: ScaleSummary
    s_hat: float
    chi2: float
    n_effective: float
    dof: float
    covariance_b: np.ndarray = field(repr=False)
    status: str = "ok"


def linearised_scale(S, r, V_Y, W, prior, iterations=50):
    """The error scale at an estimate and the covariance of ``b`` with it (module docstring).

    Parameters
    ----------
    S : numpy.ndarray, shape (m, 6)
        Sensitivities at the estimate, rad^2/s^2 per Pa.
    r : numpy.ndarray, shape (m,)
        Residuals ``Y - g`` there, rad^2/s^2.
    V_Y : numpy.ndarray, shape (m, m)
        Declared observation covariance.
    W : numpy.ndarray, shape (6, 6)
        The estimator's prior precision, 1/Pa^2 (``V_b^-1`` for B; for MVE its parameter
        covariance's inverse; may be singular): ``P^-1 = S^T V_Y^-1 S + W`` at ``s = 1``.
    prior : ErrorScalePrior
    iterations : int
        Cap on the fixed-point iterations of ``(s_hat, p)`` (converges in a few).

    Returns
    -------
    LinearisedScale
    """
    m = r.size
    Vinv = np.linalg.inv(V_Y)
    chi2 = float(r @ Vinv @ r)
    info_Y = S.T @ Vinv @ S
    a, beta = prior.shape, prior.scale + 0.5 * chi2

    def posterior(s2):
        """``P`` at ``s^2``, and the trace of the hat matrix."""
        P = np.linalg.inv(info_Y / s2 + W)
        return P, float(np.trace(P @ info_Y) / s2)

    s2 = 1.0
    for _ in range(iterations):
        p = posterior(s2)[1]
        new = beta / (a + 0.5 * (m - p))
        done = abs(new - s2) <= 1e-12 * s2
        s2 = new
        if done:
            break
    P, p = posterior(s2)
    a1 = a + 0.5 * (m - p)
    nu = 2 * a1
    tail = (1 - HDI_PROB) / 2
    lo, med, hi = np.sqrt(stats.invgamma.ppf([tail, 0.5, 1 - tail], a1, scale=beta))
    summary = _summary(med, lo, hi, prior, "linearised")
    status = "ok" if nu > 2 else "few_dof"
    factor = nu / (nu - 2) if nu > 2 else 1.0
    return LinearisedScale(summary, float(np.sqrt(s2)), chi2, p, nu, factor * P, status)


def linearised_at(problem, b, covariance_b=None):
    """:func:`linearised_scale` of a problem with an error scale at ``b`` (one forward solve).

    Parameters
    ----------
    problem : bayesplate.likelihood.posterior.GaussianProblem
        With ``error_scale`` set.
    b : array_like, shape (6,)
        The estimate, Pa.
    covariance_b : array_like, shape (6, 6), optional
        The estimator's ``P`` at ``s = 1``: its prior precision is taken as
        ``P^-1 - S^T V_Y^-1 S`` (negative eigenvalues, from ``S`` moving in the last step,
        set to 0). Default: B's, ``V_b^-1``.

    Returns
    -------
    LinearisedScale
    """
    prediction = problem.predict(b)
    S, r = prediction.S, problem.Y - prediction.g
    if covariance_b is None:
        W = np.linalg.inv(problem.V_b)
    else:
        W = np.linalg.inv(covariance_b) - S.T @ np.linalg.solve(problem.V_Y, S)
        w, U = np.linalg.eigh(0.5 * (W + W.T))
        W = (U * np.maximum(w, 0.0)) @ U.T
    return linearised_scale(S, r, problem.V_Y, W, problem.error_scale)
