"""Results out: plain-data documents of every result, written whole or not at all.

- Files (:mod:`.files`, re-exported here): :func:`atomic_write` (and its text, figure, JSON
  and netCDF forms) writes through a temporary file and a rename, so a reader never sees a
  partial file.
- Documents: one ``*_to_dict`` per result type (:func:`estimate_to_dict`,
  :func:`sampling_to_dict`, :func:`diagnosis_to_dict`) gives the JSON document of the
  command line (and the report) in case-file units: moduli in GPa, the keys of
  :data:`bayesplate.quantities.ENGINEERING_KEYS`.
"""

from __future__ import annotations

import numpy as np

from ..quantities import CASE_SCALE, ENGINEERING_KEYS, STIFFNESS_NAMES, to_case_units
from .files import (
    atomic_write,
    atomic_write_text,
    figure_png,
    jsonable,
    save_figure,
    write_json,
    write_netcdf,
    write_png,
)

__all__ = [
    "atomic_write",
    "atomic_write_text",
    "budget_to_dict",
    "constants_json",
    "diagnosis_to_dict",
    "error_scale_to_dict",
    "estimate_to_dict",
    "figure_png",
    "input_certificate_to_dict",
    "input_posterior_to_dict",
    "jsonable",
    "sampling_to_dict",
    "save_figure",
    "write_png",
    "write_json",
    "write_netcdf",
]


_TO_CASE_UNITS = 1.0 / CASE_SCALE


def constants_json(mean, sd=None, **extra):
    """Engineering constants in case-file units: ``{"E1_GPa": {"mean", "sd", ...}, ...}``.

    Parameters
    ----------
    mean, sd : array_like, shape (6,)
        SI values (Pa, dimensionless nu12); ``sd`` may be None.
    **extra : array_like, shape (6,)
        Further SI fields per constant (e.g. ``hdi_3%``).
    """
    fields = {"mean": mean, "sd": sd, **extra}
    scaled = {
        k: None if v is None else np.asarray(v, dtype=float) * _TO_CASE_UNITS
        for k, v in fields.items()
    }
    return {
        key: {k: None if v is None else float(v[i]) for k, v in scaled.items()}
        for i, key in enumerate(ENGINEERING_KEYS)
    }


# ----------------------------------------------------------------------------- documents


def budget_to_dict(budget):
    """A variance budget's JSON document (:class:`bayesplate.likelihood.inputs.VarianceBudget`).

    Returns
    -------
    dict
        ``{"status", "closure", "sources", "sd": {key: {source: sd, ..., "total": sd}},
        "share": {key: {source: fraction}}}`` with sds in case units (GPa, -).
    """
    sd = np.array([to_case_units(row) for row in budget.source_sd])
    total = to_case_units(budget.sd)
    return {
        "status": budget.status,
        "closure": float(budget.closure),
        "sources": list(budget.sources),
        "sd": {
            key: {
                **dict(zip(budget.sources, sd[:, i].tolist(), strict=True)),
                "total": float(total[i]),
            }
            for i, key in enumerate(ENGINEERING_KEYS)
        },
        "share": {
            key: dict(zip(budget.sources, budget.share[:, i].tolist(), strict=True))
            for i, key in enumerate(ENGINEERING_KEYS)
        },
    }


