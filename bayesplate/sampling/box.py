"""Where the fast model's box lies: around a (pilot) B estimate, checked against the MAP.

:func:`posterior_box` places the box of :func:`bayesplate.sampling.prepare`'s fast model
where the posterior can be; :func:`check_box` logs how far the MAP ended from its edges.
Pure computation on arrays (and one log line).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..quantities import LOG_STIFFNESS
from ..reduced import Box

__all__ = ["check_box", "posterior_box"]

log = logging.getLogger("bayesplate.sampling.setup")  # the setup's messages, as before


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
    positive = LOG_STIFFNESS
    lower[positive] = np.maximum(lower[positive], floor * b[positive])
    cap = 0.99 * math.sqrt(lower[0] * lower[1])
    lower[2], upper[2] = max(lower[2], -cap), min(upper[2], cap)
    return Box(lower, upper)


def check_box(box, estimate):
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
    log.info(
        "the MAP is %s (lower) / %s (upper) deviations from the fast model's box edges",
        np.round(low, 1),
        np.round(high, 1),
    )
