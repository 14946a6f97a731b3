"""Posterior sampling with emcee on the estimators' own Gaussian problem (issue 4).

The target is ``ln f(b | Y)`` of :class:`bayesplate.posterior.GaussianProblem`: the same
``V_Y``, prior and pairing as the estimators (``CONVENTIONS["paper"]`` by default), -inf
outside the physical region. Only the forward model is swapped for a fast one; the
log-density is still :meth:`GaussianProblem.log_posterior` of a problem built from the
same arrays (:class:`WhitenedLogPosterior`).

Fast model
    A certified reduced-basis model (:func:`bayesplate.reduced.fast_model`) over the
    *posterior* box (:func:`posterior_box`): a pilot B estimate +- 6 linearised deviations,
    and, in the coefficients the data barely inform, the prior's 3-sigma range as well; cut
    to physical laminae. Not the prior's 3-sigma box throughout: the posterior is 5 to 20
    times narrower than the prior in the well-identified coefficients, and the prior box of
    the Frederiksen case needs 37 full solves to certify (``reports/benchmark_reduced.md``),
    which alone spends the two minutes the whole posterior may take. The pilot B run (TOL
    1e-2, within ~0.1 deviations of the converged estimate) uses the case mesh or, above
    400 elements, a mesh halved in each direction (within ~0.7 deviations on the
    Frederiksen plate). The certificate (held-out points against the full model, relative
    frequency error below 1e-4) is kept in the result; where it fails, or a walker steps
    out of the box, the full model is used with a
    :class:`bayesplate.reduced.ReducedModelWarning`, and the result counts those
    evaluations. The sampler needs eigenvalues only (the fastest reduced path); the MAP and
    its covariance ``P`` come from B iterated to TOL 1e-7 on the same fast model.

Parameterisation and moves
    Walkers move in whitened log coordinates (:class:`WhitenedLogPosterior`): the
    logarithms of the positive coefficients and C12 itself, whitened by ``P`` at the MAP;
    the density carries the Jacobian. Two emcee moves are mixed: :class:`LaplaceMove`
    (90 %), an independence Metropolis-Hastings proposal (Student-t, 10 degrees of
    freedom, scale 1.1) tuned on the ensemble, and :class:`ScreenedDEMove` (10 %), emcee's
    differential evolution, local and adaptive, for where the posterior is not Gaussian.
    Tuning: three rounds of 30 steps, after each of which the proposal takes the mean and
    covariance of the ensemble; then it is frozen and the tuning steps are discarded. The
    independence proposals are truncated to the fast model's box; DE proposals outside it
    are first screened with an upper bound of the posterior from the reduced model's Ritz
    values (upper bounds of the eigenvalues everywhere), so that most of them are rejected
    without a full solve, exactly as the evaluation would. Every move leaves the posterior
    invariant whatever ``P`` and the tuning are; they only set the efficiency.

Stopping
    Every ``check_every`` steps after tuning the integrated autocorrelation time ``tau`` of
    each coordinate is estimated (``get_autocorr_time(tol=0)`` on the chain after tuning);
    the run stops once that chain is longer than ``target_tau_factor`` (50) times the
    largest ``tau``, the smallest bulk ESS of the engineering constants (after a further
    burn-in of 3 ``tau``) reaches ``min_ess`` and the largest R-hat is below ``max_rhat``
    (1.01), or at ``max_steps``.

Output
    :class:`SamplingResult` with an ArviZ ``InferenceData``: ``posterior`` in the engineering
    constants in case-file units (``E1_GPa``, ..., ``nu12``), ``log_likelihood`` (the
    pointwise log-likelihood of each measured eigenvalue, for WAIC/LOO), ``sample_stats``
    (``lp``), ``observed_data`` (``Y``, rad^2/s^2) and ``constant_data`` (frequencies, Hz),
    indexed by the measured mode number (``mode``). Walkers are ArviZ chains.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field, replace

import emcee
import numpy as np
from threadpoolctl import threadpool_limits

from . import laminate
from .case import ENGINEERING_KEYS
from .estimators import b_step, resolve_conventions, run
from .model import PlateModel
from .pairing import Pairing, pair_measured
from .posterior import GaussianProblem
from .reduced import Box, fast_model

__all__ = [
    "CASE_UNITS",
    "HDI_PROB",
    "LaplaceMove",
    "SamplingResult",
    "SamplingSetup",
    "ScreenedDEMove",
    "WhitenedLogPosterior",
    "LOG_COEFFICIENTS",
    "covariance_agreement",
    "curvature_covariance",
    "engineering_covariance",
    "linearisation_band",
    "default_moves",
    "posterior_box",
    "prepare",
    "sample",
    "sample_problem",
]

log = logging.getLogger(__name__)

#: Multipliers from SI to case-file units (GPa for moduli, nu12 as is).
CASE_UNITS = np.array([1e-9, 1e-9, 1.0, 1e-9, 1e-9, 1e-9])
#: Probability of the highest-density interval reported (ArviZ's default, 3 % to 97 %).
HDI_PROB = 0.94
#: Meshes above this many elements get a pilot B run on a mesh halved in each direction.
PILOT_MAX_ELEMENTS = 400
#: Pilot B: a relative change of 1e-2 leaves it within ~0.1 deviations of the converged
#: estimate (Frederiksen plate: 0.12 after 5 iterations), far inside a 6-deviation box.
PILOT_TOL = 1e-2
#: B to this relative change is the MAP to ~1e-6 posterior deviations (linear convergence,
#: ratio ~0.37 per iteration on the bundled plates).
MAP_TOL = 1e-7
#: Burn-in discarded, in autocorrelation times (the walkers start from the Laplace
#: approximation, close to the posterior already).
BURN_TAU = 3.0
#: Tuning of the Laplace proposal: rounds and steps per round (discarded afterwards).
TUNE_ROUNDS = 3
TUNE_STEPS = 30
#: Default fast-model settings for a posterior box: 10 design points besides the centre
#: (6 needed a second round on the Frederiksen plate, 10 passed in one: 17 full solves),
#: rounds of 4 random + 2 probe held-out points (see :func:`bayesplate.reduced.fast_model`).
FAST_DEFAULTS = {"n_snapshots": 10, "n_test": 4, "n_probe": 2}


# ----------------------------------------------------------------------------- the density


@dataclass(frozen=True)
class _Eigenvalues:
    """Eigenvalues without sensitivities (NaN): all the log-posterior needs."""

    eigenvalues: np.ndarray
    sensitivities: np.ndarray


class _EigenvalueForward:
    """``forward(b, n_modes)`` from a model's eigenvalues-only path (``model.eigenvalues``)."""

    def __init__(self, model):
        self.model = model

    @property
    def reduced(self):
        """The certified reduced model (for bounds off its box), or None."""
        return self.model.reduced if getattr(self.model, "certified", False) else None

    def __call__(self, b, n_modes):
        values = np.asarray(self.model.eigenvalues(b, n_modes))
        return _Eigenvalues(values, np.full((values.size, 6), np.nan))


#: Coefficients sampled in logarithms (all positive in a physical lamina); C12 is not.
LOG_COEFFICIENTS = np.array([True, True, False, True, True, True])


