"""What a batch computes: :class:`BatchOptions` (steps, mesh, seeds, the sampler's bounds).

Each step sees only its own options (:meth:`BatchOptions.for_step`): they, the case file's
content and the package version make the key that tells a re-run what is already done.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["STEPS", "BatchOptions"]

#: The steps a batch can run on each case, in the order they are submitted.
STEPS = ("estimate", "sample", "diagnose")


@dataclass(frozen=True)
class BatchOptions:
    """The options of every step of a batch (the single-case commands' defaults).

    Parameters
    ----------
    steps : tuple of str
        Steps run on every case, a subset of :data:`STEPS`.
    mesh : tuple of int, optional
        Elements along x and y for every case; default each case's ``[model] mesh``.
    method : {"B", "MVE", "MVE-mod"}
        The estimator of the ``estimate`` step.
    forward : {"auto", "fast", "full"}
        The model the estimator iterates on (as ``bayesplate estimate --forward``).
    pairing : str
        Measured-to-computed modes, for every step (as ``--pairing``).
    seed : int
        Seeds the sampler and diagnose's random starts (the same seed, the same results).
    walkers, max_steps : int
        The sampler's walkers and its cap on steps.
    min_ess : float
        Effective samples per constant the sampler aims for.
    """

    steps: tuple = ("estimate",)
    mesh: tuple | None = None
    method: str = "MVE"
    forward: str = "auto"
    pairing: str = "auto"
    seed: int = 0
    walkers: int = 32
    max_steps: int = 5000
    min_ess: float = 2000.0

    def __post_init__(self):
        unknown = [s for s in self.steps if s not in STEPS]
        if unknown or not self.steps:
            raise ValueError(f"steps {list(self.steps)}: each must be one of {list(STEPS)}")

    def for_step(self, step):
        """The options `step` depends on, as a JSON-able dict (part of its result's key)."""
        mesh = None if self.mesh is None else [int(n) for n in self.mesh]
        common = {"mesh": mesh, "pairing": self.pairing}
        if step == "estimate":
            return {**common, "method": self.method, "forward": self.forward}
        if step == "sample":
            return {
                **common,
                "seed": self.seed,
                "walkers": self.walkers,
                "max_steps": self.max_steps,
                "min_ess": float(self.min_ess),
            }
        if step == "diagnose":
            return {**common, "seed": self.seed}
        raise ValueError(f"step {step!r}: must be one of {list(STEPS)}")
