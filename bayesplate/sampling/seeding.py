"""The entry points' one random-number argument: ``rng``, an int seed or a Generator.

``rng`` seeds everything random in a run (the fast model's designs, the initial walkers,
emcee's random state): the same int gives the same chain. The former keyword ``seed`` (the
same values) still works for one release, with a :class:`DeprecationWarning`.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["generator", "resolve_rng"]


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


def generator(rng):
    """``(entropy or None, generator)`` from an int, a Generator or None.

    An int or None goes through :class:`numpy.random.SeedSequence` (whose entropy is
    returned, to record); a Generator is used as it is (entropy None).
    """
    if isinstance(rng, np.random.Generator):
        return None, rng
    sequence = np.random.SeedSequence(rng)
    return sequence.entropy, np.random.default_rng(sequence)
