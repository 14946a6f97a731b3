"""A global answer by likelihood: several starts over the constants, their basins compared.

Pairing by the most probable assignment makes the posterior multimodal: an assignment that
calls the fundamental spurious and a dozen modes unobserved can settle at constants several
times the truth, as locally converged as the right one. So the assignment-and-estimate
rounds start from more than the prior mean (:func:`start_points`: the moduli together, E2
and G12 alone, each scaled down and up), a start whose assignment at its own point is one
already tried being skipped; every settled answer is then weighed by its evidence
(:func:`log_evidence`) and the most probable kept. The others are its rivals, each with the
nats it trails by, which :mod:`.assess` reports where one is nearly as good and far away.

``log p(Y, a) ~ ln N(Y_a; g(b*), V_Y) + ln N(b*; mu, V_b) + 1/2 ln det(2 pi Sigma)
+ log P_assign(a)``: the paired peaks' likelihood at the estimate ``b*``, the prior there,
the Laplace volume of the estimate's covariance ``Sigma`` (B's ``P``), and the assignment's
own terms (:func:`bayesplate.matching.assignment.assignment_terms`: a spurious peak uniform over the
band, a mode in the band unobserved or not), all in eigenvalues.
"""

from __future__ import annotations

import numpy as np

from .. import laminate
from ..matching.assignment import assignment_terms
from ..matching.peak_prior import assignment_priors
from ..quantities import eigenvalue_from_hz, eigenvalue_sd

__all__ = ["START_SCALES", "start_points", "log_evidence", "rivals_of"]

#: ``(which constants, factor)`` of each start beside the prior mean: all six moduli, E2
#: alone and G12 alone (what orders a plate's low modes), each down and up.
START_SCALES = (
    ("moduli", 0.6),
    ("moduli", 1.6),
    ("E2", 0.5),
    ("E2", 2.0),
    ("G12", 0.5),
    ("G12", 2.0),
)
_WHICH = {"moduli": [0, 1, 3, 4, 5], "E2": [1], "G12": [3]}


def start_points(mean):
    """Engineering constants of the starts beside `mean` (:data:`START_SCALES`), physical only.

    Parameters
    ----------
    mean : array_like, shape (6,)
        ``(E1, E2, nu12, G12, G13, G23)``, SI.

    Returns
    -------
    list of numpy.ndarray, shape (6,)
    """
    out = []
    for which, factor in START_SCALES:
        e = np.array(mean, dtype=float)
        e[_WHICH[which]] *= factor
        if laminate.is_physical(laminate.stiffness_from_engineering(e)):
            out.append(e)
    return out


def log_evidence(case, result, assignment, prior):
    """Laplace evidence (nats) of a settled answer and its assignment; -inf when unusable.

    Parameters
    ----------
    case : bayesplate.io.Case
    result : EstimateResult
        B's answer with the assignment's pairs: ``measured_Hz``, ``frequency_Hz``, ``b``,
        ``covariance_b``.
    assignment : bayesplate.matching.assignment.Assignment
        The assignment at the answer (its spurious peaks and unobserved modes).
    prior : tuple
        ``(mu_b, V_b)``, Pa and Pa^2.

    Returns
    -------
    float
    """
    b, cov = np.asarray(result.b, dtype=float), np.asarray(result.covariance_b, dtype=float)
    if not (result.converged and laminate.is_physical(b) and np.all(np.isfinite(cov))):
        return -np.inf
    measured = case.measured
    paired = np.flatnonzero(np.asarray(assignment.modes) >= 0)
    f = np.asarray(result.measured_Hz, dtype=float)
    s = np.interp(f, measured.frequency_Hz, measured.sigma_Hz)
    var = eigenvalue_sd(f, s) ** 2
    r = eigenvalue_from_hz(f) - eigenvalue_from_hz(np.asarray(result.frequency_Hz, dtype=float))
    log_l = -0.5 * float(np.sum(r**2 / var + np.log(2 * np.pi * var)))
    mu, V = (np.asarray(x, dtype=float) for x in prior)
    d = b - mu
    _, logdet_v = np.linalg.slogdet(2 * np.pi * V)
    log_prior = -0.5 * float(d @ np.linalg.solve(V, d) + logdet_v)
    sign, logdet_sigma = np.linalg.slogdet(2 * np.pi * cov)
    if sign <= 0:
        return -np.inf
    n = int(max(np.max(assignment.modes, initial=-1), np.max(assignment.unobserved, initial=-1)))
    p_u, p_s = assignment_priors(measured, n + 1)
    if assignment.p_unobserved is not None and assignment.p_unobserved.size > n:
        p_u = assignment.p_unobserved[: n + 1]  # as the assignment was made (tap points)
    in_band = np.zeros(n + 1, dtype=bool)
    in_band[np.asarray(assignment.modes)[paired]] = True
    in_band[np.asarray(assignment.unobserved, dtype=int)] = True
    log_b = np.log(eigenvalue_from_hz(assignment.band_Hz))
    terms = assignment_terms(assignment.modes, in_band, log_b, p_u, p_s)
    return log_l + log_prior + 0.5 * logdet_sigma + terms


def rivals_of(best, candidates):
    """``(constants, nats behind best)`` of the candidates whose answers differ from best's.

    Parameters
    ----------
    best : tuple
        ``(result, evidence)``.
    candidates : sequence of tuple
        ``(result, evidence)`` each.

    Returns
    -------
    list of (numpy.ndarray, float)
        Finite evidences only, one per distinct answer (the constants within 0.1 % of each
        other are the same answer), nearest first.
    """
    out = []
    for result, evidence in sorted(candidates, key=lambda c: -c[1]):
        if not np.isfinite(evidence) or result is best[0]:
            continue
        seen = [best[0].constants] + [c for c, _ in out]
        if any(np.allclose(result.constants, c, rtol=1e-3) for c in seen):
            continue
        out.append((np.array(result.constants), float(best[1] - evidence)))
    return out
