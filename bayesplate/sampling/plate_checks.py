"""Which plate disagrees: each plate's data against the posterior of the other plates.

A plate made of another material (or measured wrongly) pulls the joint posterior towards
itself, so its misfit at the joint posterior understates the disagreement, and the misfit
of the others overstates theirs. The figure that separates them is each plate's
leave-one-out predictive check: the joint posterior of the OTHER plates (B on their stacked
problem, :func:`~bayesplate.sampling.stacked.joint_estimate`: MAP ``b_-p`` and ``P_-p``)
predicts plate ``p``'s eigenvalues, to first order, as ``N(g_p(b_-p), V_p + S_p P_-p
S_p^T)``; the statistic

    q_p = r^T (V_p + S_p P_-p S_p^T)^-1 r,   r = Y_p - g_p(b_-p),

is chi-square with ``m_p`` degrees of freedom when the plate agrees (linear-Gaussian
model), and its upper tail is the plate's p-value. With no other plate the prior predicts.

One disagreeing plate also spoils the others' leave-one-out posteriors (each includes it),
so the plates are set aside one at a time: the plate with the smallest p-value below
``alpha`` is flagged and left out, and the remaining plates are tested again among
themselves, until none is below ``alpha``. Two plates that disagree with each other and no
third cannot be told apart: both are flagged (status ``"undecided"``).

Also reported, for each plate: ``chi2`` of its residuals at the joint posterior mean with
its declared ``V_Y`` and ``chi2(m_p)``'s upper tail (a fit figure, optimistic: the joint
posterior was fitted to these data too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .stacked import joint_estimate

__all__ = ["ALPHA", "PlateCheck", "plate_checks", "predictive_check"]

#: Default level of the disagreement flag.
ALPHA = 0.01
#: B's TOL for the other plates' posterior (well inside a deviation; a few iterations from
#: the joint MAP).
REST_TOL = 1e-6


@dataclass(frozen=True)
class PlateCheck:
    """How one plate agrees with the others.

    Attributes
    ----------
    name : str
    m : int
        Paired measured frequencies.
    chi2_joint, p_joint : float
        ``chi2`` at the joint posterior mean (declared ``V_Y``) and its ``chi2(m)`` tail.
    chi2_rest, p_rest : float
        The leave-one-out predictive statistic ``q_p`` and its p-value, in the round in
        which the plate was flagged, else in the last round.
    flagged : bool
        Whether the plate disagrees at ``alpha``.
    status : str
        ``"consistent"``, ``"flagged"`` or ``"undecided"`` (one of two plates that
        disagree, with no third to side with either).
    """

    name: str
    m: int
    chi2_joint: float
    p_joint: float
    chi2_rest: float
    p_rest: float
    flagged: bool
    status: str


def predictive_check(setup, others, start=None):
    """``q_p`` and its p-value: plate `setup` predicted by the plates `others` (linearised).

    Parameters
    ----------
    setup : SamplingSetup
        The plate tested.
    others : sequence of SamplingSetup
        The plates that predict it (empty: the prior predicts).
    start : array_like, shape (6,), optional
        First iterate of B on the others (Pa).

    Returns
    -------
    q, p : float
    """
    p = setup.problem
    if others:
        rest = joint_estimate(others, start=start, tol=REST_TOL)
        b, P = rest.b, rest.covariance_b
    else:
        b, P = p.mu_b, p.V_b
    pred = setup.problem_on_fast_model().predict(b)
    C = p.V_Y + pred.S @ P @ pred.S.T
    r = p.Y - pred.g
    q = float(r @ np.linalg.solve(C, r))
    return q, float(stats.chi2.sf(q, p.m))


def _fit(setup, b):
    """``chi2`` of a plate's residuals at ``b`` (declared ``V_Y``) and its tail."""
    p = setup.problem
    g = setup.problem_on_fast_model().predict(b).g
    chi2 = p.chi2(g)
    return chi2, float(stats.chi2.sf(chi2, p.m))


def plate_checks(setups, mean_b, start=None, alpha=ALPHA, names=None):
    """Each plate's agreement with the rest, flagged at `alpha` (module docstring).

    Parameters
    ----------
    setups : sequence of SamplingSetup
        The plates (fast models covering the joint posterior).
    mean_b : array_like, shape (6,)
        The joint posterior mean of ``b``, Pa.
    start : array_like, shape (6,), optional
        First iterate of B on the other plates (the joint MAP), Pa.
    alpha : float
        Level of the flag.
    names : sequence of str, optional

    Returns
    -------
    list of PlateCheck
    """
    n = len(setups)
    names = [f"plate {i + 1}" for i in range(n)] if names is None else list(names)
    active = list(range(n))
    q, pv = np.full(n, np.nan), np.full(n, np.nan)
    status = ["consistent"] * n
    while True:
        for i in active:
            others = [setups[j] for j in active if j != i]
            q[i], pv[i] = predictive_check(setups[i], others, start)
        worst = min(active, key=lambda i: pv[i])
        if not pv[worst] < alpha:
            break
        if len(active) == 2:
            for i in active:
                if pv[i] < alpha:
                    status[i] = "undecided"
            break
        status[worst] = "flagged"
        active.remove(worst)
    checks = []
    for i, s in enumerate(setups):
        chi2, p_joint = _fit(s, mean_b)
        checks.append(
            PlateCheck(
                names[i],
                s.problem.m,
                chi2,
                p_joint,
                float(q[i]),
                float(pv[i]),
                status[i] != "consistent",
                status[i],
            )
        )
    return checks
