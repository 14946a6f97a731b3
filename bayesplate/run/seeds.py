"""The one rule from a run's seed to its random streams (:func:`run_seeds`).

A seed reaches a sampler run as :func:`bayesplate.sampling.sample` splits it when it prepares
its own setup (:func:`bayesplate.sampling.seeding.streams`): ``SeedSequence(seed)``'s first
child seeds :func:`~bayesplate.sampling.prepare` (the fast model's designs), its second the
walkers and emcee, its third the draws of the inputs; the error scale's draws take the
generator of the seed itself. So a run prepared beforehand (to keep its setup) gives the
chain of ``sample(case, rng=seed)`` alone, whichever entry point ran it.

No seed is one fresh seed, drawn once for the whole run (not one per stream): the chain's
``seed_entropy`` is then that seed, and giving it back reproduces the run.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from ..sampling.seeding import streams

__all__ = ["RunSeeds", "run_seeds"]

_SEED_RANGE = 2**63  # the command line's --seed: 0 to 2^63 - 1


@dataclass(frozen=True)
class RunSeeds:
    """The streams of one run, from its seed (each a fresh generator on every access).

    Attributes
    ----------
    seed : int
        The run's seed (drawn when none was given).
    """

    seed: int

    @property
    def prepare(self):
        """The generator of :func:`bayesplate.sampling.prepare` (the first child)."""
        return streams(self.seed)[1]

    @property
    def chain(self):
        """What :func:`bayesplate.sampling.sample` takes: the seed, which it splits itself."""
        return self.seed

    @property
    def error_scale(self):
        """The generator of the error scale's draws (the seed's own, not a child)."""
        return np.random.default_rng(self.seed)


def run_seeds(seed):
    """The :class:`RunSeeds` of `seed`.

    Parameters
    ----------
    seed : int or None
        None draws a fresh seed (from 0 to 2^63 - 1), once.

    Returns
    -------
    RunSeeds
    """
    if seed is None:
        seed = int(np.random.SeedSequence().entropy) % _SEED_RANGE
    elif isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise TypeError(
            f"seed = {seed!r}: a run takes a whole number >= 0 or None (a "
            "Generator would be split differently by each stage)"
        )
    return RunSeeds(int(seed))
