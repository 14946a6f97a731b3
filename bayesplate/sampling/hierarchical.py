"""One material, many plates, each a little different: the hierarchical posterior.

Each plate's engineering constants ``c_p`` (``E1, E2, nu12, G12, G13, G23``, all positive)
are drawn around the material's mean ``mu`` with a spread ``tau`` per constant, log-normal
and non-centred:

    ln c_p = ln mu + tau * eta_p,   eta_p ~ N(0, I),   p = 1..P.

Priors: ``mu`` has the first case's prior, the one the shared-constants form puts on ``b``
(:meth:`GaussianProblem.log_prior` of ``b(mu)``, carried to ``ln mu`` with its Jacobian), so
that ``tau -> 0`` is the shared form; each ``tau_k`` is half-normal with scale
:data:`TAU_SCALE` (0.1: a plate-to-plate spread of about 10 % is plausible, 25 % very
unlikely, P(tau > 0.2) = 4.6 %), weakly informative. Each plate's likelihood is on its own
certified fast model at ``b(c_p)``, as in the shared form.

The sampler moves in ``theta = (ln mu, ln tau, eta_1, ..., eta_P)`` (``6 + 6 + 6 P``: 30 for
three plates), whitened by the Laplace approximation at the MAP (L-BFGS, then a
finite-difference Hessian), with the one-plate sampler's moves (independence proposal
tuned on the ensemble, differential evolution), tuning, stopping rule (ESS and R-hat of the
material's mean constants, autocorrelation of every coordinate) and run loop
(:mod:`bayesplate.sampling.chain`). The independence proposals are truncated to points
whose every plate lies in its fast model's box; DE proposals outside use the full-model
fallback.

Convergence: the non-centred form suits the weakly identified constants (``tau`` and
``eta`` of G13 and G23 are the prior's); the well-identified ones (E1, E2, G12) make
``eta_p`` and ``tau`` strongly dependent (a narrow ridge ``tau eta_p = const``), which the
tuned proposal only partly follows. Sampling those centred instead (``centred``: ``ln c_p``
itself, the same posterior) was worse on these plates (1000 steps: R-hat 3.3 against 1.95
non-centred): the MAP that whitens the coordinates then sits in the funnel's neck (``tau``
of E1 near 0.001), so it is an option, not the default. On the three plates of
``studies/many_plates.py`` (30 dimensions, 62 walkers) 5000 steps took 18 minutes (load
about 6, 2026-11-25) and ended with the largest autocorrelation time at 490 steps, ESS 91
and R-hat 1.80: the hierarchical chain does not converge in reasonable time on these
plates, and the shared-constants form (:mod:`bayesplate.sampling.joint`) stays the default.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import emcee
import numpy as np
from scipy import optimize
from threadpoolctl import threadpool_limits

from .. import laminate
from .chain import TUNE_ROUNDS, TUNE_STEPS, _progress_bar, _run_chain, _tune
from .moves import LaplaceMove
from .seeding import generator, resolve_rng
from .stopping import StoppingRule, burn_in, diagnostics

__all__ = ["TAU_SCALE", "HierarchicalDensity", "HierarchicalResult", "sample_hierarchical"]

#: Scale of the half-normal prior of each ``tau`` (the spread of ``ln c`` between plates).
TAU_SCALE = 0.1


class HierarchicalDensity:
    """``ln f(theta | Y_1..Y_P)`` in whitened coordinates ``u``: ``theta = centre + L u``.

    Parameters
    ----------
    setups : sequence of SamplingSetup
        The plates (their problems and fast models).
    tau_scale : float
        Half-normal scale of each ``tau``.
    centred : array_like of bool, shape (6,), optional
        Constants sampled centred (``theta`` holds ``ln c_p`` itself, with the density's
        ``1 / tau``); default none (non-centred throughout).

    Attributes
    ----------
    P : int
        Plates.
    dim : int
        ``12 + 6 P``.
    centre, chol : numpy.ndarray, shapes (dim,), (dim, dim)
        The whitening (identity until :meth:`whiten`).
    n_forward : int
        Plate-model evaluations.
    """

    def __init__(self, setups, tau_scale=TAU_SCALE, centred=None):
        self.centred = np.zeros(6, dtype=bool) if centred is None else np.asarray(centred, bool)
        self.setups = tuple(setups)
        self.P = len(self.setups)
        self.dim = 12 + 6 * self.P
        self.tau_scale = float(tau_scale)
        self.problems = [s.problem.with_forward(s.sampling_forward()) for s in self.setups]
        self.prior = self.setups[0].problem
        self.boxes = [None if s.fast is None else s.fast.box for s in self.setups]
        self.centre, self.chol = np.zeros(self.dim), np.eye(self.dim)
        self.n_forward = 0

    def split(self, theta):
        """``(ln mu (6,), ln tau (6,), eta (P, 6))`` of ``theta`` (dim,)."""
        theta = np.asarray(theta, dtype=float)
        log_mu, log_tau = theta[:6], theta[6:12]
        raw = theta[12:].reshape(self.P, 6)
        eta = np.where(self.centred, (raw - log_mu) / np.exp(log_tau), raw)
        return log_mu, log_tau, eta

    def pack(self, log_mu, log_tau, eta):
        """``theta`` (dim,) of ``ln mu`` (6,), ``ln tau`` (6,) and ``eta`` (P, 6)."""
        eta = np.asarray(eta, dtype=float).reshape(self.P, 6)
        raw = np.where(self.centred, log_mu + np.exp(log_tau) * eta, eta)
        return np.concatenate([log_mu, log_tau, raw.ravel()])

    def plate_constants(self, theta):
        """Each plate's constants ``c_p`` (SI), shape (P, 6)."""
        theta = np.asarray(theta, dtype=float)
        log_mu, log_tau = theta[:6], theta[6:12]
        raw = theta[12:].reshape(self.P, 6)
        return np.exp(np.where(self.centred, raw, log_mu + np.exp(log_tau) * raw))

    def theta(self, u):
        """``theta`` of whitened ``u``, shape (..., dim)."""
        return self.centre + np.asarray(u, dtype=float) @ self.chol.T

    def to_b(self, u):
        """Stiffness of the material's mean ``b(mu)`` (Pa) of whitened points (..., 6)."""
        return laminate.stiffness_from_engineering(np.exp(self.theta(u)[..., :6]))

    def log_density_theta(self, theta):
        """``ln f(theta | Y)`` up to a constant; -inf where a lamina is not physical."""
        log_mu, log_tau, eta = self.split(theta)
        mu = np.exp(log_mu)
        b_mu = laminate.stiffness_from_engineering(mu)
        lp = self.prior.log_prior(b_mu)
        if not np.isfinite(lp):
            return -np.inf
        lp += np.linalg.slogdet(laminate.stiffness_jacobian(mu))[1] + np.sum(log_mu)
        tau = np.exp(log_tau)
        lp += np.sum(-0.5 * (tau / self.tau_scale) ** 2 + log_tau)  # half-normal, in ln tau
        lp += -0.5 * np.sum(eta**2) - self.P * np.sum(log_tau[self.centred])  # centred: 1/tau
        for problem, c in zip(self.problems, self.plate_constants(theta), strict=True):
            b = laminate.stiffness_from_engineering(c)
            if not laminate.is_physical(b):
                return -np.inf
            self.n_forward += 1
            lp += problem.log_likelihood(b)
        return float(lp)

    def __call__(self, u):
        """``ln f`` at whitened ``u`` (dim,) (the whitening's Jacobian is a constant)."""
        return self.log_density_theta(self.theta(u))

    def inside(self, u):
        """Whether every plate of each row of `u` (n, dim) is in its fast model's box, (n,)."""
        out = np.ones(len(u), dtype=bool)
        for k, row in enumerate(np.atleast_2d(u)):
            c = self.plate_constants(self.theta(row))
            b = laminate.stiffness_from_engineering(c)
            out[k] = all(
                box is None or box.contains(bp) for box, bp in zip(self.boxes, b, strict=True)
            )
        return out

    def start(self, singles):
        """A first ``theta``: the plates' own estimates' log-mean, spread and offsets."""
        logs = np.log([s.constants for s in singles])
        log_mu = logs.mean(axis=0)
        tau = np.maximum(logs.std(axis=0), 0.2 * self.tau_scale)
        return self.pack(log_mu, np.log(tau), (logs - log_mu) / tau)

    def whiten(self, theta0, step=1e-3):
        """Centre at the MAP from `theta0` and whiten by the inverse Hessian there."""
        f = lambda t: -self.log_density_theta(t)  # noqa: E731
        best = optimize.minimize(f, theta0, method="L-BFGS-B", options={"maxiter": 2000})
        theta = best.x if np.isfinite(best.fun) and best.fun <= f(theta0) else theta0
        H = _hessian(f, theta, step)
        w, V = np.linalg.eigh(0.5 * (H + H.T))
        w = np.maximum(w, 1e-2)  # flat directions: unit scale (ln tau, eta of the prior)
        cov = (V / w) @ V.T
        self.centre, self.chol = theta, np.linalg.cholesky(cov)
        return theta


