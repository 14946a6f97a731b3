"""The paper's estimators B, MVE and MVE-mod (Daghia et al. 2007, sections 2 and 5).

All three iterate on the stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)`` with
the Gaussian problem of :mod:`bayesplate.posterior`:

- **B** (eq. 9), the Bayesian estimator: Gauss-Newton steps on ``S_B`` (eq. 5) with the prior
  mean ``mu`` fixed, ``b^{k+1} = mu + P^k S^T V_Y^-1 [Y - g^k - S (mu - b^k)]``,
  ``P^k = (S^T V_Y^-1 S + V_b^-1)^-1``. Converges to the posterior mode (MAP).
- **MVE** (eq. 12), the minimum variance estimator: ``b^{k+1} = b^k + V S^T (S V S^T +
  V_Y)^-1 (Y - g^k)``, reporting the updated covariance ``V^{k+1} = V - V S^T (S V S^T +
  V_Y)^-1 S V``. Section 2.3: one MVE step is one B step with ``mu = b^k``.
- **MVE-mod** (section 5): MVE with small deviations and TOL = 1e-2, then MVE again from the
  stage-1 estimate with larger deviations and the prescribed TOL.

Stopping rule (section 2.4): ``|b_i^{k+1} - b_i^k| / |b_i^k| <= TOL`` for all i. A run that
leaves the physical region, oscillates (cycles or stalls), fails in the forward solve or
reaches its iteration cap returns ``converged=False`` with a message saying which; it never
raises.

Conventions the paper leaves open are keywords (:class:`Conventions`). Settled by
reproducing Tables 3-23 (``studies/paper_tables.py``), ``CONVENTIONS["paper"]``, the
default: ``V_Y = diag(d lambda^2)``, ``V_b = diag(dC^2)``; MVE iterates with the *initial*
``V_b`` (the updated ``V^{k+1}`` is only reported: re-using it would count the same data
again at every iteration, and does not reproduce the paper); the stopping rule on ``b``;
MVE-mod stage-2 deviations ``d2`` times the *initial* values. ``"full-prior"`` keeps the
correlations of the propagated prior; ``"printed"`` is section 3.6 to the letter.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import laminate
from .model import PlateModel
from .pairing import Pairing, pair_measured, track
from .posterior import (
    OBSERVATION_CONVENTIONS,
    PRIOR_CONVENTIONS,
    GaussianProblem,
    Prediction,
    prior_in_stiffness,
)
from .quantities import engineering_covariance, hz_from_eigenvalue

__all__ = [
    "METHODS",
    "STATUSES",
    "TRACKING",
    "Conventions",
    "CONVENTIONS",
    "resolve_conventions",
    "EstimateResult",
    "estimate",
    "run",
    "b_step",
    "mve_step",
]

log = logging.getLogger(__name__)

METHODS = ("B", "MVE", "MVE-mod")
#: How a run ended (:attr:`EstimateResult.status`); only the first is a success.
STATUSES = (
    "converged",
    "oscillating",
    "iteration_cap",
    "unphysical",
    "linalg_failed",
    "solve_failed",
)
TRACKING = ("auto", "report", "follow", "off")
#: The paper's longest converged run took 197 iterations (Table 6), so its cap was >= 197.
DEFAULT_MAX_ITER = 200
_CYCLE_WINDOW = 8  # iterations over which a cycle is judged
_STALL_WINDOW = 40  # iterations over which a lack of progress is judged


@dataclass(frozen=True)
class Conventions:
    """Choices the paper leaves open; see the module docstring of :mod:`bayesplate.posterior`.

    Parameters
    ----------
    observation : {"variance", "deviation"}
        ``V_Y = diag(d lambda^2)`` or ``diag(d lambda)`` as printed.
    prior : {"variance", "full", "deviation"}
        ``V_b = diag(dC^2)``, the full propagated covariance, or ``diag(dC)`` as printed.
    covariance : {"fixed", "updated"}
        MVE iterates with the initial ``V_b`` or with the updated ``V^{k+1}`` of section 2.2
        (which re-uses the same data at every iteration).
    stop_on : {"stiffness", "engineering"}
        The relative-change test of section 2.4 on ``b`` or on the engineering constants.
    stage2_base : {"initial", "estimate"}
        MVE-mod stage-2 deviations scale the initial values or the stage-1 estimate.
    """

    observation: str = "variance"
    prior: str = "variance"
    covariance: str = "fixed"
    stop_on: str = "stiffness"
    stage2_base: str = "initial"

    def __post_init__(self):
        for name, allowed in (
            ("observation", OBSERVATION_CONVENTIONS),
            ("prior", PRIOR_CONVENTIONS),
            ("covariance", ("updated", "fixed")),
            ("stop_on", ("stiffness", "engineering")),
            ("stage2_base", ("initial", "estimate")),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} = {getattr(self, name)!r}: must be one of {allowed}")


CONVENTIONS = {
    # reproduces Tables 3-23 (README.md, "Estimators"): the library and CLI default
    "paper": Conventions(),
    # the exact first-order image of the case file's independent engineering prior
    "full-prior": Conventions(prior="full"),
    # the formulas exactly as printed in section 3.6, with the MVE covariance update
    "printed": Conventions(observation="deviation", prior="deviation", covariance="updated"),
}


@dataclass(frozen=True)
class EstimateResult:
    """Outcome of one estimator run.

    Attributes
    ----------
    method : str
        ``"B"``, ``"MVE"`` or ``"MVE-mod"``.
    b : numpy.ndarray, shape (6,)
        Estimated ``(C11, C22, C12, C66, C44, C55)``, Pa (the last physical iterate when the
        run failed).
    constants : numpy.ndarray, shape (6,)
        ``(E1, E2, nu12, G12, G13, G23)``, SI.
    covariance_b : numpy.ndarray, shape (6, 6)
        B: ``P^k`` of eq. 9 at the final iterate; MVE: the updated ``V_b^{k+1}``; Pa^2.
    covariance : numpy.ndarray, shape (6, 6)
        The same carried to the engineering constants (first order), SI.
    sd : numpy.ndarray, shape (6,)
        Square roots of the diagonal of `covariance`.
    history : numpy.ndarray, shape (iterations + 1, 6)
        Engineering constants of every iterate, the initial values first.
    history_b : numpy.ndarray, shape (iterations + 1, 6)
        The same iterates as stiffness coefficients, Pa.
    iterations : int
        Updates performed.
    converged : bool
        ``status == "converged"``.
    message : str
        Why the run ended, in words.
    n_solves : int
        Forward (eigen) solves.
    frequency_Hz, measured_Hz : numpy.ndarray, shape (m,)
        Paired model frequencies at the estimate and the measured ones.
    residual : numpy.ndarray, shape (m,)
        ``frequency_Hz - measured_Hz``, Hz.
    modes : numpy.ndarray of int, shape (m,)
        1-based computed elastic mode paired with each measured frequency at the estimate.
    mode_swaps : list of tuple
        ``(iteration, measured index, old mode, new mode)`` (0-based indices, 1-based modes)
        where MAC tracking found a paired mode changing place.
    stages : tuple of EstimateResult
        MVE-mod: the two stages; empty otherwise.
    wall_time : float
        Seconds.
    settings : dict
        Tolerance, iteration cap, conventions, pairing.
    status : str
        How the run ended, one of :data:`STATUSES`: test this, never the message's text.
    """

    method: str
    b: np.ndarray
    constants: np.ndarray
    covariance_b: np.ndarray
    covariance: np.ndarray
    sd: np.ndarray
    history: np.ndarray
    history_b: np.ndarray
    iterations: int
    converged: bool
    message: str
    n_solves: int
    frequency_Hz: np.ndarray
    measured_Hz: np.ndarray
    residual: np.ndarray
    modes: np.ndarray
    mode_swaps: list = field(default_factory=list)
    stages: tuple = ()
    wall_time: float = 0.0
    settings: dict = field(default_factory=dict)
    status: str = ""

    def __post_init__(self):
        if not self.status:
            object.__setattr__(self, "status", "converged" if self.converged else "")
        if self.status not in STATUSES:
            raise ValueError(f"status = {self.status!r}: must be one of {STATUSES}")

    @property
    def residual_percent(self):
        """``100 (f - f_meas) / f_meas``, shape (m,)."""
        return 100.0 * self.residual / self.measured_Hz


# ----------------------------------------------------------------------------- one step


def _scaled(S, V, b_scale):
    """Sensitivities and covariance in the dimensionless ``x = b / b_scale``."""
    return S * b_scale[None, :], V / np.outer(b_scale, b_scale)


def b_step(b, mu, g, S, Y, V_Y, V_b):
    """One iteration of the B estimator (eq. 9).

    Parameters
    ----------
    b, mu : numpy.ndarray, shape (6,)
        Current iterate and prior mean, Pa.
    g : numpy.ndarray, shape (m,)
        Model eigenvalues at `b`.
    S : numpy.ndarray, shape (m, 6)
        Sensitivities at `b`.
    Y : numpy.ndarray, shape (m,)
    V_Y : numpy.ndarray, shape (m, m)
    V_b : numpy.ndarray, shape (6, 6)

    Returns
    -------
    b_next : numpy.ndarray, shape (6,)
    P : numpy.ndarray, shape (6, 6)
        ``[S^T V_Y^-1 S + V_b^-1]^-1``.
    """
    scale = np.abs(mu)
    Sx, Vx = _scaled(S, V_b, scale)
    W = np.linalg.inv(V_Y)
    Px = np.linalg.inv(Sx.T @ W @ Sx + np.linalg.inv(Vx))
    rhs = Y - g - S @ (mu - b)
    b_next = mu + scale * (Px @ Sx.T @ W @ rhs)
    return b_next, Px * np.outer(scale, scale)


def mve_step(b, g, S, Y, V_Y, V):
    """One iteration of the minimum variance estimator (eq. 12).

    Parameters
    ----------
    b : numpy.ndarray, shape (6,)
        Current iterate, Pa.
    g, S, Y, V_Y
        As in :func:`b_step`.
    V : numpy.ndarray, shape (6, 6)
        Parameter covariance used in this step.

    Returns
    -------
    b_next : numpy.ndarray, shape (6,)
    V_next : numpy.ndarray, shape (6, 6)
        ``V - V S^T (S V S^T + V_Y)^-1 S V`` (section 2.2).
    """
    scale = np.abs(b)
    Sx, Vx = _scaled(S, V, scale)
    C = Sx @ Vx @ Sx.T + V_Y
    K = np.linalg.solve(C, Sx @ Vx).T  # V S^T C^-1, shape (6, m)
    b_next = b + scale * (K @ (Y - g))
    V_next = Vx - K @ Sx @ Vx
    return b_next, V_next * np.outer(scale, scale)


# ----------------------------------------------------------------------------- the iteration


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


def _track(state, new, k, tracking, weight):
    """Follow the paired modes by MAC; record swaps; re-pair if ``tracking == "follow"``."""
    if tracking == "off":
        return new
    modes = state.prediction.modes
    moved, _ = track(state.prediction.modal.vectors, new.modal.vectors, modes, weight)
    for i in np.flatnonzero(moved != modes):
        state.swaps.append((k, int(i), int(modes[i]) + 1, int(moved[i]) + 1))
        log.debug("iteration %d: computed mode %d became mode %d", k, modes[i] + 1, moved[i] + 1)
    if tracking == "follow" and np.any(moved != modes) and np.all(moved >= 0):
        modal = new.modal
        return Prediction(modal.eigenvalues[moved], modal.sensitivities[moved], modal, moved)
    return new


def _step(problem, method, state, V):
    """One B or MVE update from ``state``; returns (b_next, covariance for the result)."""
    p = state.prediction
    if method == "B":
        return b_step(state.b, problem.mu_b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)
    return mve_step(state.b, p.g, p.S, problem.Y, problem.V_Y, V)


def _iterate(problem, method, tol, max_iter, conventions, tracking, weight):
    """Run B or MVE from the prior mean; returns the final :class:`_State`."""
    b = problem.mu_b.copy()
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
            new = _track(state, new, k, tracking, weight)
        except Exception as err:  # noqa: BLE001 - a failed solve ends the run, never raises
            state.message = f"forward solve failed at iteration {k}: {err}"
            state.status = "solve_failed"
            return state
        change = _change(b_next, state.b, conventions)
        state.b, state.prediction, state.cov = b_next, new, cov
        state.history.append(b_next)
        log.info("%s iteration %d: largest relative change %.3g", method, k, np.max(change))
        if np.all(change <= tol):
            state.converged = True
            state.status = "converged"
            state.message = f"converged: relative change {np.max(change):.2g} <= TOL {tol:g}"
            return state
        state.message = _oscillation(_space(state.history, conventions), tol)
        if state.message:
            state.status = "oscillating"
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
    )


def run(
    problem,
    method="MVE",
    tol=1e-3,
    max_iter=DEFAULT_MAX_ITER,
    conventions=None,
    tracking="auto",
    weight=None,
):
    """Run B or MVE on a :class:`bayesplate.posterior.GaussianProblem`, from its prior mean.

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
        order or index is re-applied at every iterate, as the paper does), re-pair along the
        tracked modes, or skip. ``"auto"``: follow when the modes were paired by shape
        (MAC pairing names physical modes, whose order changes as the iterate moves),
        report otherwise.
    weight : array_like or sparse matrix, optional
        MAC weight for tracking (the mass matrix).

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
        state = _iterate(problem, method, tol, max_iter, conventions, tracking, weight)
    except Exception as err:  # noqa: BLE001 - e.g. the first solve fails: report, never raise
        b = problem.mu_b
        state = _State(
            b, None, problem.V_b, [b], message=f"forward solve failed: {err}", status="solve_failed"
        )
        return _failed_result(problem, method, state, settings, started)
    state.message += _swap_note(state.swaps)
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
    )


