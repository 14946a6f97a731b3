"""Estimate a case's constants with B, MVE or MVE-mod (section 5: two MVE stages)."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from .. import laminate
from ..checked_order import assignment_at, checks_order, refuted_order
from ..forward import ForwardModel
from ..model import PlateModel
from ..pairing import Pairing, pair_measured, resolve_pairing
from ..posterior import prior_in_stiffness
from .assess import assess
from .assignment_rounds import most_probable, settle_assignment
from .conventions import resolve_conventions
from .fast import case_fast_model, confirmed_run, modes_to_certify, resolve_forward
from .iteration import DEFAULT_MAX_ITER
from .paired import estimate_paired
from .result import METHODS

log = logging.getLogger(__name__)

__all__ = ["OrderRefuted", "estimate", "estimate_on_fast", "settle_pairing"]


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
    *,
    forward="auto",
    fast=None,
    rng=None,
):
    """Estimate the elastic constants of a case with the paper's B, MVE or MVE-mod.

    The prior deviations of ``b`` follow from those of the engineering constants by
    first-order propagation through eqs. 20-21 (:func:`bayesplate.posterior.prior_in_stiffness`);
    ``V_Y`` from the frequency deviations, ``d lambda = 8 pi^2 f df`` (section 3.6).

    Parameters
    ----------
    case : bayesplate.io.Case
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
    pairing : {"auto", "mac", "likelihood", "index", "order"} or Pairing
        Measured-to-computed mode pairing (:func:`bayesplate.pairing.pair_measured`, at the
        prior mean): "auto" pairs by shape and frequency ("mac") when the case has measured
        shapes, else by the case's mode indices if any, else by order (the paper's).
        "likelihood": the most probable
        assignment of frequencies (:mod:`bayesplate.assignment`), made at the prior with the
        prior's spread and remade at each estimate with the estimate's, the estimator run
        again until the assignment stands (at most
        :data:`.assignment_rounds.MAX_ASSIGNMENTS` rounds); unobserved computed modes and
        spurious peaks are in ``settings`` and the message. Measured modes left unpaired are
        left out of the fit.
    tracking : {"auto", "report", "follow", "off"}
        MAC tracking of paired modes between iterates (see :func:`run`); "auto" follows
        modes paired by shape and keeps order or index pairings as they are.
    forward : {"auto", "fast", "full"}
        Iterate on the certified fast model, the answer confirmed by the full one
        (:mod:`bayesplate.estimators.fast`; the result's ``check``), or on the full model
        throughout; ``"auto"``: fast on meshes of more than ``FAST_MIN_DOFS`` unknowns,
        except for B (a handful of solves, fewer than the fast model's build).
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model already built for this case (implies the fast path); see
        :func:`estimate_on_fast` to get it back enriched.
    rng : numpy.random.Generator or int, optional
        Seed of the fast model's design (default 0: the same model every time).

    Returns
    -------
    EstimateResult
        Assessed (:func:`.assess.assess`): its ``fit``, its ``warnings`` and a status
        ``"rejected"`` or ``"implausible"`` when the answer should not be trusted.
    """
    result = _estimate(
        case,
        method,
        model,
        tol,
        max_iter,
        convention,
        prior_mean,
        prior_sd,
        stage1_tol,
        stage2_factor,
        stage2_sd,
        pairing,
        tracking,
        forward=forward,
        fast=fast,
        rng=rng,
    )
    return assess(result, case)


def _estimate(
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
    *,
    forward="auto",
    fast=None,
    rng=None,
):
    """:func:`estimate` without its assessment (what the calls inside this module make)."""
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {METHODS}")
    model = model or PlateModel.from_case(case)
    if fast is not None or resolve_forward(forward, model, method) == "fast":
        options = {
            "tol": tol,
            "max_iter": max_iter,
            "convention": convention,
            "prior_mean": prior_mean,
            "prior_sd": prior_sd,
            "stage1_tol": stage1_tol,
            "stage2_factor": stage2_factor,
            "stage2_sd": stage2_sd,
            "pairing": pairing,
            "tracking": tracking,
        }
        return _estimate_on_fast(case, method, model, fast, rng=rng, **options)[0]
    conventions = resolve_conventions(convention)
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    b0 = laminate.stiffness_from_engineering(mean)
    options = {
        "conventions": conventions,
        "tracking": tracking,
        "weight": model.mass,  # the MAC weight for tracking (ForwardModel interface)
        "tol": tol,
        "max_iter": max_iter,
        "stage1_tol": stage1_tol,
        "stage2": (stage2_factor, stage2_sd),
    }
    if isinstance(pairing, Pairing):
        return estimate_paired(case, model, pairing, method, mean, sd, options)
    how = resolve_pairing(case.measured, pairing)
    _, V = prior_in_stiffness(mean, sd, "full")
    if how != "likelihood":
        pair = pair_measured(case, model, b0, how, prior=(b0, V))
        result = estimate_paired(case, model, pair, method, mean, sd, options)
        if not checks_order(case.measured, pairing):
            return result
        at = result.b if laminate.is_physical(result.b) else b0
        found = assignment_at(case, model, at, V, pair)
        if found.keeps_order:
            return _order_checked(result, replace(pair, assignment=found))
        if not isinstance(model, PlateModel):
            # a fast model holds the order's modes only: the caller redoes it by likelihood
            raise OrderRefuted(found)
        by_likelihood = _estimate(
            case,
            method,
            model=model,
            tol=tol,
            max_iter=max_iter,
            convention=convention,
            prior_mean=prior_mean,
            prior_sd=prior_sd,
            stage1_tol=stage1_tol,
            stage2_factor=stage2_factor,
            stage2_sd=stage2_sd,
            pairing="likelihood",
            tracking=tracking,
            forward="full",
        )
        refuted = refuted_order(found)
        return replace(by_likelihood, message=f"{by_likelihood.message}; {refuted}")
    # by the most probable assignment (the constants integrated out over the prior's spread
    # centred where the model is linearised: a profile fit with its Occam factor, not the
    # evidence under a far prior mean, which would rather drop the peaks that disagree with
    # it), remade at each estimate until it stands. Far from the truth an assignment made at
    # the prior is unreliable, so two starts: pairing by order (kept when its estimate
    # confirms it), and the lowest peaks assigned at the prior and fitted first. The settled
    # one more probable at its own estimate wins. B settles it (its prior anchors it).
    first = most_probable(case, model, b0, V, "B", mean, sd, options)
    if method == "B":
        return _assigned(first.result, first.pair, first.rounds, first.note, first.rivals)
    if not first.result.converged:  # no estimate to start from: the method's own rounds
        own = most_probable(case, model, b0, V, method, mean, sd, options)
        return _assigned(own.result, own.pair, own.rounds, own.note, own.rivals)
    # MVE and MVE-mod from B's estimate, the assigned modes followed by MAC between iterates
    # (identified where B converged, not at a far prior): re-pairing by sorted index lets two
    # close modes swap places every iteration while MVE moves a weakly determined constant
    follow = {
        **options,
        "tracking": "follow" if options["tracking"] == "auto" else options["tracking"],
    }
    s = settle_assignment(case, model, b0, V, method, mean, sd, follow, first.pair, first.result.b)
    note = "" if s.settled else f"; the assignment did not settle in {s.rounds} rounds"
    note += f"; started from B's estimate (assignment settled in {first.rounds} rounds)"
    return _assigned(s.result, s.pair, first.rounds + s.rounds, note, first.rivals)


def estimate_on_fast(case, method="MVE", model=None, fast=None, *, rng=None, **options):
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
    rng : numpy.random.Generator or int, optional
        Seed of the build.
    **options
        The other keywords of :func:`estimate` (not ``forward``).

    Returns
    -------
    result : EstimateResult
        With its ``check`` (:class:`FullModelCheck`).
    fast : CertifiedModel
        The fast model, enriched where the full model corrected it: share it.
    """
    result, fast = _estimate_on_fast(case, method, model, fast, rng=rng, **options)
    return assess(result, case), fast


def _estimate_on_fast(case, method="MVE", model=None, fast=None, *, rng=None, **options):
    """:func:`estimate_on_fast` without its assessment."""
    model = model or PlateModel.from_case(case)
    pairing = options.pop("pairing", "auto")
    checked = checks_order(case.measured, pairing)
    if (
        not isinstance(pairing, Pairing)
        and not checked
        and resolve_pairing(case.measured, pairing) != "likelihood"
    ):
        # a fixed pairing is made as the full path makes it: on the full model at the prior
        pairing, _ = settle_pairing(case, model, pairing, prior_mean=options.get("prior_mean"))
    n_modes = modes_to_certify(case, pairing)
    if fast is None:
        prior = {k: options.get(k) for k in ("prior_mean", "prior_sd")}
        fast = case_fast_model(case, model, n_modes, rng=rng, **prior)
    elif n_modes > fast.reduced.n_modes + fast.reduced.margin:
        raise ValueError(
            f"the fast model holds {fast.reduced.n_modes + fast.reduced.margin} modes; "
            f"the pairing needs {n_modes}"
        )

    def run_on(reduced):
        return _estimate(case, method, model=reduced, pairing=pairing, forward="full", **options)

    try:
        return confirmed_run(run_on, model, fast)
    except OrderRefuted as refuted:
        # order checked and set aside at the estimate: by likelihood, on a fast model that
        # holds the modes the assignment may reach (a new one: this one holds the order's)
        log.info("%s", refuted)
        result, fast = _estimate_on_fast(
            case, method, model, None, rng=rng, **{**options, "pairing": "likelihood"}
        )
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
    :class:`bayesplate.pairing.Pairing`: ``"likelihood"`` is the assignment B settles on
    (:func:`estimate` with ``pairing="likelihood"``: rounds with warm starts, on `model`),
    any other name :func:`bayesplate.pairing.pair_measured` at the prior mean.

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