def _hessian(f, x, h):
    """Central finite-difference Hessian of `f` at `x` (step `h` in every coordinate)."""
    n = x.size
    H = np.zeros((n, n))
    f0 = f(x)
    E = np.eye(n) * h
    fp = np.array([f(x + E[i]) for i in range(n)])
    fm = np.array([f(x - E[i]) for i in range(n)])
    for i in range(n):
        H[i, i] = (fp[i] - 2 * f0 + fm[i]) / h**2
        for j in range(i + 1, n):
            H[i, j] = H[j, i] = (
                f(x + E[i] + E[j]) - fp[i] - fp[j] + 2 * f0 - fm[i] - fm[j] + f(x - E[i] - E[j])
            ) / (2 * h**2)
    return H


@dataclass(frozen=True, eq=False)
class HierarchicalResult:
    """The hierarchical posterior: the material's mean, the spread, each plate's constants.

    Attributes
    ----------
    mean, sd : numpy.ndarray, shape (6,)
        Posterior mean and deviation of the material's mean constants ``mu``, SI.
    hdi : numpy.ndarray, shape (2, 6)
        Its 3 % and 97 % quantiles (equal-tailed 94 %), SI.
    tau_mean, tau_hdi : numpy.ndarray, shapes (6,), (2, 6)
        The spread ``tau`` per constant (of ``ln c``: 0.05 is about 5 %): mean and 3 %,
        97 % quantiles.
    plate_mean, plate_sd : numpy.ndarray, shape (P, 6)
        Each plate's constants, SI.
    samples : numpy.ndarray, shape (draws, 12 + 6 P)
        Kept draws of ``theta`` (``ln mu``, ``ln tau``, ``eta``).
    ess_min, rhat_max : float
        Of the material's mean constants.
    tau_max : float
        Largest autocorrelation time over every coordinate, steps.
    n_steps, n_burn, n_walkers : int
    converged : bool
    status : str
        ``"converged"`` or ``"max_steps"``.
    wall_time : float
    """

    mean: np.ndarray
    sd: np.ndarray
    hdi: np.ndarray
    tau_mean: np.ndarray
    tau_hdi: np.ndarray
    plate_mean: np.ndarray
    plate_sd: np.ndarray
    samples: np.ndarray = field(repr=False)
    ess_min: float
    rhat_max: float
    tau_max: float
    n_steps: int
    n_burn: int
    n_walkers: int
    converged: bool
    status: str
    wall_time: float


