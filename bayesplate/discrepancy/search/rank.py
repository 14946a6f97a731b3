"""Step 3 of diagnose, name: every candidate fitted jointly with the constants, ranked.

Each candidate's joint fit starts from the prior mean of its parameters, its own extra
starting points and, for a located candidate, the best distinct places of its Ritz scan,
each with the nominal optimum's constants and those of the other nominal basins found; it
runs on a reduced model of the modified plate on the coarse mesh (:mod:`.pencil`; the
coarse finite-element model for a candidate without a Ritz form), corrected to the working
mesh; when promising, its best distinct reduced optima are finished on the working mesh and
the best one there is its fit (a reduced model only chooses the starting points). Every
variant of a candidate (a taper along x and along y) is fitted and refined on its own; the
candidates are ranked by the Laplace evidence gain of these working-mesh fits over the
nominal model.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np

from ...parallel import fork_map
from ..physics.reduced_model import candidate_pencil
from .constants_again import constants_anew
from .joint_fit import JointFit, JointProblem, fit, rough_fit, settle
from .local_fits import DISTINCT
from .nominal import nominal_polisher
from .probabilities import images_log_weight
from .settling import polish_and_finish
from .store import fit_digest

__all__ = ["CandidateResult", "improved_nominal", "rank", "searched_anew"]

log = logging.getLogger(__name__)

#: Evaluation cap of each local fit on a candidate's reduced coarse model.
ROUGH_NFEV = 100
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
#: (twice the ambiguity margin of :func:`.diagnose.diagnose`: the chosen one and its rivals).
LEADERS = 4.0
#: Rough gains this far below the best refined one still get refined when a candidate may be
#: named (:func:`_rivals`): a reduced coarse model misjudges a gain by ten nats and more.
RIVAL_REACH = 10.0
#: The evidence gain over which a candidate may be named, when ``level`` does not say it.
NAMED = 3.0
#: Nats a nominal refit from a candidate's constants must gain to replace the nominal fit.
IMPROVEMENT = 1e-3
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
        The candidate's :attr:`~.base.Physics.name` (its variant, a taper's direction, is
        in ``parameters``, first).
    fit : JointFit
    log_evidence_gain : float
        ``ln Z(candidate) - ln Z(nominal)``, nats.
    parameters : dict
        ``{name: value}`` in the parameters' units, after the candidate's fixed
        :meth:`~.base.Physics.settings` (a taper's ``direction``).
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


def rank(model, level, Y, sigma, mu_b, V_b, modes, nominal, scans, physics_list, say,
         stages=None):  # fmt: skip
    """Fit every candidate jointly with the constants; best evidence gain first.

    In phases, each over the candidates in parallel (``level["workers"]``; a candidate goes
    on from phase 1 to phase 2 in the same task):

    1. *rough*: every start fitted on a reduced model of the modified plate on the coarse
       mesh (:func:`.pencil.candidate_pencil`), corrected by the fine-to-coarse eigenvalue
       ratio at the nominal fit;
    2. *settled*: every candidate that gains more than ``level["margin"]`` there is refined
       to its own optimum on the working mesh: its best distinct rough optima settled in
       rounds on the coarse mesh, then in rounds of reduced models of the working mesh, each
       checked by the finite-element model (:mod:`.polish`);
    2b. *rivals*: when a refined candidate may be named, the unrefined ones whose rough gain
       lies within :data:`RIVAL_REACH` of it are refined too (:func:`_rivals`);
    3. *again*: a refined fit near the top whose rounds stopped before it settled goes on
       (:func:`_unsettled_leaders`).

    Only refined candidates can be chosen. Every variant (a taper per direction) is a
    candidate of its own.

    Parameters
    ----------
    model : PlateModel
    level : dict
        ``coarse`` (PlateModel), ``scale`` (fine / coarse eigenvalues, shape (m,)),
        ``margin`` (nats), ``workers`` (int), ``coarse_modes`` (the coarse nominal modes
        at ``nominal.b`` for the Ritz bases, shape (n_dofs, n); optional), ``rough`` (the
        nominal problem on its reduced model; optional), ``modes`` (the nominal modes at
        ``nominal.b`` on ``model``, shape (n_dofs, n), for the refinement),
        ``ambiguity_margin`` (nats; optional, default 2), ``threshold`` (the evidence gain
        over which a candidate may be named; optional, default :data:`NAMED`).
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations, rad^2/s^2.
    mu_b : numpy.ndarray, shape (6,)
    V_b : numpy.ndarray, shape (6, 6)
        Prior of the stiffness coefficients, Pa and Pa^2.
    modes : numpy.ndarray of int, shape (m,)
    nominal : JointFit
    scans : dict of Scan
        Keyed by :attr:`~.base.Physics.name`: the located candidates' scans.
    physics_list : list of Physics
    say : callable
    stages : Stages, optional
        Where each phase's result of each candidate is looked up and stored as soon as it
        is fitted (:mod:`.store`; a forked worker stores its own), in a context that covers
        everything above; its key adds the phase, the candidate and its variant, and the
        phase before's result.

    Returns
    -------
    list of CandidateResult
        Each ``fit.physics`` is the very object of ``physics_list`` (also for a result that
        came back from a worker or from the store: :func:`.pair.pairs_with` looks a
        candidate's own fit up by it). A candidate whose first phase failed is left out
        (said; see :func:`_phase`).
    """
    if stages is not None:  # a store kept by a search with fewer places is not reused
        stages = stages.then("located starts", LOCATED_STARTS)

    def problem_of(physics):
        return JointProblem(model, Y, sigma, mu_b, V_b, modes, physics)

    def rough_stage(physics):  # phase 1
        problem = problem_of(physics)
        thetas = [problem.theta_mean, *physics.starting_points(model, nominal.b),
                  *_located_starts(physics, model, scans)]  # fmt: skip
        lo, hi = problem.theta_lower, problem.theta_upper
        thetas = [np.clip(t, lo, hi) for t in thetas]
        rough = _reduced(problem, physics, model, level, nominal, thetas)
        if rough is not None and problem.k == 1:  # cheap there: a grid of sizes as well
            thetas += [np.clip(problem.theta_mean + s * problem.theta_sd, lo, hi)
                       for s in SIZE_GRID]  # fmt: skip
        # from the nominal optimum, then the best of those from the other nominal basins:
        # the constants that fit best with an effect may lie in another basin than those
        # that fit best without
        top = nominal.chi2 + nominal.chi2_prior + OTHER_BASIN_MARGIN
        others = [b for b, objective in nominal.alternatives if objective < top]
        others = others[:OTHER_BASINS]
        if rough is None:  # no reduced form: the coarse mesh, refined here when promising
            starts = [problem.pack(b, t) for b in [nominal.b, *others] for t in thetas]
            result = fit(problem, starts, max_nfev=25, coarse=level["coarse"],
                         scale=level["scale"], keep=FINISHED, distinct=True,
                         refine=lambda r: r.log_evidence - nominal.log_evidence
                         > level["margin"])  # fmt: skip
        else:

            def in_other_basins(optima):
                best = [problem.unpack(z)[1] for z in optima[:OTHER_BASIN_STARTS]]
                return [problem.pack(b, t) for b in others for t in best]

            starts = [problem.pack(nominal.b, t) for t in thetas]
            result = rough_fit(rough, starts, ROUGH_NFEV, FINISHED, more=in_other_basins)
        return _result(physics, model, nominal, result)

    def settled(item):  # phase 2
        physics, rough = item
        problem = problem_of(physics)
        starts = list(rough.rough_optima)
        if level.get("coarse_modes") is not None:  # the first rounds on the coarse mesh
            coarse = problem.on(level["coarse"], level["scale"])
            polish = _polisher(coarse, physics, level["coarse"], level["coarse_modes"],
                               level["scale"])  # fmt: skip
            # every distinct rough optimum: the coarse rounds, not a first pencil's promise,
            # say which basin is best (a pencil built far from a basin misjudges it)
            settled, _ = polish_and_finish(coarse, polish, starts, COARSE_ROUNDS, prune=False)
            starts = [s.result.x for s in settled]
        polish = _polisher(problem, physics, model, level["modes"])
        return _result(physics, model, nominal, settle(problem, polish, starts))

    def again(item):  # phase 3: a leader's rounds continued from its answer
        physics, fitted = item
        problem = problem_of(physics)
        polish = _polisher(problem, physics, model, level["modes"])
        result = settle(problem, polish, [problem.pack(fitted.b, fitted.theta)])
        return _result(physics, model, nominal, replace(result, alternatives=fitted.alternatives))

    # the candidates with most parameters take longest: they go first to the workers
    order = sorted(range(len(physics_list)),
                   key=lambda i: -len(physics_list[i].parameters(model, nominal.b)))  # fmt: skip
    results = [None] * len(physics_list)
    hits = [[] for _ in physics_list]  # the phases of each taken from the store

    def refines(rough):  # phase 2's choice: on the candidate's own rough fit alone
        chosen = _refines(rough, level["margin"])
        log.debug("%s: rough gain %+.1f, %s", _label(rough), rough.log_evidence_gain,
                  "refined" if chosen else "not refined")  # fmt: skip
        return chosen

    # phases 1 and 2 in one task per candidate: a worker refines its candidate while the
    # other still fits its rough one (the same results as one phase after the other)
    _phase(stages, "rough", rough_stage, [(i, physics_list[i], None) for i in order],
           results, hits, level["workers"], say, then=("settled", settled, refines))  # fmt: skip
    kept = [i for i, r in enumerate(results) if r is not None]  # a failed rough fit: left out
    physics_list, results, hits = ([x[i] for i in kept] for x in (physics_list, results, hits))
    todo = _rivals(results, level.get("threshold", NAMED))
    _phase(stages, "settled", settled, [(i, physics_list[i], results[i].fit) for i in todo],
           results, hits, level["workers"], say)  # fmt: skip
    todo = _unsettled_leaders(results)
    _phase(stages, "again", again, [(i, physics_list[i], results[i].fit) for i in todo],
           results, hits, level["workers"], say)  # fmt: skip
    for r, hit, physics in zip(results, hits, physics_list, strict=True):
        where = "" if r.fit.refined else " (coarse mesh, not refined)"
        if r.fit.check is not None and not r.fit.check.settled:
            where += (f" (not settled in {r.fit.check.rounds} rounds: the full model's "
                      f"objective could still fall by {r.fit.check.decrement:.2g})")
        where += "".join(f" ({phase} fit taken from the store)" for phase in hit)
        where += f" ({r.failed})" if r.failed else ""
        variant = "".join(f" ({v})" for v in physics.settings().values())
        say(f"{r.name}{variant}: chi2 = {r.fit.chi2:.1f}, evidence gain "
            f"{r.log_evidence_gain:+.1f}{where}")  # fmt: skip
    return sorted(results, key=lambda r: -r.log_evidence_gain)


def _label(result):
    """A candidate's name with its variant (a taper's direction), for the records."""
    variant = [v for v in result.parameters.values() if isinstance(v, str)]
    return result.name + "".join(f" ({v})" for v in variant)


def _phase(stages, name, compute, items, results, hits, workers, say, then=None):
    """One phase of :func:`rank`: ``compute((physics, earlier fit))`` for each item, stored.

    ``items`` are ``(index, physics, earlier fit or None)``; each result goes to
    ``results[index]`` (its ``fit.physics`` the very object given); the phase's name is
    appended to ``hits[index]`` when it came from the store (each stage used is announced:
    a rerun after an interruption shows what it took). A candidate whose fit meets a plate
    that cannot be solved (a far reduced model's mass no longer positive definite, say)
    keeps its earlier phase's result, marked ``failed`` (None for the first phase: the
    candidate is left out), and the failure is said; nothing is stored for it.

    ``then``, optional ``(name, compute, wanted)``: the next phase, which an item goes on
    to in the same task when ``wanted(its result of this one)``. Its results are those of
    the two phases run one after the other, where that next phase depends on a candidate's
    own result only: a worker then need not wait for the others' first phase.
    """
    if not items:
        return
    steps = [(name, compute)] + ([tuple(then[:2])] if then is not None else [])

    def key(name, physics, earlier):
        return stages.key(name, physics, *(() if earlier is None else (fit_digest(earlier),)))

    def step(name, compute, physics, earlier):
        """``(result, taken from the store, why it failed or "")``."""
        try:
            if stages is None:
                return compute((physics, earlier) if earlier is not None else physics), False, ""
            found, value = stages.get(key(name, physics, earlier))
            if not found:
                value = compute((physics, earlier) if earlier is not None else physics)
                stages.put(key(name, physics, earlier), value)
        except np.linalg.LinAlgError as error:
            log.warning("%s: %s fit failed: %s", physics.name, name, error)
            return None, False, f"its {name} fit failed ({type(error).__name__}: {error})"
        return value, found, ""

    def task(item):
        """The outcome of each phase the item went through (the first, maybe the next)."""
        _, physics, earlier = item
        done = [step(*steps[0], physics, earlier)]
        value, _, failed = done[0]
        if then is not None and not failed and then[2](value):
            done.append(step(*steps[1], physics, replace(value.fit, physics=physics)))
        return done

    done = fork_map(task, items, workers)
    for (i, physics, earlier), outcomes in zip(items, done, strict=True):
        for n, ((name, _), (value, found, failed)) in enumerate(
                zip(steps[: len(outcomes)], outcomes, strict=True)):
            if failed:
                failed += "; left out" if results[i] is None else "; the phase before kept"
                say(f"{physics.name}{''.join(f' ({v})' for v in physics.settings().values())}"
                    f": {failed}")  # fmt: skip
                if results[i] is not None:
                    results[i] = replace(results[i], failed=failed)
                break
            if n > 0:  # the next phase, built on the result of this one
                earlier = results[i].fit
            results[i] = replace(value, fit=replace(value.fit, physics=physics))
            if found:
                hits[i].append(name)
            if stages is not None and workers > 1 and not found:  # a worker's put may not arrive
                stages.put(key(name, physics, earlier), value)


def _best_refined(results):
    """The best evidence gain among the refined fits (-inf if none)."""
    return max((r.log_evidence_gain for r in results if r.fit.refined), default=-np.inf)


def _rivals(results, threshold):
    """Indices of the rough fits to refine because a refined one may be named (phase 2b).

    When the best refined gain exceeds ``threshold`` (a candidate may be named), every
    candidate left on its coarse reduced model whose rough gain lies within
    :data:`RIVAL_REACH` of it is refined too: the verdict compares the best with its
    runner-up (``ambiguous`` within 2 nats), and a coarse gain is not good enough for that.
    Measured: a point support of 48,000 N/m (calibration study, Frederiksen plate, 40 x 20)
    gained -0.7 on its coarse model, +1.7 refined, against +3.5 for the foundation: named a
    foundation, where refined it is ``ambiguous`` with the truth among the two.
    """
    best = _best_refined(results)
    if best <= threshold:
        return []
    return [i for i, r in enumerate(results)
            if not r.fit.refined and not r.failed
            and r.log_evidence_gain >= best - RIVAL_REACH]  # fmt: skip


def _unsettled_leaders(results):
    """Indices of the refined fits near the top whose rounds stopped before they settled.

    Those within :data:`LEADERS` nats of the best refined gain: the verdict names them (the
    chosen one, a rival that makes it ambiguous), so their rounds go on (phase 3 of
    :func:`rank`); the others are reported as they stopped, flagged.
    """
    refined = [i for i, r in enumerate(results) if r.fit.refined]
    best = _best_refined(results)
    return [i for i in refined if results[i].fit.check is not None
            and not results[i].fit.check.settled
            and results[i].log_evidence_gain >= best - LEADERS]  # fmt: skip


def _result(physics, model, nominal, fitted):
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
    """Whether a rough fit is refined on the working mesh (phase 2 of :func:`rank`).

    When it gains more than ``margin`` on its reduced coarse model. Not fewer: a reduced
    coarse model misjudges a gain by ten nats and more either way (a taper's +17 on it was
    +2.6 on the working mesh, a point mass's +116 was +126), and its optima move with the
    round-off of its many starts; the refined fits do not.
    """
    return (not rough.fit.refined and bool(rough.fit.rough_optima)
            and rough.log_evidence_gain > margin)  # fmt: skip


def _polisher(problem, physics, model, modes, scale=None):
    """``polish(z, earlier=())``: the candidate's pencil on ``model``, exact at ``z``.

    Its basis: the nominal modes at the nominal fit (``modes``), the modified plate's at
    ``z`` and the ``earlier`` snapshots (:mod:`.polish`). ``scale`` corrects the pencil's
    eigenvalues to the working mesh (``model`` a coarser mesh: :meth:`.fit.JointProblem.on`).
    """
    n = int(problem.modes.max()) + 1

    def polish(z, earlier=()):
        b, theta = problem.unpack(z)
        pencil = candidate_pencil(model, physics, b, [theta], n + 4, nominal_modes=modes,
                                  earlier=earlier, local=True)  # fmt: skip
        return problem.on_pencil(pencil, scale)

    return polish


def _reduced(problem, physics, model, level, nominal, thetas):
    """The candidate's problem on its reduced coarse model, or None (no Ritz form).

    The Ritz basis holds the coarse nominal modes and the modified plate's at the starting
    parameters and, for a single parameter, four prior deviations either side of the mean.
    """
    coarse = level["coarse"]
    n = int(problem.modes.max()) + 1
    snapshots = [t for t in thetas if not np.allclose(t, problem.theta_mean)]
    if problem.k == 1:
        for s in (-4.0, 4.0):
            t = problem.theta_mean + s * problem.theta_sd
            snapshots.append(np.clip(t, problem.theta_lower, problem.theta_upper))
    pencil = candidate_pencil(coarse, physics, nominal.b, snapshots, n + 4,
                              nominal_modes=level.get("coarse_modes"))  # fmt: skip
    return None if pencil is None else problem.on_pencil(pencil, level["scale"])


def _located_starts(physics, model, scans, n=LOCATED_STARTS):
    """Starting parameters of a located effect: the best distinct places of its scan."""
    scan = scans.get(physics.name)
    return [] if scan is None else scan.best(model, n)


def searched_anew(model, level, Y, sigma, mu_b, V_b, modes, nominal, best):
    """``best`` fitted again from its constants searched globally (:mod:`.anew`), or None.

    Parameters as for :func:`rank`; ``best`` is the refined :class:`CandidateResult` whose
    refit the chi-square rejected. Returns its :class:`CandidateResult` when the new fit's
    evidence is higher, else None.
    """
    physics = best.fit.physics
    problem = JointProblem(model, Y, sigma, mu_b, V_b, modes, physics)
    polish = _polisher(problem, physics, model, level["modes"])
    again = constants_anew(problem, best.fit, level["coarse"], polish, level["workers"])
    return None if again is None else _result(physics, model, nominal, again)


def improved_nominal(problem, nominal, ranked, level):
    """A better nominal optimum, started from candidates that beat it on the prior too.

    A candidate's fit starts from the nominal constants and may walk into a better basin of
    the constants alone; its gain would then be credited to the physics. Re-fitting the
    nominal model from there keeps the gains honest. Each re-fit runs on the nominal
    reduced model (``level["rough"]``; else the corrected coarse mesh) first; it is settled
    on the working mesh only when it reaches another optimum than the nominal one (whitened
    distance above ``DISTINCT``) that beats the nominal evidence there, and taken only when
    it beats it by more than :data:`IMPROVEMENT` on the working mesh.

    Returns
    -------
    JointFit or None
        None when no candidate leads to a better nominal fit.
    """
    total = nominal.chi2 + nominal.chi2_prior
    rough = level.get("rough") or problem.on(level["coarse"], level["scale"])
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