class WhitenedLogPosterior:
    """``ln f(b | Y)`` of a Gaussian problem in whitened log coordinates ``z``.

    ``u = L^-1 (h(b) - h(b_0))``-style coordinates: ``h`` takes the logarithm of the
    positive coefficients (``C11, C22, C66, C44, C55``) and leaves ``C12``; ``u = c + L z``
    with ``c = h(b_0)`` and ``L L^T`` the covariance of ``b`` carried to ``h`` to first
    order at ``b_0``. The weakly identified shear moduli have a steep likelihood below and
    a prior tail above (Frederiksen G13: 9 linearised deviations above the MAP); in
    logarithms that is closer to Gaussian, and the default moves give 3 to 10 times more
    effective samples per evaluation than in ``b`` (tuning runs on the Frederiksen plate).

    Calling it on ``z`` (shape (6,)) returns ``(log_density, pointwise)``: ``log_density``
    is :meth:`GaussianProblem.log_posterior` of a problem built from the same ``Y``,
    ``V_Y``, ``mu_b``, ``V_b`` and pairing (only the forward model may differ) at
    ``b(z)``, plus :meth:`log_jacobian` (the density of ``z``); ``pointwise`` (shape (m,))
    is the log-likelihood of each measured eigenvalue, summing to the log-likelihood
    (``V_Y`` is diagonal); NaN outside the physical region.

    Parameters
    ----------
    problem : GaussianProblem
    center : array_like, shape (6,)
        ``b_0``, the point at ``z = 0`` (the MAP), Pa.
    covariance : array_like, shape (6, 6)
        Covariance of ``b`` at ``b_0`` (``P`` of B), Pa^2.
    forward : callable, optional
        ``forward(b, n_modes)`` replacing the problem's (anything with ``eigenvalues`` and
        ``sensitivities``); default the problem's own.

    Attributes
    ----------
    center, chol : numpy.ndarray, shapes (6,), (6, 6)
        ``c`` and ``L`` in the coordinates ``h(b)``.
    n_forward : int
        Forward evaluations made in this process.
    """

    def __init__(self, problem, center, covariance, forward=None):
        var = np.diag(problem.V_Y)
        if not np.array_equal(problem.V_Y, np.diag(var)):
            raise ValueError("pointwise log-likelihoods need a diagonal V_Y")
        self._source = problem.forward if forward is None else forward
        self.problem = GaussianProblem(
            problem.Y, problem.V_Y, problem.mu_b, problem.V_b, self._forward, problem.pairing
        )
        b0 = np.array(center, dtype=float)
        if not laminate.is_physical(b0):
            raise ValueError("the centre of the sampler's coordinates is not a physical lamina")
        scale = np.where(LOG_COEFFICIENTS, b0, 1.0)  # d h / d b = 1 / b for the logarithms
        self.center = np.where(LOG_COEFFICIENTS, np.log(np.abs(b0)), b0)
        cov_h = np.asarray(covariance, dtype=float) / np.outer(scale, scale)
        self.chol = np.linalg.cholesky(cov_h)
        self._var = var
        self._last = None
        self.n_forward = 0

    @property
    def m(self):
        """Number of measured eigenvalues."""
        return self.problem.m

    def _forward(self, b, n_modes):
        modal = self._source(b, n_modes)
        self._last = modal.eigenvalues
        self.n_forward += 1
        return modal

    def _h(self, z):
        return self.center + np.asarray(z, dtype=float) @ self.chol.T

    def to_b(self, z):
        """Stiffness coefficients (Pa) of whitened points ``z``, shape (..., 6)."""
        u = self._h(z)
        return np.where(LOG_COEFFICIENTS, np.exp(np.where(LOG_COEFFICIENTS, u, 0.0)), u)

    def to_z(self, b):
        """Whitened coordinates of physical ``b`` (Pa), shape (..., 6)."""
        b = np.asarray(b, dtype=float)
        u = np.where(LOG_COEFFICIENTS, np.log(np.where(LOG_COEFFICIENTS, b, 1.0)), b)
        return np.linalg.solve(self.chol, (u - self.center).T).T

    def log_jacobian(self, z):
        """``ln |d b / d z|`` up to the constant ``ln det L``: the sum of the logarithms."""
        u = self._h(z)
        return np.sum(u[..., LOG_COEFFICIENTS], axis=-1)

    def pointwise(self, g):
        """Log-likelihood of each measured eigenvalue given paired model ones ``g``, (m,)."""
        r = self.problem.Y - g
        return -0.5 * (r**2 / self._var + np.log(2 * np.pi * self._var))

    def __call__(self, z):
        """``(log_density, pointwise)`` at whitened ``z``, shape (6,)."""
        self._last = None
        lp = self.problem.log_posterior(self.to_b(z))
        if not np.isfinite(lp) or self._last is None:
            return -np.inf, np.full(self.m, np.nan)
        g = self._last[self.problem.pairing.modes]
        return lp + self.log_jacobian(z), self.pointwise(g)


# ----------------------------------------------------------------------------- the moves


class LaplaceMove(emcee.moves.MHMove):
    """Independence Metropolis-Hastings proposal from a Gaussian approximation.

    In whitened coordinates the proposal is ``z' = m + scale A t`` whatever the current
    ``z``, with ``t`` standard normal (``df=None``) or multivariate Student-t with ``df``
    degrees of freedom; ``m = 0``, ``A = I`` (the Laplace approximation the coordinates are
    whitened by) until :meth:`set_proposal` sets them, e.g. from the ensemble after a
    tuning run. The Hastings factor is ``ln q(z) - ln q(z')``. A ``scale`` above 1 and
    Student-t tails make the proposal wider than the approximation, so that posterior tails
    a little heavier than it are still reached.

    With ``inside``, the proposal is truncated to a region (the fast model's certified box):
    draws outside it are redrawn, so no proposal of this move needs the full model. The
    truncated density differs from the untruncated one by a constant inside, so the factor
    is unchanged there, and it is zero outside: from a walker outside the region (which
    only another move can take there) this move is never accepted. Each pair of points
    then still satisfies detailed balance, so the move leaves the posterior invariant; the
    other move (differential evolution) keeps the whole space reachable.

    Parameters
    ----------
    scale : float
        Proposal deviation in units of ``A``.
    inside : callable, optional
        ``inside(z) -> bool array`` for ``z`` of shape (n, 6).
    df : float, optional
        Degrees of freedom of Student-t proposals; None for Gaussian ones.
    max_redraws : int
        Redraws of proposals outside the region before giving up (then rejected).
    """

    def __init__(self, scale=1.1, inside=None, df=None, max_redraws=100):
        self.scale = float(scale)
        self.inside = inside
        self.df = None if df is None else float(df)
        self.max_redraws = int(max_redraws)
        self.mean = None
        self.chol = None
        super().__init__(self._proposal)

    def set_proposal(self, mean, covariance):
        """Centre ``m`` and covariance ``A A^T`` of the proposal (whitened coordinates)."""
        self.mean = np.array(mean, dtype=float)
        self.chol = np.linalg.cholesky(np.asarray(covariance, dtype=float))

    def _standardised(self, z):
        if self.mean is None:
            return z / self.scale
        return np.linalg.solve(self.chol, (z - self.mean).T).T / self.scale

    def _log_q(self, z):
        r2 = np.sum(self._standardised(z) ** 2, axis=1)
        if self.df is None:
            return -0.5 * r2
        return -0.5 * (self.df + z.shape[1]) * np.log1p(r2 / self.df)

    def _draw(self, n, d, random):
        t = random.randn(n, d)
        if self.df is not None:
            t *= np.sqrt(self.df / random.chisquare(self.df, size=(n, 1)))
        t *= self.scale
        return t if self.mean is None else self.mean + t @ self.chol.T

    def _proposal(self, z, random):
        new = self._draw(*z.shape, random)
        if self.inside is not None:
            for _ in range(self.max_redraws):
                out = ~self.inside(new)
                if not np.any(out):
                    break
                new[out] = self._draw(int(np.sum(out)), z.shape[1], random)
        factor = self._log_q(z) - self._log_q(new)
        if self.inside is not None:
            factor[~self.inside(z) | ~self.inside(new)] = -np.inf
        return new, factor


