"""A case to its estimate: :func:`run_estimate` (estimate, budget, error scale, document)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

__all__ = ["EstimateRun", "run_estimate"]


@dataclass(frozen=True, eq=False)
class EstimateRun:
    """What :func:`run_estimate` computed.

    Attributes
    ----------
    case : bayesplate.io.Case
    model : bayesplate.plate.model.PlateModel
        The full model of the run (its mesh).
    result : bayesplate.estimators.EstimateResult
        The estimate; with the case's error scale, its sd widened by it.
    budget : bayesplate.likelihood.inputs.VarianceBudget or None
        The variance budget (at the declared deviations); None when not asked for or when
        the estimate has no covariance.
    scale : bayesplate.likelihood.error_scale.LinearisedScale or None
        The inferred error scale, when the case declares one.
    """

    case: object
    model: object
    result: object
    budget: object = None
    scale: object = None

    @cached_property
    def document(self):
        """The JSON document (:func:`bayesplate.io.estimate_to_dict`), made once."""
        from ..io import estimate_to_dict

        return estimate_to_dict(self.result, self.case, self.model, self.budget, self.scale)


def run_estimate(case, options, *, model=None, fast=None):
    """Estimate the constants of `case`: the estimate, its budget, its error scale.

    Parameters
    ----------
    case : bayesplate.io.Case
    options : EstimateOptions
    model : bayesplate.plate.model.PlateModel, optional
        The full model, already built; default the case's on ``options.mesh``.
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model shared with other runs: the estimator iterates on it and the full model
        checks the answer (:func:`bayesplate.estimators.estimate_on_fast`); ``options.forward``
        is then not used.

    Returns
    -------
    EstimateRun
    """
    from ..estimators import estimate, estimate_on_fast
    from ..plate.model import PlateModel
    from .budget import converged_budget

    if model is None:
        model = PlateModel.from_case(case, mesh=options.mesh)
    keywords = {
        "tol": options.tol,
        "max_iter": options.max_iter,
        "convention": options.convention,
        "pairing": options.pairing,
    }
    if fast is None:
        result = estimate(case, options.method, model=model, forward=options.forward, **keywords)
    else:
        result, _ = estimate_on_fast(case, options.method, model, fast, **keywords)
    budget = converged_budget(case, result, model) if options.budget else None
    scale = None
    if case.measured.error_scale is not None:  # the sd widened by the inferred scale
        from .budget import scale_estimate

        result, scale = scale_estimate(case, model, result)
    return EstimateRun(case, model, result, budget, scale)
