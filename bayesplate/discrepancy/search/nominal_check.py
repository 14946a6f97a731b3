"""Step 1 of a pass: the nominal model's global fit (:mod:`.nominal`), stored, and checked.

The check: chi-square of the standardised residuals against ``m - p_eff`` degrees of
freedom (``p_eff``: parameters the data fix), a predictive check per mode and the constants
the data leave loose (:mod:`.verdict`).
"""

from __future__ import annotations

from scipy.stats import chi2 as chi2_dist

from .nominal import check_fast, nominal_stage
from .state import NominalCheck, NominalStage
from .store import Stages, digest, fit_digest, plate_digest
from .verdict import predictive_p_values, unidentified

__all__ = ["check_nominal", "fit_nominal_stage"]


def fit_nominal_stage(run, data, rng):
    """The nominal fit of a pass's `data` and its checks (:class:`.state.NominalStage`).

    Its stages' context (:mod:`.store`) covers the data, the prior, the options, the plate,
    the candidates and the fast model; the stages after it add the nominal fit.
    """
    mu_b, V_b = run.prior
    context = digest(
        data.Y,
        data.sigma,
        data.measured.frequency_Hz,
        data.modes,
        mu_b,
        V_b,
        run.options.store_key(),
        plate_digest(run.model),
        run.physics,
        run.fast,
    )
    stages = Stages(run.store, context, run.say)
    rough, nominal = nominal_stage(
        data.problem,
        run.prior,
        run.coarse,
        data.correction,
        rng,
        run.options.n_starts,
        run.options.workers,
        run.fast,
        stages,
    )
    stages = stages.then("nominal", fit_digest(nominal))
    notes = []
    if run.fast is not None:
        check_fast(run.fast, nominal, data.modes, notes)
    check = check_nominal(run, data, nominal)
    run.say(
        f"nominal fit: chi2 = {nominal.chi2:.1f} on {check.dof:.1f} dof, p = {check.p_value:.3g}"
    )
    return NominalStage(check, rough, stages, tuple(notes))


def check_nominal(run, data, nominal):
    """The chi-square test, predictive p-values and loose constants of a nominal fit."""
    dof = max(data.m - nominal.effective_parameters, 1.0)
    p_value = float(chi2_dist.sf(nominal.chi2, dof))
    mode_p = predictive_p_values(nominal, data.problem)
    loose = unidentified(
        nominal, run.prior[1], run.options.unidentified_ratio, run.options.basin_margin
    )
    return NominalCheck(nominal, dof, p_value, mode_p, loose)
