"""B to the MAP on the sampler's model, and B or MVE there: :func:`~.setup.prepare`'s estimates.

:func:`run_on_fast` runs an estimator on the sampler's model (the reduced model uncertified
off its box for the early iterates), :func:`map_estimate` is B to :data:`MAP_TOL` on it, and
:func:`scaled_map` widens its ``P`` by an inferred error scale.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from ..estimators import run

__all__ = ["MAP_TOL", "map_estimate", "run_on_fast", "scaled_map"]

log = logging.getLogger("bayesplate.sampling.setup")  # the setup's messages, as before

#: B to this relative change is the MAP to ~1e-6 posterior deviations (linear convergence,
#: ratio ~0.37 per iteration on the bundled plates).
MAP_TOL = 1e-7


def map_estimate(setup, conventions, start=None):
    """B to ``MAP_TOL`` on the sampler's model: the MAP and ``P`` (eq. 9)."""
    return run_on_fast(setup, "B", MAP_TOL, conventions=conventions, start=start)


def scaled_map(setup, estimate):
    """B's estimate with ``P`` widened by an inferred error scale (linearised; none: as is).

    The walkers' coordinates are whitened with ``P`` and the default moves propose from a
    Student-t of that shape (:mod:`bayesplate.sampling.moves`): with ``s`` unknown the
    posterior is ``s_hat`` times wider than ``P`` at ``s = 1``, and proposals that narrow
    mix slowly. The estimate stays B's (``s = 1`` weights).
    """
    if setup.problem.error_scale is None:
        return estimate
    from ..likelihood.error_scale import linearised_at
    from ..quantities import engineering_covariance

    cov_b = linearised_at(setup.problem_on_fast_model(), estimate.b).covariance_b
    cov = engineering_covariance(estimate.constants, cov_b)
    return replace(estimate, covariance_b=cov_b, covariance=cov, sd=np.sqrt(np.diag(cov)))


def run_on_fast(setup, method, tol, **kwargs):
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
    free = p.with_forward(fast.reduced.solve)
    result = run(free, method, tol=tol, **kwargs)
    if fast.box.contains(result.b) and result.status != "solve_failed":
        return result
    log.warning(
        "%s ends outside the fast model's box (%s); again with the full fallback",
        method,
        result.message,
    )
    return run(setup.problem_on_fast_model(), method, tol=tol, **kwargs)