class ScreenedDEMove(emcee.moves.DEMove):
    """emcee's differential-evolution move that skips proposals it can prove rejected.

    Metropolis-Hastings accepts a proposal ``q`` of walker ``j`` when ``ln f(q) > t_j =
    ln f(x_j) + ln u_j - factor_j``. With ``screen(q)``, an upper bound of ``ln f(q)``,
    a proposal whose bound is below ``t_j`` is rejected without evaluating ``ln f``: the
    decision is the one the evaluation would give, so the chain is that of ``DEMove``
    (with the uniform draws taken before the evaluations). Used for proposals outside the
    fast model's box, which would otherwise each cost a full finite-element solve.

    Parameters
    ----------
    screen : callable, optional
        ``screen(q) -> numpy.ndarray, shape (n,)``: upper bounds of ``ln f`` at the
        proposals ``q`` (shape (n, 6)); ``+inf`` where none is known. None: plain DEMove.
    **kwargs
        Of :class:`emcee.moves.DEMove`.

    Attributes
    ----------
    n_screened : int
        Proposals rejected without evaluation.
    """

    def __init__(self, screen=None, **kwargs):
        super().__init__(**kwargs)
        self.screen = screen
        self.n_screened = 0

    def propose(self, model, state):
        """One red-blue sweep; see :meth:`emcee.moves.RedBlueMove.propose`."""
        if self.screen is None:
            return super().propose(model, state)
        nwalkers = state.coords.shape[0]
        self.setup(state.coords)
        accepted = np.zeros(nwalkers, dtype=bool)
        all_inds = np.arange(nwalkers)
        inds = all_inds % self.nsplits
        if self.randomize_split:
            model.random.shuffle(inds)
        for split in range(self.nsplits):
            S1 = inds == split
            sets = [state.coords[inds == j] for j in range(self.nsplits)]
            q, factors = self.get_proposal(sets[split], sets[:split] + sets[split + 1 :],
                                           model.random)  # fmt: skip
            log_u = np.log(model.random.rand(len(q)))
            threshold = state.log_prob[S1] + log_u - factors
            need = ~(self.screen(q) < threshold)
            self.n_screened += int(np.sum(~need))
            log_prob = np.full(len(q), -np.inf)
            blobs = None
            if state.blobs is not None:
                blobs = np.full((len(q), *state.blobs.shape[1:]), np.nan)
            if np.any(need):
                lp, bl = model.compute_log_prob_fn(q[need])
                log_prob[need] = lp
                if blobs is not None:
                    blobs[need] = bl
            accepted[all_inds[S1]] = log_prob > threshold
            new_state = emcee.State(q, log_prob=log_prob, blobs=blobs)
            state = self.update(state, new_state, accepted, S1)
        return state, accepted


class _RitzScreen:
    """Upper bounds of ``ln f(b | Y)`` off the fast model's box, from Ritz values.

    The reduced eigenvalues are upper bounds of the finite-element ones anywhere
    (Courant-Fischer; the rigid-body motions are in the basis): with ``g_i <= R_i``, the
    misfit of a measured ``Y_i > R_i`` is at least ``Y_i - R_i``, so ``ln f <= ln prior -
    sum_{Y_i > R_i} (Y_i - R_i)^2 / (2 v_i) - sum ln(2 pi v_i) / 2``, plus the sampler's
    log-Jacobian. ``R`` is inflated by ``1e-8`` relative for rounding. Inside the box (no
    full solve needed) the bound is ``+inf``: evaluate.
    """

    def __init__(self, density, reduced, box):
        self.density, self.reduced, self.box = density, reduced, box
        p = density.problem
        self._norm = -0.5 * np.sum(np.log(2 * np.pi * np.diag(p.V_Y)))

    def __call__(self, z):
        p = self.density.problem
        b = self.density.to_b(z)
        bounds = np.full(len(b), np.inf)
        for k in np.flatnonzero(~self.box.contains(b)):
            prior = p.log_prior(b[k])
            if not np.isfinite(prior):
                bounds[k] = -np.inf
                continue
            try:
                R = self.reduced.eigenvalues(b[k], p.pairing.n_modes())[p.pairing.modes]
            except ValueError:  # the basis holds too few modes there: no bound
                continue
            gap = np.maximum(p.Y - R * (1 + 1e-8), 0.0)
            bounds[k] = prior + self._norm - 0.5 * np.sum(gap**2 / np.diag(p.V_Y))
        return bounds + self.density.log_jacobian(z)


def default_moves(inside=None, screen=None):
    """The moves of :func:`sample`: 80 % :class:`LaplaceMove` (scale 1.1), 20 % DE.

    Tuning runs (seeds 1 and 2) in whitened ``b`` on Plate 1 (case prior), effective
    samples per 1000 evaluations: Gaussian independence proposal, scale 1.1, 80/20 with DE,
    320-390; scale 1.2, 70/30, 250-280; scale 1.0, 170-270; emcee's stretch move 8-9; DE
    with snooker moves 35-42. On the Frederiksen plate in log coordinates with tuning:
    Student-t (10) at 90/10 65-106, at 80/20 65-92.

    Parameters
    ----------
    inside : callable, optional
        Region the Laplace proposals are truncated to (see :class:`LaplaceMove`).
    screen : callable, optional
        Upper bounds of the log-posterior for the DE move (see :class:`ScreenedDEMove`).
    """
    return [(LaplaceMove(1.1, inside, df=10), 0.9), (ScreenedDEMove(screen), 0.1)]


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class SamplingResult:
    """A sampled posterior and how it was obtained.

    Attributes
    ----------
    idata : arviz.InferenceData
        ``posterior`` (engineering constants, case units), ``log_likelihood``,
        ``sample_stats`` (``lp``), ``observed_data``, ``constant_data``; burn-in discarded.
    summary : pandas.DataFrame
        ``arviz.summary`` at ``HDI_PROB``: mean, sd, hdi_3%, hdi_97%, mcse, ess_bulk,
        ess_tail, r_hat per constant (case units).
    mean, sd : numpy.ndarray, shape (6,)
        Posterior mean and deviation of ``(E1, E2, nu12, G12, G13, G23)``, SI.
    hdi : numpy.ndarray, shape (2, 6)
        94 % highest-density interval (3 % and 97 % bounds), SI.
    covariance : numpy.ndarray, shape (6, 6)
        Sample covariance of the engineering constants, SI.
    mean_b, covariance_b : numpy.ndarray, shapes (6,), (6, 6)
        The same for the stiffness coefficients, Pa and Pa^2.
    samples_b : numpy.ndarray, shape (n_walkers * (n_steps - n_burn), 6)
        Every kept draw as stiffness coefficients, Pa.
    ess_bulk, ess_tail, rhat : numpy.ndarray, shape (6,)
        ArviZ diagnostics per constant (walkers as chains).
    ess_min, rhat_max : float
        Smallest bulk ESS and largest R-hat over the constants.
    chain : numpy.ndarray, shape (n_walkers, n_steps, 6)
        Every step of every walker, burn-in included, engineering constants in case units.
    acf : numpy.ndarray, shape (6, lags)
        Autocorrelation function of each engineering constant after burn-in, averaged over
        walkers (lag 0 first).
    tau : numpy.ndarray, shape (6,)
        Integrated autocorrelation times of the sampler's coordinates (the stopping rule),
        steps.
    tau_constants : numpy.ndarray, shape (6,)
        The same for the engineering constants after burn-in, steps.
    tau_history : numpy.ndarray, shape (checks, 7)
        Chain length and the six ``tau`` at every check of the stopping rule.
    n_steps, n_burn, n_walkers : int
        Steps in the chain (all runs of a resumed backend), steps discarded, walkers.
    acceptance : float
        Mean acceptance fraction over walkers.
    converged : bool
        Whether the stopping rule was met before ``max_steps``.
    message : str
    wall_time : float
        Seconds spent sampling in this call.
    n_evaluations : int
        Log-density evaluations in this call (proposals and initial walkers).
    n_forward : int
        Forward evaluations in this process (0 with a process pool).
    n_full : int
        Of them, full finite-element solves (fallbacks of the fast model).
    n_screened : int
        Proposals rejected on an upper bound without evaluation (:class:`ScreenedDEMove`).
    fallbacks : dict
        Full-model evaluations by reason (:class:`bayesplate.reduced.CertifiedModel`).
    certificate : bayesplate.reduced.Certificate or None
        The fast model's certificate; None when the full model was sampled.
    estimate : EstimateResult or None
        The B estimate (the MAP and its linearised covariance ``P``) on the same problem.
    timings : dict
        Seconds: ``pilot``, ``build`` (fast model, certification included), ``map``,
        ``sampling``, ``total`` (the setup included, also when prepared beforehand).
    settings : dict
        Seed entropy, walkers, moves, box, stopping settings.
    """

    idata: object = field(repr=False)
    summary: object = field(repr=False)
    mean: np.ndarray
    sd: np.ndarray
    hdi: np.ndarray
    covariance: np.ndarray
    mean_b: np.ndarray
    covariance_b: np.ndarray
    samples_b: np.ndarray = field(repr=False)
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    rhat: np.ndarray
    ess_min: float
    rhat_max: float
    chain: np.ndarray = field(repr=False)
    acf: np.ndarray = field(repr=False)
    tau: np.ndarray
    tau_constants: np.ndarray
    tau_history: np.ndarray = field(repr=False)
    n_steps: int
    n_burn: int
    n_walkers: int
    acceptance: float
    converged: bool
    message: str
    wall_time: float
    n_evaluations: int
    n_forward: int = 0
    n_full: int = 0
    n_screened: int = 0
    fallbacks: dict = field(default_factory=dict)
    certificate: object = None
    estimate: object = field(default=None, repr=False)
    timings: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict, repr=False)

    @property
    def ess_per_second(self):
        """Smallest bulk ESS over the sampling wall time, 1/s."""
        return self.ess_min / self.wall_time if self.wall_time > 0 else float("nan")

    def constants_table(self):
        """``{"E1_GPa": {"mean", "sd", "hdi_3%", "hdi_97%"}, ...}`` in case units."""
        from .io import constants_json

        return constants_json(self.mean, self.sd, **{"hdi_3%": self.hdi[0], "hdi_97%": self.hdi[1]})


