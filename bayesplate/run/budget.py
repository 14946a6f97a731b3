"""What a run adds to an estimate: its variance budget and its error scale.

Both rebuild the estimate's Gaussian problem
(:class:`bayesplate.likelihood.posterior.GaussianProblem`) and combine it with a lower piece: the
measured inputs' Jacobian (:mod:`bayesplate.likelihood.inputs`) or the error scale's linearisation
(:mod:`bayesplate.likelihood.error_scale`). They live here, above all three, so that the
likelihood's pieces do not import the likelihood that uses them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..likelihood.error_scale import linearised_at
from ..likelihood.inputs import (
    INPUT_NAMES,
    VarianceBudget,
    input_jacobian,
    input_sources,
    variance_budget,
)
from ..likelihood.posterior import GaussianProblem
from ..plate.model import PlateModel
from ..quantities import engineering_covariance

__all__ = ["converged_budget", "estimate_budget", "scale_estimate"]


def estimate_budget(case, result, model=None, jacobian=None) -> VarianceBudget:
    """The variance budget of an estimate of a case (B, MVE or MVE-mod).

    Parameters
    ----------
    case : bayesplate.io.Case
        Its plate's ``*_sd`` are the input deviations.
    result : bayesplate.estimators.EstimateResult
        The estimate; its pairing, conventions and (final stage's) prior rebuild its problem.
    model : PlateModel, optional
        Full model for the sensitivities at the estimate and the input Jacobian's mesh;
        default the case's.
    jacobian : InputJacobian, optional
        Already computed at ``result.b`` for these modes (skips 6 solves). Not computed when
        every input deviation is 0.

    Returns
    -------
    VarianceBudget
    """
    model = model or PlateModel.from_case(case)
    conventions = result.settings["conventions"]
    problem = GaussianProblem.from_case(
        case,
        model,
        result.pairing,
        conventions.observation,
        conventions.prior,
        result.settings.get("prior_mean"),
        result.settings.get("prior_sd"),
    )
    modes = np.asarray(result.modes) - 1
    prediction = problem.predict(result.b, modes)
    names, A = input_sources(case.plate)
    if not np.any(A):  # every input taken as exact: no share, no solves
        J = np.zeros((modes.size, len(INPUT_NAMES)))
    elif jacobian is None:
        mesh = (model.mesh.nx, model.mesh.ny)
        J = input_jacobian(case, result.b, modes, mesh=mesh).J
    else:
        J = jacobian.J
    if case.plate.mass is None:  # (h, rho, a, b) independent: as before, bit for bit
        J_sources, sd = J, np.diag(A)
    else:  # one deviation of each reading (h, m, a, b) through rho = m / (a b h)
        J_sources, sd = J @ A, np.ones(len(names))
    return variance_budget(
        result.covariance_b,
        prediction.S,
        problem.V_Y,
        problem.V_b,
        J_sources,
        sd,
        result.b,
        result.method,
        names,
    )


def converged_budget(case, result, model=None):
    """:func:`estimate_budget` of a converged estimate; None when there is no covariance.

    What ``bayesplate estimate`` and ``bayesplate batch`` both report (one rule for both).
    """
    if not result.converged or not np.all(np.isfinite(result.covariance_b)):
        return None
    return estimate_budget(case, result, model)


def scale_estimate(case, model, result):
    """An estimate (B, MVE, MVE-mod) with the case's error scale: ``s`` and the widened ``P``.

    The estimate stays where the estimator put it; its covariance becomes
    :attr:`LinearisedScale.covariance_b` (module docstring), carried to the engineering
    constants to first order.

    Parameters
    ----------
    case : bayesplate.io.Case
        With ``measured.error_scale`` set.
    model : bayesplate.plate.forward.ForwardModel
        The full model (one solve at the estimate).
    result : bayesplate.estimators.EstimateResult

    Returns
    -------
    scaled : EstimateResult
        `result` with ``covariance_b``, ``covariance`` and ``sd`` replaced.
    linearised : LinearisedScale
    """
    conventions = result.settings.get("conventions")
    observation = getattr(conventions, "observation", "variance")
    problem = GaussianProblem.from_case(case, model, result.pairing, observation)
    lin = linearised_at(problem, result.b, result.covariance_b)
    cov = engineering_covariance(result.constants, lin.covariance_b)
    scaled = dataclasses.replace(
        result, covariance_b=lin.covariance_b, covariance=cov, sd=np.sqrt(np.diag(cov))
    )
    return scaled, lin
