"""Steps 3b-4 of a pass: what the ranking leads to before the verdict.

After the candidates are ranked (:func:`.rank.rank`):

- the nominal fit improved: a candidate's fit that walked into a better basin of the
  constants alone re-starts the nominal fit, so that its gain is not credited to the
  physics (:func:`improved_nominal`);
- the best candidate's refit tested; when rejected, its constants searched again, globally
  (:func:`searched_anew`, :mod:`.constants_again`);
- when still rejected, two effects at once (:mod:`.two_effects`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .constants_again import constants_anew
from .joint_fit import rough_fit, settle
from .local_fits import DISTINCT
from .nominal import nominal_polisher
from .nominal_check import check_nominal
from .rank import candidate_polisher, candidate_problem, candidate_result
from .state import Searched
from .store import fit_digest
from .two_effects import two_effects
from .unnamed import beaten, unnamed
from .verdict import refit_test, unidentified

__all__ = ["IMPROVEMENT", "improved_nominal", "refit", "searched_anew"]

#: Nats a nominal refit from a candidate's constants must gain to replace the nominal fit.
IMPROVEMENT = 1e-3


def refit(run, data, nominal_stage, located, ranked):
    """The nominal fit improved, the best candidate refitted, searched again, paired.

    Parameters
    ----------
    run : Run
    data : Deviations
    nominal_stage : NominalStage
    located : Located
    ranked : list of CandidateResult
        Best first (:func:`.rank.rank` on ``located.fitting``).

    Returns
    -------
    Searched
    """
    o, m = run.options, data.m
    check, fitting, ranked = _improved(run, data, nominal_stage.check, located.fitting, ranked)
    best = next((c for c in ranked if c.fit.refined), None)
    warranted = best is not None and best.log_evidence_gain > o.evidence_threshold
    refit_dof, refit_p = refit_test(best.fit, m) if warranted else (np.nan, np.nan)
    if warranted and refit_p < o.alpha:  # rejected: its constants searched again, globally
        fitting, ranked, best = _searched_again(fitting, ranked, best, refit_p)
        refit_dof, refit_p = refit_test(best.fit, m)
    change, stopped = None, None
    if warranted and refit_p < o.alpha and o.pairs:  # two effects at once
        change = _unnamed(run, data, check)
        enough = None if change is None else _beaten_by(change, o.unnamed_margin)
        top, two, stopped = two_effects(
            best, ranked, run.physics, fitting, o.evidence_threshold, o.alpha, m, enough=enough
        )
        if top is not None:
            best = top
            refit_dof, refit_p = refit_test(best.fit, m)
        ranked = sorted(ranked + two, key=lambda r: -r.log_evidence_gain)
    loose = (
        unidentified(best.fit, run.prior[1], o.unidentified_ratio)
        if warranted
        else check.unidentified
    )
    notes = (stopped,) if stopped else ()
    return Searched(
        check, ranked, best, warranted, refit_dof, refit_p, loose, unnamed=change, notes=notes
    )


def _unnamed(run, data, check):
    """The unnamed local change at the nominal fit (:mod:`.unnamed`), or None if left out."""
    if run.options.unnamed_margin is None:
        return None
    return unnamed(run.model, check.fit, data.problem, data.modes)


def _beaten_by(change, margin):
    """``enough(gain)`` of :func:`.two_effects.two_effects`: the unnamed change ahead."""

    def enough(gain):
        if not beaten(gain, change, margin):
            return None
        return (
            f"an unnamed local change gains {change.log_evidence_gain:+.1f} nats, more than "
            f"every candidate and pair fitted ({gain:+.1f}) by over {margin:g}: the pairs of "
            "the next candidates were not fitted"
        )

    return enough


def _improved(run, data, check, fitting, ranked):
    """``(check, fitting, ranked)``, the nominal fit improved where it can be.

    Where a candidate's constants lead to a better nominal fit (:func:`improved_nominal`),
    it replaces the nominal fit and the candidates' gains are shifted by the difference.
    """
    nominal, stages = check.fit, fitting.stages
    better = stages.run(
        "nominal refit from the candidates' constants",
        stages.key("improved", [fit_digest(c.fit) for c in ranked]),
        lambda: improved_nominal(data.problem, nominal, ranked, fitting),
    )
    if better is None:
        return check, fitting, ranked
    stages = stages.then("improved", fit_digest(better))
    run.say(f"nominal fit improved from a candidate's constants: chi2 = {better.chi2:.1f}")
    shift = better.log_evidence - nominal.log_evidence
    ranked = [replace(c, log_evidence_gain=c.log_evidence_gain - shift) for c in ranked]
    earlier = ((nominal.b, nominal.chi2 + nominal.chi2_prior), *nominal.alternatives)
    nominal = replace(better, alternatives=earlier)  # the other basins stay known
    fitting = replace(fitting, nominal=nominal, stages=stages)
    return check_nominal(run, data, nominal), fitting, ranked


def _searched_again(fitting, ranked, best, refit_p):
    """``(fitting, ranked, best)`` after `best`'s constants were searched again (stored)."""
    stages = fitting.stages
    anew = stages.run(
        f"{best.name}: constants searched again",
        stages.key("anew", fit_digest(best.fit)),
        lambda: searched_anew(fitting, best),
    )
    if anew is None:
        return fitting, ranked, best
    anew = replace(anew, fit=replace(anew.fit, physics=best.fit.physics))
    fitting = replace(fitting, stages=stages.then("anew", fit_digest(anew.fit)))
    fitting.say(
        f"{best.name}: refit rejected (p = {refit_p:.2g}); from its constants "
        f"searched again: chi2 = {anew.fit.chi2:.1f}, evidence gain "
        f"{anew.log_evidence_gain:+.1f}"
    )
    ranked = sorted([anew if c is best else c for c in ranked], key=lambda r: -r.log_evidence_gain)
    return fitting, ranked, anew