@dataclass(frozen=True, eq=False)
class SamplingSetup:
    """The problem, its fast model and its MAP: everything :func:`sample` needs first.

    Attributes
    ----------
    problem : GaussianProblem
        On the full model, with the estimators' conventions, prior and pairing (no extra
        modes beyond the paired ones: the sampler does not track modes).
    model : PlateModel
        The full model.
    fast : bayesplate.reduced.CertifiedModel or None
        None when the full model is sampled.
    estimate : EstimateResult
        B on the sampler's forward model: the MAP and ``P``.
    pilot : EstimateResult or None
        The pilot B run that placed the box.
    box : bayesplate.reduced.Box or None
    timings : dict
        Seconds: ``pilot``, ``build``, ``map``.
    n_full_solves : int
        Full finite-element solves spent (pilot on the case mesh, build, certification).
    """

    problem: GaussianProblem = field(repr=False)
    model: object = field(repr=False)
    fast: object
    estimate: object = field(repr=False)
    pilot: object = field(repr=False)
    box: object
    timings: dict
    n_full_solves: int

    @property
    def certificate(self):
        """The fast model's certificate, or None."""
        return None if self.fast is None else self.fast.certificate

    def forward_with_sensitivities(self):
        """``forward(b, n_modes)`` of the sampler's model with sensitivities (for B, MVE)."""
        return self.model.solve if self.fast is None else self.fast.solve

    def sampling_forward(self):
        """``forward(b, n_modes)`` the sampler uses: the fast model's eigenvalues path."""
        return self.model.solve if self.fast is None else _EigenvalueForward(self.fast)

    def problem_on_fast_model(self, mu_b=None, V_b=None):
        """The same problem (or another prior) on the sampler's model with sensitivities."""
        p = self.problem
        mu_b = p.mu_b if mu_b is None else mu_b
        V_b = p.V_b if V_b is None else V_b
        return GaussianProblem(p.Y, p.V_Y, mu_b, V_b, self.forward_with_sensitivities(), p.pairing)

    def run_estimator(self, method="MVE", tol=1e-3, **kwargs):
        """B or MVE (:func:`bayesplate.estimators.run`) on the sampler's model.

        Iterates outside the certified box use the reduced model uncertified; the result is
        recomputed with the full-model fallback if it ends outside the box.
        """
        return _run_on_fast(self, method, tol, **kwargs)


# ----------------------------------------------------------------------------- setup


def _pilot_model(case, model, pilot_mesh):
    """The model of the pilot B run: the model itself, or the case on a coarser mesh."""
    if pilot_mesh is None:
        return model
    if pilot_mesh == "auto":
        mesh = getattr(model, "mesh", None)
        if mesh is None or mesh.nx * mesh.ny <= PILOT_MAX_ELEMENTS:
            return model
        pilot_mesh = (math.ceil(mesh.nx / 2), math.ceil(mesh.ny / 2))
    return PlateModel.from_case(case, mesh=tuple(pilot_mesh))


def posterior_box(estimate, mu_b, V_b, n_sigma=6.0, weak=0.25, prior_sigma=3.0, floor=0.1):
    """The fast model's box: where the posterior can be, from a (pilot) B estimate.

    ``b`` +- ``n_sigma`` deviations of ``P`` in every coefficient; where the data barely
    inform a coefficient (its deviation in ``P`` above ``weak`` times the prior's), the
    posterior is not Gaussian and reaches as far as the prior (Frederiksen G13: 9
    deviations of ``P`` above the MAP), so the box also covers the prior mean +-
    ``prior_sigma`` prior deviations there. Cut to physical laminae as
    :meth:`bayesplate.reduced.Box.from_covariance`: positive coefficients above ``floor``
    times the estimate, ``|C12|`` below 0.99 ``sqrt(C11 C22)`` at the lower corner.

    Parameters
    ----------
    estimate : EstimateResult
    mu_b : array_like, shape (6,)
        Prior mean of ``b``, Pa.
    V_b : array_like, shape (6, 6)
        Prior covariance of ``b``, Pa^2.
    n_sigma, weak, prior_sigma, floor : float

    Returns
    -------
    Box
    """
    b = np.asarray(estimate.b, dtype=float)
    sd = np.sqrt(np.diag(estimate.covariance_b))
    sd0 = np.sqrt(np.diag(np.asarray(V_b, dtype=float)))
    lower, upper = b - n_sigma * sd, b + n_sigma * sd
    wide = sd > weak * sd0
    mu = np.asarray(mu_b, dtype=float)
    lower[wide] = np.minimum(lower[wide], mu[wide] - prior_sigma * sd0[wide])
    upper[wide] = np.maximum(upper[wide], mu[wide] + prior_sigma * sd0[wide])
    positive = LOG_COEFFICIENTS
    lower[positive] = np.maximum(lower[positive], floor * b[positive])
    cap = 0.99 * math.sqrt(lower[0] * lower[1])
    lower[2], upper[2] = max(lower[2], -cap), min(upper[2], cap)
    return Box(lower, upper)


