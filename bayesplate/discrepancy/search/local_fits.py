"""Local least-squares fits of a joint problem from many starts, and their distinct optima.

Each start is fitted by scipy's trust-region reflective least squares on the whitened
residuals ``r(z)`` of :class:`.joint_fit.JointProblem` (``|r|^2 = chi2 + chi2_prior``), within the
problem's bounds, the independent starts on forked workers (:func:`bayesplate.parallel.fork_map`).
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ...parallel import fork_map

__all__ = ["DISTINCT", "distinct", "local_fits", "problem_name"]

log = logging.getLogger("bayesplate.discrepancy.search.joint_fit")  # the fits' records, as before

DISTINCT = 0.3  # whitened distance under which two optima are the same


def distinct(results):
    """Results (best first) farther than ``DISTINCT`` from every better one."""
    chosen = []
    for r in results:
        if all(np.linalg.norm(r.x - c.x) > DISTINCT for c in chosen):
            chosen.append(r)
    return chosen


def local_fits(problem, starts, max_nfev, workers=1, tol=1e-8):
    """Least-squares results from every start, lowest cost first (``tol``: ftol and xtol).

    A start whose fit meets a plate that cannot be solved (on a reduced model far from
    where it was built, a pair's summed mass matrix need not stay positive definite) is
    dropped with a warning; if every start fails, their results are returned at their
    starts with an infinite cost.
    """
    lo, hi = problem.bounds()

    def local_fit(z0):
        solves = problem.n_solves
        z0 = np.clip(np.asarray(z0, dtype=float), lo + 1e-9, hi - 1e-9)
        try:
            res = least_squares(
                problem.residuals,
                z0,
                jac=problem.jacobian,
                bounds=(lo, hi),
                method="trf",
                x_scale="jac",
                max_nfev=max_nfev,
                ftol=tol,
                xtol=tol,
            )
        except np.linalg.LinAlgError as error:
            log.warning(
                "%s start %s: fit failed (%s: %s)",
                problem_name(problem),
                np.round(z0, 2),
                type(error).__name__,
                error,
            )
            failed = OptimizeResult(
                x=z0, cost=np.inf, success=False, status=-1, message=f"failed: {error}"
            )
            failed.n_solves = problem.n_solves - solves
            return failed
        log.info(
            "%s start %s: cost %.3g (%s)",
            problem_name(problem),
            np.round(z0, 2),
            2 * res.cost,
            res.message,
        )
        res.n_solves = problem.n_solves - solves
        return res

    solves = problem.n_solves
    results = fork_map(local_fit, starts, workers)
    problem.n_solves = solves + sum(r.n_solves for r in results)  # also those of workers
    fitted = [r for r in results if np.isfinite(r.cost)]
    return sorted(fitted or results, key=lambda r: r.cost)


def problem_name(problem):
    """The name in log records: "nominal" or the candidate's."""
    return "nominal" if problem.physics is None else problem.physics.name
