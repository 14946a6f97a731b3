"""The population's answer: the chain's draws summarised, each plate drawn in it.

:func:`result_of` turns a finished chain of :func:`bayesplate.sampling.sample_population`
into a :class:`HierarchicalResult`: the material's means and spreads with their 94 %
intervals, every plate's shrunk constants (drawn given each kept population draw,
:mod:`bayesplate.sampling.population_draws`) beside its own answer, and the outlier
probabilities.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MAX_DRAWS", "HierarchicalResult", "result_of"]

#: Most kept draws of the population for each plate's conditional draws and the ArviZ data.
MAX_DRAWS = 8000


@dataclass(frozen=True, eq=False)
class HierarchicalResult:
    """The population of plates of one material, and each plate in it.

    Attributes
    ----------
    names : tuple of str
        The plates.
    mean, sd : numpy.ndarray, shape (6,)
        Posterior mean and deviation of the material's mean constants ``mu``, SI.
    hdi : numpy.ndarray, shape (2, 6)
        Its 3 % and 97 % quantiles (equal-tailed 94 %), SI.
    tau_mean, tau_sd : numpy.ndarray, shape (6,)
        The spread ``tau`` per constant (of ``ln c``: 0.05 is about 5 %).
    tau_hdi : numpy.ndarray, shape (2, 6)
        Its 3 % and 97 % quantiles.
    plate_mean, plate_sd : numpy.ndarray, shape (P, 6)
        Each plate's shrunk constants, SI.
    plate_hdi : numpy.ndarray, shape (2, P, 6)
        Their 3 % and 97 % quantiles, SI.
    own, own_sd : numpy.ndarray, shape (P, 6)
        Each plate's own answer (its B estimate under the case's prior), SI; NaN without one.
    outlier : numpy.ndarray, shape (P,)
        Posterior probability that the plate is not of the population.
    outlier_constant : numpy.ndarray of int, shape (P,)
        The likeliest widened component of an outlier: 0-5 a constant, 6 all six.
    samples : numpy.ndarray, shape (draws, 12)
        Kept draws of ``theta = (ln mu, ln tau)`` (thinned to at most :data:`MAX_DRAWS`).
    plate_samples : numpy.ndarray, shape (draws, P, 6)
        Each plate's constants drawn given each kept ``theta``, SI.
    ess, rhat : numpy.ndarray, shape (12,)
        Bulk ESS and R-hat of ``ln mu`` then ``ln tau`` (walkers as chains).
    ess_min, rhat_max, tau_max : float
        Smallest ESS, largest R-hat, largest autocorrelation time (steps).
    n_steps, n_burn, n_walkers : int
    acceptance : float
    refined : tuple of int
        0-based plates linearised again at their shrunk mean.
    converged : bool
    status : str
        ``"converged"`` or ``"max_steps"``.
    message : str
    idata : arviz.InferenceData
        ``posterior``: ``mu`` (case units), ``tau``, ``plate`` constants (case units), with
        walkers as chains; ``sample_stats``: ``outlier`` responsibilities per plate.
    wall_time : float
        Seconds of the sampling (both rounds).
    """

    names: tuple
    mean: np.ndarray
    sd: np.ndarray
    hdi: np.ndarray
    tau_mean: np.ndarray
    tau_sd: np.ndarray
    tau_hdi: np.ndarray
    plate_mean: np.ndarray
    plate_sd: np.ndarray
    plate_hdi: np.ndarray
    own: np.ndarray
    own_sd: np.ndarray
    outlier: np.ndarray
    outlier_constant: np.ndarray
    samples: np.ndarray = field(repr=False)
    plate_samples: np.ndarray = field(repr=False)
    ess: np.ndarray
    rhat: np.ndarray
    ess_min: float
    rhat_max: float
    tau_max: float
    n_steps: int
    n_burn: int
    n_walkers: int
    acceptance: float
    refined: tuple
    converged: bool
    status: str
    message: str
    idata: object = field(repr=False)
    wall_time: float

    @property
    def flagged(self):
        """0-based plates more likely outliers than not."""
        return tuple(int(i) for i in np.flatnonzero(self.outlier > 0.5))


def _kept(density, sampler, burn):
    """Kept ``theta`` (D, 12), step-major, thinned to at most :data:`MAX_DRAWS`."""
    u = sampler.get_chain(discard=burn)
    thin = max(1, int(np.ceil(u.shape[0] * u.shape[1] / MAX_DRAWS)))
    return density.theta(u[::thin]).reshape(-1, 12)


def result_of(fits, done, refined, wall, rng):
    """The :class:`HierarchicalResult` of a finished chain (`done`: density and chain)."""
    from .population_draws import inference_data, plate_draws

    density, sampler, burn, tau_max, ess, rhat, ok = done
    theta = _kept(density, sampler, burn)
    plates, resp = plate_draws(density, theta, rng)
    names = tuple(f.name for f in fits)
    mu, tau = np.exp(theta[:, :6]), np.exp(theta[:, 6:])
    q = [3, 97]
    own = np.array([_own(f)[0] for f in fits])
    own_sd = np.array([_own(f)[1] for f in fits])
    widened = resp[..., 1:].mean(axis=0)  # (P, 7)
    status = "converged" if ok else "max_steps"
    message = (
        f"{sampler.iteration} steps, tau <= {tau_max:.1f}, ESS >= {np.min(ess):.0f}, "
        f"R-hat <= {np.max(rhat):.3f}"
    )
    return HierarchicalResult(
        names=names,
        mean=mu.mean(0),
        sd=mu.std(0, ddof=1),
        hdi=np.percentile(mu, q, axis=0),
        tau_mean=tau.mean(0),
        tau_sd=tau.std(0, ddof=1),
        tau_hdi=np.percentile(tau, q, axis=0),
        plate_mean=plates.mean(0),
        plate_sd=plates.std(0, ddof=1),
        plate_hdi=np.percentile(plates, q, axis=0),
        own=own,
        own_sd=own_sd,
        outlier=1.0 - resp[..., 0].mean(axis=0),
        outlier_constant=np.argmax(widened, axis=1),
        samples=theta,
        plate_samples=plates,
        ess=ess,
        rhat=rhat,
        ess_min=float(np.min(ess)),
        rhat_max=float(np.max(rhat)),
        tau_max=tau_max,
        n_steps=sampler.iteration,
        n_burn=burn,
        n_walkers=sampler.nwalkers,
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        refined=refined,
        converged=ok,
        status=status,
        message=message,
        idata=inference_data(theta, plates, resp, sampler.nwalkers, names),
        wall_time=wall,
    )


def _own(fit):
    """A plate's own answer and its deviations (SI), NaN without an estimate."""
    est = fit.estimate
    if est is None:
        return np.full(6, np.nan), np.full(6, np.nan)
    sd = getattr(est, "sd", None)
    return np.asarray(est.constants, float), np.full(6, np.nan) if sd is None else np.asarray(sd)
