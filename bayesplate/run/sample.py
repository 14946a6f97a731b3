"""A case to its posterior: :func:`run_sample` (prepare, the chain, the error scale, MVE)."""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass
from functools import cached_property

from .seeds import run_seeds

__all__ = ["SampleRun", "run_sample"]


@dataclass(frozen=True, eq=False)
class SampleRun:
    """What :func:`run_sample` computed.

    Attributes
    ----------
    case : bayesplate.io.Case
    model : bayesplate.plate.model.PlateModel
        The full model of the run (its mesh).
    setup : bayesplate.sampling.SamplingSetup
        The sampler's problem, fast model and MAP.
    result : bayesplate.sampling.SamplingResult
        The chain and its summary.
    seed : int
        The run's seed (drawn when none was given; the result's ``seed_entropy``).
    scale : bayesplate.likelihood.error_scale.ScaleSummary or None
        The error scale from the chain's draws, when the case declares one.
    mve : bayesplate.estimators.EstimateResult or None
        MVE on the sampler's model, when asked for.
    warnings : tuple of str or None
        The distinct warnings of the set-up and the chain, when recorded.
    """

    case: object
    model: object
    setup: object
    result: object
    seed: int
    scale: object = None
    mve: object = None
    warnings: tuple | None = None

    @cached_property
    def document(self):
        """The JSON document (:func:`bayesplate.io.sampling_to_dict`), made once."""
        from ..io import sampling_to_dict

        return sampling_to_dict(self.result, self.case, self.mve, self.scale)


def run_sample(
    case, options, seed, *, model=None, fast=None, pool=None, progress=False, record_warnings=False
):
    """Sample the posterior of `case`: prepare, the chain, the error scale's draws, MVE.

    Parameters
    ----------
    case : bayesplate.io.Case
    options : SampleOptions
    seed : int or None
        Split into the run's streams by :func:`~bayesplate.run.run_seeds` (None: a fresh
        seed, once): the same seed, the chain of ``sample(case, rng=seed)``.
    model : bayesplate.plate.model.PlateModel, optional
        The full model, already built; default the case's on ``options.mesh``.
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model shared with other runs, used when the inputs are exact: with
        marginalised inputs the posterior is wider than the box it was certified over, and
        the sampler places and certifies its own.
    pool : optional
        ``map`` of the walkers' log-densities (:class:`bayesplate.batch.TaskPool`); the
        numbers do not depend on it.
    progress : bool
        The chain's progress on standard error.
    record_warnings : bool
        Record the set-up's and the chain's warnings (in ``SampleRun.warnings``) instead of
        letting them through.

    Returns
    -------
    SampleRun
    """
    from ..plate.model import PlateModel
    from ..sampling import ChainOptions, SetupOptions, prepare, resolve_inputs, sample

    seeds = run_seeds(seed)
    if model is None:
        model = PlateModel.from_case(case, mesh=options.mesh)
    inputs = resolve_inputs(case, options.inputs)
    if inputs != "exact":
        fast = None
    setup_options = SetupOptions(
        forward=options.forward, pairing=options.pairing, fast=fast, inputs=inputs
    )
    chain = ChainOptions(
        n_walkers=options.walkers,
        max_steps=options.max_steps,
        min_ess=options.min_ess,
        backend_path=options.backend,
        progress=progress,
    )
    with _recording(record_warnings) as recorded:
        setup = prepare(case, model=model, rng=seeds.prepare, options=setup_options)
        result = sample(case, rng=seeds.chain, options=chain, setup=setup, pool=pool)
    noted = None if recorded is None else tuple(sorted({str(w.message) for w in recorded}))
    scale = None
    if case.measured.error_scale is not None:
        from ..likelihood.error_scale import scale_from_draws

        scale = scale_from_draws(
            setup.problem, result.samples_b, setup.sampling_forward(), rng=seeds.error_scale
        )[0]
    mve = setup.run_estimator("MVE") if options.mve else None
    return SampleRun(case, model, setup, result, seeds.seed, scale, mve, noted)


@contextlib.contextmanager
def _recording(on):
    """Every warning inside, recorded in the list yielded (`on`), or let through (None)."""
    if not on:
        yield None
        return
    with warnings.catch_warnings(record=True) as recorded:
        warnings.simplefilter("always")
        yield recorded
