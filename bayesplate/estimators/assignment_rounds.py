"""Rounds of assignment and estimate, from several starts: the most probable settled answer.

:func:`bayesplate.estimators.estimate` pairs by likelihood through these rounds: estimate
with a pairing, make the most probable assignment at the estimate, estimate again, until the
assignment stands (:func:`settle_assignment`); from the order, from the lowest peaks fitted
first and from starts over the constants, the most probable by its evidence kept
(:func:`most_probable`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import laminate
from ..matching.pairing import Pairing, pair_measured
from ..plate.model import PlateModel
from .paired import estimate_paired
from .starts import log_evidence, rivals_of, start_points

__all__ = [
    "FIRST_ROUND_MIN",
    "FIRST_ROUND_QUANTILE",
    "MAX_ASSIGNMENTS",
    "MAX_OTHER_STARTS",
    "SCREEN_NATS",
    "most_probable",
    "settle_assignment",
]


def most_probable(case, model, b0, V, method, mean, sd, options):
    """Starts by order, lowest peaks first and over the constants, each settled; the best.

    The most probable by its evidence (:func:`.starts.log_evidence`), the other answers its
    rivals (:func:`.starts.rivals_of`). A start over the constants (:func:`.starts.start_points`)
    is settled only when its assignment at its own point is one not tried yet.
    """
    settle = (case, model, b0, V, method, mean, sd, options)
    tried = [settle_assignment(*settle, pair_measured(case, model, b0, "order"), None)]
    a = tried[0]
    if not (a.settled and a.pair.assignment.in_order and a.result.converged):
        tried.append(settle_assignment(*settle, *_lowest_first(*settle)))
    tried += _other_starts(settle, tried)
    scored = [(t, log_evidence(case, t.result, t.pair.assignment, (b0, V))) for t in tried]
    best, evidence = max(scored, key=lambda x: (x[0].result.converged, x[1], x[0].settled))
    rivals = rivals_of((best.result, evidence), [(t.result, e) for t, e in scored])
    note = (
        ""
        if best.settled
        else (f"; the assignment did not settle in {best.rounds} rounds: kept the most probable")
    )
    if len(tried) > 1:
        note += (
            f"; {len(tried)} starts settled, the most probable kept"
            f" ({len(rivals)} other answer{'s' if len(rivals) != 1 else ''})"
        )
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
    return [settle_assignment(*settle, pair, b) for _, b, pair in found[:MAX_OTHER_STARTS]]


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


def settle_assignment(case, model, b0, V, method, mean, sd, options, pair, start):
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
