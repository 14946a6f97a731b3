"""One material, many plates, each a little different: the population and each plate in it.

Each plate's constants ``c_p`` (``E1, E2, nu12, G12, G13, G23``) are log-normal around the
material's mean ``mu`` with a spread ``tau`` per constant, ``ln c_p ~ N(ln mu, diag tau^2)``
(or, with probability :data:`~bayesplate.sampling.population.OUTLIER_PRIOR`, an outlier:
:mod:`bayesplate.sampling.population`). Each plate's likelihood is its Laplace approximation
in ``z = ln c`` on its certified fast model (:mod:`bayesplate.sampling.plate_laplace`), so
that ``c_p`` integrates out in closed form: the sampler moves in the twelve population
parameters ``theta = (ln mu, ln tau)`` only, whatever the number of plates, and each plate's
constants are drawn afterwards from their Gaussian conditional given each kept ``theta``
(shrunk towards the population). The earlier sampler of ``theta`` and every plate's
``6 P`` offsets together (non-centred) did not converge (R-hat 1.80 after 5000 steps on
three plates); this one does in seconds (``reports/benchmark_hierarchical.md``).

Priors: ``mu`` has the first case's prior (Gaussian in the stiffness coefficients ``b``,
:meth:`GaussianProblem.log_prior`, carried to ``ln mu`` with its Jacobian
``|d b / d e| prod mu = E2 / D^3 prod mu``, ``D = 1 - nu12^2 E2 / E1``), so that
``tau -> 0`` is the shared-constants form of :mod:`bayesplate.sampling.joint`; each ``tau_k``
is half-normal with scale :data:`TAU_SCALE` (0.1: a plate-to-plate spread of about 10 % is
plausible, 25 % unlikely), carried to ``ln tau``.

The chain: the one-plate sampler's moves (:mod:`bayesplate.sampling.moves`: 80 % an
independence Student-t proposal tuned on the ensemble, 20 % differential evolution) in
coordinates whitened by the Laplace approximation of ``theta`` at its MAP, with its tuning
rounds (:func:`~bayesplate.sampling.chain._tune`, longer ones); the stretch move alone had
autocorrelation times of 110 steps, differential evolution 50-70, on ten synthetic plates (the
density costs a few milliseconds for 48 walkers and 10 plates), stopped when it is longer than
``target_tau_factor`` autocorrelation times, and every population parameter has ``min_ess``
bulk effective samples and R-hat below ``max_rhat`` (walkers as chains; burn-in
:data:`~bayesplate.sampling.stopping.BURN_TAU` autocorrelation times).

Refinement: the Laplace is accurate where the plate's conditional posterior is, not
necessarily at its own mode (a constant the plate barely identifies, shrunk to the
population, moves the others through their correlation). Before sampling, each plate whose
conditional mean at the population's MAP lies more than :data:`REFINE_DISTANCE` of its own
deviations (in ``H``'s metric) from its linearisation point is linearised again there (one
solve on its fast model), and the MAP found again, until none moves (at most four rounds).
"""

from __future__ import annotations

import time

import emcee
import numpy as np
from scipy import optimize

from .. import laminate
from .chain import TUNE_ROUNDS, TUNE_STEPS, _tune
from .moves import LaplaceMove
from .plate_marginal import Plates, conditional_y, mixture_y
from .population import (
    OUTLIER_PRIOR,
    OUTLIER_SCALE,
    conditional,
    mixture_log_likelihood,
)
from .population_result import HierarchicalResult, result_of
from .seeding import generator, resolve_rng
from .stopping import burn_in, load_arviz

__all__ = [
    "REFINE_DISTANCE",
    "TAU_SCALE",
    "HierarchicalResult",
    "PopulationDensity",
    "sample_hierarchical",
    "sample_population",
]

#: Scale of the half-normal prior of each ``tau`` (the spread of ``ln c`` between plates).
TAU_SCALE = 0.1
#: A plate is linearised again when its shrunk mean is this many of its own deviations away.
REFINE_DISTANCE = 1.0


def log_jacobian(mu):
    """``ln |det d b / d e|`` at engineering constants `mu` (..., 6): ``ln(E2 / D^3)``."""
    E1, E2, nu12 = mu[..., 0], mu[..., 1], mu[..., 2]
    return np.log(E2) - 3.0 * np.log(1.0 - nu12**2 * E2 / E1)


