"""Step 1 of a pass: the nominal model's global fit (:mod:`.nominal`), stored, and checked.

The check: chi-square of the standardised residuals against ``m - p_eff`` degrees of
freedom (``p_eff``: parameters the data fix), a predictive check per mode and the constants
the data leave loose (:mod:`.verdict`).
"""

from __future__ import annotations

from scipy.stats import chi2 as chi2_dist

from .joint_fit import settle
from .nominal import check_fast, nominal_polisher, nominal_stage
from .state import NominalCheck, NominalStage
from .store import Stages, digest, fit_digest, plate_digest
from .verdict import predictive_p_values, unidentified

__all__ = ["check_nominal", "fit_nominal_stage", "nominal_again"]


def fit_nominal_stage(run, data, rng):
    """The nominal fit of a pass's `data` and its checks (:class:`.state.NominalStage`).

    Its stages' context (:mod:`.store`) covers the data, the prior, the options, the plate,
    the candidates and the fast model; the stages after it add the nominal fit.
    """
    stages = _stages(run, data)
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
    return _checked(run, data, rough, nominal, stages)


def nominal_again(run, data, first):
    """The nominal fit of `data` settled from the optima of an earlier one, `first`.

    For data that differ from `first`'s only a little (the corrected rule's deviations with
    the mesh's error estimated again at the first fit: :func:`.passes.one_pass`): the
    first fit's optima (its answer and its alternatives) are each settled on the working
    mesh (:func:`.joint_fit.settle`), without the global stage's reduced model and random
    starts; the global stage's reduced problem is `first`'s, on the new data. Stored as a
    stage of its own (:mod:`.store`); draws no random numbers.

    Parameters
    ----------
    run : Run
    data : Deviations
    first : NominalStage

    Returns
    -------
    NominalStage
    """
    problem, fitted = data.problem, first.check.fit
    starts = [problem.pack(fitted.b)] + [problem.pack(b) for b, _ in fitted.alternatives]
    stages = _stages(run, data)
    key = stages.key("nominal again", fit_digest(fitted))
    nominal = stages.run(
        "nominal fit again", key, lambda: settle(problem, nominal_polisher(problem), starts)
    )
    rough = None if first.rough is None else problem.on(first.rough.model, first.rough.scale)
    return _checked(run, data, rough, nominal, stages)


def _stages(run, data):
    """The stages of a pass's `data`: their context (:mod:`.store`)."""
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
    return Stages(run.store, context, run.say)


def _checked(run, data, rough, nominal, stages):
    """The checked :class:`.state.NominalStage` of `nominal`, the stages after it."""
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