def sample_hierarchical(setups, singles, rng=None, n_walkers=None, max_steps=5000,
                        target_tau_factor=50.0, min_ess=2000.0, max_rhat=1.01, check_every=20,
                        tau_scale=TAU_SCALE, centred=None, progress=False):  # fmt: skip
    """Sample the hierarchical posterior of plates of one material (module docstring).

    Parameters
    ----------
    setups : sequence of SamplingSetup
        The plates (e.g. :attr:`JointSetup.setups`).
    singles : sequence of EstimateResult
        Each plate's own estimate (the start).
    rng : int, numpy.random.Generator or None
        Seeds the initial walkers and emcee.
    n_walkers : int, optional
        Default twice the dimension plus two.
    max_steps, target_tau_factor, min_ess, max_rhat, check_every
        As for :func:`~bayesplate.sampling.chain.sample_problem`.
    tau_scale : float
        Half-normal scale of each ``tau``.
    centred : array_like of bool, shape (6,), optional
        Constants sampled centred; default none (non-centred throughout, as the issue asks).
    progress : bool
        Progress bar.

    Returns
    -------
    HierarchicalResult
    """
    started = time.perf_counter()
    rng = generator(resolve_rng(rng, None, "sample_hierarchical"))[1]
    density = HierarchicalDensity(setups, tau_scale, centred)
    limits = threadpool_limits(limits=1, user_api="blas")
    try:
        density.whiten(density.start(singles))
        d = density.dim
        n_walkers = n_walkers or 2 * d + 2
        laplace = LaplaceMove(1.1, density.inside, df=10)
        moves = [(laplace, 0.9), (emcee.moves.DEMove(), 0.1)]
        sampler = emcee.EnsembleSampler(n_walkers, d, density, moves=moves)
        sampler.random_state = np.random.RandomState(int(rng.integers(2**32))).get_state()
        u0 = 0.3 * rng.standard_normal((n_walkers, d))
        state = emcee.State(u0)
        bar = _progress_bar(progress, max_steps, 0)
        state, n_tune = _tune(sampler, state, laplace, TUNE_ROUNDS, TUNE_STEPS, max_steps, bar)
        stop = StoppingRule(density, n_tune, target_tau_factor, min_ess, max_rhat)
        state, history, converged = _run_chain(sampler, state, max_steps, check_every, stop,
                                               bar, n_tune)  # fmt: skip
        if bar is not None:
            bar.close()
    finally:
        limits.restore_original_limits()
    tau = history[-1, 1:] if len(history) else np.full(d, np.inf)
    tau_max = float(np.max(tau))
    burn = burn_in(n_tune, tau_max, sampler.iteration)
    u = sampler.get_chain(discard=burn)  # (steps, walkers, d)
    theta = density.theta(u)
    mu = np.exp(theta[..., :6])
    ess, rhat = diagnostics(mu.swapaxes(0, 1))
    flat = theta.reshape(-1, d)
    mu_flat, tau_flat = np.exp(flat[:, :6]), np.exp(flat[:, 6:12])
    plates = np.array([density.plate_constants(t) for t in flat])
    q = [3, 97]
    return HierarchicalResult(
        mean=mu_flat.mean(axis=0), sd=mu_flat.std(axis=0, ddof=1),
        hdi=np.percentile(mu_flat, q, axis=0), tau_mean=tau_flat.mean(axis=0),
        tau_hdi=np.percentile(tau_flat, q, axis=0), plate_mean=plates.mean(axis=0),
        plate_sd=plates.std(axis=0, ddof=1), samples=flat, ess_min=ess, rhat_max=rhat,
        tau_max=tau_max, n_steps=sampler.iteration, n_burn=burn, n_walkers=n_walkers,
        converged=bool(converged), status="converged" if converged else "max_steps",
        wall_time=time.perf_counter() - started,
    )  # fmt: skip
