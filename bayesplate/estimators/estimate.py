"""Estimate a case's constants with B, MVE or MVE-mod (section 5: two MVE stages)."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from .. import laminate
from ..likelihood.posterior import prior_in_stiffness
from ..matching.checked_order import assignment_at, checks_order, refuted_order
from ..matching.pairing import Pairing, pair_measured, resolve_pairing
from ..plate.forward import ForwardModel
from ..plate.model import PlateModel
from .assess import assess
from .assignment_rounds import most_probable, settle_assignment
from .conventions import resolve_conventions
from .fast import case_fast_model, confirmed_run, modes_to_certify, resolve_forward
from .options import EstimatorOptions
from .paired import estimate_paired
from .result import METHODS

log = logging.getLogger(__name__)

__all__ = ["EstimatorOptions", "OrderRefuted", "estimate", "estimate_on_fast", "settle_pairing"]


class OrderRefuted(Exception):
    """Pairing by order checked on a model too small to make the assignment by likelihood.

    Raised inside a run on a fast model (which holds the order's modes only) when the most
    probable assignment at the estimate is not the order; the caller redoes the run by
    likelihood on a fast model that holds the modes it needs.
    """

    def __init__(self, assignment):
        super().__init__(refuted_order(assignment))
        self.assignment = assignment


def estimate(
    case,
    method="MVE",
    model: ForwardModel | None = None,
    *,
    options=None,
    fast=None,
    rng=None,
    **settings,
):
    """Estimate the elastic constants of a case with the paper's B, MVE or MVE-mod.

    The prior deviations of ``b`` follow from those of the engineering constants by
    first-order propagation through eqs. 20-21
    (:func:`bayesplate.likelihood.posterior.prior_in_stiffness`); ``V_Y`` from the frequency
    deviations, ``d lambda = 8 pi^2 f df`` (section 3.6).

    The stages: the fast path (:func:`_estimate_on_fast`) or, on the full model, a given
    pairing (:func:`.paired.estimate_paired`), a named one (:func:`_by_named_pairing`, the
    order checked at the estimate) or the most probable assignment
    (:func:`_by_likelihood`); then the assessment.

    Parameters
    ----------
    case : bayesplate.io.Case
    method : {"B", "MVE", "MVE-mod"}
    model : PlateModel, optional
        Forward model; default ``PlateModel.from_case(case)`` (the case's mesh).
    options : EstimatorOptions, optional
        The stopping rule, conventions, prior, MVE-mod's stages, pairing, tracking and
        forward model (default ``EstimatorOptions()``).
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model already built for this case (implies the fast path); see
        :func:`estimate_on_fast` to get it back enriched.
    rng : numpy.random.Generator or int, optional
        Seed of the fast model's design (default 0: the same model every time).
    **settings
        Any field of :class:`~bayesplate.estimators.options.EstimatorOptions` by name, over
        `options`: ``tol`` (TOL of section 2.4), ``max_iter``, ``convention`` (``"paper"``,
        ``"consistent"`` or :class:`Conventions`), ``prior_mean`` and ``prior_sd`` (SI),
        ``stage1_tol``, ``stage2_factor``, ``stage2_sd`` (MVE-mod), ``pairing`` (``"auto"``,
        ``"mac"``, ``"likelihood"``, ``"index"``, ``"order"`` or a Pairing), ``tracking``
        (``"auto"``, ``"report"``, ``"follow"``, ``"off"``) and ``forward`` (``"auto"``,
        ``"fast"``, ``"full"``).

    Returns
    -------
    EstimateResult
        Assessed (:func:`.assess.assess`): its ``fit``, its ``warnings`` and a status
        ``"rejected"`` or ``"implausible"`` when the answer should not be trusted.

    Raises
    ------
    TypeError
        A keyword that is no field of :class:`~bayesplate.estimators.options.EstimatorOptions`.
    """
    options = EstimatorOptions.of(options, "estimate", **settings)
    return assess(_estimate(case, method, model, options, fast=fast, rng=rng), case)


def _estimate(case, method, model, options, *, fast=None, rng=None):
    """:func:`estimate` without its assessment (what the calls inside this module make)."""
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {METHODS}")
    model = model or PlateModel.from_case(case)
    if fast is not None or resolve_forward(options.forward, model, method) == "fast":
        return _estimate_on_fast(case, method, model, fast, rng, options)[0]
    run = _run_settings(options, model)
    mean = np.asarray(
        case.prior.mean if options.prior_mean is None else options.prior_mean, dtype=float
    )
    sd = np.asarray(case.prior.sd if options.prior_sd is None else options.prior_sd, dtype=float)
    b0 = laminate.stiffness_from_engineering(mean)
    if isinstance(options.pairing, Pairing):
        return estimate_paired(case, model, options.pairing, method, mean, sd, run)
    how = resolve_pairing(case.measured, options.pairing)
    _, V = prior_in_stiffness(mean, sd, "full")
    prior = (mean, sd, b0, V)
    if how != "likelihood":
        return _by_named_pairing(case, model, method, options, how, prior, run)
    return _by_likelihood(case, model, method, prior, run)


def _run_settings(options, model):
    """The settings of every run (:func:`.paired.estimate_paired`) from the options."""
    return {
        "conventions": resolve_conventions(options.convention),
        "tracking": options.tracking,
        "weight": model.mass,  # the MAC weight for tracking (ForwardModel interface)
        "tol": options.tol,
        "max_iter": options.max_iter,
        "stage1_tol": options.stage1_tol,
        "stage2": (options.stage2_factor, options.stage2_sd),
    }


def _by_named_pairing(case, model, method, options, how, prior, run):
    """The estimate paired by ``how`` at the prior mean; by order, the order checked.

    The order is checked at the estimate (:func:`.checked_order.assignment_at`): kept when
    the most probable assignment there keeps it, else the estimate made by likelihood (on
    the full model; a fast model raises :class:`OrderRefuted` for its caller to redo it).
    ``prior``: ``(mean, sd, b0, V)``, the engineering prior (SI) and its mean and
    covariance in ``b`` (Pa, Pa^2).
    """
    mean, sd, b0, V = prior
    pair = pair_measured(case, model, b0, how, prior=(b0, V))
    result = estimate_paired(case, model, pair, method, mean, sd, run)
    if not checks_order(case.measured, options.pairing):
        return result
    at = result.b if laminate.is_physical(result.b) else b0
    found = assignment_at(case, model, at, V, pair)
    if found.keeps_order:
        return _order_checked(result, replace(pair, assignment=found))
    if not isinstance(model, PlateModel):
        # a fast model holds the order's modes only: the caller redoes it by likelihood
        raise OrderRefuted(found)
    again = replace(options, pairing="likelihood", forward="full")
    by_likelihood = _estimate(case, method, model, again)
    refuted = refuted_order(found)
    return replace(by_likelihood, message=f"{by_likelihood.message}; {refuted}")


def _by_likelihood(case, model, method, prior, run):
    """The estimate by the most probable assignment, remade at each estimate until it stands.

    ``prior``: ``(mean, sd, b0, V)`` as for :func:`_by_named_pairing`.
    """
    mean, sd, b0, V = prior
    # by the most probable assignment (the constants integrated out over the prior's spread
    # centred where the model is linearised: a profile fit with its Occam factor, not the
    # evidence under a far prior mean, which would rather drop the peaks that disagree with
    # it), remade at each estimate until it stands. Far from the truth an assignment made at
    # the prior is unreliable, so two starts: pairing by order (kept when its estimate
    # confirms it), and the lowest peaks assigned at the prior and fitted first. The settled
    # one more probable at its own estimate wins. B settles it (its prior anchors it).
    first = most_probable(case, model, b0, V, "B", mean, sd, run)
    if method == "B":
        return _assigned(first.result, first.pair, first.rounds, first.note, first.rivals)
    if not first.result.converged:  # no estimate to start from: the method's own rounds
        own = most_probable(case, model, b0, V, method, mean, sd, run)
        return _assigned(own.result, own.pair, own.rounds, own.note, own.rivals)
    # MVE and MVE-mod from B's estimate, the assigned modes followed by MAC between iterates
    # (identified where B converged, not at a far prior): re-pairing by sorted index lets two
    # close modes swap places every iteration while MVE moves a weakly determined constant
    follow = {**run, "tracking": "follow" if run["tracking"] == "auto" else run["tracking"]}
    s = settle_assignment(case, model, b0, V, method, mean, sd, follow, first.pair, first.result.b)
    note = "" if s.settled else f"; the assignment did not settle in {s.rounds} rounds"
    note += f"; started from B's estimate (assignment settled in {first.rounds} rounds)"
    return _assigned(s.result, s.pair, first.rounds + s.rounds, note, first.rivals)


def estimate_on_fast(
    case, method="MVE", model=None, fast=None, *, options=None, rng=None, **settings
):
    """:func:`estimate` on the certified fast model, confirmed by the full model.

    Parameters
    ----------
    case : bayesplate.io.Case
    method : {"B", "MVE", "MVE-mod"}
    model : PlateModel, optional
        The full model (default the case's mesh): builds the fast model, pairs at the prior
        mean and checks the answer.
    fast : bayesplate.reduced.CertifiedModel, optional
        Built over the prior's box when not given (:func:`.fast.case_fast_model`).
    options : EstimatorOptions, optional
        As for :func:`estimate` (its ``forward`` is not used).
    rng : numpy.random.Generator or int, optional
        Seed of the build.
    **settings
        The other keywords of :func:`estimate` (not ``forward``), over `options`.

    Returns
    -------
    result : EstimateResult
        With its ``check`` (:class:`FullModelCheck`).
    fast : CertifiedModel
        The fast model, enriched where the full model corrected it: share it.
    """
    options = EstimatorOptions.of(options, "estimate_on_fast", **settings)
    result, fast = _estimate_on_fast(case, method, model, fast, rng, options)
    return assess(result, case), fast


def _estimate_on_fast(case, method, model, fast, rng, options):
    """:func:`estimate_on_fast` without its assessment."""
    model = model or PlateModel.from_case(case)
    pairing = options.pairing
    checked = checks_order(case.measured, pairing)
    if (
        not isinstance(pairing, Pairing)
        and not checked
        and resolve_pairing(case.measured, pairing) != "likelihood"
    ):
        # a fixed pairing is made as the full path makes it: on the full model at the prior
        pairing, _ = settle_pairing(case, model, pairing, prior_mean=options.prior_mean)
    n_modes = modes_to_certify(case, pairing)
    if fast is None:
        prior = {"prior_mean": options.prior_mean, "prior_sd": options.prior_sd}
        fast = case_fast_model(case, model, n_modes, rng=rng, **prior)
    elif n_modes > fast.reduced.n_modes + fast.reduced.margin:
        raise ValueError(
            f"the fast model holds {fast.reduced.n_modes + fast.reduced.margin} modes; "
            f"the pairing needs {n_modes}"
        )
    on_reduced = replace(options, pairing=pairing, forward="full")

    def run_on(reduced):
        return _estimate(case, method, reduced, on_reduced)

    try:
        return confirmed_run(run_on, model, fast)
    except OrderRefuted as refuted:
        # order checked and set aside at the estimate: by likelihood, on a fast model that
        # holds the modes the assignment may reach (a new one: this one holds the order's)
        log.info("%s", refuted)
        again = replace(options, pairing="likelihood")
        result, fast = _estimate_on_fast(case, method, model, None, rng, again)
        return replace(result, message=f"{result.message}; {refuted}"), fast


def settle_pairing(
    case,
    model,
    how="auto",
    *,
    tol=1e-3,
    convention="paper",
    prior_mean=None,
    prior_sd=None,
    modal=None,
    forward="auto",
    fast=None,
):
    """The pairing for a case, and the B run that settled it when it is by likelihood.

    The one place where the sampler, diagnose and the report turn a pairing's name into a
    :class:`bayesplate.matching.pairing.Pairing`: ``"likelihood"`` is the assignment B settles on
    (:func:`estimate` with ``pairing="likelihood"``: rounds with warm starts, on `model`),
    any other name :func:`bayesplate.matching.pairing.pair_measured` at the prior mean.

    Parameters
    ----------
    case : bayesplate.io.Case
    model : ForwardModel
    how : {"auto", "mac", "likelihood", "index", "order"}
    tol : float
        TOL of the settling B run.
    convention, prior_mean, prior_sd
        As for :func:`estimate` (SI).
    modal : ModalResult, optional
        Modes already computed at the prior mean (for :func:`pair_measured`).
    forward, fast
        The settling B run's model (as for :func:`estimate`).

    Returns
    -------
    pairing : Pairing
    settled : EstimateResult or None
        The B run (by likelihood only): its estimate is a good start or pilot.
    """
    if resolve_pairing(case.measured, how) == "likelihood":
        settled = estimate(
            case,
            "B",
            model=model,
            tol=tol,
            convention=convention,
            prior_mean=prior_mean,
            prior_sd=prior_sd,
            pairing="likelihood",
            forward=forward,
            fast=fast,
        )
        return settled.pairing, settled
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    b, V = prior_in_stiffness(mean, sd, "full")
    return pair_measured(case, model, b, how, modal=modal, prior=(b, V)), None


def _order_checked(result, pair):
    """The order's result, checked: its assignment made at the estimate kept in ``settings``.

    Peaks that assignment calls spurious in their own place stay paired (outliers of the
    fit, which the order keeps: diagnose is what examines them) and are named.
    """
    a = pair.assignment
    outliers = (a.spurious + 1).tolist()
    note = "pairing by order, checked: at the estimate the most probable assignment pairs "
    note += (
        "every peak in order"
        if not outliers
        else f"no peak with another mode (it would call peak{'s' if len(outliers) > 1 else ''} "
        f"{', '.join(map(str, outliers))} spurious: outliers of this fit, kept)"
    )
    settings = {
        **result.settings,
        "assignment": a,
        "assignment_rounds": 1,
        "outlier_peaks": outliers,
        "unobserved_modes": [],
        "spurious_peaks": [],
    }
    return replace(result, settings=settings, message=f"{result.message}; {note}", pairing=pair)


def _assigned(result, pair, rounds, note, rivals=()):
    """The result with its assignment (`pair`'s) and `rivals` in ``settings``, said too."""
    a = pair.assignment
    settings = {
        **result.settings,
        "assignment": a,
        "assignment_rounds": rounds,
        "unobserved_modes": (a.unobserved + 1).tolist(),
        "spurious_peaks": (a.spurious + 1).tolist(),
        "rivals": list(rivals),
    }
    message = f"{result.message}; assignment: {a.describe()}{note}"
    return replace(result, settings=settings, message=message, pairing=pair)
