"""Rough optima settled on reduced models of the working mesh, each answer checked by the full one.

A rough optimum ``z`` (found on a cheap model) is settled in rounds. Each round builds the
fit's reduced model of the working mesh with a snapshot at the current point (``polish(z,
basis)``: the finite-element plate solved there, its modes added to the basis of the rounds
before, :func:`..physics.reduced_model.candidate_pencil`). Such a pencil is exact at its
snapshot: its eigenvalues are the finite-element ones and so are their first derivatives
(Rayleigh quotients of vectors in the basis; :data:`..physics.reduced_model.BASIS_TOL`). At
the new point the round therefore knows the full model's residuals ``r`` and Jacobian ``J``
(of the whitened residuals, prior terms included), and with them the Newton decrement

    delta = r^T J (J^T J)^-1 J^T r,

the decrease of ``chi2 + chi2_prior`` that a Gauss-Newton step on the full model would still
give. Where ``delta <= DECREMENT_TOL`` the point is the full model's optimum to that precision
and is the answer; otherwise the pencil (snapshots at every point so far, so that its second
derivatives improve as the points close in) is fitted tightly from there and the next round
starts at its optimum. Each round costs one finite-element solve and one projection, where a
least-squares fit on the finite-element model costs one solve (and, for a candidate, two
assembled plates per parameter) per evaluation, tens of them.

The answer is reported with its check (:class:`FitCheck`): the objective the reduced model
gave there, the finite-element objective, their largest eigenvalue difference and the
decrement. An answer whose decrement is still above the tolerance after
:data:`MAX_ROUNDS` is logged as an error and flagged (``FitCheck.settled`` False), not
passed off.

Only optima that can still win are settled: the first round of every rough optimum is its
*polish* (one build at it and one fit of that pencil, whose optimum's objective is its
promise); of the polished optima, most promising first, one whose promise exceeds the best
settled objective by more than :data:`FINISH_MARGIN` plus the largest promise error seen so
far (``|promise - settled|``) is kept as an alternative and not settled.

Mirror images: a located effect whose images fit equally (the plate's symmetry, exact on its
symmetric mesh: :meth:`~..physics.base.Physics.mirror_images`) is settled at one canonical
image, the one with the smallest parameters (in order: a mass's ``x`` then ``y``), so that the
answer does not depend on which image a path reached.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from .local_fits import DISTINCT, problem_name

__all__ = [
    "DECREMENT_TOL",
    "FINISH_MARGIN",
    "FitCheck",
    "MAX_ROUNDS",
    "STEP_TOL",
    "Settled",
    "canonical",
    "polish_and_finish",
]

log = logging.getLogger("bayesplate.discrepancy.search.joint_fit")  # the fits' records, as before

#: See the module's docstring. On the measured Frederiksen plate the nominal polish is
#: within 0.002 of the finished objective and the second basin 2.55 above the best; a
#: cutout's polish was off by up to 2.7 (plate 1), which the error term covers.
FINISH_MARGIN = 2.0
#: Newton decrement (``chi2 + chi2_prior``) under which a point is the full model's optimum
#: (times the objective where that is above one: :func:`_tolerance`): the objective is then
#: within about that of its optimum (the evidence within half of it, in nats: far below what
#: a verdict turns on) and a whitened step of at most its square root (a hundredth of a
#: prior deviation) is left. The answer does not depend on the round-off of the path: the
#: rounds from two nearby starts stay together.
DECREMENT_TOL = 1e-4
#: Rounds at most, the polish's included.
MAX_ROUNDS = 6
#: Whitened step under which the optimum of the pencil exact at a point is that point.
STEP_TOL = 1e-4
#: Snapshots a pencil keeps (the newest): enough for its second derivatives to improve as
#: the points close in, few enough that a build stays cheap.
SNAPSHOTS = 3
#: Trust region of the first round (whitened, largest component: one prior deviation).
RADIUS = 1.0
#: Share of the predicted decrease a proposal must achieve on the full model to be taken.
ACCEPT = 0.1
#: ``ftol``, ``xtol`` and ``gtol`` of the fits on a pencil (cheap: converged tightly).
PENCIL_TOL = 1e-10
#: Evaluation cap of a fit on a pencil: a smooth one converges in 10 to 50; where the
#: objective has kinks (a hole's or a patch's edge crossing an element's) more buy nothing,
#: the next round's pencil is better.
PENCIL_NFEV = 60
#: Whitened distance to a bound under which an unknown is at it.
AT_BOUND = 1e-6


@dataclass(frozen=True)
class FitCheck:
    """The full (finite-element) model at the answer a reduced model gave.

    Attributes
    ----------
    fast_objective, full_objective : float
        ``chi2 + chi2_prior`` there by the reduced model that gave the answer and by the
        finite-element model.
    max_rel_error : float
        Largest ``|lambda_fast / lambda_full - 1|`` of the paired eigenvalues there.
    decrement : float
        Newton decrement of the finite-element objective there (what a further step would
        gain, in ``chi2 + chi2_prior``).
    rounds : int
        Rounds (finite-element checks), the polish's included.
    full_solves : int
        Finite-element solves of the polish and the rounds.
    settled : bool
        Whether the answer is the full model's optimum: its decrement under
        :data:`DECREMENT_TOL`, or the pencil exact there has its optimum there.
    """

    fast_objective: float
    full_objective: float
    max_rel_error: float
    decrement: float
    rounds: int
    full_solves: int
    settled: bool


@dataclass(frozen=True)
class Settled:
    """One optimum settled on reduced models: its result, the pencil exact there, its check.

    Attributes
    ----------
    result : scipy.optimize.OptimizeResult
        ``x`` (whitened unknowns, shape (6 + k,)) and ``cost`` (half the finite-element
        objective).
    problem : JointProblem
        On the pencil built at ``result.x`` (exact there).
    check : FitCheck
    """

    result: OptimizeResult
    problem: object
    check: FitCheck

    @property
    def snapshot(self):
        """The finite-element solution at the answer (a ``ModalResult``)."""
        return self.problem.pencil.snapshot


def polish_and_finish(problem, polish, starts, rounds=None, prune=True):
    """The rough optima ``starts`` polished and, where they can still win, settled.

    Parameters
    ----------
    problem : JointProblem
        On the working mesh (its unknowns, bounds and physics).
    polish : callable
        ``polish(z, earlier=()) -> JointProblem``: ``problem`` on a pencil of the working
        mesh with a finite-element snapshot at ``z`` and the ``earlier`` snapshots kept.
    starts : sequence of numpy.ndarray, each shape (6 + k,)
        Rough optima (whitened unknowns).
    rounds : int, optional
        Rounds at most per optimum (default :data:`MAX_ROUNDS`). Fewer give provisional
        answers: their ``check.settled`` is False unless they settled within them.
    prune : bool
        Leave out the optima whose promise cannot win (False: settle every distinct one).

    Returns
    -------
    settled : list of Settled
        Best (lowest finite-element objective) first; at least one.
    others : list of (numpy.ndarray, float)
        The constants ``b`` (Pa) and objective of every other optimum, settled or only
        polished (its finite-element objective where it was left), lowest first.
    """
    first = [_first(problem, polish, z) for z in starts]
    if all(p is None for p in first):  # no solvable plate: the best one's error
        _first(problem, polish, starts[0], strict=True)
    # most promising first: the objective at the optimum of the pencil built at each
    first = sorted((p for p in first if p is not None), key=lambda p: p.promise)
    settled, far, error = [], [], 0.0
    for state in first:
        if (
            prune
            and settled
            and state.promise > settled[0].check.full_objective + FINISH_MARGIN + error
        ):
            far.append(state)
            continue
        if any(_same(problem, state.promise_z, s.result.x) for s in settled):
            continue  # its polish leads to an optimum settled already (or to its image)
        known = [s.result.x for s in settled]
        done = _settled(problem, polish, state, rounds or MAX_ROUNDS, known=known)
        if done is not None:
            error = max(error, abs(state.promise - done.check.full_objective))
            settled = sorted([*settled, done], key=lambda s: s.check.full_objective)
    if not settled:  # none could be settled: the best one's error
        _settled(problem, polish, first[0], rounds or MAX_ROUNDS, strict=True)
    others = [(s.problem.unpack(s.result.x)[0], s.check.full_objective) for s in settled[1:]]
    others += [(problem.unpack(p.z)[0], p.objective) for p in far]
    return settled, sorted(others, key=lambda pair: pair[1])


@dataclass(frozen=True)
class _Round:
    """Where the rounds are: a point, the pencil exact there, what the full model says."""

    problem: object  # the pencil problem, exact at z
    own: np.ndarray  # the snapshot at z (mode shapes): every later pencil keeps it
    z: np.ndarray
    fast: np.ndarray  # residuals at z by the pencil that proposed z (z's own at the start)
    full: np.ndarray  # residuals at z by the full model
    decrement: float
    radius: float  # of the trust region around z (whitened, largest component)
    rounds: int
    solves: int
    promise: float = np.inf  # the objective at the optimum of the first pencil (its polish)
    promise_z: np.ndarray = None  # ... and that optimum

    @property
    def objective(self):
        return float(self.full @ self.full)


def _first(problem, polish, z, strict=False):
    """The first round: the pencil built at (the canonical image of) the rough optimum ``z``.

    None (unless ``strict``) when the plate at ``z`` cannot be solved (a far rough optimum
    of an inaccurate reduced model: its modified plate is not positive definite).
    """
    try:
        z = canonical(problem, z)
        state = _built(problem, polish(z), z, None, RADIUS, 0, 0)
        polished = _tight(state.problem, z)
        return replace(state, promise=2.0 * polished.cost, promise_z=polished.x)
    except (ValueError, np.linalg.LinAlgError) as error:
        if strict:
            raise
        log.warning(
            "%s: rough optimum %s not polished (%s)", problem_name(problem), np.round(z, 2), error
        )
        return None


def _built(problem, pencil_problem, z, fast, radius, rounds, solves):
    """The round at ``z`` from the pencil just built there (exact at ``z``)."""
    full = pencil_problem.residuals(z)
    fast = full if fast is None else fast
    decrement = _decrement(full, pencil_problem.jacobian(z), z, *problem.bounds())
    log.debug(
        "%s: round %d: objective %.8g (reduced %.8g), decrement %.3g",
        problem_name(problem),
        rounds + 1,
        full @ full,
        fast @ fast,
        decrement,
    )
    own = pencil_problem.pencil.snapshots[-1]
    return _Round(pencil_problem, own, z, fast, full, decrement, radius, rounds + 1, solves + 1)


def _settled(problem, polish, state, max_rounds, strict=False, known=()):
    """Trust-region rounds from a first round until the full model confirms the answer.

    Each round fits the pencil exact at the current point within the trust region around
    it, builds the pencil at the proposal (the full model there) and takes the proposal if
    the full objective fell by at least :data:`ACCEPT` of what the pencil predicted (the
    region then doubles when the prediction held and the step reached its edge); otherwise
    the point stays, with the richer pencil, and the region shrinks to half the step. The
    rounds end when the decrement is under :data:`DECREMENT_TOL`, or when the pencil exact
    at the point has its optimum there (a step under :data:`STEP_TOL`: at a kink of the
    objective, a damaged patch's edge on an element's, the decrement of a smooth model need
    not vanish). None (unless ``strict``) when a plate on the way cannot be solved, or when
    the rounds reach one of the optima ``known`` (whitened unknowns) already settled.

    Stages: :func:`_rounds` (the rounds, each :func:`_next_round`), then :func:`_answer`
    (the check, its record and the result).
    """
    ended = _rounds(problem, polish, state, max_rounds, strict, known)
    if ended is None:
        return None
    state, step = ended
    return _answer(problem, state, step, max_rounds)


def _rounds(problem, polish, state, max_rounds, strict, known):
    """The rounds of :func:`_settled`: ``(last round, last step)``, or None where it says.

    The step is the whitened length of the last fit's move (``inf`` without a round).
    """
    step = np.inf
    lo, hi = problem.bounds()
    try:
        while state.decrement > _tolerance(state) and state.rounds < max_rounds:
            state, step, moved = _next_round(problem, polish, state, (lo, hi))
            if step <= STEP_TOL:
                break
            if moved and any(_same(problem, state.z, other) for other in known):
                return None  # the same optimum as one settled already
    except (ValueError, np.linalg.LinAlgError) as error:
        if strict:
            raise
        log.warning(
            "%s: polished optimum %s not settled (%s)",
            problem_name(problem),
            np.round(state.z, 2),
            error,
        )
        return None
    return state, step


def _next_round(problem, polish, state, bounds):
    """One round from ``state``: ``(next state, step, whether the point moved)``.

    The pencil exact at the point is fitted in the trust region (whose ``bounds`` are the
    unknowns' ``(lo, hi)``); a step under :data:`STEP_TOL` leaves ``state`` as it is.
    Otherwise the pencil is built at the proposal and the proposal taken or the region
    shrunk (:func:`_settled`).
    """
    lo, hi = bounds
    box = (np.maximum(lo, state.z - state.radius), np.minimum(hi, state.z + state.radius))
    fitted = _tight(state.problem, state.z, box)
    step = float(np.linalg.norm(fitted.x - state.z))
    if step <= STEP_TOL:
        return state, step, False
    reach = float(np.max(np.abs(fitted.x - state.z)))
    predicted = state.objective - 2.0 * fitted.cost
    z = canonical(problem, fitted.x)
    fast = state.problem.residuals(z)
    # the point's own snapshot and the newest others: the pencil stays exact at z
    others = [v for v in state.problem.pencil.snapshots if v is not state.own]
    earlier = [*others[len(others) - (SNAPSHOTS - 2) :], state.own]
    trial = _built(
        problem, polish(z, earlier=earlier), z, fast, state.radius, state.rounds, state.solves
    )
    actual = state.objective - trial.objective
    if predicted > 0 and actual >= ACCEPT * predicted:
        grow = actual >= 0.75 * predicted and reach >= 0.9 * state.radius
        return replace(trial, radius=2.0 * state.radius if grow else state.radius), step, True
    # the point stays; the pencil with the proposal's snapshot is exact there too
    stays = replace(
        state, problem=trial.problem, radius=0.5 * reach, rounds=trial.rounds, solves=trial.solves
    )
    return stays, step, False


def _answer(problem, state, step, max_rounds):
    """The :class:`Settled` answer at the last round ``state``, its check recorded."""
    m = problem.Y.size
    lam_fast = problem.Y - state.fast[:m] * problem.sigma
    lam_full = problem.Y - state.full[:m] * problem.sigma
    settled = state.decrement <= _tolerance(state) or step <= STEP_TOL
    check = FitCheck(
        float(state.fast @ state.fast),
        state.objective,
        float(np.max(np.abs(lam_fast / lam_full - 1.0))),
        state.decrement,
        state.rounds,
        state.solves,
        settled,
    )
    _record(problem_name(problem), check, max_rounds)
    result = OptimizeResult(
        x=state.z,
        cost=0.5 * check.full_objective,
        success=settled,
        message=f"settled in {state.rounds} rounds"
        if settled
        else f"not settled in {state.rounds} rounds",
        n_solves=state.solves,
    )
    return Settled(result, state.problem, check)


def _record(name, check, max_rounds):
    """The answer's check in the log: settled, provisional (fewer rounds asked) or not."""
    if check.settled:
        log.info(
            "%s: settled in %d rounds: objective %.6g (reduced %.6g), decrement %.2g",
            name,
            check.rounds,
            check.full_objective,
            check.fast_objective,
            check.decrement,
        )
    elif max_rounds < MAX_ROUNDS:
        log.info(
            "%s: provisional after %d rounds: objective %.6g (reduced %.6g), decrement %.2g",
            name,
            check.rounds,
            check.full_objective,
            check.fast_objective,
            check.decrement,
        )
    else:
        log.error(
            "%s: not settled in %d rounds: the full model's objective %.6g could still "
            "fall by %.2g (reduced model %.6g)",
            name,
            check.rounds,
            check.full_objective,
            check.decrement,
            check.fast_objective,
        )


def _same(problem, z, other):
    """Whether ``z`` is the optimum ``other`` (or its image): whitened distance under DISTINCT."""
    return bool(np.linalg.norm(canonical(problem, z) - canonical(problem, other)) <= DISTINCT)


def _tolerance(state):
    """The decrement accepted at a round: :data:`DECREMENT_TOL`, relative to a large objective.

    A misfit of thousands (a plate far from the model) leaves a decrement of about 1e-8 of
    it from the round-off of the derivatives alone.
    """
    return DECREMENT_TOL * max(1.0, state.objective)


def _decrement(r, J, z, lo, hi):
    """Newton decrement ``r^T J (J^T J)^-1 J^T r`` of ``|r|^2`` (Gauss-Newton), in the bounds.

    Unknowns at a bound that the descent direction ``-J^T r`` pushes outward are held there
    (their columns left out): a mass fitted as zero is an optimum, not a point to move from.
    """
    g = J.T @ r
    tol = AT_BOUND * (1.0 + np.abs(z))
    held = ((z <= lo + tol) & (g > 0)) | ((z >= hi - tol) & (g < 0))
    if held.all():
        return 0.0
    step = np.linalg.lstsq(J[:, ~held], r, rcond=None)[0]
    return float(r @ (J[:, ~held] @ step))


def _tight(problem, z, bounds=None):
    """``problem`` fitted tightly from ``z`` (least squares, then Gauss-Newton steps).

    ``bounds``: ``(lo, hi)`` of the whitened unknowns (default: the problem's own).
    """
    lo, hi = problem.bounds() if bounds is None else bounds
    z0 = np.clip(np.asarray(z, dtype=float), lo + 1e-12, hi - 1e-12)
    res = least_squares(
        problem.residuals,
        z0,
        jac=problem.jacobian,
        bounds=(lo, hi),
        method="trf",
        x_scale="jac",
        max_nfev=PENCIL_NFEV,
        ftol=PENCIL_TOL,
        xtol=PENCIL_TOL,
        gtol=PENCIL_TOL,
    )
    z = res.x
    r = problem.residuals(z)
    cost = float(r @ r)
    for _ in range(4):  # Gauss-Newton steps while they lower the objective
        dz = np.linalg.lstsq(problem.jacobian(z), -r, rcond=None)[0]
        trial = np.clip(z + dz, lo, hi)
        r_trial = problem.residuals(trial)
        if not float(r_trial @ r_trial) <= cost:
            break
        z, r, cost = trial, r_trial, float(r_trial @ r_trial)
        if np.linalg.norm(dz) <= PENCIL_TOL * (1.0 + np.linalg.norm(z)):
            break
    return OptimizeResult(x=z, cost=0.5 * cost, success=res.success, message=res.message)


def canonical(problem, z):
    """The image of ``z`` with the smallest physics parameters (``z`` itself if it has none).

    The images (:meth:`~..physics.base.Physics.mirror_images`) are the plate's exact
    symmetries: they fit exactly as well, so the choice needs no evaluation.
    """
    if problem.physics is None:
        return np.asarray(z, dtype=float)
    b, theta = problem.unpack(z)
    images = problem.physics.mirror_images(problem.model, theta)
    if not images:
        return np.asarray(z, dtype=float)
    chosen = min(
        [np.asarray(theta, dtype=float), *[np.asarray(t, dtype=float) for t in images]], key=tuple
    )
    lo, hi = problem.bounds()
    return np.clip(problem.pack(b, chosen), lo, hi)
