"""The checks of a fit and the verdict: predictive p-values, unidentified constants, basins.

Step 1 and step 5 of :func:`..diagnose.diagnose`: what a fit's Laplace posterior says about
each measured mode and each constant, which other optima fit about as well, and the
verdicts. Pure computation on :class:`.laplace.JointFit` results.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm

from ... import laminate
from ...quantities import ENGINEERING_NAMES, engineering_covariance

__all__ = [
    "basins_note",
    "predictive_p_values",
    "refit_test",
    "rival_optima",
    "runner_up",
    "tie_text",
    "ties",
    "unidentified",
    "unsettled_notes",
    "verdict",
]


def verdict(p_value, warranted, refit_p, alpha, best, tied=False):
    """The verdicts of the issue.

    Parameters
    ----------
    p_value : float
        Of the nominal fit's chi-square.
    warranted : bool
        Whether the best refined candidate gains enough evidence.
    refit_p : float
        Of the best candidate's chi-square (NaN when not warranted).
    alpha : float
        Significance of the tests.
    best : CandidateResult or None
    tied : bool
        Another candidate ties with ``best`` (:func:`ties`: within the ambiguity margin of
        log-odds, or fitting as well within the prior margin): an explained mismatch is
        ``ambiguous``.

    Returns
    -------
    verdict : {"consistent", "explained", "ambiguous", "unexplained"}
    chosen : CandidateResult or None
        ``best`` when explained or ambiguous (its fit is the refit).
    """
    if warranted and refit_p >= alpha:
        return ("ambiguous" if tied else "explained"), best
    if p_value >= alpha and not warranted:
        return "consistent", None
    return "unexplained", None


def runner_up(best, ranked, probabilities, margin=2.0, prior_margin=np.inf):
    """The rival of ``best``, a refined candidate of another name; the log-odds between.

    A refined candidate of another name ties when it fits the recordings about as well as
    ``best`` (its best fit's log-likelihood ``-chi2 / 2`` no more than ``margin`` below
    ``best``'s), and its posterior log-odds are

    - ``"odds"``: within ``margin`` nats of ``best``'s (the issue's rule);
    - ``"fit"``: within ``prior_margin`` nats. The odds between the two then come from their
      Occam factors alone, ``ln(prior width / posterior width)`` of each parameter the
      recordings hardly fix (a point support's position, say, against a foundation's one
      stiffness). Those prior widths are conventions (a position uniform over the plate, a
      stiffness over decades), not knowledge: halving or doubling one moves the odds by
      ln 2 = 0.7 nats, and two candidates differ by two to five such parameters (1.4-3.5
      nats). A preference of a few nats is then the priors' and not the recordings', and
      is said as a tie.

    For the same reason a candidate that fits worse than ``best`` by more than ``margin``
    does not tie, however close its odds: the recordings prefer ``best``, and only the
    rival's smaller prior volume (fewer parameters) brings it near. A thickness taper (one
    parameter) came within 1.1-1.4 nats of a local stiffness loss on a concealed slot while
    fitting it 3.8-5.0 nats worse (``studies/outside_effects.py``); on the cached
    calibrations no true candidate was such a rival (``reports/tie_rule.md``).

    Parameters
    ----------
    best : CandidateResult
    ranked : list of CandidateResult
        Best first.
    probabilities : dict
        ``{name: posterior probability}`` (:func:`.probabilities.model_probabilities`).
    margin : float
        Nats, both in log-odds and in log-likelihood.
    prior_margin : float
        Nats of log-odds within which a rival that fits as well ties (default: none does).

    Returns
    -------
    rival : CandidateResult or None
        Another variant of ``best``'s candidate (a taper along the other side) is no rival.
        The first candidate that ties (:func:`ties`), else the best refined one of another
        name.
    gap : float
        ``ln P(best's name) - ln P(rival's name)``, nats; ``inf`` without a rival.
    tie : {"odds", "fit"} or None
        Why ``rival`` ties; None when it does not.
    """
    others = [c for c in ranked if c.fit.refined and c.name != best.name]
    if not others:
        return None, np.inf, None
    tied = ties(best, ranked, probabilities, margin, prior_margin)
    rival, tie = tied[0] if tied else (others[0], None)
    return rival, _gap(best, rival, probabilities), tie


def ties(best, ranked, probabilities, margin=2.0, prior_margin=np.inf):
    """Every refined candidate of another name that ties with ``best``, best first.

    The ties of :func:`runner_up`; each name once, its best refined variant. An ``ambiguous``
    verdict names them all: when a third candidate ties as well, naming two would leave out
    one the recordings do not rule out.

    Returns
    -------
    list of (CandidateResult, str)
        Each with its kind of tie, ``"odds"`` or ``"fit"``.
    """
    out, seen = [], {best.name}
    for c in ranked:
        if not c.fit.refined or c.name in seen:
            continue
        seen.add(c.name)
        if 0.5 * (c.fit.chi2 - best.fit.chi2) > margin:
            continue  # fits worse: only its prior volume brings it near
        gap = _gap(best, c, probabilities)
        if gap < margin:
            out.append((c, "odds"))
        elif gap < prior_margin:
            out.append((c, "fit"))
    return out


def _gap(best, c, probabilities):
    """``ln P(best's name) - ln P(c's name)``, nats."""
    with np.errstate(divide="ignore"):
        return float(np.log(probabilities[best.name]) - np.log(probabilities[c.name]))


def tie_text(best, tied, probabilities):
    """The note's sentence on why ``best`` and the candidates ``tied`` (:func:`ties`) tie."""
    rival, tie = tied[0]
    odds = (
        f"posterior probabilities {probabilities[best.name]:.2f} and "
        f"{probabilities[rival.name]:.2f}"
    )
    if tie == "fit":
        text = (
            f"{best.name} and {rival.name} fit the recordings about equally well (chi2 "
            f"{best.fit.chi2:.1f} and {rival.fit.chi2:.1f}); {best.name} is the more "
            f"probable ({odds}) by its prior volume alone, not by the recordings"
        )
    else:
        text = f"{best.name} and {rival.name} fit about equally well ({odds})"
    if len(tied) > 1:
        more = ", ".join(
            f"{c.name} (chi2 {c.fit.chi2:.1f}, probability {probabilities[c.name]:.2f})"
            for c, _ in tied[1:]
        )
        text += f"; so {'does' if len(tied) == 2 else 'do'} {more}"
    return text + ": "


