"""The last steps of a joint fit on the working mesh: tight convergence, a canonical image.

The fit reported by :func:`.joint_fit.fit` must not depend on round-off. Two things made it do so:
a least-squares stop at relative changes of 1e-8 leaves a poorly informed constant wherever
the path happened to stop (a whitened step of ``sqrt(2 ftol cost)``, 1e-4 and more), and a
located effect whose mirror images fit equally (the plate's symmetry) was reported at
whichever image the path reached. Here the optimum is finished by least squares at 1e-10,
then by Gauss-Newton steps on the whitened objective ``|r|^2 + |z|^2`` (its Hessian is at
least the identity, so the steps converge fast and to the same point from nearby starts),
and of the images whose objectives agree within :data:`MIRROR_TOL` the one with the
smallest parameters (in order: a mass's ``x`` then ``y``) is reported.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.optimize import least_squares

__all__ = ["FINISH_TOL", "GAUSS_NEWTON_STEPS", "MIRROR_TOL", "finish"]

#: ``ftol``, ``xtol`` and ``gtol`` of the finishing least squares.
FINISH_TOL = 1e-10
#: Gauss-Newton steps at most after it (each one full solve with its derivatives).
GAUSS_NEWTON_STEPS = 4
#: Objectives (``chi2 + chi2_prior``) closer than this are equal: the images tie.
MIRROR_TOL = 1e-6


def finish(problem, res, max_nfev):
    """The optimum ``res`` finished tightly on ``problem``, at its canonical mirror image.

    Parameters
    ----------
    problem : JointProblem
        On the working mesh (its physics' :meth:`~..physics.base.Physics.mirror_images` are used).
    res : scipy.optimize.OptimizeResult
        A least-squares result on ``problem`` (``x``: whitened unknowns, shape (6 + k,)).
    max_nfev : int
        Evaluation cap of the finishing least squares.

    Returns
    -------
    scipy.optimize.OptimizeResult
        A copy of ``res`` with the finished ``x``, ``cost`` (half the objective) and
        ``n_solves`` (eigen solves of the finish added).
    """
    solves = problem.n_solves
    lo, hi = problem.bounds()
    z0 = np.clip(np.asarray(res.x, dtype=float), lo + 1e-12, hi - 1e-12)
    tight = least_squares(
        problem.residuals,
        z0,
        jac=problem.jacobian,
        bounds=(lo, hi),
        method="trf",
        x_scale="jac",
        max_nfev=max_nfev,
        ftol=FINISH_TOL,
        xtol=FINISH_TOL,
        gtol=FINISH_TOL,
    )
    z = _gauss_newton(problem, tight.x)
    z = _canonical(problem, z)
    out = copy.copy(tight)
    r = problem.residuals(z)
    out.x, out.cost = z, 0.5 * float(r @ r)
    out.n_solves = getattr(res, "n_solves", 0) + problem.n_solves - solves
    return out


def _gauss_newton(problem, z, steps=GAUSS_NEWTON_STEPS):
    """Gauss-Newton steps from ``z`` while they lower the objective (within the bounds)."""
    lo, hi = problem.bounds()
    r = problem.residuals(z)
    cost = float(r @ r)
    for _ in range(steps):
        J = problem.jacobian(z)
        dz = np.linalg.lstsq(J, -r, rcond=None)[0]
        trial = np.clip(z + dz, lo, hi)
        r_trial = problem.residuals(trial)
        c_trial = float(r_trial @ r_trial)
        if not c_trial <= cost:
            break
        z, r, cost = trial, r_trial, c_trial
        if np.linalg.norm(dz) <= FINISH_TOL * (1.0 + np.linalg.norm(z)):
            break
    return z


def _canonical(problem, z):
    """The mirror image of the optimum ``z`` to report (``z`` itself when it has none).

    The images of ``z`` (same constants, the physics' mirror-image parameters) are
    evaluated; of those whose objective is within :data:`MIRROR_TOL` of the lowest, the one
    with the lexicographically smallest parameters is taken and finished by Gauss-Newton
    steps (one or two: it is an optimum already when the symmetry is exact).
    """
    if problem.physics is None:
        return z
    b, theta = problem.unpack(z)
    images = problem.physics.mirror_images(problem.model, theta)
    if not images:
        return z
    lo, hi = problem.bounds()
    points = [z] + [np.clip(problem.pack(b, t), lo, hi) for t in images]
    costs = []
    for p in points:
        r = problem.residuals(p)
        costs.append(float(r @ r))
    best = min(costs)
    tied = [i for i, c in enumerate(costs) if c <= best + MIRROR_TOL]
    thetas = [theta, *images]  # as the physics gives them: a mass equal to the last bit
    chosen = min(tied, key=lambda i: tuple(np.asarray(thetas[i], dtype=float)))
    return z if chosen == 0 else _gauss_newton(problem, points[chosen])