def estimate_to_dict(result, case, model, budget=None, scale=None):
    """The JSON document of an estimate (``bayesplate estimate --json``).

    Parameters
    ----------
    result : bayesplate.estimators.EstimateResult
        The estimate.
    case : bayesplate.io.Case
        The case it was computed for (its name).
    model : bayesplate.plate.forward.ForwardModel
        The model it was computed with (its mesh).
    budget : bayesplate.likelihood.inputs.VarianceBudget, optional
        Its variance budget (:func:`bayesplate.run.budget.converged_budget`), under
        ``"variance_budget"``.
    scale : bayesplate.likelihood.error_scale.LinearisedScale, optional
        The inferred error scale (the case's ``measured.error_scale``), under
        ``"error_scale"`` (:func:`error_scale_to_dict`); `result`'s sd then include it.

    Returns
    -------
    dict
        Constants ``{"E1_GPa": {"mean", "sd"}, ...}`` in case units, stiffness in GPa,
        frequencies and residuals in Hz, per-stage constants for a two-stage method;
        ``"status"`` (:data:`bayesplate.estimators.STATUSES`: ``"converged"`` only when the
        iteration stopped and nothing was flagged; ``"converged"`` the boolean is that it
        stopped), ``"fit"`` (``chi2``, ``dof``, ``p_value``, ``p_effective``, ``n_paired``
        and ``worst_residuals``: ``peak`` 1-based, ``measured_Hz``, ``computed_Hz``, ``sd``;
        None when the result was not assessed) and ``"warnings"`` (sentences).
    """

    def constants(r):
        mean, sd = to_case_units(r.constants), to_case_units(r.sd)
        return {
            key: {"mean": float(mean[i]), "sd": float(sd[i])}
            for i, key in enumerate(ENGINEERING_KEYS)
        }

    conventions = result.settings.get("conventions")
    out = {
        "case": case.name,
        "method": result.method,
        "convention": None if conventions is None else vars(conventions),
        "mesh": [model.mesh.nx, model.mesh.ny],
        "converged": bool(result.converged),
        "status": result.status,
        "fit": None if result.fit is None else result.fit.to_dict(),
        "warnings": list(result.warnings),
        "iterations": int(result.iterations),
        "message": result.message,
        "n_solves": int(result.n_solves),
        "wall_time_s": float(result.wall_time),
        "constants": constants(result),
        "stiffness_GPa": dict(zip(STIFFNESS_NAMES, (result.b / 1e9).tolist(), strict=True)),
        "frequency_Hz": result.frequency_Hz,
        "measured_Hz": result.measured_Hz,
        "residual_Hz": result.residual,
        "modes": result.modes,
        "mode_swaps": [list(s) for s in result.mode_swaps],
    }
    for key in ("unobserved_modes", "spurious_peaks"):  # 1-based, a pairing by likelihood
        if key in result.settings:
            out[key] = [int(v) for v in result.settings[key]]
    rivals = result.settings.get("rivals") or []
    if rivals:  # other optima of the search: constants and the nats they trail by
        out["rivals"] = [
            {
                "constants": dict(zip(ENGINEERING_KEYS, to_case_units(c).tolist(), strict=True)),
                "nats_behind": float(n),
            }
            for c, n in rivals
        ]
    if result.stages:
        out["stages"] = [
            {
                "converged": bool(s.converged),
                "iterations": int(s.iterations),
                "message": s.message,
                "constants": constants(s),
            }
            for s in result.stages
        ]
    if budget is not None:
        out["variance_budget"] = budget_to_dict(budget)
    if scale is not None:
        out["error_scale"] = error_scale_to_dict(scale.summary, scale)
    return out


def error_scale_to_dict(summary, linearised=None):
    """The inferred error scale ``s`` (dimensionless): posterior median, 94 % interval, prior.

    Parameters
    ----------
    summary : bayesplate.likelihood.error_scale.ScaleSummary
    linearised : bayesplate.likelihood.error_scale.LinearisedScale, optional
        At an estimate: adds ``s_hat``, ``chi2``, the effective number of constants and the
        Student-t degrees of freedom.

    Returns
    -------
    dict
    """
    out = {
        "median": summary.median,
        "interval_94": list(summary.interval),
        "source": summary.source,
        "status": summary.status,
        "prior": {
            "median": summary.prior.median,
            "upper95": summary.prior.upper95,
            "shape": summary.prior.shape,
            "scale": summary.prior.scale,
        },
    }
    if linearised is not None:
        out.update(
            s_hat=linearised.s_hat,
            chi2=linearised.chi2,
            n_effective=linearised.n_effective,
            dof=linearised.dof,
        )
    return out


