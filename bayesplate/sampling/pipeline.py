"""From a case to its posterior: :func:`prepare`, then the chain, with the fast model's counts.

:func:`sample` is the case-level entry point: the setup (problem, fast model, MAP; or one
prepared beforehand), then :func:`~bayesplate.sampling.chain.sample_problem` on the fast
model's eigenvalues path inside its box, and the result completed with the full solves the
fast model fell back to, its certificate, the MAP and the timings of every stage.
"""

from __future__ import annotations

import time
from dataclasses import replace

from ..inputs_posterior import inputs_from_chain
from .chain import sample_problem
from .seeding import resolve_rng, streams
from .setup import prepare

__all__ = ["sample"]


def sample(
    case,
    rng=None,
    n_walkers=32,
    max_steps=5000,
    target_tau_factor=50.0,
    min_ess=2000.0,
    check_every=20,
    pool=None,
    backend_path=None,
    progress=True,
    *,
    max_rhat=1.01,
    setup=None,
    moves=None,
    model=None,
    forward="reduced",
    convention="paper",
    prior_mean=None,
    prior_sd=None,
    pairing="auto",
    box_sigma=6.0,
    box=None,
    pilot_mesh="auto",
    fast=None,
    fast_options=None,
    seed=None,
    inputs="auto",
):
    """Sample the posterior of a case's elastic constants (the estimators' problem).

    Parameters
    ----------
    case : case object
        With ``.name``, ``.plate``, ``.measured`` and ``.prior`` (a
        :class:`bayesplate.io.Case`).
    rng : int, numpy.random.Generator or None
        Seeds the fast model's designs, the initial walkers and emcee: the same int, the same
        chain (it is split into two streams, for :func:`prepare` and the chain).
    n_walkers, max_steps, target_tau_factor, min_ess, check_every, pool, backend_path, \
progress, max_rhat, moves
        See :func:`~bayesplate.sampling.chain.sample_problem`.
    setup : SamplingSetup, optional
        From :func:`prepare` (skips the pilot, the fast model and the MAP); the keywords of
        :func:`prepare` below are then not used.
    model, forward, convention, prior_mean, prior_sd, pairing, box_sigma, box, pilot_mesh, \
fast, fast_options
        Of :func:`prepare`, with its defaults: the full model (default the case's own),
        ``"reduced"`` or ``"full"`` forward model, the estimators' conventions
        (``"paper"``), an engineering prior replacing the case's (SI), the pairing
        (``"auto"``), the posterior box's half-width in deviations (6) or an explicit box,
        the pilot's mesh (``"auto"``), a fast model already built, keywords of
        :func:`bayesplate.reduced.fast_model`.
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    inputs : {"auto", "exact", "marginal"}
        Of :func:`prepare`: the plate's measured inputs exact, or their deviations
        marginalised (``"auto"``: marginal when the case gives any). The result's
        ``settings["inputs"]`` says which was used. Marginalised, the declared readings are
        then drawn once per kept draw of the constants (at most 4000, a seeded subset) from
        their Gaussian conditional (:mod:`bayesplate.inputs_posterior`; the third stream of
        `rng`): exact joint draws under the linear input model, whose certificate at the MAP
        the result carries (``input_certificate``).

    Returns
    -------
    SamplingResult
    """
    started = time.perf_counter()
    entropy, build_rng, walk_rng, inputs_rng = streams(resolve_rng(rng, seed, "sample"), 3)
    given = setup is not None
    if setup is None:
        setup = prepare(
            case,
            model=model,
            forward=forward,
            rng=build_rng,
            convention=convention,
            prior_mean=prior_mean,
            prior_sd=prior_sd,
            pairing=pairing,
            box_sigma=box_sigma,
            box=box,
            pilot_mesh=pilot_mesh,
            fast=fast,
            fast_options=fast_options,
            inputs=inputs,
        )
    certified = setup.fast  # None when the full model is sampled
    fallbacks0 = dict(certified.fallbacks) if certified is not None else {}
    est = setup.estimate
    result = sample_problem(
        setup.problem,
        est.b,
        est.covariance_b,
        rng=walk_rng,
        n_walkers=n_walkers,
        max_steps=max_steps,
        target_tau_factor=target_tau_factor,
        min_ess=min_ess,
        max_rhat=max_rhat,
        check_every=check_every,
        pool=pool,
        backend_path=backend_path,
        progress=progress,
        moves=moves,
        forward=setup.sampling_forward(),
        box=setup.box,
        assigned=setup.assigned,
    )
    input_posterior, drawn = None, time.perf_counter()
    if setup.input_model is not None:  # one draw of the readings per kept draw of b
        input_posterior = inputs_from_chain(setup.problem, result.samples_b,
                                            setup.sampling_forward(), setup.input_model,
                                            inputs_rng)  # fmt: skip
    drawn = time.perf_counter() - drawn
    fallbacks = {}
    if certified is not None:
        fallbacks = {k: certified.fallbacks[k] - fallbacks0.get(k, 0) for k in certified.fallbacks}
    n_full = result.n_forward if certified is None else sum(fallbacks.values())
    timings = {**setup.timings, "sampling": result.wall_time}
    if input_posterior is not None:
        timings["inputs"] = drawn
    # total: the setup's time too when it was prepared beforehand
    timings["total"] = time.perf_counter() - started + (sum(setup.timings.values()) if given else 0)
    settings = {**result.settings, "seed_entropy": entropy, "case": case.name,
                "box_lower": None if setup.box is None else setup.box.lower,
                "box_upper": None if setup.box is None else setup.box.upper,
                "full_solves_setup": setup.n_full_solves, "inputs": setup.inputs,
                "assignment": setup.assignment}  # fmt: skip
    return replace(
        result,
        input_posterior=input_posterior,
        input_certificate=setup.input_certificate,
        n_full=n_full,
        fallbacks=fallbacks,
        certificate=setup.certificate,
        estimate=est,
        timings=timings,
        settings=settings,
    )
