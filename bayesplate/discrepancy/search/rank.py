"""Step 3 of diagnose, name: every candidate fitted jointly with the constants, ranked.

Each candidate's joint fit starts from the prior mean of its parameters, its own extra
starting points and, for a located candidate, the best distinct places of its Ritz scan,
each with the nominal optimum's constants and those of the other nominal basins found; it
runs on a reduced model of the modified plate on the coarse mesh
(:mod:`..physics.reduced_model`; the coarse finite-element model for a candidate without a
Ritz form), corrected to the working mesh; when promising, its best distinct reduced optima
are finished on the working mesh and the best one there is its fit (a reduced model only
chooses the starting points). Every
variant of a candidate (a taper along x and along y) is fitted and refined on its own; the
candidates are ranked by the Laplace evidence gain of these working-mesh fits over the
nominal model.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..physics.reduced_model import candidate_pencil
from .joint_fit import ROUGH_TOL, JointProblem, fit, rough_fit, settle
from .laplace import JointFit
from .phases import run_phase
from .probabilities import images_log_weight
from .settling import polish_and_finish

__all__ = [
    "CandidateResult",
    "candidate_polisher",
    "candidate_problem",
    "candidate_result",
    "rank",
]

log = logging.getLogger(__name__)

#: Evaluation cap of each local fit on a candidate's reduced coarse model. A fit still
#: crawling at the cap is handed on as it is: the coarse rounds of the refinement go on from
#: it. At 100, a quarter of a concealed 0.3 g point mass's rough fits ran to the cap and took
#: 58 % of the rough evaluations. At 60, with :data:`.joint_fit.ROUGH_TOL` 1e-4 (against 100
#: and 1e-8), six of the concealment study's recordings (50 x 50, two workers) kept their
#: verdict and chosen name and took 6-22 % less time; one refined a candidate more
#: (``reports/benchmark_diagnose.md``).
ROUGH_NFEV = 60
#: Other nominal optima (``nominal.alternatives``, best first) whose constants start the
#: candidates' reduced fits too.
OTHER_BASINS = 2
#: ... within this much of the nominal optimum's ``chi2 + chi2_prior`` (a fit far worse,
#: or one that left the physical region, is no basin to start from).
OTHER_BASIN_MARGIN = 20.0
#: ... with the physics parameters of this many best distinct optima reached from the
#: nominal optimum's constants.
OTHER_BASIN_STARTS = 3
#: Best distinct places of a located candidate's scan that start its reduced fits. Three
#: missed a point support's best basin on a concealment recording (1e5 N/m at (80, 40) mm on
#: the Frederiksen plate, deviations without the mesh's error added: the support settled at
#: an objective of 25.7, where a fit from its sixth place reaches 20.0, and a foundation was
#: named alone); on a consistent plate 6 places cost about a tenth more time than 3.
LOCATED_STARTS = 6
#: Distinct reduced optima of a candidate finished on the working mesh (the best one there
#: is its fit: a reduced model of a strong taper can misjudge which basin is best).
FINISHED = 3
#: Nats below the best refined gain within which a fit that did not settle is settled further
#: (twice the ambiguity margin of :class:`.options.DiagnoseOptions`: the chosen one and its rivals).
LEADERS = 4.0
#: Rough gains this far below the best refined one still get refined when a candidate may be
#: named (:func:`_rivals`): a reduced coarse model misjudges a gain by ten nats and more.
RIVAL_REACH = 10.0
#: Nats below the best rough gain within which a candidate is refined first
#: (:func:`_within_reach`). On a concealed point mass of 0.3 g (the concealment study's
#: row 2, 50 x 50) the mass gained +26.8 on its coarse model and +29.5 refined; five of the
#: seven candidates refined there ended 9 to 26 nats below it, and took two thirds of the
#: refinement's time. A candidate behind by more is refined when it may still rival the
#: refined best (:data:`RIVAL_REACH`).
REACH = 10.0
#: ... or within this share of the best gain, where that is more (both reaches): a coarse
#: model's error grows with the deviations it fits. A point mass's +116 on it was +126
#: refined (8 % more); on a 15 g mass with a 15 % taper (plate 1, 12 x 6) the pair of the
#: two gained +4,822 on it, 153 nats below another pair, and +5,308 refined (10 % more),
#: 323 nats above that pair.
REACH_SHARE = 0.2
#: The evidence gain over which a candidate may be named, when ``fitting`` does not say it.
NAMED = 3.0
#: Rounds at most of a refinement on the coarse mesh before the working mesh's (cheap ones:
#: they bring a rough optimum close, where the working mesh's rounds converge fast).
COARSE_ROUNDS = 4
#: Extra starts (prior deviations from the mean) of a one-parameter candidate's reduced fit:
#: a large effect that reorders modes has local optima on the way from the mean.
SIZE_GRID = (-8.0, -6.0, -4.0, -3.0, -2.0, 2.0, 3.0, 4.0, 6.0, 8.0)


@dataclass(frozen=True)
class CandidateResult:
    """One candidate physics fitted jointly with the constants.

    Attributes
    ----------
    name : str
        The candidate's :attr:`~..physics.base.Physics.name` (its variant, a taper's direction, is
        in ``parameters``, first).
    fit : JointFit
    log_evidence_gain : float
        ``ln Z(candidate) - ln Z(nominal)``, nats.
    parameters : dict
        ``{name: value}`` in the parameters' units, after the candidate's fixed
        :meth:`~..physics.base.Physics.settings` (a taper's ``direction``).
    parameters_sd : dict
    mirror_images : list of dict
        Parameter values that fit equally by the plate's symmetry.
    failed : str
        Empty, or why a later phase of :func:`rank` failed on this candidate (a plate on
        the way that could not be solved): the result is then that of the phase before.
    """

    name: str
    fit: JointFit = field(repr=False)
    log_evidence_gain: float
    parameters: dict
    parameters_sd: dict
    mirror_images: list
    failed: str = ""


def rank(fitting, physics_list):
    """Fit every candidate jointly with the constants; best evidence gain first.

    In phases, each over the candidates in parallel (``fitting.workers``):

    1. *rough*: every start fitted on a reduced model of the modified plate on the coarse
       mesh (:func:`..physics.reduced_model.candidate_pencil`), corrected by the
       fine-to-coarse eigenvalue ratio at the nominal fit (:func:`rough_stage`);
    2. *settled*: every candidate that gains more than ``fitting.margin`` there and lies
       within :data:`REACH` of the best rough gain (or :data:`REACH_SHARE` of it, where
       more) is refined to its own optimum on the
       working mesh: its best distinct rough optima settled in rounds on the coarse mesh,
       then in rounds of reduced models of the working mesh, each checked by the
       finite-element model (:mod:`.settling`; :func:`settled_stage`, :func:`_within_reach`);
    2b. *rivals*: when a refined candidate may be named, the unrefined ones whose rough gain
       lies within :data:`RIVAL_REACH` of it (or the share) are refined too; when none may,
       every one that gained more than ``fitting.margin`` (:func:`_rivals`);
    3. *again*: a refined fit near the top whose rounds stopped before it settled goes on
       (:func:`_unsettled_leaders`, :func:`again_stage`).

    Only refined candidates can be chosen. Every variant (a taper per direction) is a
    candidate of its own. Each phase's result of each candidate is looked up in and stored
    to ``fitting.stages`` as soon as it is fitted (:mod:`.store`; a forked worker stores its
    own); its key adds the phase, the candidate and its variant, and the phase before's.

    Parameters
    ----------
    fitting : Fitting
        What every candidate's fit takes (:class:`.state.Fitting`).
    physics_list : list of Physics

    Returns
    -------
    list of CandidateResult
        Each ``fit.physics`` is the very object of ``physics_list`` (also for a result that
        came back from a worker or from the store: :func:`..physics.combined.pairs_with`
        looks a candidate's own fit up by it). A candidate whose first phase failed is left
        out (said; see :func:`.phases.run_phase`).
    """
    if fitting.stages is not None:  # a store kept by other rough fits is not reused
        rough = ("located starts", LOCATED_STARTS, "rough", ROUGH_NFEV, ROUGH_TOL)
        fitting = replace(fitting, stages=fitting.stages.then(*rough))
    stages, workers, say = fitting.stages, fitting.workers, fitting.say
    # the candidates with most parameters take longest: they go first to the workers
    order = _longest_first(fitting, physics_list, range(len(physics_list)))
    results = [None] * len(physics_list)
    hits = [[] for _ in physics_list]  # the phases of each taken from the store
    items = [(i, physics_list[i], None) for i in order]
    run_phase(stages, "rough", partial(rough_stage, fitting), items, results, hits, workers, say)
    kept = [i for i, r in enumerate(results) if r is not None]  # a failed rough fit: left out
    physics_list, results, hits = ([x[i] for i in kept] for x in (physics_list, results, hits))
    settled = partial(settled_stage, fitting)
    first = partial(_within_reach, margin=fitting.margin)
    later = partial(_rivals, threshold=fitting.threshold, margin=fitting.margin)
    for choose in (first, later):  # phases 2 and 2b
        todo = _longest_first(fitting, physics_list, choose(results))
        items = [(i, physics_list[i], results[i].fit) for i in todo]
        run_phase(stages, "settled", settled, items, results, hits, workers, say)
    todo = _unsettled_leaders(results)
    run_phase(
        stages,
        "again",
        partial(again_stage, fitting),
        [(i, physics_list[i], results[i].fit) for i in todo],
        results,
        hits,
        workers,
        say,
    )
    for r, hit, physics in zip(results, hits, physics_list, strict=True):
        say(_summary(r, hit, physics))
    return sorted(results, key=lambda r: -r.log_evidence_gain)


def candidate_problem(fitting, physics):
    """The joint problem of the constants and `physics` on the working mesh."""
    f = fitting
    return JointProblem(f.model, f.Y, f.sigma, f.mu_b, f.V_b, f.modes, physics)


def rough_stage(fitting, physics):
    """Phase 1 of :func:`rank`: a candidate's rough fit (its reduced coarse model)."""
    model, nominal = fitting.model, fitting.nominal
    problem = candidate_problem(fitting, physics)
    thetas = [
        problem.theta_mean,
        *physics.starting_points(model, nominal.b),
        *_located_starts(physics, model, fitting.scans),
    ]
    lo, hi = problem.theta_lower, problem.theta_upper
    thetas = [np.clip(t, lo, hi) for t in thetas]
    rough = _reduced(fitting, problem, physics, thetas)
    if rough is not None and problem.k == 1:  # cheap there: a grid of sizes as well
        thetas += [np.clip(problem.theta_mean + s * problem.theta_sd, lo, hi) for s in SIZE_GRID]
    # from the nominal optimum, then the best of those from the other nominal basins:
    # the constants that fit best with an effect may lie in another basin than those
    # that fit best without
    top = nominal.chi2 + nominal.chi2_prior + OTHER_BASIN_MARGIN
    others = [b for b, objective in nominal.alternatives if objective < top]
    others = others[:OTHER_BASINS]
    if rough is None:  # no reduced form: the coarse mesh, refined here when promising
        starts = [problem.pack(b, t) for b in [nominal.b, *others] for t in thetas]
        result = fit(
            problem,
            starts,
            max_nfev=25,
            coarse=fitting.coarse,
            scale=fitting.scale,
            keep=FINISHED,
            distinct=True,
            refine=lambda r: r.log_evidence - nominal.log_evidence > fitting.margin,
        )
    else:

        def in_other_basins(optima):
            best = [problem.unpack(z)[1] for z in optima[:OTHER_BASIN_STARTS]]
            return [problem.pack(b, t) for b in others for t in best]

        starts = [problem.pack(nominal.b, t) for t in thetas]
        result = rough_fit(rough, starts, ROUGH_NFEV, FINISHED, more=in_other_basins)
    return candidate_result(physics, model, nominal, result)


def settled_stage(fitting, item):
    """Phase 2 of :func:`rank`: ``item = (physics, rough fit)`` refined on the working mesh."""
    physics, rough = item
    problem = candidate_problem(fitting, physics)
    starts = list(rough.rough_optima)
    if fitting.coarse_modes is not None:  # the first rounds on the coarse mesh
        coarse = problem.on(fitting.coarse, fitting.scale)
        polish = candidate_polisher(
            coarse, physics, fitting.coarse, fitting.coarse_modes, fitting.scale
        )
        # every distinct rough optimum: the coarse rounds, not a first pencil's promise,
        # say which basin is best (a pencil built far from a basin misjudges it)
        settled, _ = polish_and_finish(coarse, polish, starts, COARSE_ROUNDS, prune=False)
        starts = [s.result.x for s in settled]
    polish = candidate_polisher(problem, physics, fitting.model, fitting.ritz_modes)
    result = settle(problem, polish, starts)
    return candidate_result(physics, fitting.model, fitting.nominal, result)


def again_stage(fitting, item):
    """Phase 3 of :func:`rank`: a leader's rounds continued from its answer."""
    physics, fitted = item
    problem = candidate_problem(fitting, physics)
    polish = candidate_polisher(problem, physics, fitting.model, fitting.ritz_modes)
    result = settle(problem, polish, [problem.pack(fitted.b, fitted.theta)])
    result = replace(result, alternatives=fitted.alternatives)
    return candidate_result(physics, fitting.model, fitting.nominal, result)


def _longest_first(fitting, physics_list, indices):
    """``indices`` of ``physics_list``, the candidates with most parameters first."""
    model, b = fitting.model, fitting.nominal.b
    return sorted(indices, key=lambda i: -len(physics_list[i].parameters(model, b)))


def _summary(r, hit, physics):
    """The line said of a ranked candidate: its fit, its gain, and how it was reached."""
    where = "" if r.fit.refined else " (coarse mesh, not refined)"
    if r.fit.check is not None and not r.fit.check.settled:
        where += (
            f" (not settled in {r.fit.check.rounds} rounds: the full model's "
            f"objective could still fall by {r.fit.check.decrement:.2g})"
        )
    where += "".join(f" ({phase} fit taken from the store)" for phase in hit)
    where += f" ({r.failed})" if r.failed else ""
    variant = "".join(f" ({v})" for v in physics.settings().values())
    return (
        f"{r.name}{variant}: chi2 = {r.fit.chi2:.1f}, evidence gain "
        f"{r.log_evidence_gain:+.1f}{where}"
    )


def _label(result):
    """A candidate's name with its variant (a taper's direction), for the records."""
    variant = [v for v in result.parameters.values() if isinstance(v, str)]
    return result.name + "".join(f" ({v})" for v in variant)


def _best_refined(results):
    """The best evidence gain among the refined fits (-inf if none)."""
    return max((r.log_evidence_gain for r in results if r.fit.refined), default=-np.inf)


def _within_reach(results, margin):
    """Indices of the rough fits refined first (phase 2 of :func:`rank`), each logged.

    Those that gain more than ``margin`` on their reduced coarse model (:func:`_refines`)
    and lie within :data:`REACH` of the best rough gain (or :data:`REACH_SHARE` of it). A
    candidate far behind the best on its coarse model is refined later only if it may
    still rival the refined best (:func:`_rivals`).
    """
    top = max((r.log_evidence_gain for r in results if _refinable(r)), default=-np.inf)
    chosen = []
    for i, r in enumerate(results):
        if not _refines(r, margin):
            why = "not refined"
        elif r.log_evidence_gain < top - _reach(top, REACH):
            why = f"not refined yet ({top - r.log_evidence_gain:.1f} behind the best)"
        else:
            why = "refined"
            chosen.append(i)
        log.debug("%s: rough gain %+.1f, %s", _label(r), r.log_evidence_gain, why)
    return chosen


def _rivals(results, threshold, margin):
    """Indices of the rough fits refined after the first ones (phase 2b of :func:`rank`).

    When the best refined gain exceeds ``threshold`` (a candidate may be named), every
    candidate left on its coarse reduced model whose rough gain lies within
    :data:`RIVAL_REACH` of it (or :data:`REACH_SHARE` of it) is refined too: the verdict
    compares the best with its runner-up (``ambiguous`` within 2 nats), and a coarse gain
    is not good enough for that.
    Measured: a point support of 48,000 N/m (calibration study, Frederiksen plate, 40 x 20)
    gained -0.7 on its coarse model, +1.7 refined, against +3.5 for the foundation: named a
    foundation, where refined it is ``ambiguous`` with the truth among the two.

    When none may be named, the leaders on the coarse model lost their gain on the working
    mesh (a taper's +17 was +2.6 there), and every unrefined candidate that gains more than
    ``margin`` on its coarse model is refined: one of them may still gain enough.
    """
    best = _best_refined(results)
    if best <= threshold:
        return [i for i, r in enumerate(results) if _refines(r, margin) and not r.failed]
    return [
        i
        for i, r in enumerate(results)
        if _refinable(r)
        and not r.failed
        and r.log_evidence_gain >= best - _reach(best, RIVAL_REACH)
    ]


def _reach(best, nats):
    """How far below the best gain ``best`` a rough gain is within reach, nats.

    ``nats``, or :data:`REACH_SHARE` of ``best`` where that is more.
    """
    return max(nats, REACH_SHARE * best)


def _unsettled_leaders(results):
    """Indices of the refined fits near the top whose rounds stopped before they settled.

    Those within :data:`LEADERS` nats of the best refined gain: the verdict names them (the
    chosen one, a rival that makes it ambiguous), so their rounds go on (phase 3 of
    :func:`rank`); the others are reported as they stopped, flagged.
    """
    refined = [i for i, r in enumerate(results) if r.fit.refined]
    best = _best_refined(results)
    return [
        i
        for i in refined
        if results[i].fit.check is not None
        and not results[i].fit.check.settled
        and results[i].log_evidence_gain >= best - LEADERS
    ]


def candidate_result(physics, model, nominal, fitted):
    """The :class:`CandidateResult` of a candidate's joint fit."""
    gain = fitted.log_evidence - nominal.log_evidence
    params = {**physics.settings(), **physics.labelled(model, nominal.b, fitted.theta)}
    sds = physics.labelled(model, nominal.b, fitted.theta_sd)
    mirrors = []
    if fitted.refined:  # (a pair's images cost full solves: for the refined fits only)
        images = physics.mirror_images(model, fitted.theta)
        mirrors = [physics.labelled(model, nominal.b, t) for t in images]
        # every image is a posterior mode of its own (probabilities.images_log_weight)
        gain += images_log_weight(fitted.theta, fitted.covariance[6:, 6:], images)
    return CandidateResult(physics.name, fitted, gain, params, sds, mirrors)


def _refines(rough, margin):
    """Whether a rough fit may be refined on the working mesh (phases 2 and 2b of :func:`rank`).

    When it gains more than ``margin`` on its reduced coarse model. Not fewer: a reduced
    coarse model misjudges a gain by ten nats and more either way (a taper's +17 on it was
    +2.6 on the working mesh, a point mass's +116 was +126), and its optima move with the
    round-off of its many starts; the refined fits do not.
    """
    return _refinable(rough) and rough.log_evidence_gain > margin


def _refinable(rough):
    """Whether a fit is left on its reduced coarse model, with optima to refine from."""
    return not rough.fit.refined and bool(rough.fit.rough_optima)


def candidate_polisher(problem, physics, model, modes, scale=None):
    """``polish(z, earlier=())``: the candidate's pencil on ``model``, exact at ``z``.

    Its basis: the nominal modes at the nominal fit (``modes``), the modified plate's at
    ``z`` and the ``earlier`` snapshots (:mod:`.settling`). ``scale`` corrects the pencil's
    eigenvalues to the working mesh (``model`` a coarser mesh: :meth:`.joint_fit.JointProblem.on`).
    """
    n = int(problem.modes.max()) + 1

    def polish(z, earlier=()):
        b, theta = problem.unpack(z)
        pencil = candidate_pencil(
            model, physics, b, [theta], n + 4, nominal_modes=modes, earlier=earlier, local=True
        )
        return problem.on_pencil(pencil, scale)

    return polish


def _reduced(fitting, problem, physics, thetas):
    """The candidate's problem on its reduced coarse model, or None (no Ritz form).

    The Ritz basis holds the coarse nominal modes and the modified plate's at the starting
    parameters and, for a single parameter, four prior deviations either side of the mean.
    """
    n = int(problem.modes.max()) + 1
    snapshots = [t for t in thetas if not np.allclose(t, problem.theta_mean)]
    if problem.k == 1:
        for s in (-4.0, 4.0):
            t = problem.theta_mean + s * problem.theta_sd
            snapshots.append(np.clip(t, problem.theta_lower, problem.theta_upper))
    pencil = candidate_pencil(
        fitting.coarse,
        physics,
        fitting.nominal.b,
        snapshots,
        n + 4,
        nominal_modes=fitting.coarse_modes,
    )
    return None if pencil is None else problem.on_pencil(pencil, fitting.scale)


def _located_starts(physics, model, scans, n=LOCATED_STARTS):
    """Starting parameters of a located effect: the best distinct places of its scan."""
    scan = scans.get(physics.name)
    return [] if scan is None else scan.best(model, n)