def sampling_to_dict(result, case, mve=None, scale=None):
    """The JSON document of a sampled posterior (``bayesplate sample --json``).

    Parameters
    ----------
    result : bayesplate.sampling.SamplingResult
        The sampled posterior, with its B estimate (``result.estimate``).
    case : bayesplate.io.Case
        The case it was sampled for (its name).
    mve : bayesplate.estimators.EstimateResult, optional
        The MVE estimate, reported beside B.
    scale : bayesplate.likelihood.error_scale.ScaleSummary, optional
        The posterior of the error scale, under ``"error_scale"`` (:func:`error_scale_to_dict`).

    Returns
    -------
    dict
        Posterior summary per constant in case units, convergence diagnostics, costs, the
        reduced model's certificate and the estimates ``{"B": ..., "MVE": ...}``.
    """
    est = result.estimate
    cert = result.certificate
    certificate = None
    if cert is not None:
        certificate = {
            "max_rel_error": cert.max_rel_error,
            "tolerance": cert.tolerance,
            "passed": bool(cert.passed),
            "n_test": cert.n_test,
            "basis_size": cert.basis_size,
        }
    out = {
        "case": case.name,
        "constants": result.constants_table(),
        "ess_min": result.ess_min,
        "rhat_max": result.rhat_max,
        "ess_bulk": dict(zip(ENGINEERING_KEYS, result.ess_bulk.tolist(), strict=True)),
        "rhat": dict(zip(ENGINEERING_KEYS, result.rhat.tolist(), strict=True)),
        "converged": bool(result.converged),
        "message": result.message,
        "n_walkers": result.n_walkers,
        "n_steps": result.n_steps,
        "n_burn": result.n_burn,
        "tau_steps": result.tau,
        "acceptance": result.acceptance,
        "n_evaluations": result.n_evaluations,
        "n_full_solves_sampling": result.n_full,
        "n_full_solves_setup": result.settings.get("full_solves_setup"),
        "certificate": certificate,
        "timings_s": result.timings,
        "seed_entropy": result.settings.get("seed_entropy"),
        "inputs": result.settings.get("inputs", "exact"),
        "estimates": {
            name: constants_json(r.constants, r.sd)
            for name, r in (("B", est), ("MVE", mve))
            if r is not None
        },
    }
    if scale is not None:
        out["error_scale"] = error_scale_to_dict(scale)
    if result.input_posterior is not None:
        out["inputs_posterior"] = input_posterior_to_dict(result.input_posterior)
    if result.input_certificate is not None:
        out["input_certificate"] = input_certificate_to_dict(result.input_certificate)
    if result.settings.get("assignment") is not None:
        out["assignment"] = chain_assignment_to_dict(
            result.settings["assignment"], result.assignment
        )
    return out


def chain_assignment_to_dict(note, assignment):
    """How the chain assigned the peaks (pairing by likelihood), for JSON.

    The note, and per peak the fraction of draws with each 1-based computed mode and
    spurious (no peaks where the assignment was kept as settled).
    """
    out = {"note": note}
    if assignment is not None:
        n = assignment.fractions.shape[1] - 1
        out["n_draws"] = assignment.n_draws
        out["peaks"] = [
            {
                "peak": i + 1,
                "frequency_Hz": float(assignment.frequency_Hz[i]),
                "modes": {str(j + 1): float(row[j]) for j in range(n) if row[j] > 0},
                "spurious": float(row[n]),
            }
            for i, row in enumerate(assignment.fractions)
        ]
    return out


def input_posterior_to_dict(posterior):
    """The declared inputs' posterior in case units (mm, g, kg/m^3).

    ``{"thickness_mm": {"declared", "declared_sd", "mean", "sd", "hdi_3%", "hdi_97%"}, ...,
    "n_draws": n}``: the case's value and deviation (the prior) beside the posterior.
    """
    return {**posterior.table(), "n_draws": int(len(posterior.rows))}


def input_certificate_to_dict(certificate):
    """The linear input model's certificate (an ``inputs_posterior.InputCertificate``).

    The largest error relative to an eigenvalue and in units of a mode's declared deviation,
    the pass mark, ``passed`` and ``status`` (``"ok"`` or ``"nonlinear"``), where the largest
    error sits, and every error: ``relative[reading]["+"|"-"]``, one per paired mode.
    """
    worst = certificate.worst
    if worst is not None:
        worst = {"input": worst[0], "sign": worst[1], "position": worst[2]}
    relative = {
        name: {"+": certificate.relative[k, 0].tolist(), "-": certificate.relative[k, 1].tolist()}
        for k, name in enumerate(certificate.names)
    }
    return {
        "max_relative_error": certificate.max_relative,
        "max_error_in_sd": certificate.max_in_sd,
        "fraction": certificate.fraction,
        "n_sd": certificate.n_sd,
        "passed": bool(certificate.passed),
        "status": certificate.status,
        "worst": worst,
        "n_solves": certificate.n_solves,
        "relative": relative,
        "text": str(certificate),
    }


def _fit_summary(fit_, dof, p_value):
    """Chi-square, constants and residuals of one fit, for JSON."""
    return {
        "chi2": fit_.chi2,
        "dof": dof,
        "p_value": p_value,
        "residual_sigma": fit_.residual_sigma,
        "frequency_Hz": fit_.frequency_Hz,
        "constants": constants_json(fit_.constants, fit_.constants_sd),
        "check": _check(fit_),
    }