def searched_anew(fitting, best):
    """``best`` fitted again from its constants searched globally, or None.

    ``best`` is the refined :class:`~.rank.CandidateResult` whose refit the chi-square
    rejected (:mod:`.constants_again`). Returns its :class:`~.rank.CandidateResult` when
    the new fit's evidence is higher, else None.
    """
    physics = best.fit.physics
    problem = candidate_problem(fitting, physics)
    polish = candidate_polisher(problem, physics, fitting.model, fitting.ritz_modes)
    again = constants_anew(problem, best.fit, fitting.coarse, polish, fitting.workers)
    if again is None:
        return None
    return candidate_result(physics, fitting.model, fitting.nominal, again)


def improved_nominal(problem, nominal, ranked, fitting):
    """A better nominal optimum, started from candidates that beat it on the prior too.

    A candidate's fit starts from the nominal constants and may walk into a better basin of
    the constants alone; its gain would then be credited to the physics. Re-fitting the
    nominal model from there keeps the gains honest. Each re-fit runs on the nominal
    reduced model (``fitting.rough``; else the corrected coarse mesh) first; it is settled
    on the working mesh only when it reaches another optimum than the nominal one (whitened
    distance above ``DISTINCT``) that beats the nominal evidence there, and taken only when
    it beats it by more than :data:`IMPROVEMENT` on the working mesh.

    Returns
    -------
    JointFit or None
        None when no candidate leads to a better nominal fit.
    """
    total = nominal.chi2 + nominal.chi2_prior
    rough = fitting.rough or problem.on(fitting.coarse, fitting.scale)
    here = problem.pack(nominal.b)
    best = nominal
    for c in ranked:
        if not (c.fit.refined and c.fit.chi2 + c.fit.chi2_prior < total - 0.5):
            continue
        start = rough_fit(rough, [problem.pack(c.fit.b)], 200, 1)
        z = start.rough_optima[0]
        if np.linalg.norm(z - here) <= DISTINCT or start.log_evidence <= best.log_evidence:
            continue  # the nominal optimum again, or no better on the reduced model
        trial = settle(problem, nominal_polisher(problem), [z])
        if trial.log_evidence > best.log_evidence + IMPROVEMENT:
            best = trial
    return None if best is nominal else best
