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

from dataclasses import dataclass, field, replace

import numpy as np

from .fit import JointFit, JointProblem, fit
from .parallel import fork_map
from .pencil import candidate_pencil

__all__ = ["CandidateResult", "improved_nominal", "rank"]

#: Evaluation cap of a candidate's refinement on the working mesh, from its reduced optimum.
REFINE_NFEV = 25
#: Other nominal optima (``nominal.alternatives``, best first) whose constants start the
#: candidates' reduced fits too.
OTHER_BASINS = 2
#: ... within this much of the nominal optimum's ``chi2 + chi2_prior`` (a fit far worse,
#: or one that left the physical region, is no basin to start from).
OTHER_BASIN_MARGIN = 20.0
#: Distinct reduced optima of a candidate finished on the working mesh (the best one there
#: is its fit: a reduced model of a strong taper can misjudge which basin is best).
FINISHED = 3
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
    """

    name: str
    fit: JointFit = field(repr=False)
    log_evidence_gain: float
    parameters: dict
    parameters_sd: dict
    mirror_images: list


def rank(model, level, Y, sigma, mu_b, V_b, modes, nominal, scans, physics_list, say,
         stages=None):  # fmt: skip
    """Fit every candidate jointly with the constants; best evidence gain first.

    Every start is fitted on a reduced model of the modified plate on the coarse mesh
    (:func:`.pencil.candidate_pencil`), corrected by the fine-to-coarse eigenvalue ratio at
    the nominal fit; candidates that gain at least ``level["margin"]`` there are refined on
    the working mesh. Only refined candidates can be chosen. Every variant (a taper per
    direction) is a candidate of its own.

    Parameters
    ----------
    model : PlateModel
    level : dict
        ``coarse`` (PlateModel), ``scale`` (fine / coarse eigenvalues, shape (m,)),
        ``margin`` (nats), ``workers`` (int), ``coarse_modes`` (the coarse nominal modes
        at ``nominal.b`` for the Ritz bases, shape (n_dofs, n); optional), ``rough`` (the
        nominal problem on its reduced model; optional), ``modes`` (the nominal modes at
        ``nominal.b`` on ``model``, shape (n_dofs, n), for the refinement; optional).
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
        Where each candidate's result is looked up and stored as soon as it is fitted
        (:mod:`.store`; a forked worker stores its own), in a context that covers everything
        above; its key adds the candidate and its variant.

    Returns
    -------
    list of CandidateResult
        Each ``fit.physics`` is the very object of ``physics_list`` (also for a result that
        came back from a worker or from the store: :func:`.pair.pairs_with` looks a
        candidate's own fit up by it).
    """

    def promising(rough):
        return rough.log_evidence - nominal.log_evidence > level["margin"]

    def stored(physics):  # (result, taken from the store)
        if stages is None:
            return candidate(physics), False
        key = stages.key("candidate", physics)
        found, result = stages.get(key)
        if not found:
            result = candidate(physics)
            stages.put(key, result)
        return result, found

    def candidate(physics):
        problem = JointProblem(model, Y, sigma, mu_b, V_b, modes, physics)
        thetas = [problem.theta_mean, *physics.starting_points(model, nominal.b),
                  *_located_starts(physics, model, scans)]  # fmt: skip
        lo, hi = problem.theta_lower, problem.theta_upper
        thetas = [np.clip(t, lo, hi) for t in thetas]
        rough = _reduced(problem, physics, model, level, nominal, thetas)
        if rough is not None and problem.k == 1:  # cheap there: a grid of sizes as well
            thetas += [np.clip(problem.theta_mean + s * problem.theta_sd, lo, hi)
                       for s in SIZE_GRID]  # fmt: skip
        # from the nominal optimum and from the other nominal basins: the constants that
        # fit best with an effect may lie in another basin than those that fit best without
        top = nominal.chi2 + nominal.chi2_prior + OTHER_BASIN_MARGIN
        others = [b for b, objective in nominal.alternatives if objective < top]
        bases = [nominal.b, *others[:OTHER_BASINS]]
        starts = [problem.pack(b, t) for b in bases for t in thetas]
        # on a reduced model the local fits run to convergence; a reduced model of the
        # working mesh around the rough optimum polishes it, checked by one full solve
        polish = None
        if rough is not None and level.get("modes") is not None:
            polish = _polisher(problem, physics, model, level["modes"])
        result = fit(problem, starts, max_nfev=REFINE_NFEV if rough else 25,
                     coarse=level["coarse"], scale=level["scale"], refine=promising,
                     rough=rough, rough_nfev=100, polish=polish, keep=FINISHED,
                     distinct=True)  # fmt: skip
        gain = result.log_evidence - nominal.log_evidence
        params = {**physics.settings(), **physics.labelled(model, nominal.b, result.theta)}
        sds = physics.labelled(model, nominal.b, result.theta_sd)
        mirrors = [physics.labelled(model, nominal.b, t)
                   for t in physics.mirror_images(model, result.theta)]  # fmt: skip
        return CandidateResult(physics.name, result, gain, params, sds, mirrors)

    # the candidates with most parameters take longest: they go first to the workers
    order = sorted(range(len(physics_list)),
                   key=lambda i: -len(physics_list[i].parameters(model, nominal.b)))  # fmt: skip
    fitted = fork_map(stored, [physics_list[i] for i in order], level["workers"])
    fitted = [fitted[order.index(i)] for i in range(len(physics_list))]
    results = [replace(r, fit=replace(r.fit, physics=physics))
               for (r, _), physics in zip(fitted, physics_list, strict=True)]  # fmt: skip
    if stages is not None and level["workers"] > 1:  # a worker's put may not reach `store`
        for (r, found), physics in zip(fitted, physics_list, strict=True):
            if not found:
                stages.put(stages.key("candidate", physics), r)
    for r, (_, found), physics in zip(results, fitted, physics_list, strict=True):
        where = "" if r.fit.refined else " (coarse mesh, not refined)"
        where += " (taken from the store)" if found else ""
        variant = "".join(f" ({v})" for v in physics.settings().values())
        say(f"{r.name}{variant}: chi2 = {r.fit.chi2:.1f}, evidence gain "
            f"{r.log_evidence_gain:+.1f}{where}")  # fmt: skip
    return sorted(results, key=lambda r: -r.log_evidence_gain)


def _polisher(problem, physics, model, modes):
    """``polish(z)``: the candidate's pencil on the working mesh with a snapshot at ``z``."""
    n = int(problem.modes.max()) + 1

    def polish(z):
        b, theta = problem.unpack(z)
        pencil = candidate_pencil(model, physics, b, [theta], n + 4, nominal_modes=modes)
        return problem.on_pencil(pencil)

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


def _located_starts(physics, model, scans, n=3):
    """Starting parameters of a located effect: the best distinct places of its scan."""
    scan = scans.get(physics.name)
    return [] if scan is None else scan.best(model, n)


def improved_nominal(problem, nominal, ranked, level):
    """A better nominal optimum, started from candidates that beat it on the prior too.

    A candidate's fit starts from the nominal constants and may walk into a better basin of
    the constants alone; its gain would then be credited to the physics. Re-fitting the
    nominal model from there keeps the gains honest. Each re-fit runs on the nominal
    reduced model (``level["rough"]``; else the corrected coarse mesh) first and is refined
    only when it beats the nominal evidence there.

    Returns
    -------
    JointFit or None
        None when no candidate leads to a better nominal fit.
    """
    total = nominal.chi2 + nominal.chi2_prior
    best = nominal
    for c in ranked:
        if c.fit.refined and c.fit.chi2 + c.fit.chi2_prior < total - 0.5:
            trial = fit(
                problem,
                [problem.pack(c.fit.b)],
                coarse=level["coarse"],
                scale=level["scale"],
                rough=level.get("rough"),
                refine=lambda rough, bar=best.log_evidence: rough.log_evidence > bar,
            )
            if trial.refined and trial.log_evidence > best.log_evidence:
                best = trial
    return None if best is nominal else best
