"""Estimate a case's constants with B, MVE or MVE-mod (section 5: two MVE stages)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np

from .. import laminate
from ..checked_order import assignment_at, checks_order, refuted_order
from ..forward import ForwardModel
from ..model import PlateModel
from ..pairing import Pairing, pair_measured, resolve_pairing
from ..posterior import prior_in_stiffness
from .assess import assess
from .conventions import resolve_conventions
from .fast import case_fast_model, confirmed_run, modes_to_certify, resolve_forward
from .iteration import DEFAULT_MAX_ITER
from .paired import estimate_paired
from .result import METHODS
from .starts import log_evidence, rivals_of, start_points

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
        again until the assignment stands (at most :data:`MAX_ASSIGNMENTS` rounds); unobserved
        computed modes and spurious peaks are in ``settings`` and the message. Measured modes
        left unpaired are left out of the fit.
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
        case, method, model, tol, max_iter, convention, prior_mean, prior_sd, stage1_tol,
        stage2_factor, stage2_sd, pairing, tracking, forward=forward, fast=fast, rng=rng,
    )  # fmt: skip
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
        options = {"tol": tol, "max_iter": max_iter, "convention": convention,
                   "prior_mean": prior_mean, "prior_sd": prior_sd, "stage1_tol": stage1_tol,
                   "stage2_factor": stage2_factor, "stage2_sd": stage2_sd, "pairing": pairing,
                   "tracking": tracking}  # fmt: skip
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
            case, method, model=model, tol=tol, max_iter=max_iter, convention=convention,
            prior_mean=prior_mean, prior_sd=prior_sd, stage1_tol=stage1_tol,
            stage2_factor=stage2_factor, stage2_sd=stage2_sd, pairing="likelihood",
            tracking=tracking, forward="full",
        )  # fmt: skip
        refuted = refuted_order(found)
        return replace(by_likelihood, message=f"{by_likelihood.message}; {refuted}")
    # by the most probable assignment (the constants integrated out over the prior's spread
    # centred where the model is linearised: a profile fit with its Occam factor, not the
    # evidence under a far prior mean, which would rather drop the peaks that disagree with
    # it), remade at each estimate until it stands. Far from the truth an assignment made at
    # the prior is unreliable, so two starts: pairing by order (kept when its estimate
    # confirms it), and the lowest peaks assigned at the prior and fitted first. The settled
    # one more probable at its own estimate wins. B settles it (its prior anchors it).
    first = _most_probable(case, model, b0, V, "B", mean, sd, options)
    if method == "B":
        return _assigned(first.result, first.pair, first.rounds, first.note, first.rivals)
    if not first.result.converged:  # no estimate to start from: the method's own rounds
        own = _most_probable(case, model, b0, V, method, mean, sd, options)
        return _assigned(own.result, own.pair, own.rounds, own.note, own.rivals)
    # MVE and MVE-mod from B's estimate, the assigned modes followed by MAC between iterates
    # (identified where B converged, not at a far prior): re-pairing by sorted index lets two
    # close modes swap places every iteration while MVE moves a weakly determined constant
    follow = {
        **options,
        "tracking": "follow" if options["tracking"] == "auto" else options["tracking"],
    }
    s = _settle(case, model, b0, V, method, mean, sd, follow, first.pair, first.result.b)
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
    if (not isinstance(pairing, Pairing) and not checked
            and resolve_pairing(case.measured, pairing) != "likelihood"):  # fmt: skip
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
        result, fast = _estimate_on_fast(case, method, model, None, rng=rng,
                                         **{**options, "pairing": "likelihood"})  # fmt: skip
        return replace(result, message=f"{result.message}; {refuted}"), fast


def settle_pairing(
    case, model, how="auto", *, tol=1e-3, convention="paper", prior_mean=None, prior_sd=None,
    modal=None, forward="auto", fast=None,
):  # fmt: skip
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
            case, "B", model=model, tol=tol, convention=convention, prior_mean=prior_mean,
            prior_sd=prior_sd, pairing="likelihood", forward=forward, fast=fast,
        )  # fmt: skip
        return settled.pairing, settled
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    b, V = prior_in_stiffness(mean, sd, "full")
    return pair_measured(case, model, b, how, modal=modal, prior=(b, V)), None


def _most_probable(case, model, b0, V, method, mean, sd, options):
    """Starts by order, lowest peaks first and over the constants, each settled; the best.

    The most probable by its evidence (:func:`.starts.log_evidence`), the other answers its
    rivals (:func:`.starts.rivals_of`). A start over the constants (:func:`.starts.start_points`)
    is settled only when its assignment at its own point is one not tried yet.
    """
    settle = (case, model, b0, V, method, mean, sd, options)
    tried = [_settle(*settle, pair_measured(case, model, b0, "order"), None)]
    a = tried[0]
    if not (a.settled and a.pair.assignment.in_order and a.result.converged):
        tried.append(_settle(*settle, *_lowest_first(*settle)))
    tried += _other_starts(settle, tried)
    scored = [(t, log_evidence(case, t.result, t.pair.assignment, (b0, V))) for t in tried]
    best, evidence = max(scored, key=lambda x: (x[0].result.converged, x[1], x[0].settled))
    rivals = rivals_of((best.result, evidence), [(t.result, e) for t, e in scored])
    note = "" if best.settled else (
        f"; the assignment did not settle in {best.rounds} rounds: kept the most probable"
    )  # fmt: skip
    if len(tried) > 1:
        note += (f"; {len(tried)} starts settled, the most probable kept"
                 f" ({len(rivals)} other answer{'s' if len(rivals) != 1 else ''})")  # fmt: skip
    rounds = sum(t.rounds for t in tried)
    return replace(best, rounds=rounds, note=note, rivals=rivals)


def _other_starts(settle, tried):
    """Settled answers from the starts over the constants that might beat those `tried`.

    Each start is screened by the assignment made at it, its probability integrated over
    the prior (linearised there: one solve, on the mesh half as fine each way: a screen
    compares assignments, which a 1 % shift of every frequency leaves in their order);
    those within :data:`SCREEN_NATS` of the best tried answer's, screened the same way, and
    new, are settled on the full model (at most :data:`MAX_OTHER_STARTS`, the most probable
    first).
    """
    case, model, b0, V, method, mean, sd, options = settle
    m = case.measured.size
    coarse = _screening_model(model)
    done = [t for t in tried if t.result.converged and laminate.is_physical(t.result.b)]
    level = max(
        (_screen(case, coarse, t.result.b, V, b0, t.pair) for t in done),
        key=lambda p: p.assignment.log_probability,
        default=None,
    )
    screened = [t.pair for t in tried]
    found = []
    for e in start_points(mean):
        pair = _screen(case, coarse, laminate.stiffness_from_engineering(e), V, b0)
        if any(_same(pair, other, m) for other in screened):
            continue
        screened.append(pair)
        if level is None or pair.assignment.log_probability > (
            level.assignment.log_probability - SCREEN_NATS
        ):
            found.append(
                (pair.assignment.log_probability, laminate.stiffness_from_engineering(e), pair)
            )
    found.sort(key=lambda x: -x[0])
    return [_settle(*settle, pair, b) for _, b, pair in found[:MAX_OTHER_STARTS]]


def _screening_model(model):
    """`model` on the mesh half as fine each way (at least 8 x 4), where it has a mesh."""
    if not isinstance(model, PlateModel):
        return model
    nx, ny = model.mesh.nx, model.mesh.ny
    half = (max(nx // 2, min(nx, 8)), max(ny // 2, min(ny, 4)))
    return model if half == (nx, ny) else model.on_mesh(half)


def _screen(case, model, b, V, b0, start=None):
    """The most probable assignment at `b`, the constants integrated over the prior at b0."""
    return pair_measured(case, model, b, "likelihood", prior=(b0, V), start=start)


#: A start over the constants is settled when its screened assignment is at most this many
#: nats less probable than the best tried answer's.
SCREEN_NATS = 5.0
#: Starts over the constants settled at most.
MAX_OTHER_STARTS = 3


@dataclass
class _Settled:
    """Where the rounds of assignment and estimate from one start ended."""

    result: object
    pair: Pairing  # with its assignment, made at result.b
    log_probability: float
    rounds: int
    settled: bool
    note: str = ""
    rivals: list = field(default_factory=list)  # (constants, nats behind), other answers


def _settle(case, model, b0, V, method, mean, sd, options, pair, start):
    """Estimate with `pair` (from `start`), reassign at the estimate, until it stands."""
    tried = []
    for _ in range(MAX_ASSIGNMENTS):
        result = estimate_paired(case, model, pair, method, mean, sd, options, start)
        at = result.b if laminate.is_physical(result.b) else b0
        start = at if result.converged else start  # the next round goes on from here
        again = pair_measured(case, model, at, "likelihood", prior=(at, V), start=pair)
        tried.append(_Settled(result, again, again.assignment.log_probability, 0, False))
        if _same(again, pair, case.measured.size):
            return replace(tried[-1], rounds=len(tried), settled=True)
        if any(_same(again, t.pair, case.measured.size) for t in tried[:-1]):
            break
        pair = again
    pool = [t for t in tried if t.result.converged] or tried
    return replace(max(pool, key=lambda t: t.log_probability), rounds=len(tried))


#: Rounds of assignment and estimate before giving up on a settled assignment.
MAX_ASSIGNMENTS = 5


#: The first round fits the peaks up to this quantile of the measured band (at least
#: :data:`FIRST_ROUND_MIN` peaks): low modes keep their order far from the truth, high ones
#: cross (and in-plane modes move among the bending ones) as the constants change.
FIRST_ROUND_QUANTILE = 0.5
FIRST_ROUND_MIN = 6


def _lowest_first(case, model, b0, V, method, mean, sd, options):
    """The pairing to start from, and where: every peak assigned at the lowest ones' estimate.

    At a prior far from the truth the linearised marginal prefers wrong assignments of the
    upper peaks; the lowest are assigned at the prior, fitted, and all are assigned at that
    estimate, where the next run starts (None: at the prior mean).
    """
    m = case.measured.size
    n_low = max(FIRST_ROUND_MIN, int(FIRST_ROUND_QUANTILE * m))
    if n_low >= m:
        return pair_measured(case, model, b0, "likelihood", prior=(b0, V)), None
    lower = case.with_measured(case.measured.select(np.arange(n_low)))
    first = pair_measured(lower, model, b0, "likelihood", prior=(b0, V))
    result = estimate_paired(lower, model, first, method, mean, sd, options)
    at = result.b if laminate.is_physical(result.b) else b0
    start = at if result.converged else None
    return pair_measured(case, model, at, "likelihood", prior=(at, V)), start


def _same(a, b, m):
    """Whether two pairings pair the same of `m` measured frequencies with the same modes."""
    return np.array_equal(a.kept(m), b.kept(m)) and np.array_equal(a.modes, b.modes)


def _order_checked(result, pair):
    """The order's result, checked: its assignment made at the estimate kept in ``settings``.

    Peaks that assignment calls spurious in their own place stay paired (outliers of the
    fit, which the order keeps: diagnose is what examines them) and are named.
    """
    a = pair.assignment
    outliers = (a.spurious + 1).tolist()
    note = "pairing by order, checked: at the estimate the most probable assignment pairs "
    note += ("every peak in order" if not outliers else
             f"no peak with another mode (it would call peak{'s' if len(outliers) > 1 else ''} "
             f"{', '.join(map(str, outliers))} spurious: outliers of this fit, kept)")  # fmt: skip
    settings = {**result.settings, "assignment": a, "assignment_rounds": 1, "outlier_peaks":
                outliers, "unobserved_modes": [], "spurious_peaks": []}  # fmt: skip
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