def _check(fit_):
    """The full model at the answer a reduced model gave (:class:`FitCheck`), or None."""
    check = getattr(fit_, "check", None)
    if check is None:
        return None
    return {
        "settled": check.settled,
        "objective_full": check.full_objective,
        "objective_fast": check.fast_objective,
        "max_rel_error": check.max_rel_error,
        "decrement": check.decrement,
        "rounds": check.rounds,
        "full_solves": check.full_solves,
    }


def _rival(d):
    """The runner-up of an ``ambiguous`` diagnosis and what would separate it, or None."""
    rival, separation = getattr(d, "rival", None), getattr(d, "separation", None)
    if rival is None:
        return None
    out = {
        "physics": rival.name,
        "log_evidence_gain": rival.log_evidence_gain,
        "chi2": rival.fit.chi2,
        "parameters": rival.parameters,
        "parameters_sd": rival.parameters_sd,
        "separation": None,
    }
    if separation is not None:
        out["separation"] = {
            "mode": separation.mode,
            "frequency_Hz": list(separation.frequency_Hz),
            "difference_sd": separation.difference_sd,
            "shape_mode": separation.shape_mode,
            "point_mm": list(separation.point_mm),
            "shape_difference": separation.shape_difference,
            "text": separation.text(),
        }
    return out


def diagnosis_to_dict(d):
    """The diagnosis as plain data, in the units of the case files (see the issue's keys)."""
    nominal = _fit_summary(d.nominal, d.dof, d.p_value)
    nominal["mode_p_value"] = d.mode_p_values
    refit = None
    if d.chosen is not None:
        refit = _fit_summary(d.chosen.fit, d.refit_dof, d.refit_p_value)
        refit["parameters"] = d.chosen.parameters
        refit["parameters_sd"] = d.chosen.parameters_sd
        refit["mirror_images"] = d.chosen.mirror_images
    return {
        "verdict": d.verdict,
        "measured_Hz": d.measured_Hz,
        "sigma_Hz": d.sigma_Hz,
        "mesh_error_Hz": d.mesh_error_Hz,
        "nominal": nominal,
        "located": {
            "modes": d.located_modes,
            "mode_kinds": d.mode_kinds,
            "region_mm": None if d.region_mm is None else list(d.region_mm),
            "region_mirrors_mm": [list(p) for p in d.region_mirrors_mm],
        },
        "candidates": [
            {
                "physics": c.name,
                "log_evidence_gain": c.log_evidence_gain,
                "chi2": c.fit.chi2,
                "parameters": c.parameters,
                "parameters_sd": c.parameters_sd,
                "refined": c.fit.refined,
                "check": _check(c.fit),
                # why a later phase of the ranking failed on it (then its phase before's
                # result), or "" (rank.CandidateResult.failed)
                "failed": getattr(c, "failed", ""),
            }
            for c in d.candidates
        ],
        "chosen": None if d.chosen is None else d.chosen.name,
        "refit": refit,
        "probabilities": dict(getattr(d, "probabilities", {})),
        "rival": _rival(d),
        "also_tied": [c.name for c in getattr(d, "also_tied", [])],
        "unnamed_change": _unnamed(getattr(d, "unnamed", None)),
        "unidentified": d.unidentified,
        "notes": d.notes,
        # the computed mode (1-based) of every measured peak, null where left out as
        # spurious; present when the assignment was made again at the verdict's fit
        "passes": getattr(d, "passes", 1),  # each with another assignment of the peaks
        "peak_modes": None
        if getattr(d, "peak_modes", None) is None
        else [None if j < 0 else int(j) + 1 for j in d.peak_modes],
    }


def _unnamed(change):
    """The unnamed local change every name must beat (search/unnamed.py), or None."""
    if change is None:
        return None
    x0, x1, y0, y1 = (float(v) for v in change.window_mm)
    return {
        "log_evidence_gain": float(change.log_evidence_gain),
        "window_mm": {"x": [x0, x1], "y": [y0, y1]},
        "weight": float(change.weight),
        "relative_change": {
            "stiffness": float(change.change[0]),
            "shear_stiffness": float(change.change[1]),
            "mass": float(change.change[2]),
        },
    }
