"""Estimate a case's constants with B, MVE or MVE-mod (section 5: two MVE stages)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import laminate
from ..model import PlateModel
from ..pairing import Pairing, pair_measured
from ..posterior import GaussianProblem, prior_in_stiffness
from .conventions import resolve_conventions
from .iteration import DEFAULT_MAX_ITER, run
from .result import METHODS

__all__ = ["estimate"]


def estimate(
    case,
    method="MVE",
    model=None,
    tol=1e-3,
    max_iter=DEFAULT_MAX_ITER,
    convention="paper",
    prior_mean=None,
    prior_sd=None,
    stage1_tol=1e-2,
    stage2_factor=2.0,
    stage2_sd=None,
    pairing="auto",
    tracking="auto",
):
    """Estimate the elastic constants of a case with the paper's B, MVE or MVE-mod.

    The prior deviations of ``b`` follow from those of the engineering constants by
    first-order propagation through eqs. 20-21 (:func:`bayesplate.posterior.prior_in_stiffness`);
    ``V_Y`` from the frequency deviations, ``d lambda = 8 pi^2 f df`` (section 3.6).

    Parameters
    ----------
    case : bayesplate.case.Case
    method : {"B", "MVE", "MVE-mod"}
    model : PlateModel, optional
        Forward model; default ``PlateModel.from_case(case)`` (the case's mesh).
    tol : float
        TOL of section 2.4 (of stage 2 for MVE-mod).
    max_iter : int
        Iteration cap (per stage).
    convention : str or Conventions
        ``"paper"`` (reproduces the paper, the default) or ``"consistent"``, or explicit
        :class:`Conventions`.
    prior_mean, prior_sd : array_like, shape (6,), optional
        Initial values and deviations of ``(E1, E2, nu12, G12, G13, G23)`` in SI, replacing
        the case's prior (stage 1 of MVE-mod).
    stage1_tol : float
        MVE-mod stage-1 TOL (section 5: 1e-2).
    stage2_factor : float
        MVE-mod stage-2 deviations are this multiple of stage 1's (section 6: 2).
    stage2_sd : array_like, shape (6,), optional
        Explicit stage-2 deviations (SI), overriding `stage2_factor`.
    pairing : {"auto", "mac", "index", "order"} or Pairing
        Measured-to-computed mode pairing (:func:`bayesplate.pairing.pair_measured`, at the
        prior mean): "auto" pairs by shape (MAC) when the case has measured shapes, else by
        the case's mode indices if any, else by order. Measured modes left unpaired are left
        out of the fit.
    tracking : {"auto", "report", "follow", "off"}
        MAC tracking of paired modes between iterates (see :func:`run`); "auto" follows
        modes paired by shape and keeps order or index pairings as they are.

    Returns
    -------
    EstimateResult
    """
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {METHODS}")
    conventions = resolve_conventions(convention)
    model = model or PlateModel.from_case(case)
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    pair = pairing
    if not isinstance(pair, Pairing):
        pair = pair_measured(case, model, laminate.stiffness_from_engineering(mean), pairing)
    problem = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    weight = model.mass  # the MAC weight for tracking (ForwardModel interface)
    options = {"conventions": conventions, "tracking": tracking, "weight": weight}
    if method != "MVE-mod":
        return _noted(run(problem, method, tol, max_iter, **options), mean, sd)
    stage1 = _noted(run(problem, "MVE", stage1_tol, max_iter, **options), mean, sd)
    if not stage1.converged:
        return _combine(stage1, None)
    mean2 = stage1.constants
    sd2 = _stage2_sd(mean2, mean, sd, stage2_factor, stage2_sd, conventions)
    mu_b, V_b = prior_in_stiffness(mean2, sd2, conventions.prior)
    stage2 = run(problem.with_prior(mu_b, V_b), "MVE", tol, max_iter, **options)
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