class PopulationDensity:
    """``ln f(theta | Y_1..Y_P)``, ``theta = (ln mu, ln tau)``, vectorised over rows.

    Parameters
    ----------
    laplaces : sequence of PlateLaplace
        Each plate's likelihood in ``z = ln c``.
    mu_b, V_b : numpy.ndarray, shapes (6,), (6, 6)
        The material's prior on ``b`` (Pa, Pa^2), the first case's.
    tau_scale, outlier_prior, outlier_scale : float
        :data:`TAU_SCALE`, and the mixture's (``outlier_prior = 0``: no outliers).
    """

    dim = 12

    def __init__(
        self,
        laplaces,
        mu_b,
        V_b,
        tau_scale=TAU_SCALE,
        outlier_prior=OUTLIER_PRIOR,
        outlier_scale=OUTLIER_SCALE,
    ):
        self.H = np.array([fit.H for fit in laplaces])
        self.h = np.array([fit.h for fit in laplaces])
        in_y = len(laplaces) > 0 and all(getattr(f, "A", None) is not None for f in laplaces)
        self.in_y = Plates.of(laplaces) if in_y else None
        self.P = len(self.H)
        self.mu_b = np.asarray(mu_b, dtype=float)
        self.Vb_inv = np.linalg.inv(np.asarray(V_b, dtype=float))
        self.tau_scale = float(tau_scale)
        self.outlier_prior, self.outlier_scale = float(outlier_prior), float(outlier_scale)
        self.centre, self.chol = np.zeros(12), np.eye(12)

    def log_prior(self, theta):
        """``ln f(ln mu) + ln f(ln tau)``, (n,); -inf where ``mu`` is not a physical lamina."""
        theta = np.atleast_2d(theta)
        mu = np.exp(theta[:, :6])
        b = laminate.stiffness_from_engineering(mu)
        d = b - self.mu_b
        lp = -0.5 * np.einsum("ni,ij,nj->n", d, self.Vb_inv, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            lp = lp + log_jacobian(mu) + theta[:, :6].sum(axis=1)
        tau = np.exp(theta[:, 6:])
        lp = lp + np.sum(-0.5 * (tau / self.tau_scale) ** 2 + theta[:, 6:], axis=1)
        return np.where(laminate.is_physical(b) & np.isfinite(lp), lp, -np.inf)

    def plates(self, theta):
        """Each plate's marginal and its components' responsibilities, (n, P), (n, P, 8)."""
        theta = np.atleast_2d(theta)
        log_mu, tau = theta[:, :6], np.exp(theta[:, 6:])
        if self.in_y is not None:  # the likelihoods Gaussian in y: Laplace at each plate's mode
            return mixture_y(log_mu, tau, self.in_y, self.outlier_prior, self.outlier_scale)
        return mixture_log_likelihood(
            log_mu, tau, self.H, self.h, self.outlier_prior, self.outlier_scale
        )

    def conditional(self, log_mu, tau):
        """Each plate's ``z = ln c`` given the population: mean (..., P, 6), cov (..., P, 6, 6).

        `log_mu`, `tau` (..., P, 6) broadcast against the plates.
        """
        if self.in_y is not None:
            return conditional_y(log_mu, tau, self.in_y.A, self.in_y.a)
        return conditional(log_mu, tau, self.H, self.h)

    def log_density_theta(self, theta):
        """``ln f(theta | Y)`` up to a constant, (n,)."""
        lp = self.log_prior(theta)
        ok = np.isfinite(lp)
        if np.any(ok):
            lp[ok] += self.plates(np.atleast_2d(theta)[ok])[0].sum(axis=1)
        return lp

    def theta(self, u):
        """``theta`` of whitened ``u`` (..., 12)."""
        return self.centre + np.asarray(u, dtype=float) @ self.chol.T

    def __call__(self, u):
        """``ln f`` at whitened rows ``u`` (n, 12) (emcee, vectorised)."""
        return self.log_density_theta(self.theta(np.atleast_2d(u)))

    def whiten(self, theta0, step=1e-4):
        """Centre at the MAP from `theta0`; whiten by the inverse Hessian there."""
        f = lambda t: -float(self.log_density_theta(t)[0])  # noqa: E731
        best = optimize.minimize(f, theta0, method="L-BFGS-B", options={"maxiter": 5000})
        theta = best.x if np.isfinite(best.fun) and best.fun <= f(theta0) else theta0
        H = _hessian(f, theta, step)
        if not np.all(np.isfinite(H)):  # a neighbour off the physical region: the prior's scale
            H = np.eye(theta.size)
        w, V = np.linalg.eigh(0.5 * (H + H.T))
        w = np.maximum(w, 1.0)  # flat directions (unidentified spreads): the prior's scale
        self.centre, self.chol = theta, np.linalg.cholesky((V / w) @ V.T)
        return theta


def _hessian(f, x, h):
    """Central finite-difference Hessian of scalar `f` at `x` (step `h` in every coordinate)."""
    n = x.size
    E = np.eye(n) * h
    f0 = f(x)
    fp = np.array([f(x + E[i]) for i in range(n)])
    fm = np.array([f(x - E[i]) for i in range(n)])
    H = np.diag((fp - 2 * f0 + fm) / h**2)
    for i in range(n):
        for j in range(i + 1, n):
            H[i, j] = H[j, i] = (
                f(x + E[i] + E[j]) - fp[i] - fp[j] + 2 * f0 - fm[i] - fm[j] + f(x - E[i] - E[j])
            ) / (2 * h**2)
    return H


def _diagnostics(chain):
    """Bulk ESS and R-hat of each coordinate of `chain` (steps, walkers, 12), (12,) each."""
    az = load_arviz()
    x = chain.swapaxes(0, 1)
    ess = np.array([float(az.ess(x[..., j])) for j in range(x.shape[-1])])
    rhat = np.array([float(az.rhat(x[..., j])) for j in range(x.shape[-1])])
    return ess, rhat


def _run(density, rng, n_walkers, max_steps, check_every, target_tau_factor, min_ess, max_rhat):
    """The chain to its stopping rule: (sampler, burn, tau_max, ess, rhat, converged)."""
    import warnings

    laplace = LaplaceMove(1.1, df=5)
    moves = [(laplace, 0.8), (emcee.moves.DEMove(), 0.2)]
    sampler = emcee.EnsembleSampler(n_walkers, 12, density, moves=moves, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**32))).get_state()
    state = emcee.State(0.5 * rng.standard_normal((n_walkers, 12)))
    # tuned on a longer run than one plate's (4 x 240 steps, not 3 x 30): the population's
    # ln tau is skewed, and a proposal fitted to a short run from the starting ball was
    # accepted 13 % of the time (autocorrelation 115 steps, R-hat 1.016 after 8000 steps on
    # ten synthetic plates); fitted to the longer run 23 % (19 steps, converged at 3460)
    state, n_tune = _tune(sampler, state, laplace, TUNE_ROUNDS + 1, 8 * TUNE_STEPS, max_steps, None)
    burn, tau_max, ess, rhat, done = n_tune, np.inf, np.zeros(12), np.full(12, np.inf), False
    while sampler.iteration < max_steps and not done:
        state = sampler.run_mcmc(state, min(check_every, max_steps - sampler.iteration))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            tau = sampler.get_autocorr_time(discard=n_tune, tol=0)
        tau_max = float(np.max(np.where(np.isfinite(tau), tau, np.inf)))
        burn = burn_in(n_tune, tau_max, sampler.iteration)
        if not np.isfinite(tau_max) or sampler.iteration - burn <= target_tau_factor * tau_max:
            continue
        ess, rhat = _diagnostics(density.theta(sampler.get_chain(discard=burn)))
        done = bool(np.min(ess) >= min_ess and np.max(rhat) < max_rhat)
    if not done:  # the last check's numbers, on the chain as it ended
        ess, rhat = _diagnostics(density.theta(sampler.get_chain(discard=burn)))
    return sampler, burn, tau_max, ess, rhat, done


