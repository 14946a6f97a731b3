"""Posterior probabilities of "nothing left out" and of each candidate, from their evidences.

With the Laplace log-evidences :func:`..diagnose.diagnose` computes, ``ln Z_0`` of the
nominal model and ``ln Z_i = ln Z_0 + g_i`` of each fitted candidate (``g_i`` its evidence
gain, nats), Bayes' rule gives

    P(i | Y) = pi_i Z_i / sum_j pi_j Z_j,

computed as ``exp(ln pi_i + g_i - logsumexp(ln pi + g))`` (log-sum-exp: gains of hundreds of
nats neither overflow nor underflow to all zeros; adding a constant to every log-evidence
leaves the probabilities unchanged, so only the gains are needed).

Variants. A candidate fitted in several variants (a taper along x and one along y, which
share a :attr:`~..physics.base.Physics.name`) is *one* candidate whose variant is a discrete
parameter with a uniform prior: each variant gets ``1 / n_variants`` of the candidate's
prior odds and the candidate's probability is the sum of its variants'. A candidate thus
weighs the same in the prior however many variants it is fitted in, and the probabilities
are keyed by candidate name. (A pair of effects, :mod:`..physics.combined`, is a candidate
of its own, named ``first+second``.)

Prior odds are equal (odds 1 for every candidate against the nominal model) unless given.

Mirror images. A candidate's gain counts every posterior mode its mirror images make
(:func:`images_log_weight`), since the Laplace evidence at one fit counts one: without it a
located candidate on a symmetric plate lost up to ``ln 4`` (1.4 nats) against one without
images (a point support against a foundation).
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

__all__ = ["NOMINAL", "images_log_weight", "model_probabilities"]

#: Key of "nothing left out" (the nominal model) among the probabilities.
NOMINAL = "nominal"


def model_probabilities(results, prior_odds=None, nominal=0.0):
    """Posterior probability of the nominal model and of each candidate.

    Parameters
    ----------
    results : sequence of (str, float)
        ``(name, log_evidence)`` of every fitted candidate variant: its
        :attr:`~..physics.base.Physics.name` and its ``ln Z`` in nats, on the scale where the
        nominal model's is ``nominal`` (with the default 0: the evidence gains). Variants share a
        name. A value of ``-inf`` or NaN (a fit that left the physical region) has
        probability zero.
    prior_odds : dict, optional
        ``{name: odds}``: a candidate's prior odds against the nominal model (default 1
        for every name; ``prior_odds[NOMINAL]`` is ignored, the nominal model's odds are 1).
    nominal : float
        ``ln Z`` of the nominal model, nats.

    Returns
    -------
    dict
        ``{name: probability}``, :data:`NOMINAL` first, then the candidates in decreasing
        probability (ties in the order first seen); the values sum to one.

    Raises
    ------
    ValueError
        If a prior odds value is negative or not finite.
    """
    prior_odds = dict(prior_odds or {})
    for name, odds in prior_odds.items():
        if not (np.isfinite(odds) and odds >= 0):
            raise ValueError(f"prior_odds[{name!r}] = {odds!r}: must be finite and >= 0")
    names = [str(n) for n, _ in results]
    gains = np.array([float(g) for _, g in results], dtype=float) - float(nominal)
    gains = np.where(np.isnan(gains), -np.inf, gains)
    counts = {n: names.count(n) for n in names}
    with np.errstate(divide="ignore"):  # odds 0: log prior -inf, probability 0
        log_prior = np.array([np.log(prior_odds.get(n, 1.0) / counts[n]) for n in names])
    log_post = np.concatenate([[0.0], log_prior + gains])  # the nominal model: odds 1, gain 0
    log_post = np.where(np.isnan(log_post), -np.inf, log_post)
    p = np.exp(log_post - logsumexp(log_post))
    by_name = {}
    for n, value in zip(names, p[1:], strict=True):
        by_name[n] = by_name.get(n, 0.0) + float(value)
    order = sorted(by_name, key=lambda n: -by_name[n])  # sorted() is stable: ties keep order
    return {NOMINAL: float(p[0]), **{n: by_name[n] for n in order}}


def images_log_weight(theta, covariance, images):
    """``ln`` of the posterior modes a fit's mirror images add to its Laplace evidence.

    A located effect on a symmetric plate (a mass at ``(x, y)`` or at ``(a - x, y)``), a
    taper of either sign, a misalignment of either sign: the frequencies and the prior are
    the same at every mirror image, so the posterior has a mode at each, and the evidence is
    their sum, where the Laplace approximation at one fit counts one. An image far from the
    fit (many posterior deviations) adds one whole mode; one on top of it (a point on a line
    of symmetry, a taper of size zero) is the same mode and adds nothing. Between, each image
    adds ``1 - exp(-d^2 / 4)``, ``d`` its Mahalanobis distance from the fit under the fit's
    posterior covariance of the parameters (0.63 at 2 deviations, 0.98 at 4): a smooth
    stand-in for two equal Gaussian modes, within 0.03 nats of their integral against the
    Laplace approximation at the higher point, at every separation tried
    (``tests/test_verdict.py``).

    Parameters
    ----------
    theta : numpy.ndarray, shape (k,)
        The fit's parameters.
    covariance : numpy.ndarray, shape (k, k)
        Their posterior (Laplace) covariance.
    images : sequence of numpy.ndarray, shape (k,)
        The mirror images of ``theta`` (:meth:`~..physics.base.Physics.mirror_images`).

    Returns
    -------
    float
        ``ln(1 + sum_images (1 - exp(-d^2 / 4)))``, in [0, ln(1 + len(images))], nats.
    """
    theta = np.asarray(theta, dtype=float)
    if not len(images) or theta.size == 0:
        return 0.0
    C = np.asarray(covariance, dtype=float)
    steps = np.array([np.asarray(t, dtype=float) - theta for t in images])
    d2 = np.einsum("ik,ik->i", steps, np.linalg.lstsq(C, steps.T, rcond=None)[0].T)
    return float(np.log1p(np.sum(-np.expm1(-np.maximum(d2, 0.0) / 4.0))))
