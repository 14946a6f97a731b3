"""Step 3 of diagnose, name: every candidate fitted jointly with the constants, ranked.

Each candidate's joint fit starts from the prior mean of its parameters, its own extra
starting points and, for a located candidate, the best distinct places of its Ritz scan; it
runs on the coarse mesh corrected to the working one and is refined only when promising.
The candidates are ranked by their Laplace evidence gain over the nominal model.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .fit import JointFit, JointProblem, fit
from .parallel import fork_map

__all__ = ["CandidateResult", "improved_nominal", "rank"]


@dataclass(frozen=True)
class CandidateResult:
    """One candidate physics fitted jointly with the constants.

    Attributes
    ----------
    name : str
        The candidate's :attr:`~.base.Physics.name`.
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


def rank(model, level, Y, sigma, mu_b, V_b, modes, nominal, scans, physics_list, say):
    """Fit every candidate jointly with the constants; best evidence gain first.

    Every start is fitted on the coarse mesh corrected by the fine-to-coarse eigenvalue
    ratio at the nominal fit; candidates that gain at least ``level["margin"]`` there are
    refined on the working mesh. Only refined candidates can be chosen. Candidates of one
    name (a taper per direction) keep the better.

    Parameters
    ----------
    model : PlateModel
    level : dict
        ``coarse`` (PlateModel), ``scale`` (fine / coarse eigenvalues, shape (m,)),
        ``margin`` (nats), ``workers`` (int).
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

    Returns
    -------
    list of CandidateResult
    """

    def promising(rough):
        return rough.log_evidence - nominal.log_evidence > level["margin"]

    def candidate(physics):
        problem = JointProblem(model, Y, sigma, mu_b, V_b, modes, physics)
        thetas = [problem.theta_mean, *physics.starting_points(model, nominal.b),
                  *_located_starts(physics, model, scans)]  # fmt: skip
        lo, hi = problem.theta_lower, problem.theta_upper
        starts = [problem.pack(nominal.b, np.clip(t, lo, hi)) for t in thetas]
        result = fit(problem, starts, max_nfev=25, coarse=level["coarse"],
                     scale=level["scale"], refine=promising)  # fmt: skip
        result = canonical_image(physics, model, result)
        gain = result.log_evidence - nominal.log_evidence
        params = {**physics.settings(), **physics.labelled(model, nominal.b, result.theta)}
        sds = physics.labelled(model, nominal.b, result.theta_sd)
        mirrors = [physics.labelled(model, nominal.b, t)
                   for t in physics.mirror_images(model, result.theta)]  # fmt: skip
        return CandidateResult(physics.name, result, gain, params, sds, mirrors)

    # the candidates with most parameters take longest: they go first to the workers
    order = sorted(range(len(physics_list)),
                   key=lambda i: -len(physics_list[i].parameters(model, nominal.b)))  # fmt: skip
    fitted = fork_map(candidate, [physics_list[i] for i in order], level["workers"])
    results = [fitted[order.index(i)] for i in range(len(physics_list))]
    for r in results:
        where = "" if r.fit.refined else " (coarse mesh, not refined)"
        say(f"{r.name}: chi2 = {r.fit.chi2:.1f}, evidence gain {r.log_evidence_gain:+.1f}{where}")
    best_by_name = {}
    for r in results:  # the taper is fitted once per direction; keep the better
        if (
            r.name not in best_by_name
            or r.log_evidence_gain > best_by_name[r.name].log_evidence_gain
        ):
            best_by_name[r.name] = r
    return sorted(best_by_name.values(), key=lambda r: -r.log_evidence_gain)


def canonical_image(physics, model, result):
    """The fit expressed at the first of its mirror images in ``(x, y)`` order.

    A located effect and its mirror images fit equally well (the plate's symmetry), so which
    of them a fit reaches depends on its path, and on round-off where two paths part: a
    point mass found at ``y = 28.6`` or ``71.4`` mm on a 100 mm plate is one answer. The
    fit is reported at the image whose parameters come first (lexicographically, position
    first); the reflection is affine with slopes +-1, read from
    :meth:`~.base.Physics.mirror_images` itself, and carries the covariance along.
    Fits without mirror images are returned as they are. The fit's ``modal`` stays the one
    computed (its eigenvalues are the image's too).
    """
    theta = np.asarray(result.theta, dtype=float)
    images = physics.mirror_images(model, theta)
    if not images:
        return result
    key = _position_first(physics, model, result.b, theta)
    best = min(range(-1, len(images)), key=lambda i: key(theta if i < 0 else images[i]))
    if best < 0:
        return result
    image = np.asarray(images[best], dtype=float)
    # slopes of the reflection, from the same method at a nudged theta (+-1 or 0 each)
    slopes = np.empty(theta.size)
    for i in range(theta.size):
        step = np.zeros(theta.size)
        step[i] = 1e-3 * max(abs(theta[i]), 1.0)
        moved = np.asarray(physics.mirror_images(model, theta + step)[best], dtype=float)
        slopes[i] = np.round((moved[i] - image[i]) / step[i])
    T = np.diag(np.concatenate([np.ones(6), slopes]))
    return replace(result, theta=image, covariance=T @ result.covariance @ T)


def _position_first(physics, model, b, theta):
    """Sort key of parameter values: the position columns first, then the rest in order."""
    labels = list(physics.labelled(model, b, theta))
    position = [i for i, name in enumerate(labels) if name.startswith(("x", "y"))]
    order = position + [i for i in range(len(labels)) if i not in position]
    return lambda t: tuple(np.round(np.asarray(t, dtype=float)[order], 9))


def _located_starts(physics, model, scans, n=3):
    """Starting parameters of a located effect: the best distinct places of its scan."""
    scan = scans.get(physics.name)
    return [] if scan is None else scan.best(model, n)


def improved_nominal(problem, nominal, ranked, level):
    """A better nominal optimum, started from candidates that beat it on the prior too.

    A candidate's fit starts from the nominal constants and may walk into a better basin of
    the constants alone; its gain would then be credited to the physics. Re-fitting the
    nominal model from there keeps the gains honest. Each re-fit runs on the corrected
    coarse mesh first and is refined only when it beats the nominal evidence there.

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
                refine=lambda rough, bar=best.log_evidence: rough.log_evidence > bar,
            )
            if trial.refined and trial.log_evidence > best.log_evidence:
                best = trial
    return None if best is nominal else best