def resolve_conventions(convention):
    """The :class:`Conventions` of a name in :data:`CONVENTIONS`, or the object itself."""
    if isinstance(convention, Conventions):
        return convention
    if convention not in CONVENTIONS:
        raise ValueError(f"convention = {convention!r}: must be one of {tuple(CONVENTIONS)}")
    return CONVENTIONS[convention]


def estimate(
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
):
    """Estimate the elastic constants of a case with the paper's B, MVE or MVE-mod.

    The prior deviations of ``b`` follow from those of the engineering constants by
    first-order propagation through eqs. 20-21 (:func:`bayesplate.posterior.prior_in_stiffness`);
    ``V_Y`` from the frequency deviations, ``d lambda = 8 pi^2 f df`` (section 3.6).

    Parameters
    ----------
    case : bayesplate.case.Case
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
    pairing : {"auto", "mac", "index", "order"} or Pairing
        Measured-to-computed mode pairing (:func:`bayesplate.pairing.pair_measured`, at the
        prior mean): "auto" pairs by shape (MAC) when the case has measured shapes, else by
        the case's mode indices if any, else by order. Measured modes left unpaired are left
        out of the fit.
    tracking : {"auto", "report", "follow", "off"}
        MAC tracking of paired modes between iterates (see :func:`run`); "auto" follows
        modes paired by shape and keeps order or index pairings as they are.

    Returns
    -------
    EstimateResult
    """
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {METHODS}")
    conventions = resolve_conventions(convention)
    model = model or PlateModel.from_case(case)
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    pair = pairing
    if not isinstance(pair, Pairing):
        pair = pair_measured(case, model, laminate.stiffness_from_engineering(mean), pairing)
    problem = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    weight = getattr(model, "mass", None)
    options = {"conventions": conventions, "tracking": tracking, "weight": weight}
    if method != "MVE-mod":
        return _noted(run(problem, method, tol, max_iter, **options), mean, sd)
    stage1 = _noted(run(problem, "MVE", stage1_tol, max_iter, **options), mean, sd)
    if not stage1.converged:
        return _combine(stage1, None)
    mean2 = stage1.constants
    sd2 = _stage2_sd(mean2, mean, sd, stage2_factor, stage2_sd, conventions)
    mu_b, V_b = prior_in_stiffness(mean2, sd2, conventions.prior)
    stage2 = run(problem.with_prior(mu_b, V_b), "MVE", tol, max_iter, **options)
    return _combine(stage1, _noted(stage2, mean2, sd2))


