"""The entry points' one random-number argument: ``rng``, an int seed or a Generator.

``rng`` seeds everything random in a run (the fast model's designs, the initial walkers,
emcee's random state): the same int gives the same chain. The former keyword ``seed`` (the
same values) still works for one release, with a :class:`DeprecationWarning`.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["generator", "resolve_rng", "streams"]


def resolve_rng(rng, seed, caller):
    """`rng`, or the deprecated `seed` given instead of it (with a DeprecationWarning).

    Parameters
    ----------
    rng, seed : int, numpy.random.Generator or None
    caller : str
        Name of the function, for the messages.

    Returns
    -------
    int, numpy.random.Generator or None
    """
    if seed is None:
        return rng
    if rng is not None:
        raise TypeError(f"{caller}() takes rng or the deprecated seed, not both")
    warnings.warn(
        f"{caller}(seed=...) is deprecated and will be removed in the next release; "
        "use rng=... (the same values give the same chains)",
        DeprecationWarning,
        stacklevel=3,
    )
    return seed


def streams(rng, n=2):
    """``(entropy or None, build, walk[, inputs])``: the generators a sampler run draws from.

    ``build`` seeds :func:`~bayesplate.sampling.setup.prepare` (the fast model's designs),
    ``walk`` the chain; :func:`~bayesplate.sampling.pipeline.sample` splits its ``rng`` so,
    and a caller that prepares the setup itself (to keep it) gets the same chain by seeding
    ``prepare`` with ``build``. With ``n=3`` a third, ``inputs``, draws the measured inputs
    after the chain (:mod:`bayesplate.likelihood.inputs_posterior`); the first two are the same
    whatever ``n`` (numpy's spawned children are numbered in order).
    """
    entropy, g = generator(rng)
    return (entropy, *g.spawn(n))


def generator(rng):
    """``(entropy or None, generator)`` from an int, a Generator or None.

    An int or None goes through :class:`numpy.random.SeedSequence` (whose entropy is
    returned, to record); a Generator is used as it is (entropy None).
    """
    if isinstance(rng, np.random.Generator):
        return None, rng
    sequence = np.random.SeedSequence(rng)
    return sequence.entropy, np.random.default_rng(sequence)
