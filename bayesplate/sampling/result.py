"""The sampled posterior: :class:`SamplingResult` and its ArviZ ``InferenceData``.

:func:`build_result` reads a finished emcee sampler: the chain after burn-in as engineering
constants (case units in the ``InferenceData``, SI in the arrays), ArviZ's summary and
diagnostics, the pointwise log-likelihood of each measured eigenvalue (for WAIC/LOO), the
autocorrelation function and times.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import emcee
import numpy as np

from .. import laminate
from ..quantities import CASE_SCALE, ENGINEERING_KEYS, hz_from_eigenvalue, hz_sd
from .assigned import ChainAssignment
from .density import engineering_constants
from .stopping import autocorr_time, burn_in, load_arviz

__all__ = ["CASE_UNITS", "HDI_PROB", "SamplingResult", "build_result"]

#: Multipliers from SI to case-file units (GPa for moduli, nu12 as is): ``1 / CASE_SCALE``,
#: the array ``[1e-9, 1e-9, 1, 1e-9, 1e-9, 1e-9]`` to the last bit (the results multiply by
#: it, which differs in the last bit from dividing by ``CASE_SCALE``).
CASE_UNITS = 1.0 / CASE_SCALE
#: Probability of the highest-density interval reported (ArviZ's default, 3 % to 97 %).
HDI_PROB = 0.94


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
        ``sampling``, ``total`` (the setup included, also when prepared beforehand); with
        the inputs drawn, ``input_certificate`` and ``inputs`` (their draws).
    settings : dict
        Seed entropy, walkers, moves, box, stopping settings.
    input_posterior : bayesplate.likelihood.input_summary.InputPosterior or None
        The declared inputs' posterior (inputs marginalised; one conditional draw per kept
        draw of ``b``); None with the inputs exact or none declared.
    input_certificate : bayesplate.likelihood.inputs_posterior.InputCertificate or None
        The linear input model against full solves at the MAP.
    assignment : bayesplate.sampling.assigned.ChainAssignment or None
        With the assignment re-made at every point (pairing by likelihood): per measured
        peak, the fraction of kept draws in which each computed mode explained it or it was
        spurious. The ``log_likelihood`` group then covers all the peaks. None otherwise
        (``settings["assignment"]`` says why when the pairing is by likelihood).
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
    input_posterior: object = field(default=None, repr=False)
    input_certificate: object = None
    assignment: object = None

    @property
    def ess_per_second(self):
        """Smallest bulk ESS over the sampling wall time, 1/s."""
        return self.ess_min / self.wall_time if self.wall_time > 0 else float("nan")

    def constants_table(self):
        """``{"E1_GPa": {"mean", "sd", "hdi_3%", "hdi_97%"}, ...}`` in case units (floats)."""
        fields = {"mean": self.mean, "sd": self.sd, "hdi_3%": self.hdi[0], "hdi_97%": self.hdi[1]}
        scaled = {k: np.asarray(v, dtype=float) * CASE_UNITS for k, v in fields.items()}
        return {
            key: {k: float(v[i]) for k, v in scaled.items()}
            for i, key in enumerate(ENGINEERING_KEYS)
        }


def build_result(sampler, density, history, converged, wall, n_eval, forward0, settings):
    """A :class:`SamplingResult` from a finished sampler.

    Parameters
    ----------
    sampler : emcee.EnsembleSampler
    density : WhitenedLogPosterior
    history : numpy.ndarray, shape (checks, 7)
        Chain length and ``tau`` at every check.
    converged : bool
    wall : float
        Seconds spent sampling.
    n_eval : int
        Log-density evaluations (screened proposals included).
    forward0 : int
        ``density.n_forward`` before the run.
    settings : dict
        With ``n_tune``, ``target_tau_factor``, ``min_ess``, ``max_rhat``, ``max_steps``.

    Returns
    -------
    SamplingResult
    """
    n_tune = settings["n_tune"]
    tau = autocorr_time(sampler, n_tune)
    n = sampler.iteration
    tau_max = float(np.max(tau))
    burn = burn_in(n_tune, tau_max, n)
    chain = sampler.get_chain(discard=burn)  # (draws, walkers, 6)
    pointwise, modes = density.split_blob(sampler.get_blobs(discard=burn))
    idata = _inference_data(density, chain, sampler.get_log_prob(discard=burn), pointwise, settings)
    assignment = None
    if modes is not None:  # the best assignment stored at every draw (emcee's blobs)
        assignment = ChainAssignment.from_draws(
            density.assigned.frequency_Hz, modes.reshape(-1, density.m), density.assigned.n
        )
    az = load_arviz()
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
        chain=engineering_constants(density, sampler.get_chain()).swapaxes(0, 1) * CASE_UNITS,
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
        assignment=assignment,
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


def _observed(density):
    """Measured eigenvalues, their variances and 1-based numbers in the log-likelihood."""
    assigned = density.assigned
    if assigned is not None:  # every peak, the assignment re-made
        return assigned.Y, assigned.variance, np.arange(1, assigned.m + 1)
    p = density.problem
    return p.Y, np.diag(p.V_Y), _measured_numbers(p)


def _inference_data(density, chain, lp, blobs, settings):
    """ArviZ data: engineering constants (case units), pointwise log-likelihood, lp."""
    az = load_arviz()
    e = engineering_constants(density, chain).swapaxes(0, 1) * CASE_UNITS  # (walkers, draws, 6)
    Y, variance, numbers = _observed(density)
    f = hz_from_eigenvalue(Y)  # Y > 0: sqrt(Y) / (2 pi)
    sigma_f = hz_sd(f, np.sqrt(variance))
    return az.from_dict(
        posterior={key: e[..., j] for j, key in enumerate(ENGINEERING_KEYS)},
        log_likelihood={"Y": np.asarray(blobs, dtype=float).swapaxes(0, 1)},
        sample_stats={"lp": (np.asarray(lp) - density.log_jacobian(chain)).T},
        observed_data={"Y": Y},
        constant_data={"frequency_Hz": f, "sigma_Hz": sigma_f},
        coords={"mode": numbers},
        dims={"Y": ["mode"], "frequency_Hz": ["mode"], "sigma_Hz": ["mode"]},
        attrs={
            "units": "moduli in GPa, nu12 dimensionless; Y in rad^2/s^2",
            "sampler": "emcee " + emcee.__version__,
            "walkers_as_chains": 1,
            "seed_entropy": str(settings.get("seed_entropy")),
        },
    )