def predictive_p_values(fit_, problem):
    """Two-sided p-value of each residual under the Laplace posterior predictive.

    Parameters
    ----------
    fit_ : JointFit
    problem : JointProblem

    Returns
    -------
    numpy.ndarray, shape (m,)
    """
    S = fit_.modal.sensitivities[problem.modes]
    var = problem.sigma**2 + np.einsum("ij,jk,ik->i", S, fit_.covariance[:6, :6], S)
    z = (problem.Y - fit_.eigenvalues) / np.sqrt(var)
    return 2.0 * norm.sf(np.abs(z))


def unidentified(fit_, V_b, ratio, margin=None):
    """Engineering constants the data do not fix.

    Those whose posterior deviation is close to the prior one, and, when ``margin`` is
    given, those that differ by more than two deviations at another local optimum whose
    objective ``chi2 + chi2_prior`` is within ``margin`` of the best: the data fit both
    basins about equally, so neither value is an estimate (the Laplace deviation, local to
    one basin, would understate the uncertainty).

    Parameters
    ----------
    fit_ : JointFit
    V_b : numpy.ndarray, shape (6, 6)
        Prior covariance of the stiffness coefficients, Pa^2.
    ratio : float
        Posterior sd / prior sd above which a constant is unidentified.
    margin : float, optional

    Returns
    -------
    list of str
        Names of :data:`bayesplate.quantities.ENGINEERING_NAMES`.
    """
    prior_sd = np.sqrt(np.diag(engineering_covariance(fit_.constants, V_b)))
    loose = fit_.constants_sd > ratio * prior_sd
    for _, _, differs in rival_optima(fit_, margin) if margin is not None else ():
        loose |= differs
    return [n for n, flag in zip(ENGINEERING_NAMES, loose, strict=True) if flag]


def rival_optima(fit_, margin):
    """Other optima within ``margin`` of the best objective whose constants differ.

    Returns
    -------
    list of (constants, objective, differs)
        ``differs``: bool (6,), the constants more than two deviations from the best fit's.
    """
    best = fit_.chi2 + fit_.chi2_prior
    rivals = []
    for b, objective in fit_.alternatives:
        if objective - best < margin and laminate.is_physical(b):
            e = laminate.engineering_from_stiffness(b)
            differs = np.abs(e - fit_.constants) > 2.0 * fit_.constants_sd
            if differs.any():
                rivals.append((e, objective, differs))
    return rivals


def basins_note(fit_, margin):
    """A note naming the other optimum that fits about as well, or None."""
    rivals = rival_optima(fit_, margin)
    if not rivals:
        return None
    e, objective, differs = rivals[0]
    values = ", ".join(
        f"{n} {_case_units(n, fit_.constants)} vs {_case_units(n, e)}"
        for n, d in zip(ENGINEERING_NAMES, differs, strict=True)
        if d
    )
    return (
        f"the nominal fit has a second optimum that fits about as well (objective "
        f"{fit_.chi2 + fit_.chi2_prior:.2f} vs {objective:.2f}): {values}; these "
        "constants are reported as unidentified"
    )


def _case_units(name, e):
    i = ENGINEERING_NAMES.index(name)
    return f"{e[i]:.3g}" if name == "nu12" else f"{1e-9 * e[i]:.3g} GPa"


def refit_test(fit_, m):
    """``(dof, p)``: the chi-square test of a candidate's refit on ``m`` frequencies."""
    dof = max(m - fit_.effective_parameters, 1.0)
    return dof, float(chi2_dist.sf(fit_.chi2, dof))


def unsettled_notes(nominal, chosen, tied=(), ranked=()):
    """A note for each fit the verdict rests on whose full-model check did not settle.

    The nominal fit, the named candidate ``chosen`` (or None) and, for an ``ambiguous``
    verdict, every candidate ``tied`` with it (``(candidate, kind)`` pairs, as
    :func:`ties` gives them); and one for each candidate of ``ranked`` whose fit failed
    (its ``failed``: ranked as its phase before left it).
    """
    named = [c for c in (chosen, *(t for t, _ in tied)) if c is not None]
    notes = []
    for label, fit_ in [("the nominal fit", nominal), *((c.name, c.fit) for c in named)]:
        check = fit_.check
        if check is not None and not check.settled:
            notes.append(
                f"{label}: the full model's objective {check.full_objective:.4g} could still "
                f"fall by {check.decrement:.2g} (a Newton step) after {check.rounds} rounds on "
                "reduced models; its numbers are those of the last round"
            )
    notes += [f"{c.name}: {c.failed}" for c in ranked if c.failed]
    return notes
