"""What a run computes: :class:`EstimateOptions` and :class:`SampleOptions` (frozen).

Their defaults are the command line's (``bayesplate estimate``, ``bayesplate sample``); a
batch and the report fill in what they take from their own options. Only what changes the
numbers is an option: the resources a run uses (a model already built, a shared fast model,
a pool of workers, progress lines) are keywords of :func:`~bayesplate.run.run_estimate` and
:func:`~bayesplate.run.run_sample`, and the seed is an argument of its own.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..estimators.iteration import DEFAULT_MAX_ITER

__all__ = ["EstimateOptions", "SampleOptions"]


@dataclass(frozen=True)
class EstimateOptions:
    """One of the paper's estimators on a case (:func:`bayesplate.estimators.estimate`).

    Parameters
    ----------
    method : {"B", "MVE", "MVE-mod"}
    mesh : tuple of int, optional
        Elements along x and y; default the case's ``[model] mesh`` (unused when the run is
        given a model).
    tol : float
        TOL of section 2.4.
    max_iter : int
        Iteration cap per stage.
    convention : str
        Covariance conventions (:data:`bayesplate.estimators.CONVENTIONS`).
    pairing : str or bayesplate.matching.pairing.Pairing
        Measured-to-computed modes.
    forward : {"auto", "fast", "full"}
        The model iterated on (ignored when the run is given a shared fast model).
    budget : bool
        Also the variance budget of a converged estimate
        (:func:`bayesplate.run.budget.converged_budget`; the report shows none).
    """

    method: str = "MVE"
    mesh: tuple | None = None
    tol: float = 1e-3
    max_iter: int = DEFAULT_MAX_ITER
    convention: str = "paper"
    pairing: object = "auto"
    forward: str = "auto"
    budget: bool = True


@dataclass(frozen=True)
class SampleOptions:
    """The posterior of a case by emcee (:func:`bayesplate.sampling.sample`).

    Parameters
    ----------
    mesh : tuple of int, optional
        Elements along x and y; default the case's ``[model] mesh`` (unused when the run is
        given a model).
    walkers : int
        emcee walkers.
    max_steps : int
        Cap on steps.
    min_ess : float
        Effective samples per constant to reach.
    forward : {"reduced", "full"}
        The certified fast model around B, or the full model throughout.
    pairing : str or bayesplate.matching.pairing.Pairing
        Measured-to-computed modes.
    inputs : {"auto", "exact", "marginal"}
        The plate's measured inputs exact, or their deviations marginalised (``"auto"``:
        marginal when the case gives any).
    backend : str, optional
        An HDF5 file keeping the chain; a run on an existing one continues it.
    mve : bool
        Also MVE on the sampler's model, reported beside B (the JSON document's
        ``estimates``).
    """

    mesh: tuple | None = None
    walkers: int = 32
    max_steps: int = 5000
    min_ess: float = 2000.0
    forward: str = "reduced"
    pairing: object = "auto"
    inputs: str = "auto"
    backend: str | None = None
    mve: bool = True
