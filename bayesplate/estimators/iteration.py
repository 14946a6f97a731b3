"""The iteration of section 2.4: B or MVE from the prior mean to convergence, or why not.

:func:`run` takes a :class:`bayesplate.likelihood.posterior.GaussianProblem`; it follows the paired
modes by MAC between iterates, stops on the relative change of ``b`` (or of the engineering
constants), and ends a run that cycles, stalls, leaves the physical region, fails to solve or
reaches its cap with ``converged=False``, a :attr:`~EstimateResult.status` and a message; it
never raises. Two rules keep a run from cycling silently to the cap: a pairing by order or
index that flips between two crossing modes is frozen (:func:`_freeze`), and an MVE run that
drifts along directions the data barely determine stops as ``"unidentified"``
(:func:`.drift.drift`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .. import laminate
from ..likelihood.posterior import Prediction
from ..matching.pairing import track
from ..quantities import engineering_covariance, hz_from_eigenvalue
from ..reduced.model import ReducedModalResult
from . import drift as _drift_rule
from .conventions import CONVENTIONS
from .result import EstimateResult
from .steps import b_step, mve_step

__all__ = ["TRACKING", "DEFAULT_MAX_ITER", "run"]

log = logging.getLogger("bayesplate.estimators")

TRACKING = ("auto", "report", "follow", "off")
#: The paper's longest converged run took 197 iterations (Table 6), so its cap was >= 197.
DEFAULT_MAX_ITER = 200
_CYCLE_WINDOW = 8  # iterations over which a cycle is judged
_STALL_WINDOW = 40  # iterations over which a lack of progress is judged
#: Consecutive iterations in which the same peaks change mode (MAC) before a pairing by
#: order or index is called cycling and frozen.
PAIRING_CYCLE = 4


def _relative_change(new, old):
    return np.abs(new - old) / np.abs(old)


def _oscillation(history, tol, window=_CYCLE_WINDOW, stall=_STALL_WINDOW):
    """A message if the iterates cycle or stop making progress, else "".

    Cycle of period p (2 to 4): over the last `window` iterations every iterate is within
    `tol` (relative) of the one p steps earlier while consecutive iterates still differ by
    more than `tol`. Stall: over the last `stall` iterations the largest relative change
    per iteration has not fallen below its smallest value of the `stall` before.
    """
    h = np.asarray(history)
    steps = np.max(_relative_change(h[1:], h[:-1]), axis=1)
    if len(h) >= window + 5 and np.all(steps[-window:] > tol):
        for p in (2, 3, 4):
            back = np.max(_relative_change(h[p:], h[:-p]), axis=1)[-window:]
            if np.all(back <= tol):
                return f"oscillating: the iterates cycle with period {p} (steps {steps[-1]:.2g})"
    if len(steps) >= 2 * stall and np.min(steps[-stall:]) >= np.min(steps[-2 * stall : -stall]):
        return f"oscillating: no progress in {stall} iterations (relative change {steps[-1]:.2g})"
    return ""


@dataclass
class _State:
    """Mutable bookkeeping of one run."""

    b: np.ndarray
    prediction: object
    cov: np.ndarray
    history: list
    swaps: list = field(default_factory=list)
    message: str = ""
    converged: bool = False
    status: str = ""
    since: int = 0  # first iterate of the current regime (after a frozen pairing)
    note: str = ""  # what the run changed on the way (a frozen pairing), for the message
    frozen: dict = field(default_factory=dict)
    drift: list = field(default_factory=list)  # contractions of a drift, iterate by iterate
    drifted: dict = field(default_factory=dict)  # what an "unidentified" stop found


def _track(state, new, k, tracking, weight):
    """Follow the paired modes by MAC; record swaps; re-pair if ``tracking == "follow"``.

    Returns the prediction to go on with and the tracked modes (0-based, shape (m,); None
    when ``tracking == "off"``).
    """
    if tracking == "off":
        return new, None
    modes = state.prediction.modes
    old_shapes, new_shapes, weight = _shapes(state.prediction.modal, new.modal, weight)
    moved, _ = track(old_shapes, new_shapes, modes, weight)
    for i in np.flatnonzero(moved != modes):
        state.swaps.append((k, int(i), int(modes[i]) + 1, int(moved[i]) + 1))
        log.debug("iteration %d: computed mode %d became mode %d", k, modes[i] + 1, moved[i] + 1)
    if tracking == "follow" and np.any(moved != modes) and np.all(moved >= 0):
        modal = new.modal
        return Prediction(modal.eigenvalues[moved], modal.sensitivities[moved], modal, moved), moved
    return new, moved


def _pairing_cycle(swaps, k, window=None):
    """The measured indices (0-based) that changed mode in each of the last `window` iterations.

    A pairing by order or index re-applied at every iterate names another physical mode
    whenever two computed modes cross; when the same peaks do so in `window` consecutive
    iterations the iterates straddle the crossing and the pairing flips back and forth.
    Empty when they do not. `window` defaults to :data:`PAIRING_CYCLE`.
    """
    window = PAIRING_CYCLE if window is None else window
    if k < window:
        return []
    peaks = [{s[1] for s in swaps if s[0] == j} for j in range(k - window + 1, k + 1)]
    common = set.intersection(*peaks)
    return sorted(common) if all(p == common for p in peaks) else []


def _freeze(problem, new, moved, peaks, k):
    """Freeze a cycling pairing on the candidate with the smaller ``chi^2`` at the iterate.

    The candidates are the pairing re-applied at the iterate (`new`) and the modes MAC
    tracking followed from the previous iterate (`moved`, when it matched every one); both
    are evaluated on the same solve. Returns the prediction to go on with (followed by MAC
    from here), a note for the message and the frozen peaks (1-based measured indices).
    """
    modal = new.modal
    chi2 = problem.chi2(new.g), np.inf
    kept = new
    if np.all(moved >= 0):
        tracked = Prediction(modal.eigenvalues[moved], modal.sensitivities[moved], modal, moved)
        chi2 = chi2[0], problem.chi2(tracked.g)
        kept = new if chi2[0] <= chi2[1] else tracked
    measured = problem.pairing.measured
    peak = [int(i if measured is None else measured[i]) + 1 for i in peaks]  # 1-based
    pairs = ", ".join(
        f"peak {p} with mode {kept.modes[i] + 1}" for p, i in zip(peak, peaks, strict=True)
    )
    note = (
        f"; the pairing by {problem.pairing.how} flipped {PAIRING_CYCLE} iterations running "
        f"(peak{'s' if len(peaks) > 1 else ''} {', '.join(map(str, peak))}): frozen at "
        f"iteration {k} on the pairing with the smaller chi2 ({pairs}: chi2 {min(chi2):.3g} "
        f"against {max(chi2):.3g}), followed by MAC from there"
    )
    return kept, note, peak


def _shapes(old, new, weight):
    """``(old shapes, new shapes, weight)`` for MAC tracking, in the fewest unknowns.

    Two reduced-model results on one basis compare their coefficients: the basis is
    M-orthonormal, so their plain MAC is the mass-weighted MAC of the full shapes, without
    forming those (``n_dofs x n`` each).
    """
    if isinstance(old, ReducedModalResult) and isinstance(new, ReducedModalResult):
        if old.basis is new.basis:
            return old.coefficients, new.coefficients, None
    return old.vectors, new.vectors, weight


def _step(problem, method, state, V):
    """One B or MVE update from ``state``; returns (b_next, covariance for the result)."""
    p = state.prediction
    if method == "B":
        return b_step(state.b, problem.mu_b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)
    return mve_step(state.b, p.g, p.S, problem.Y, problem.V_Y, V)


def _iterate(problem, method, tol, max_iter, conventions, tracking, weight, start=None):
    """Run B or MVE from the prior mean; returns the final :class:`_State`."""
    b = (problem.mu_b if start is None else np.asarray(start, dtype=float)).copy()
    state = _State(b, problem.predict(b), problem.V_b, [b])
    V = problem.V_b
    for k in range(1, max_iter + 1):
        try:
            b_next, cov = _step(problem, method, state, V)
        except np.linalg.LinAlgError as err:
            state.message = f"linear algebra failed at iteration {k}: {err}"
            state.status = "linalg_failed"
            return state
        if conventions.covariance == "updated":
            V = cov
        if not laminate.is_physical(b_next):
            state.message = f"left the physical region at iteration {k} (not positive definite)"
            state.status = "unphysical"
            return state
        modes = state.prediction.modes if tracking == "follow" else None
        try:
            new = problem.predict(b_next, modes)
            new, moved = _track(state, new, k, tracking, weight)
        except Exception as err:  # noqa: BLE001 - a failed solve ends the run, never raises
            state.message = f"forward solve failed at iteration {k}: {err}"
            state.status = "solve_failed"
            return state
        peaks = _pairing_cycle(state.swaps, k) if tracking == "report" else []
        if peaks:
            new, note, frozen = _freeze(problem, new, moved, peaks, k)
            tracking, state.since, state.note = "follow", k, state.note + note
            state.drift = []
            state.frozen = {
                "iteration": k,
                "peaks": frozen,
                "modes": (np.asarray(new.modes) + 1).tolist(),
            }
            log.info("%s iteration %d: pairing frozen%s", method, k, note)
        change = _change(b_next, state.b, conventions)
        step = (b_next - state.b) / np.abs(state.b)
        state.b, state.prediction, state.cov = b_next, new, cov
        state.history.append(b_next)
        log.info("%s iteration %d: largest relative change %.3g", method, k, np.max(change))
        if np.all(change <= tol):
            state.converged = True
            state.status = "converged"
            state.message = f"converged: relative change {np.max(change):.2g} <= TOL {tol:g}"
            return state
        state.message = _oscillation(_space(state.history[state.since :], conventions), tol)
        if state.message and method == "MVE" and conventions.covariance == "fixed":
            weak = _drift_rule.weakly_determined(problem, state, V, step, tol)
            state.message, state.status = (
                (weak, "unidentified") if weak else (state.message, "oscillating")
            )
            return state
        if state.message:
            state.status = "oscillating"
            return state
        if method == "MVE" and conventions.covariance == "fixed":
            state.message = _drift_rule.drift(problem, state, V, step, tol, k, max_iter)
            if state.message:
                state.status = "unidentified"
                return state
    state.message = f"iteration cap reached: {max_iter} iterations, TOL {tol:g} not met"
    state.status = "iteration_cap"
    return state


def _space(history, conventions):
    h = np.asarray(history)
    return laminate.engineering_from_stiffness(h) if conventions.stop_on == "engineering" else h


def _change(b_next, b, conventions):
    """Relative change of section 2.4, on ``b`` or on the engineering constants."""
    if conventions.stop_on == "engineering":
        e_next, e = laminate.engineering_from_stiffness(np.array([b_next, b]))
        return _relative_change(e_next, e)
    return _relative_change(b_next, b)


def _final_covariance(problem, method, state, conventions):
    """B: ``P`` at the final iterate; MVE: the updated ``V^{k+1}`` (or from fixed ``V_b``)."""
    p = state.prediction
    if method == "B":
        return b_step(state.b, problem.mu_b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)[1]
    if conventions.covariance == "fixed" or len(state.history) == 1:
        return mve_step(state.b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)[1]
    return state.cov


def _result(problem, method, state, conventions, settings, n_solves, started):
    try:
        cov_b = _final_covariance(problem, method, state, conventions)
        cov = engineering_covariance(laminate.engineering_from_stiffness(state.b), cov_b)
    except np.linalg.LinAlgError:  # a singular final step: report no covariance, not raise
        cov_b = cov = np.full((6, 6), np.nan)
    history_b = np.asarray(state.history)
    f = hz_from_eigenvalue(state.prediction.g)
    measured = hz_from_eigenvalue(problem.Y)
    return EstimateResult(
        method=method,
        b=state.b,
        constants=laminate.engineering_from_stiffness(state.b),
        covariance_b=cov_b,
        covariance=cov,
        sd=np.sqrt(np.maximum(np.diag(cov), 0.0)),
        history=laminate.engineering_from_stiffness(history_b),
        history_b=history_b,
        iterations=len(state.history) - 1,
        converged=state.converged,
        message=state.message,
        n_solves=n_solves,
        frequency_Hz=f,
        measured_Hz=measured,
        residual=f - measured,
        modes=np.asarray(state.prediction.modes) + 1,
        mode_swaps=list(state.swaps),
        wall_time=time.perf_counter() - started,
        settings=settings,
        status=state.status,
        pairing=problem.pairing,
    )


def run(
    problem,
    method="MVE",
    tol=1e-3,
    max_iter=DEFAULT_MAX_ITER,
    conventions=None,
    tracking="auto",
    weight=None,
    start=None,
):
    """Run B or MVE on a Gaussian problem, from its prior mean.

    Parameters
    ----------
    problem : GaussianProblem
    method : {"B", "MVE"}
    tol : float
        TOL of section 2.4.
    max_iter : int
        Iteration cap.
    conventions : Conventions, optional
        Only ``covariance`` and ``stop_on`` matter here; default ``CONVENTIONS["paper"]``.
    tracking : {"auto", "report", "follow", "off"}
        MAC tracking of the paired modes between iterates: report swaps only (pairing by
        order or index is re-applied at every iterate, as the paper does, until the same
        peaks change mode :data:`PAIRING_CYCLE` iterations running: then the pairing is
        frozen and followed, ``settings["frozen_pairing"]``), re-pair along the tracked
        modes, or skip. ``"auto"``: follow when the modes were paired by shape
        (MAC pairing names physical modes, whose order changes as the iterate moves),
        report otherwise (an assignment by frequency names modes by their order at the
        point where it was made: following them from a prior far off would follow modes
        the prior misplaced).
    weight : array_like or sparse matrix, optional
        MAC weight for tracking (the mass matrix).
    start : array_like, shape (6,), optional
        First iterate (Pa); default the prior mean. B's prior mean stays the problem's: only
        the path changes, not the fixed point (MVE's fixed point does not depend on it).

    Returns
    -------
    EstimateResult
    """
    if method not in ("B", "MVE"):
        raise ValueError(f"method = {method!r}: run() takes 'B' or 'MVE'")
    if tracking not in TRACKING:
        raise ValueError(f"tracking = {tracking!r}: must be one of {TRACKING}")
    if tracking == "auto":
        tracking = "follow" if problem.pairing.how == "mac" else "report"
    conventions = conventions or CONVENTIONS["paper"]
    started, solves0, seconds0 = time.perf_counter(), problem.n_solves, problem.solve_seconds
    settings = {
        "tol": tol,
        "max_iter": max_iter,
        "conventions": conventions,
        "tracking": tracking,
        "pairing": problem.pairing.how,
    }
    try:
        state = _iterate(problem, method, tol, max_iter, conventions, tracking, weight, start)
    except Exception as err:  # noqa: BLE001 - e.g. the first solve fails: report, never raise
        b = problem.mu_b
        state = _State(
            b, None, problem.V_b, [b], message=f"forward solve failed: {err}", status="solve_failed"
        )
        return _failed_result(problem, method, state, settings, started)
    state.message += state.note + _swap_note(state.swaps)
    if state.frozen:
        settings["frozen_pairing"] = state.frozen
    if state.drifted:
        settings["unidentified"] = state.drifted
    settings["solve_seconds"] = problem.solve_seconds - seconds0
    return _result(
        problem, method, state, conventions, settings, problem.n_solves - solves0, started
    )


def _swap_note(swaps):
    """A note on the mode-order changes MAC tracking saw, for the message ("" if none)."""
    if not swaps:
        return ""
    iterations = sorted({s[0] for s in swaps})
    return (
        f"; the paired modes changed order (MAC) in {len(iterations)} iterations, "
        f"last at iteration {iterations[-1]} (see mode_swaps)"
    )


def _failed_result(problem, method, state, settings, started):
    """A result for a run whose very first forward solve failed."""
    m = problem.m
    nan = np.full(m, np.nan)
    e = laminate.engineering_from_stiffness(state.b)
    return EstimateResult(
        method,
        state.b,
        e,
        problem.V_b,
        np.full((6, 6), np.nan),
        np.full(6, np.nan),
        e[None, :],
        state.b[None, :],
        0,
        False,
        state.message,
        0,
        nan,
        hz_from_eigenvalue(problem.Y),
        nan,
        problem.pairing.modes + 1,
        wall_time=time.perf_counter() - started,
        settings=settings,
        status=state.status,
        pairing=problem.pairing,
    )