def _start(laplaces, mu_b):
    """A first ``theta``: the plates' own points' mean, a spread of half the prior scale."""
    z = np.array([fit.z0 for fit in laplaces])
    log_mu = np.mean(z, axis=0)
    if not laminate.is_physical(laminate.stiffness_from_engineering(np.exp(log_mu))):
        log_mu = np.log(laminate.engineering_from_stiffness(mu_b))
    return np.concatenate([log_mu, np.full(6, np.log(0.5 * TAU_SCALE))])


def _settle(fits, mu_b, V_b, options, rounds=4):
    """Fits linearised again where the population would put them, and the plates moved.

    At the population's MAP each plate's conditional mean (as one of the population: for an
    outlier too, whose likelihood the Gauss-Newton model then extrapolates to its own mode)
    is where its likelihood matters; a plate whose mean lies over :data:`REFINE_DISTANCE`
    of its own deviations (``H``'s metric) from its linearisation point is linearised again
    there (one solve), up to `rounds` times. Returns the fits, the plates moved, and the
    density whitened at the last round when no plate moved in it (else None: rebuild it).
    """
    moved = set()
    for _ in range(rounds):
        density = PopulationDensity([f.laplace for f in fits], mu_b, V_b, **options)
        theta = density.whiten(_start([f.laplace for f in fits], mu_b))
        mean = density.conditional(theta[:6], np.exp(theta[6:]))[0]  # (P, 6)
        far = [
            p
            for p, f in enumerate(fits)
            if f.problem is not None
            and (d := mean[p] - f.laplace.z0) @ f.laplace.H @ d > REFINE_DISTANCE**2
        ]
        if not far:
            return fits, tuple(sorted(moved)), density
        from .plate_laplace import relinearise

        fits = [relinearise(f, mean[p]) if p in far else f for p, f in enumerate(fits)]
        moved.update(far)
    return fits, tuple(sorted(moved)), None


