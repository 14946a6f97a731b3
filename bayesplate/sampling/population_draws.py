"""After the population's chain: each plate's constants, its outlier probability, ArviZ data.

Given each kept population draw ``theta = (ln mu, ln tau)``, a plate's component (the
population, or one of the outlier mixture's wide ones) is drawn from its responsibility and
its ``z = ln c`` from the Gaussian conditional of that component
(:func:`bayesplate.sampling.population.conditional`): exact draws of the plate's posterior
under the Laplace likelihood. Outlier probabilities are the responsibilities averaged over
the draws (Rao-Blackwellised: no draw-to-draw noise of a 0/1 indicator).
"""

from __future__ import annotations

import numpy as np

from ..quantities import CASE_SCALE, ENGINEERING_KEYS
from .population import component_spreads
from .stopping import load_arviz

__all__ = ["inference_data", "plate_draws"]


def plate_draws(density, theta, rng):
    """Each plate's constants drawn given each population draw, and the responsibilities.

    Parameters
    ----------
    density : PopulationDensity
    theta : numpy.ndarray, shape (D, 12)
        Population draws.
    rng : numpy.random.Generator

    Returns
    -------
    constants : numpy.ndarray, shape (D, P, 6)
        SI.
    resp : numpy.ndarray, shape (D, P, 8)
        Each component's posterior probability given the draw.
    """
    D, P = len(theta), density.P
    _, resp = density.plates(theta)
    cum = np.cumsum(resp, axis=-1)
    pick = np.minimum((rng.random((D, P, 1)) > cum).sum(axis=-1), resp.shape[-1] - 1)
    spreads = component_spreads(np.exp(theta[:, 6:]), density.outlier_scale)  # (D, 8, 6)
    tau = np.take_along_axis(spreads, pick[..., None], axis=1)  # (D, P, 6)
    log_mu = np.broadcast_to(theta[:, None, :6], (D, P, 6))
    mean, cov = density.conditional(log_mu, tau)
    L = np.linalg.cholesky(cov + 1e-300 * np.eye(6))
    z = mean + np.einsum("...ij,...j->...i", L, rng.standard_normal((D, P, 6)))
    return np.exp(z), resp


def inference_data(theta, constants, resp, n_walkers, names):
    """ArviZ data: ``mu`` and ``plate`` in case units, ``tau``, walkers as chains.

    Parameters
    ----------
    theta : numpy.ndarray, shape (D, 12)
        Population draws, step-major (``D = steps * n_walkers``).
    constants : numpy.ndarray, shape (D, P, 6)
        SI.
    resp : numpy.ndarray, shape (D, P, 8)
    n_walkers : int
    names : sequence of str

    Returns
    -------
    arviz.InferenceData
    """
    az = load_arviz()
    scale = 1.0 / CASE_SCALE

    def chains(x):
        return np.swapaxes(x.reshape(-1, n_walkers, *x.shape[1:]), 0, 1)

    posterior = {
        "mu": chains(np.exp(theta[:, :6]) * scale),
        "tau": chains(np.exp(theta[:, 6:])),
        "plate": chains(constants * scale),
    }
    stats = {"outlier": chains(1.0 - resp[..., 0])}
    coords = {"constant": list(ENGINEERING_KEYS), "plate_name": list(names)}
    dims = {
        "mu": ["constant"],
        "tau": ["constant"],
        "plate": ["plate_name", "constant"],
        "outlier": ["plate_name"],
    }
    return az.from_dict(posterior=posterior, sample_stats=stats, coords=coords, dims=dims)