def prepare(
    case,
    *,
    model=None,
    forward="reduced",
    seed=None,
    convention="paper",
    prior_mean=None,
    prior_sd=None,
    pairing="auto",
    box_sigma=6.0,
    box=None,
    pilot_mesh="auto",
    fast=None,
    fast_options=None,
):
    """The sampler's problem, fast model and MAP for a case.

    Parameters
    ----------
    case : bayesplate.case.Case
    model : PlateModel, optional
        Full model; default ``PlateModel.from_case(case)``.
    forward : {"reduced", "full"}
        Sample with the certified fast model (falling back to the full one where it is not
        certified) or with the full model throughout.
    seed : int, numpy.random.Generator or None
        Seed of the fast model's designs.
    convention : str or Conventions
        As for :func:`bayesplate.estimators.estimate` (default ``"paper"``).
    prior_mean, prior_sd : array_like, shape (6,), optional
        Engineering prior (SI) replacing the case's.
    pairing : {"auto", "mac", "index", "order"} or Pairing
        As for :func:`bayesplate.estimators.estimate` (:func:`bayesplate.pairing.pair_measured`
        at the prior mean); the sampler computes no modes beyond the paired ones.
    box_sigma : float
        Half-width of the posterior box in deviations of the pilot B estimate.
    box : Box, optional
        Explicit box for the fast model (no pilot run).
    pilot_mesh : "auto", None or (nx, ny)
        Mesh of the pilot B run: ``"auto"`` halves meshes above 400 elements (only when the
        model is the case's own); None runs it on ``model``.
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model already built (e.g. shared by several priors); no pilot, no build.
    fast_options : dict, optional
        Keywords of :func:`bayesplate.reduced.fast_model` (default ``FAST_DEFAULTS``).

    Returns
    -------
    SamplingSetup
    """
    if forward not in ("reduced", "full"):
        raise ValueError(f"forward = {forward!r}: must be 'reduced' or 'full'")
    conventions = resolve_conventions(convention)
    own_model = model is None
    model = model or PlateModel.from_case(case)
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    if not isinstance(pairing, Pairing):
        b_prior = laminate.stiffness_from_engineering(mean)
        pairing = pair_measured(case, model, b_prior, pairing)
    pair = replace(pairing, extra=0)
    problem = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    timings = {"pilot": 0.0, "build": 0.0, "map": 0.0}
    pilot, solves = None, 0
    if forward == "reduced" and fast is None:
        if box is None:
            started = time.perf_counter()
            pilot_model = _pilot_model(case, model, pilot_mesh if own_model else None)
            pilot_problem = GaussianProblem.from_case(
                case, pilot_model, pair, conventions.observation, conventions.prior, mean, sd
            )
            pilot = run(pilot_problem, "B", tol=PILOT_TOL, conventions=conventions)
            solves += pilot.n_solves if pilot_model is model else 0
            box = posterior_box(pilot, problem.mu_b, problem.V_b, box_sigma)
            timings["pilot"] = time.perf_counter() - started
            log.info("pilot B (%s): %s", _mesh_text(pilot_model), pilot.message)
        started = time.perf_counter()
        options = {**FAST_DEFAULTS, **(fast_options or {})}
        center = box.center if pilot is None else pilot.b
        fast = fast_model(model, center, box, pair.n_modes(), rng=seed, **options)
        timings["build"] = time.perf_counter() - started
        solves += 1 + options["n_snapshots"] + sum(c.n_test for c in fast.history)
        log.info("fast model: %s", fast.certificate)
    setup = SamplingSetup(problem, model, fast if forward == "reduced" else None, None,
                          pilot, None if fast is None else fast.box, timings, solves)  # fmt: skip
    started = time.perf_counter()
    estimate = _map(setup, conventions)
    timings["map"] = time.perf_counter() - started
    if not estimate.converged:
        log.warning("B (the MAP) did not converge: %s", estimate.message)
    _check_box(setup.box, estimate)
    return replace(setup, estimate=estimate)


def _map(setup, conventions):
    """B to ``MAP_TOL`` on the sampler's model: the MAP and ``P`` (eq. 9)."""
    return _run_on_fast(setup, "B", MAP_TOL, conventions=conventions)


def _run_on_fast(setup, method, tol, **kwargs):
    """B or MVE on the sampler's model, early iterates on the reduced model even off-box.

    The estimators start from the prior mean, outside the posterior box; their early
    iterates only set the path, not the fixed point, so they use the reduced model beyond
    its certified box too (no full solves, no warnings). The fixed point is then checked to
    lie in the box; if it does not, the run is repeated with the full-model fallback.
    """
    fast = setup.fast
    if fast is None or not fast.certified:
        return run(setup.problem_on_fast_model(), method, tol=tol, **kwargs)
    p = setup.problem
    free = GaussianProblem(p.Y, p.V_Y, p.mu_b, p.V_b, fast.reduced.solve, p.pairing)
    result = run(free, method, tol=tol, **kwargs)
    if fast.box.contains(result.b) and result.status != "solve_failed":
        return result
    log.warning("%s ends outside the fast model's box (%s); again with the full fallback",
                method, result.message)  # fmt: skip
    return run(setup.problem_on_fast_model(), method, tol=tol, **kwargs)


def _mesh_text(model):
    mesh = getattr(model, "mesh", None)
    return "model" if mesh is None else f"{mesh.nx} x {mesh.ny} mesh"


def _check_box(box, estimate):
    """Log how far the MAP is from the box's edges, in linearised deviations.

    An edge closer than ``box_sigma`` deviations is a physical cut (a floor of
    :meth:`Box.from_covariance`, where the likelihood usually falls steeply: G23 of the
    Frederiksen plate loses 600 in log-likelihood at the floor, 2.5 deviations below the
    MAP). Walkers beyond an edge are full-model fallbacks, warned about by the fast model
    and counted in the result.
    """
    if box is None:
        return
    sd = np.sqrt(np.diag(estimate.covariance_b))
    low, high = (estimate.b - box.lower) / sd, (box.upper - estimate.b) / sd
    log.info("the MAP is %s (lower) / %s (upper) deviations from the fast model's box "
             "edges", np.round(low, 1), np.round(high, 1))  # fmt: skip


# ----------------------------------------------------------------------------- sampling


def _seeds(seed):
    """``(entropy or None, generator)`` from an int, a Generator or None."""
    if isinstance(seed, np.random.Generator):
        return None, seed
    sequence = np.random.SeedSequence(seed)
    return sequence.entropy, np.random.default_rng(sequence)


class _InBox:
    """``inside(z)``: whether whitened points map into a box of ``b``."""

    def __init__(self, density, box):
        self.density, self.box = density, box

    def __call__(self, z):
        return np.asarray(self.box.contains(self.density.to_b(z)))


def _initial_walkers(density, n_walkers, rng, box=None, tries=1000):
    """``z ~ N(0, I)`` (the B estimate with its covariance), redrawn until physical."""
    z = rng.standard_normal((n_walkers, 6))
    for _ in range(tries):
        b = density.to_b(z)
        bad = ~laminate.is_physical(b)
        if box is not None:
            bad |= ~box.contains(b)
        if not np.any(bad):
            return z
        z[bad] = rng.standard_normal((int(np.sum(bad)), 6))
    raise RuntimeError("could not draw physical initial walkers around the B estimate")


_ATTRS = ("bayesplate_center", "bayesplate_chol", "bayesplate_fingerprint")


def _fingerprint(problem):
    """Numbers identifying a problem: its data, prior and pairing."""
    parts = [problem.Y, np.diag(problem.V_Y), problem.mu_b, problem.V_b.ravel()]
    return np.concatenate([*parts, problem.pairing.modes.astype(float)])


def _backend(path, density, n_walkers):
    """An emcee backend and, for an HDF file that holds a chain, its stored settings.

    A chain of the same problem is resumed (its whitening replaces ``density``'s);
    another problem's is refused.
    """
    if path is None:
        return emcee.backends.Backend(), None
    backend = emcee.backends.HDFBackend(str(path))
    fingerprint = _fingerprint(density.problem)
    if backend.initialized and backend.iteration > 0:
        with backend.open() as f:
            attrs = f[backend.name].attrs
            stored = {k: np.asarray(attrs[k]) for k in attrs if k.startswith("bayesplate_")}
        if not all(k in stored for k in _ATTRS):
            raise ValueError(f"{path}: an emcee chain not written by bayesplate")
        same = stored["bayesplate_fingerprint"].shape == fingerprint.shape and np.allclose(
            stored["bayesplate_fingerprint"], fingerprint, rtol=1e-12, atol=0
        )
        if not same or backend.shape != (n_walkers, 6):
            raise ValueError(
                f"{path} holds a chain of another problem or ensemble size "
                f"{backend.shape[0]} walkers; use another file to start afresh"
            )
        density.center = stored["bayesplate_center"]
        density.chol = stored["bayesplate_chol"]
        return backend, stored
    backend.reset(n_walkers, 6)
    _store(backend, center=density.center, chol=density.chol, fingerprint=fingerprint)
    return backend, None


