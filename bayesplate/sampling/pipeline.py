"""From a case to its posterior: :func:`prepare`, then the chain, with the fast model's counts.

:func:`sample` is the case-level entry point: the setup (problem, fast model, MAP; or one
prepared beforehand), then :func:`~bayesplate.sampling.chain.sample_problem` on the fast
model's eigenvalues path inside its box, and the result completed with the full solves the
fast model fell back to, its certificate, the MAP and the timings of every stage.

With the inputs marginalised (:class:`~bayesplate.sampling.options.SetupOptions`' ``inputs``),
the declared readings are then drawn once per kept draw of the constants (at most 4000, a
seeded subset) from their Gaussian conditional (:mod:`bayesplate.likelihood.inputs_posterior`; the
third stream of ``rng``): exact joint draws under the linear input model, whose certificate at the
MAP the result carries (``input_certificate``); ``settings["inputs"]`` says which treatment
was used.
"""

from __future__ import annotations

import time
from dataclasses import replace

from ..likelihood.inputs_posterior import inputs_from_chain
from .chain import sample_problem
from .options import CHAIN_FIELDS, ChainOptions, SetupOptions
from .seeding import resolve_rng, streams
from .setup import prepare

__all__ = ["sample"]


def sample(
    case,
    rng=None,
    *,
    options=None,
    setup=None,
    setup_options=None,
    model=None,
    pool=None,
    seed=None,
    **settings,
):
    """Sample the posterior of a case's elastic constants (the estimators' problem).

    The stages: :func:`prepare` (unless a setup is given), the chain (:func:`_chain`), the
    inputs drawn (:func:`_draw_inputs`), the result completed (:func:`_complete`).

    Parameters
    ----------
    case : case object
        With ``.name``, ``.plate``, ``.measured``, ``.prior`` (a :class:`bayesplate.io.Case`).
    rng : int, numpy.random.Generator or None
        Seeds the fast model's designs, the initial walkers and emcee: the same int, the same
        chain (it is split into streams, for :func:`prepare`, the chain and the inputs).
    options : ChainOptions, optional
        Size, stopping rule, tuning, moves, progress bar, file (default ``ChainOptions()``).
    setup : SamplingSetup, optional
        From :func:`prepare` (skips the pilot, the fast model and the MAP); `setup_options`
        and `model` are then not used.
    setup_options : SetupOptions, optional
        Of :func:`prepare` (default ``SetupOptions()``); with the inputs marginalised, the
        declared readings are drawn after the chain (module docstring).
    model : PlateModel, optional
        The full model (default the case's own), for :func:`prepare`.
    pool : object with ``map``, optional
        Maps the walkers' log-densities (:func:`~bayesplate.sampling.chain.sample_problem`).
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    **settings
        Any field of :class:`ChainOptions` or of :class:`SetupOptions` by name
        (``n_walkers=16``, ``min_ess=500``, ``pairing="likelihood"``, ...), over `options`
        and `setup_options`.

    Returns
    -------
    SamplingResult
    """
    started = time.perf_counter()
    entropy, build_rng, walk_rng, inputs_rng = streams(resolve_rng(rng, seed, "sample"), 3)
    chain = {k: settings.pop(k) for k in CHAIN_FIELDS & settings.keys()}
    options = ChainOptions.of(options, "sample", **chain)
    setup_options = SetupOptions.of(setup_options, "sample", **settings)
    given = setup is not None
    if setup is None:
        setup = prepare(case, model=model, rng=build_rng, options=setup_options)
    result, fallbacks = _chain(setup, walk_rng, options, pool)
    input_posterior, drawn = _draw_inputs(setup, result, inputs_rng)
    timings = {**setup.timings, "sampling": result.wall_time, **drawn}
    # total: the setup's time too when it was prepared beforehand
    timings["total"] = time.perf_counter() - started + (sum(setup.timings.values()) if given else 0)
    return _complete(result, case, setup, entropy, input_posterior, fallbacks, timings)


def _chain(setup, rng, options, pool):
    """The chain on the setup's problem from its MAP; the fast model's fallbacks meanwhile.

    Returns the result and ``{reason: full solves}`` the certified model fell back to during
    the chain (empty when the full model is sampled).
    """
    certified = setup.fast  # None when the full model is sampled
    before = dict(certified.fallbacks) if certified is not None else {}
    est = setup.estimate
    result = sample_problem(
        setup.problem,
        est.b,
        est.covariance_b,
        rng=rng,
        options=options,
        pool=pool,
        forward=setup.sampling_forward(),
        box=setup.box,
        assigned=setup.assigned,
    )
    if certified is None:
        return result, {}
    return result, {k: certified.fallbacks[k] - before.get(k, 0) for k in certified.fallbacks}


def _draw_inputs(setup, result, rng):
    """One draw of the declared readings per kept draw of ``b``, and ``{"inputs": seconds}``.

    None and ``{}`` when the inputs are exact (or no deviation is declared).
    """
    if setup.input_model is None:
        return None, {}
    started = time.perf_counter()
    drawn = inputs_from_chain(
        setup.problem, result.samples_b, setup.sampling_forward(), setup.input_model, rng
    )
    return drawn, {"inputs": time.perf_counter() - started}


def _complete(result, case, setup, entropy, input_posterior, fallbacks, timings):
    """The chain's result with the setup's: MAP, certificate, full solves, settings, timings."""
    n_full = result.n_forward if setup.fast is None else sum(fallbacks.values())
    box = setup.box
    settings = {
        **result.settings,
        "seed_entropy": entropy,
        "case": case.name,
        "box_lower": None if box is None else box.lower,
        "box_upper": None if box is None else box.upper,
        "full_solves_setup": setup.n_full_solves,
        "inputs": setup.inputs,
        "assignment": setup.assignment,
    }
    return replace(
        result,
        input_posterior=input_posterior,
        input_certificate=setup.input_certificate,
        n_full=n_full,
        fallbacks=fallbacks,
        certificate=setup.certificate,
        estimate=setup.estimate,
        timings=timings,
        settings=settings,
    )