def _noted(result, mean, sd):
    """The result with its engineering prior (initial values, deviations) in ``settings``."""
    settings = {**result.settings, "prior_mean": np.array(mean), "prior_sd": np.array(sd)}
    return replace(result, settings=settings)


def _stage2_sd(e1, mean, sd1, factor, sd2, conventions):
    """Stage-2 deviations: explicit, or `factor` x stage 1's (rescaled to the estimate)."""
    if sd2 is not None:
        return np.asarray(sd2, dtype=float)
    if conventions.stage2_base == "estimate":
        return factor * sd1 / np.abs(mean) * np.abs(e1)
    return factor * sd1


def _combine(stage1, stage2):
    """One MVE-mod result from its stages (stage 2 may be missing when stage 1 failed)."""
    if stage2 is None:
        message = f"stage 1 did not converge: {stage1.message}"
        return replace(stage1, method="MVE-mod", message=message, stages=(stage1,))
    return replace(
        stage2,
        method="MVE-mod",
        history=np.vstack([stage1.history, stage2.history[1:]]),
        history_b=np.vstack([stage1.history_b, stage2.history_b[1:]]),
        iterations=stage1.iterations + stage2.iterations,
        n_solves=stage1.n_solves + stage2.n_solves,
        mode_swaps=stage1.mode_swaps + stage2.mode_swaps,
        message=f"stage 1: {stage1.message}; stage 2: {stage2.message}",
        stages=(stage1, stage2),
        wall_time=stage1.wall_time + stage2.wall_time,
        settings={
            **stage2.settings,
            "solve_seconds": sum(s.settings.get("solve_seconds", 0.0) for s in (stage1, stage2)),
        },
    )