def _store(backend, **values):
    """Write ``bayesplate_*`` attributes to an HDF backend (nothing for one in memory)."""
    if not isinstance(backend, emcee.backends.HDFBackend):
        return
    with backend.open("a") as f:
        for key, value in values.items():
            f[backend.name].attrs[f"bayesplate_{key}"] = value


def _store_tuning(backend, move, n_tune):
    """Record the frozen proposal and the end of tuning, for a resumed run."""
    if move is None or move.mean is None:
        _store(backend, tuned_at=n_tune)
    else:
        _store(backend, tuned_at=n_tune, proposal_mean=move.mean, proposal_chol=move.chol)


def _restore_tuning(stored, move):
    """The end of tuning of a resumed chain (its proposal set on ``move``), or None."""
    if stored is None or "bayesplate_tuned_at" not in stored:
        return None
    if move is not None and "bayesplate_proposal_mean" in stored:
        move.mean = stored["bayesplate_proposal_mean"]
        move.chol = stored["bayesplate_proposal_chol"]
    return int(stored["bayesplate_tuned_at"])


def _engineering(density, chain_z):
    """Engineering constants (SI) of a chain in whitened coordinates, same leading shape."""
    return laminate.engineering_from_stiffness(density.to_b(chain_z))


def _arviz():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # ArviZ announces its refactor
        import arviz

    return arviz


def _diagnostics(e_walker_draw):
    """Smallest bulk ESS and largest R-hat over the constants; ``e`` (walkers, draws, 6)."""
    az = _arviz()
    ess = min(float(az.ess(e_walker_draw[..., j])) for j in range(6))
    rhat = max(float(az.rhat(e_walker_draw[..., j])) for j in range(6))
    return ess, rhat


def _progress_bar(progress, total, initial):
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover - tqdm comes with the test environment
        return None
    return tqdm(total=total, initial=initial, desc="sampling", unit="step", leave=False)


