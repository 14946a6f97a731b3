"""The report's steps: each computes one result of a case as plain data (arrays, JSON values).

Every function takes the case, the working model and what the step needs, and returns a dict
that :class:`bayesplate.report.cache.StepCache` can store; none of them reads or writes files.
The order they run in and their caching are :mod:`bayesplate.report.runner`'s.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..laminate import stiffness_from_engineering
from ..matching.checked_order import checks_order
from ..matching.pairing import MAC_EXTRA_MODES
from ..quantities import to_case_units

# Chain bounds of the posterior section: the sampler's own defaults (5000 steps, ESS 2000)
# cost tens of minutes of full solves where walkers leave the fast model's box.
_CHAINS = {"max_steps": 1000, "min_ess": 1000.0}
_QUICK_CHAINS = {"max_steps": 400, "min_ess": 400.0}
_CORNER_DRAWS = 4000  # posterior draws kept for the corner plot


def pairing_step(case, model, how="auto"):
    """Modes at the prior mean and the pairing (with any warnings as text).

    ``how == "likelihood"``: the assignment B settles on (:mod:`bayesplate.matching.assignment`),
    with its unobserved computed modes and spurious peaks (0-based) in the result.
    """
    m = case.measured.size
    b = stiffness_from_engineering(case.prior.mean)
    modal = model.solve(b, m + MAC_EXTRA_MODES)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from ..estimators import settle_pairing

        # by order checked: each step checks it at its own answer (at the prior mean an
        # assignment is no test of the order: far from the answer it sets good pairs aside)
        pairing, _ = settle_pairing(case, model, how, modal=modal)
    data = {
        "how": pairing.how,
        "modes": pairing.modes,
        "describe": pairing.describe(m),
        "warnings": [str(w.message) for w in caught],
        "prior_frequency_Hz": modal.frequency_Hz,
        "threshold": pairing.threshold,
        "checked": checks_order(case.measured, how),
    }
    if pairing.measured is not None:
        data["measured"] = pairing.measured
    if pairing.mac is not None:
        data["mac"] = pairing.mac
    if pairing.assignment is not None:
        data["unobserved"] = pairing.assignment.unobserved
        data["spurious"] = pairing.assignment.spurious
    return data


def estimate_step(case, model, method, pairing, fast=None):
    """One of the paper's estimators (:func:`bayesplate.run.run_estimate`) as plain data.

    With a fast model (a :class:`bayesplate.reduced.CertifiedModel`) the estimator iterates
    on it and the full model checks the answer (the ``check`` entry).
    """
    from ..io.export import budget_to_dict
    from ..run import run_estimate

    options = estimate_options(method, pairing, model)
    done = run_estimate(case, options, model=model, fast=fast)
    r, lin = done.result, done.scale
    scale = None
    if lin is not None:  # the sd widened by the inferred scale
        scale = {**_scale_data(lin.summary), "s_hat": lin.s_hat, "dof": lin.dof}
    return {
        "method": r.method,
        "converged": bool(r.converged),
        "iterations": int(r.iterations),
        "message": r.message,
        "n_solves": int(r.n_solves),
        "wall_time": float(r.wall_time),
        "modes": np.asarray(r.modes),
        "constants": r.constants,
        "sd": r.sd,
        "covariance": r.covariance,
        "budget": None if done.budget is None else budget_to_dict(done.budget),
        "b": r.b,
        "frequency_Hz": r.frequency_Hz,
        "measured_Hz": r.measured_Hz,
        "residual_Hz": r.residual,
        "stages": [
            {"converged": bool(s.converged), "iterations": int(s.iterations), "message": s.message}
            for s in r.stages
        ],
        "status": r.status,
        "fit": None if r.fit is None else r.fit.to_dict(),
        "warnings": list(r.warnings),
        "check": None if r.check is None else _check_data(r.check),
        "error_scale": scale,
    }


def estimate_options(method, pairing, model):
    """The run layer's options of the report's estimate of `method`.

    The command line's defaults; on the full model unless the step is given the report's
    shared fast model (which the report builds where ``"auto"`` takes the fast path); the
    variance budget of B's (the report's figure of where each constant's uncertainty comes
    from).
    """
    from ..run import EstimateOptions

    mesh = (model.mesh.nx, model.mesh.ny)
    return EstimateOptions(
        method=method, mesh=mesh, pairing=pairing, forward="full", budget=method == "B"
    )


def _scale_data(summary):
    """A :class:`bayesplate.likelihood.error_scale.ScaleSummary` as plain data, its sentence too."""
    return {
        "median": summary.median,
        "interval": list(summary.interval),
        "status": summary.status,
        "text": str(summary),
    }


def _check_data(check):
    """A :class:`bayesplate.estimators.FullModelCheck` as plain data."""
    return {
        "fast_Hz": check.fast_Hz,
        "full_Hz": check.full_Hz,
        "max_rel_error": check.max_rel_error,
        "tolerance": check.tolerance,
        "confirmed": check.confirmed,
        "rounds": int(check.rounds),
        "n_full_solves": int(check.n_full_solves),
        "text": str(check),
    }


def modes_step(case, model, b, n_modes, n_shapes):
    """Modes, normalised sensitivities, mode kinds and the first `n_shapes` shapes at `b`."""
    from ..discrepancy.search.locate import mode_kinds

    modal = model.solve(np.asarray(b, dtype=float), n_modes)
    return {
        "b": modal.b,
        "frequency_Hz": modal.frequency_Hz,
        "eigenvalues": modal.eigenvalues,
        "normalised_sensitivities": modal.normalised_sensitivities(),
        "kinds": mode_kinds(model, modal),
        "vectors": modal.vectors[:, :n_shapes],
    }


def diagnose_step(case, model, pairing, options, progress, store=None):
    """Model discrepancy (:func:`bayesplate.discrepancy.diagnose.diagnose`) as plain data.

    ``store`` keeps diagnose's own stages (``get``/``put``, :mod:`bayesplate.discrepancy.
    store`), so that a report killed inside this step resumes inside it.
    """
    from ..discrepancy.diagnose import diagnose
    from ..io import diagnosis_to_dict

    d = diagnose(
        case,
        model=model,
        rng=options.seed,
        pairing=pairing,
        progress=lambda msg: progress(f"    {msg}"),
        n_starts=options.n_starts,
        workers=2,  # the fits are independent: the results do not depend on it
        store=store,
    )
    data = {"diagnosis": diagnosis_to_dict(d), "mode_kinds": d.mode_kinds}
    for key, lm in d.maps.items():
        for name in ("points_mm", "chi2_drop", "amplitude", "physical"):
            data[f"map_{key}_{name}"] = np.asarray(getattr(lm, name))
        data[f"map_{key}_shape"] = np.asarray(lm.shape)
    return data


def sample_step(case, model, pairing, options, fast=None):
    """The posterior by :func:`bayesplate.run.run_sample` (only when the module exists).

    With `fast` (the report's shared :class:`bayesplate.reduced.CertifiedModel`) the sampler
    builds no fast model of its own, unless the case gives input deviations: the posterior
    then has them marginalised (``inputs="auto"``) and is wider than the box the shared
    model was certified over, so the sampler places and certifies its own.

    The draws kept for the corner plot (at most ``_CORNER_DRAWS``, shape (n, 6)) are in
    case units (GPa, -).
    """
    from ..laminate import engineering_from_stiffness
    from ..likelihood.inputs import describe_inputs
    from ..run import run_sample

    done = run_sample(
        case,
        sample_options(options, pairing, model),
        options.seed,
        model=model,
        fast=fast,
        record_warnings=True,
    )
    r = done.result
    scale = None if done.scale is None else _scale_data(done.scale)
    e = to_case_units(engineering_from_stiffness(r.samples_b))
    keep = np.linspace(0, len(e) - 1, min(len(e), _CORNER_DRAWS)).astype(int)
    return {
        "mean": r.mean,
        "sd": r.sd,
        "hdi": r.hdi,
        "ess_bulk": r.ess_bulk,
        "rhat": r.rhat,
        "converged": bool(r.converged),
        "message": r.message,
        "n_steps": int(r.n_steps),
        "n_burn": int(r.n_burn),
        "n_walkers": int(r.n_walkers),
        "acceptance": float(r.acceptance),
        "n_full": int(r.n_full),
        "certificate": None if r.certificate is None else str(r.certificate),
        "timings": {k: float(v) for k, v in r.timings.items()},
        "map": None if r.estimate is None else r.estimate.constants,
        "draws": e[keep],
        "warnings": list(done.warnings),  # counted in the report, not repeated
        "inputs": done.setup.inputs,
        "inputs_given": describe_inputs(case.plate),
        "error_scale": scale,
        "inputs_posterior": None if r.input_posterior is None else r.input_posterior.table(),
        "input_certificate": _certificate_data(r.input_certificate),
    }


def sample_options(options, pairing, model):
    """The run layer's options of the report's posterior (a :class:`ReportOptions`' chains).

    The sampler's defaults but the chain bounds (``_CHAINS``, or ``_QUICK_CHAINS`` for a
    quick report) and no MVE beside B.
    """
    from ..run import SampleOptions

    chains = _QUICK_CHAINS if options.quick else _CHAINS
    mesh = (model.mesh.nx, model.mesh.ny)
    return SampleOptions(mesh=mesh, pairing=pairing, mve=False, **chains)


def _certificate_data(certificate):
    """The linear input model's certificate as plain data (None when none was made)."""
    if certificate is None:
        return None
    return {"text": str(certificate), "passed": bool(certificate.passed)}
