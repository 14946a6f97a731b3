"""When the chain is long enough: autocorrelation time, burn-in, bulk ESS and R-hat.

Every ``check_every`` steps after tuning the integrated autocorrelation time ``tau`` of each
whitened coordinate is estimated (:func:`autocorr_time`, ``get_autocorr_time(tol=0)`` on the
chain after tuning); the run stops (:class:`StoppingRule`) once that chain is longer than
``target_tau_factor`` times the largest ``tau``, the smallest bulk ESS of the engineering
constants after a further burn-in of :data:`BURN_TAU` ``tau`` (:func:`burn_in`) reaches
``min_ess`` and the largest R-hat (walkers as chains) is below ``max_rhat``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from .density import engineering_constants

__all__ = ["BURN_TAU", "StoppingRule", "autocorr_time", "burn_in", "diagnostics", "load_arviz"]

#: Burn-in discarded, in autocorrelation times (the walkers start from the Laplace
#: approximation, close to the posterior already).
BURN_TAU = 3.0


def load_arviz():
    """The ``arviz`` module, imported without its announcement of a refactor (FutureWarning)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # ArviZ announces its refactor
        import arviz

    return arviz


def diagnostics(e_walker_draw):
    """Smallest bulk ESS and largest R-hat over the constants.

    Parameters
    ----------
    e_walker_draw : numpy.ndarray, shape (walkers, draws, 6)
        Engineering constants, walkers as chains.

    Returns
    -------
    ess, rhat : float
    """
    az = load_arviz()
    ess = min(float(az.ess(e_walker_draw[..., j])) for j in range(6))
    rhat = max(float(az.rhat(e_walker_draw[..., j])) for j in range(6))
    return ess, rhat


def autocorr_time(sampler, discard=0):
    """Integrated autocorrelation time of each coordinate after `discard` steps, (6,).

    ``emcee``'s estimate with ``tol=0`` (no warning on short chains); ``inf`` where it is
    not finite (too short a chain).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # short chains: all NaN before steps
        tau = sampler.get_autocorr_time(discard=discard, tol=0)
    return np.where(np.isfinite(tau), tau, np.inf)


def burn_in(n_tune, tau_max, n):
    """Steps discarded: the tuning rounds and ``BURN_TAU`` autocorrelation times after.

    At most half the chain after tuning (all of it when ``tau_max`` is not finite).

    Parameters
    ----------
    n_tune : int
        Steps of tuning.
    tau_max : float
        Largest autocorrelation time, steps.
    n : int
        Steps in the chain.

    Returns
    -------
    int
    """
    extra = math.ceil(BURN_TAU * tau_max) if np.isfinite(tau_max) else (n - n_tune) // 2
    return n_tune + min(extra, (n - n_tune) // 2)


class StoppingRule:
    """``rule(sampler, tau) -> (done, note)``: the stopping rule of the chain.

    Parameters
    ----------
    density : WhitenedLogPosterior
        Maps the chain to the engineering constants.
    n_tune : int
        Steps of tuning (not counted).
    target_tau_factor, min_ess, max_rhat : float
        Chain after tuning longer than ``target_tau_factor`` times the largest ``tau``,
        smallest bulk ESS at least ``min_ess``, largest R-hat below ``max_rhat``.
    """

    def __init__(self, density, n_tune, target_tau_factor, min_ess, max_rhat):
        self.density, self.n_tune = density, n_tune
        self.target_tau_factor, self.min_ess, self.max_rhat = target_tau_factor, min_ess, max_rhat

    def __call__(self, sampler, tau):
        """Whether to stop, and a note for the progress bar."""
        n = sampler.iteration - self.n_tune
        tau_max = float(np.max(tau))
        if not np.isfinite(tau_max) or n <= self.target_tau_factor * tau_max:
            return False, f"tau {tau_max:.1f}"
        chain = sampler.get_chain(discard=burn_in(self.n_tune, tau_max, sampler.iteration))
        ess, rhat = diagnostics(engineering_constants(self.density, chain).swapaxes(0, 1))
        done = ess >= self.min_ess and rhat < self.max_rhat
        return done, f"tau {tau_max:.1f}, ESS {ess:.0f}, R-hat {rhat:.3f}"