def _tau(sampler, discard=0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # short chains: all NaN before steps
        tau = sampler.get_autocorr_time(discard=discard, tol=0)
    return np.where(np.isfinite(tau), tau, np.inf)


def _burn(n_tune, tau_max, n):
    """Steps discarded: the tuning rounds and ``BURN_TAU`` autocorrelation times after."""
    extra = math.ceil(BURN_TAU * tau_max) if np.isfinite(tau_max) else (n - n_tune) // 2
    return n_tune + min(extra, (n - n_tune) // 2)


def _run_chain(sampler, state, max_steps, check_every, stop, bar, n_tune):
    """Advance ``check_every`` steps at a time until ``stop(sampler)`` or ``max_steps``."""
    history = []
    converged = False
    while sampler.iteration < max_steps:
        steps = min(check_every, max_steps - sampler.iteration)
        state = sampler.run_mcmc(state, steps, progress=False, skip_initial_state_check=True)
        tau = _tau(sampler, n_tune)
        history.append([sampler.iteration, *tau])
        converged, note = stop(sampler, tau)
        if bar is not None:
            bar.update(steps)
            bar.set_postfix_str(note, refresh=False)
        if converged:
            break
    return state, np.array(history).reshape(-1, 7), converged


def _tune(sampler, state, move, rounds, steps, max_steps, bar):
    """Rounds of ``steps``; after each, ``move`` proposes from the ensemble's last half.

    Returns the state and the step at which the proposal was frozen (the burn-in).
    """
    for _ in range(rounds):
        steps = min(steps, max_steps - sampler.iteration)
        if steps < 4:
            break
        state = sampler.run_mcmc(state, steps, progress=False, skip_initial_state_check=True)
        z = sampler.get_chain(discard=sampler.iteration - steps // 2).reshape(-1, 6)
        move.set_proposal(z.mean(axis=0), np.cov(z, rowvar=False))
        if bar is not None:
            bar.update(steps)
            bar.set_postfix_str("tuning", refresh=False)
    return state, sampler.iteration


def _laplace_move(moves):
    found = [m for m in moves if isinstance(m, LaplaceMove)]
    return found[0] if found else None


def sample_problem(
    problem,
    center,
    covariance,
    *,
    seed=None,
    n_walkers=32,
    max_steps=5000,
    target_tau_factor=50.0,
    min_ess=2000.0,
    max_rhat=1.01,
    check_every=20,
    tune_rounds=TUNE_ROUNDS,
    tune_steps=TUNE_STEPS,
    pool=None,
    backend_path=None,
    progress=True,
    moves=None,
    forward=None,
    box=None,
):
    """Sample ``ln f(b | Y)`` of a Gaussian problem with emcee, whitened around ``center``.

    Parameters
    ----------
    problem : GaussianProblem
    center : array_like, shape (6,)
        Centre of the whitening and of the initial walkers (the MAP), Pa.
    covariance : array_like, shape (6, 6)
        Whitening and initial spread (``P`` of the B estimate), Pa^2.
    seed : int, numpy.random.Generator or None
        Seeds the initial walkers and emcee's random state (a ``RandomState`` seeded with
        an integer drawn from it): the same seed gives the same chain.
    n_walkers : int
        Walkers (at least 12).
    max_steps : int
        Cap on the chain length (steps in the backend, resumed ones included).
    target_tau_factor : float
        Stop once the chain after tuning is longer than this many autocorrelation times...
    min_ess : float
        ... and the smallest bulk ESS of the constants after burn-in reaches this...
    max_rhat : float
        ... and the largest R-hat (walkers as chains) is below this.
    check_every : int
        Steps between checks of the stopping rule.
    tune_rounds, tune_steps : int
        Tuning: rounds of ``tune_steps`` steps after each of which the
        :class:`LaplaceMove` proposes from the mean and covariance of the ensemble over the
        round's second half; then the proposal is frozen and the tuning steps discarded.
        Without a :class:`LaplaceMove` among the moves there is no tuning.
    pool : object with ``map``, optional
        E.g. a ``multiprocessing.Pool``; the log-density (problem and model) is pickled
        with every batch of proposals, which pays for slow models only.
    backend_path : path, optional
        HDF5 file (emcee ``HDFBackend``) holding the chain; if it holds one of the same
        problem, the run continues it (same coordinates, proposal and random state).
    progress : bool
        Progress bar (tqdm) with the current ``tau`` and ESS.
    moves : list, optional
        emcee moves; default :func:`default_moves`.
    forward : callable, optional
        ``forward(b, n_modes)`` replacing the problem's (e.g. an eigenvalues-only path).
    box : Box, optional
        The fast model's box: initial walkers and the Laplace proposals (default moves)
        are drawn inside it, and DE proposals outside it are screened.

    Returns
    -------
    SamplingResult
        Without ``estimate``, ``certificate`` and fast-model counts (see :func:`sample`).
    """
    if n_walkers < 12:
        raise ValueError(f"n_walkers = {n_walkers}: need at least 12 (twice the dimension)")
    entropy, rng = _seeds(seed)
    density = WhitenedLogPosterior(problem, center, covariance, forward)
    backend, stored = _backend(backend_path, density, n_walkers)
    if moves is None:
        inside = None if box is None else _InBox(density, box)
        reduced = getattr(forward, "reduced", None)
        screen = None if box is None or reduced is None else _RitzScreen(density, reduced, box)
        moves = default_moves(inside, screen)
    laplace = _laplace_move([m[0] if isinstance(m, tuple) else m for m in moves])
    sampler = emcee.EnsembleSampler(n_walkers, 6, density, pool=pool, moves=moves, backend=backend)
    emcee_seed = int(rng.integers(2**32))
    resumed = stored is not None
    if resumed:
        state = backend.get_last_sample()
        log.info("resuming %s at step %d", backend_path, backend.iteration)
    else:
        sampler.random_state = np.random.RandomState(emcee_seed).get_state()
        state = emcee.State(_initial_walkers(density, n_walkers, rng, box))
    started, steps0, forward0 = time.perf_counter(), sampler.iteration, density.n_forward
    bar = _progress_bar(progress, max_steps, sampler.iteration)
    # the reduced model solves small dense eigenproblems: BLAS threads only slow them down
    # (up to ten times on a busy machine, reports/benchmark_reduced.md)
    limits = threadpool_limits(limits=1, user_api="blas")
    try:
        n_tune = _restore_tuning(stored, laplace)
        if n_tune is None:
            rounds = tune_rounds if laplace is not None else 0
            state, n_tune = _tune(sampler, state, laplace, rounds, tune_steps, max_steps, bar)
            _store_tuning(backend, laplace, n_tune)

        def stop(sampler, tau):
            n = sampler.iteration - n_tune
            tau_max = float(np.max(tau))
            if not np.isfinite(tau_max) or n <= target_tau_factor * tau_max:
                return False, f"tau {tau_max:.1f}"
            chain = sampler.get_chain(discard=_burn(n_tune, tau_max, sampler.iteration))
            ess, rhat = _diagnostics(_engineering(density, chain).swapaxes(0, 1))
            done = ess >= min_ess and rhat < max_rhat
            return done, f"tau {tau_max:.1f}, ESS {ess:.0f}, R-hat {rhat:.3f}"

        state, history, converged = _run_chain(
            sampler, state, max_steps, check_every, stop, bar, n_tune
        )
    finally:
        limits.restore_original_limits()
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - started
    n_eval = n_walkers * (sampler.iteration - steps0 + (0 if resumed else 1))
    settings = {
        "seed_entropy": entropy,
        "emcee_seed": None if resumed else emcee_seed,
        "n_walkers": n_walkers,
        "max_steps": max_steps,
        "target_tau_factor": target_tau_factor,
        "min_ess": min_ess,
        "max_rhat": max_rhat,
        "check_every": check_every,
        "n_tune": n_tune,
        "moves": [type(m).__name__ for m in sampler._moves],
        "move_weights": list(map(float, sampler._weights)),
        "backend": None if backend_path is None else str(backend_path),
        "resumed": resumed,
        "center_b": density.center,
        "chol_b": density.chol,
    }
    result = _result(sampler, density, history, converged, wall, n_eval, forward0, settings)
    screened = sum(getattr(m, "n_screened", 0) for m in sampler._moves)
    return replace(result, n_screened=screened, n_evaluations=n_eval - screened)


def _result(sampler, density, history, converged, wall, n_eval, forward0, settings):
    """A :class:`SamplingResult` from a finished sampler."""
    n_tune = settings["n_tune"]
    tau = _tau(sampler, n_tune)
    n = sampler.iteration
    tau_max = float(np.max(tau))
    burn = _burn(n_tune, tau_max, n)
    chain = sampler.get_chain(discard=burn)  # (draws, walkers, 6)
    idata = _inference_data(density, chain, sampler.get_log_prob(discard=burn),
                            sampler.get_blobs(discard=burn), settings)  # fmt: skip
    az = _arviz()
    summary = az.summary(
        idata, var_names=list(ENGINEERING_KEYS), hdi_prob=HDI_PROB, round_to="none"
    )
    b = density.to_b(chain).reshape(-1, 6)
    e = laminate.engineering_from_stiffness(b)
    cols = list(ENGINEERING_KEYS)
    scale = CASE_UNITS
    if converged:
        message = (
            f"converged: {n - n_tune} steps after tuning > {settings['target_tau_factor']:g} "
            f"tau (max {tau_max:.1f}), ESS >= {settings['min_ess']:g}, R-hat < "
            f"{settings['max_rhat']:g}"
        )
    else:
        message = f"step cap {settings['max_steps']} reached before the stopping rule was met"
    return SamplingResult(
        idata=idata,
        summary=summary,
        mean=summary.loc[cols, "mean"].to_numpy() / scale,
        sd=summary.loc[cols, "sd"].to_numpy() / scale,
        hdi=np.vstack(
            [summary.loc[cols, "hdi_3%"].to_numpy(), summary.loc[cols, "hdi_97%"].to_numpy()]
        )
        / scale,
        covariance=np.cov(e, rowvar=False),
        mean_b=b.mean(axis=0),
        covariance_b=np.cov(b, rowvar=False),
        samples_b=b,
        ess_bulk=summary.loc[cols, "ess_bulk"].to_numpy(),
        ess_tail=summary.loc[cols, "ess_tail"].to_numpy(),
        rhat=summary.loc[cols, "r_hat"].to_numpy(),
        ess_min=float(summary.loc[cols, "ess_bulk"].min()),
        rhat_max=float(summary.loc[cols, "r_hat"].max()),
        chain=_engineering(density, sampler.get_chain()).swapaxes(0, 1) * CASE_UNITS,
        acf=_acf(e.reshape(chain.shape), tau_max),
        tau=tau,
        tau_constants=emcee.autocorr.integrated_time(e.reshape(chain.shape), quiet=True),
        tau_history=history,
        n_steps=n,
        n_burn=burn,
        n_walkers=sampler.nwalkers,
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        converged=converged,
        message=message,
        wall_time=wall,
        n_evaluations=n_eval,
        n_forward=density.n_forward - forward0,
        settings=settings,
    )


def _acf(chain, tau_max, lags=10.0):
    """Walker-averaged autocorrelation of each coordinate up to ``lags`` tau (>= 20 steps)."""
    n = chain.shape[0]
    k = min(n, max(20, int(lags * tau_max) if np.isfinite(tau_max) else n))
    acf = np.zeros((chain.shape[2], k))
    for j in range(chain.shape[2]):
        for w in range(chain.shape[1]):
            acf[j] += emcee.autocorr.function_1d(chain[:, w, j])[:k]
    return acf / chain.shape[1]


def _measured_numbers(problem):
    """1-based numbers of the measured frequencies in ``Y`` (paired ones only)."""
    kept = problem.pairing.measured
    return np.arange(1, problem.m + 1) if kept is None else np.asarray(kept) + 1


def _inference_data(density, chain, lp, blobs, settings):
    """ArviZ data: engineering constants (case units), pointwise log-likelihood, lp."""
    az = _arviz()
    e = _engineering(density, chain).swapaxes(0, 1) * CASE_UNITS  # (walkers, draws, 6)
    problem = density.problem
    f = np.sqrt(problem.Y) / (2 * np.pi)
    sigma_f = np.sqrt(np.diag(problem.V_Y)) / (8 * np.pi**2 * f)
    return az.from_dict(
        posterior={key: e[..., j] for j, key in enumerate(ENGINEERING_KEYS)},
        log_likelihood={"Y": np.asarray(blobs, dtype=float).swapaxes(0, 1)},
        sample_stats={"lp": (np.asarray(lp) - density.log_jacobian(chain)).T},
        observed_data={"Y": problem.Y},
        constant_data={"frequency_Hz": f, "sigma_Hz": sigma_f},
        coords={"mode": _measured_numbers(problem)},
        dims={"Y": ["mode"], "frequency_Hz": ["mode"], "sigma_Hz": ["mode"]},
        attrs={
            "units": "moduli in GPa, nu12 dimensionless; Y in rad^2/s^2",
            "sampler": "emcee " + emcee.__version__,
            "walkers_as_chains": 1,
            "seed_entropy": str(settings.get("seed_entropy")),
        },
    )


def sample(
    case,
    seed=None,
    n_walkers=32,
    max_steps=5000,
    target_tau_factor=50.0,
    min_ess=2000.0,
    check_every=20,
    pool=None,
    backend_path=None,
    progress=True,
    *,
    max_rhat=1.01,
    setup=None,
    moves=None,
    **prepare_options,
):
    """Sample the posterior of a case's elastic constants (the estimators' problem).

    Parameters
    ----------
    case : bayesplate.case.Case
    seed : int, numpy.random.Generator or None
        Seeds the fast model's designs, the initial walkers and emcee: same seed, same chain.
    n_walkers, max_steps, target_tau_factor, min_ess, check_every, pool, backend_path, \
progress, max_rhat, moves
        See :func:`sample_problem`.
    setup : SamplingSetup, optional
        From :func:`prepare` (skips the pilot, the fast model and the MAP).
    **prepare_options
        Keywords of :func:`prepare` (``model``, ``forward``, ``convention``, ``prior_mean``,
        ``prior_sd``, ``pairing``, ``box_sigma``, ``box``, ``pilot_mesh``, ``fast``,
        ``fast_options``).

    Returns
    -------
    SamplingResult
    """
    started = time.perf_counter()
    entropy, rng = _seeds(seed)
    build_rng, walk_rng = rng.spawn(2)
    given = setup is not None
    setup = setup or prepare(case, seed=build_rng, **prepare_options)
    fast = setup.fast
    fallbacks0 = dict(fast.fallbacks) if fast is not None else {}
    est = setup.estimate
    result = sample_problem(
        setup.problem,
        est.b,
        est.covariance_b,
        seed=walk_rng,
        n_walkers=n_walkers,
        max_steps=max_steps,
        target_tau_factor=target_tau_factor,
        min_ess=min_ess,
        max_rhat=max_rhat,
        check_every=check_every,
        pool=pool,
        backend_path=backend_path,
        progress=progress,
        moves=moves,
        forward=setup.sampling_forward(),
        box=setup.box,
    )
    fallbacks = {}
    if fast is not None:
        fallbacks = {k: fast.fallbacks[k] - fallbacks0.get(k, 0) for k in fast.fallbacks}
    n_full = result.n_forward if fast is None else sum(fallbacks.values())
    timings = {**setup.timings, "sampling": result.wall_time}
    # total: the setup's time too when it was prepared beforehand
    timings["total"] = time.perf_counter() - started + (sum(setup.timings.values()) if given else 0)
    settings = {**result.settings, "seed_entropy": entropy, "case": case.name,
                "box_lower": None if setup.box is None else setup.box.lower,
                "box_upper": None if setup.box is None else setup.box.upper,
                "full_solves_setup": setup.n_full_solves}  # fmt: skip
    return replace(
        result,
        n_full=n_full,
        fallbacks=fallbacks,
        certificate=setup.certificate,
        estimate=est,
        timings=timings,
        settings=settings,
    )


# ----------------------------------------------------------------------------- checks


def engineering_covariance(b, covariance_b):
    """First-order ``J^-1 cov_b J^-T`` with ``J = d b / d e`` at ``b`` (as the estimators)."""
    J_inv = np.linalg.inv(laminate.stiffness_jacobian(laminate.engineering_from_stiffness(b)))
    return J_inv @ np.asarray(covariance_b, dtype=float) @ J_inv.T


def curvature_covariance(problem, b, covariance, step=0.05):
    """Laplace covariance with the full Hessian of ``ln f(b | Y)`` at ``b`` (the MAP).

    B's ``P`` (eq. 9) is the Gauss-Newton inverse curvature: it drops the term
    ``sum_i r_i (V_Y^-1)_ii d^2 g_i / db^2`` of the residuals ``r = Y - g``, which matters
    when the residuals are large (a prior that pulls the fit away from the data). Here the
    Hessian is taken by central differences of :meth:`GaussianProblem.log_posterior` along
    ``b = b_MAP + L y`` with ``L L^T = covariance``, where it is close to the identity: the
    truncation error is O(``step``^2) relative (~2e-3 for 0.05) and the rounding
    ~1e-16 |ln f| / step^2. An independent check of ``P``, no sampling involved.

    Parameters
    ----------
    problem : GaussianProblem
        E.g. :meth:`SamplingSetup.problem_on_fast_model`.
    b : array_like, shape (6,)
        The MAP, Pa.
    covariance : array_like, shape (6, 6)
        ``P``, Pa^2: sets the directions and scale of the steps.
    step : float
        Difference step in units of ``L``.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        Covariance of ``b``, Pa^2.
    """
    b = np.asarray(b, dtype=float)
    L = np.linalg.cholesky(np.asarray(covariance, dtype=float))
    eye = step * np.eye(6)

    def f(y):
        return problem.log_posterior(b + L @ y)

    H = np.zeros((6, 6))
    for i in range(6):
        for j in range(i, 6):
            a, c = eye[i], eye[j]
            H[i, j] = H[j, i] = -(f(a + c) - f(a - c) - f(c - a) + f(-a - c)) / (4 * step**2)
    return L @ np.linalg.inv(H) @ L.T


def linearisation_band(problem, b, covariance_b):
    """How much B's deviations change over one deviation around the MAP, per constant.

    ``P`` of eq. 9 is recomputed at ``b +- L_k`` (the columns of ``chol(P)``, 12 points)
    and carried to the engineering constants; the largest relative change of each
    deviation measures the nonlinearity of the problem over the bulk of the posterior, an
    error of the linearised covariance that needs no sampling.

    Parameters
    ----------
    problem : GaussianProblem
        On a model with sensitivities (e.g. :meth:`SamplingSetup.problem_on_fast_model`).
    b : array_like, shape (6,)
        The MAP, Pa.
    covariance_b : array_like, shape (6, 6)
        ``P`` at the MAP, Pa^2.

    Returns
    -------
    numpy.ndarray, shape (6,)
        ``max_k |sd_i(b +- L_k) / sd_i(b) - 1|`` for ``(E1, E2, nu12, G12, G13, G23)``.
    """
    b = np.asarray(b, dtype=float)
    L = np.linalg.cholesky(np.asarray(covariance_b, dtype=float))
    sd0 = np.sqrt(np.diag(engineering_covariance(b, covariance_b)))
    change = []
    for k in range(6):
        for sign in (1.0, -1.0):
            point = b + sign * L[:, k]
            p = problem.predict(point)
            P = b_step(point, problem.mu_b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)[1]
            change.append(np.sqrt(np.diag(engineering_covariance(point, P))) / sd0 - 1)
    return np.max(np.abs(change), axis=0)


def covariance_agreement(result, covariance, n_mc=4.0):
    """Sampled deviations and correlations against a Gaussian approximation's, with bands.

    The Monte Carlo error of a sampled deviation is ``sd / sqrt(2 ESS)`` and of a
    correlation ``(1 - rho^2) / sqrt(ESS)`` (the Gaussian formulas, ESS the bulk ESS, the
    smaller of the pair); they agree when the difference is within ``n_mc`` of them.

    Parameters
    ----------
    result : SamplingResult
    covariance : array_like, shape (6, 6)
        Engineering covariance to compare with (e.g. ``EstimateResult.covariance``), SI.
    n_mc : float
        Monte Carlo errors allowed.

    Returns
    -------
    dict
        ``sd_sampled``, ``sd_linear``, ``ratio``, ``band`` (allowed ``|ratio - 1|``),
        ``sd_agrees`` (6,); ``corr_sampled``, ``corr_linear``, ``corr_band``,
        ``corr_agrees`` (6, 6).
    """
    ess = np.asarray(result.ess_bulk, dtype=float)
    cov = np.asarray(covariance, dtype=float)
    sd_s = np.sqrt(np.diag(result.covariance))
    sd_l = np.sqrt(np.diag(cov))
    ratio = sd_s / sd_l
    band = n_mc / np.sqrt(2 * ess)
    corr_s = result.covariance / np.outer(sd_s, sd_s)
    corr_l = cov / np.outer(sd_l, sd_l)
    corr_band = n_mc * (1 - corr_l**2) / np.sqrt(np.minimum.outer(ess, ess))
    np.fill_diagonal(corr_band, 0.0)
    return {
        "sd_sampled": sd_s,
        "sd_linear": sd_l,
        "ratio": ratio,
        "band": band,
        "sd_agrees": np.abs(ratio - 1) <= band,
        "corr_sampled": corr_s,
        "corr_linear": corr_l,
        "corr_band": corr_band,
        "corr_agrees": np.abs(corr_s - corr_l) <= corr_band + 1e-12,
    }