def sample_population(
    fits,
    mu_b,
    V_b,
    rng=None,
    n_walkers=48,
    max_steps=20000,
    target_tau_factor=50.0,
    min_ess=1000.0,
    max_rhat=1.01,
    check_every=500,
    tau_scale=TAU_SCALE,
    outlier_prior=OUTLIER_PRIOR,
    refine=True,
):
    """Sample the population of plates of one material; draw each plate in it (module doc).

    Parameters
    ----------
    fits : sequence of PlateFit
        Each plate's Laplace (:func:`~bayesplate.sampling.plate_laplace.fit_plate`); a fit
        without a ``problem`` is not refined.
    mu_b, V_b : numpy.ndarray, shapes (6,), (6, 6)
        The material's prior on ``b`` (Pa, Pa^2).
    rng : int, numpy.random.Generator or None
        Seeds the walkers, emcee and the plates' draws.
    n_walkers, max_steps, target_tau_factor, min_ess, max_rhat, check_every
        The chain and its stopping rule (module docstring).
    tau_scale, outlier_prior : float
        Half-normal scale of each ``tau``; prior probability of an outlier plate (0: none).
    refine : bool
        Linearise far plates again at their shrunk mean and sample again (once).

    Returns
    -------
    HierarchicalResult
    """
    started = time.perf_counter()
    rng = generator(resolve_rng(rng, None, "sample_population"))[1]
    fits = list(fits)
    if len(fits) < 2:
        raise ValueError(f"a population needs two plates or more, not {len(fits)}")
    chain = dict(
        n_walkers=n_walkers,
        max_steps=max_steps,
        check_every=check_every,
        target_tau_factor=target_tau_factor,
        min_ess=min_ess,
        max_rhat=max_rhat,
    )
    options = dict(tau_scale=tau_scale, outlier_prior=outlier_prior)
    refined, density = (), None
    if refine:
        fits, refined, density = _settle(fits, mu_b, V_b, options)
    if density is None:  # not settled, or its last round moved a plate
        laplaces = [f.laplace for f in fits]
        density = PopulationDensity(laplaces, mu_b, V_b, **options)
        density.whiten(_start(laplaces, mu_b))
    done = (density, *_run(density, rng, **chain))
    return result_of(fits, done, refined, time.perf_counter() - started, rng)


def sample_hierarchical(setups, singles=None, rng=None, *, names=None, **options):
    """:func:`sample_population` of plates already set up (e.g. :attr:`JointSetup.setups`).

    Parameters
    ----------
    setups : sequence of SamplingSetup
        The plates, each with its problem, fast model and MAP (the first one's prior is the
        material's).
    singles : sequence of EstimateResult, optional
        Each plate's own answer (default its setup's estimate).
    rng : int, numpy.random.Generator or None
    names : sequence of str, optional
    **options
        Of :func:`sample_population`.

    Returns
    -------
    HierarchicalResult
    """
    from .plate_laplace import PlateFit, linearise

    singles = [s.estimate for s in setups] if singles is None else list(singles)
    names = [f"plate {p + 1}" for p in range(len(setups))] if names is None else list(names)
    problems = [s.problem_on_fast_model() for s in setups]
    fits = [
        PlateFit(n, linearise(q, s.estimate.b), e, q)
        for n, s, e, q in zip(names, setups, singles, problems, strict=True)
    ]
    p = setups[0].problem
    return sample_population(fits, p.mu_b, p.V_b, rng=rng, **options)
