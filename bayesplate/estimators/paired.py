"""One estimator run with a fixed pairing: B, MVE, or MVE-mod's two MVE stages (section 5).

What :func:`bayesplate.estimators.estimate` runs once the pairing is made (by order, index,
shape, or each round of the most probable assignment).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..likelihood.posterior import GaussianProblem, prior_in_stiffness
from .iteration import run

__all__ = ["estimate_paired"]


def estimate_paired(case, model, pair, method, mean, sd, options, start=None):
    """B, MVE or MVE-mod with a fixed pairing, from `start` (default the prior mean)."""
    conventions, tol, max_iter = options["conventions"], options["tol"], options["max_iter"]
    problem = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    run_options = {k: options[k] for k in ("conventions", "tracking", "weight")}
    run_options["start"] = start
    if method != "MVE-mod":
        return _noted(run(problem, method, tol, max_iter, **run_options), mean, sd)
    stage1 = _noted(run(problem, "MVE", options["stage1_tol"], max_iter, **run_options), mean, sd)
    if not stage1.converged:
        return _combine(stage1, None)
    mean2 = stage1.constants
    stage2_factor, stage2_sd = options["stage2"]
    sd2 = _stage2_sd(mean2, mean, sd, stage2_factor, stage2_sd, conventions)
    mu_b, V_b = prior_in_stiffness(mean2, sd2, conventions.prior)
    run_options["start"] = None  # stage 2 starts from stage 1's estimate, its prior mean
    stage2 = run(problem.with_prior(mu_b, V_b), "MVE", tol, max_iter, **run_options)
    return _combine(stage1, _noted(stage2, mean2, sd2))


def _noted(result, mean, sd):
    """The result with its engineering prior (initial values, deviations) in ``settings``."""
    settings = {**result.settings, "prior_mean": np.array(mean), "prior_sd": np.array(sd)}
    return replace(result, settings=settings)


def _stage2_sd(e1, mean, sd1, factor, sd2, conventions):
    """Stage-2 deviations: explicit, or `factor` x stage 1's (rescaled to the estimate)."""
    if sd2 is not None:
        return np.asarray(sd2, dtype=float)
    if conventions.stage2_base == "estimate":
        return factor * sd1 / np.abs(mean) * np.abs(e1)
    return factor * sd1


def _combine(stage1, stage2):
    """One MVE-mod result from its stages (stage 2 may be missing when stage 1 failed)."""
    if stage2 is None:
        message = f"stage 1 did not converge: {stage1.message}"
        return replace(stage1, method="MVE-mod", message=message, stages=(stage1,))
    return replace(
        stage2,
        method="MVE-mod",
        history=np.vstack([stage1.history, stage2.history[1:]]),
        history_b=np.vstack([stage1.history_b, stage2.history_b[1:]]),
        iterations=stage1.iterations + stage2.iterations,
        n_solves=stage1.n_solves + stage2.n_solves,
        mode_swaps=stage1.mode_swaps + stage2.mode_swaps,
        message=f"stage 1: {stage1.message}; stage 2: {stage2.message}",
        stages=(stage1, stage2),
        wall_time=stage1.wall_time + stage2.wall_time,
        settings={
            **stage2.settings,
            "solve_seconds": sum(s.settings.get("solve_seconds", 0.0) for s in (stage1, stage2)),
        },
    )
