"""One material, many plates: the joint posterior of the six constants the plates share.

Several tests of one material (plates of different sizes, thicknesses, layups or densities,
each its own case) inform one set of lamina constants. The joint target is

    ln f(b | Y_1, ..., Y_P) = ln f(b) + sum_p ln f(Y_p | b) + const,

each plate's log-likelihood on ITS OWN certified fast model (its own geometry, inputs,
pairing and deviations, from :func:`~bayesplate.sampling.setup.prepare`), plus ONE prior.

It is built as one stacked :class:`~bayesplate.likelihood.posterior.GaussianProblem`
(:func:`joint_problem`): ``Y`` the plates' paired eigenvalues one after another, ``V_Y``
block-diagonal (plates are independent given ``b``; a plate's block keeps its marginalised
inputs), the forward model :class:`JointForward` (each plate's model at the same ``b``, its
paired modes concatenated). The stacked problem's log-posterior is then exactly the sum
above, and the one-plate chain (:func:`~bayesplate.sampling.chain.sample_problem`: whitened
log coordinates, the same moves, tuning, seeding, stopping rule and HDF backend) samples it
unchanged. Proposals are not Ritz-screened (one bound per plate model would be needed):
differential-evolution proposals outside the box use each plate's full-model fallback,
counted in the result.

Rules (:func:`check_plates`, refused with :class:`PlatesMismatch`, a one-line ValueError
naming the plate, key, value and rule):

- the prior is the first case's and every case must state the same one (the prior is
  the material's; two different statements of it are two materials, or a typing error);
- the same test twice (equal cases) is refused: it would count its data twice;
- a case with an error scale (``measured.error_scale``) is refused: the stacked problem
  has one Gaussian likelihood, not one Student-t per plate (not yet);
- layups may differ (e.g. a ``[0]`` and a ``[0, 90, 90, 0]`` plate): all laminae of all
  plates are of the one material, which is what is estimated.

The fast models: each plate's is built over its own posterior box; the joint MAP (B on the
stacked problem, iterated on the plates' reduced models) then places the joint box
(:func:`~bayesplate.sampling.setup.posterior_box`), and a plate whose box does not hold it
(a plate that disagrees with the rest) gets a fast model rebuilt over the joint box. The
sampler's box is the intersection of the plates' boxes. Which plate disagrees:
:mod:`bayesplate.sampling.plate_checks`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..reduced import Box
from .chain import sample_problem
from .plate_checks import plate_checks
from .seeding import generator, resolve_rng, streams
from .setup import posterior_box, prepare
from .stacked import JointForward, joint_estimate, joint_problem

__all__ = [
    "JointForward",
    "JointResult",
    "JointSetup",
    "PlatesMismatch",
    "check_plates",
    "joint_problem",
    "prepare_joint",
    "sample_plates",
]

log = logging.getLogger(__name__)


class PlatesMismatch(ValueError):
    """Cases that cannot be one material's plates: which one, its key, value and rule.

    Parameters
    ----------
    index : int
        0-based position of the offending case.
    key : str
        Its case-file key (e.g. ``prior.E1_GPa``).
    value : object
        The value given.
    rule : str
        The rule broken, phrased as a requirement.
    """

    def __init__(self, index, key, value, rule):
        self.index, self.key, self.value, self.rule = index, key, value, rule
        super().__init__(f"plate {index + 1}: {key} = {value}: {rule}")


def check_plates(cases):
    """Refuse cases that cannot be sampled as plates of one material (module docstring).

    Parameters
    ----------
    cases : sequence of bayesplate.io.Case
        Two or more.

    Raises
    ------
    PlatesMismatch
    """
    from ..quantities import ENGINEERING_KEYS, to_case_units

    if len(cases) < 2:
        raise PlatesMismatch(0, "cases", len(cases), "a joint posterior needs two plates or more")
    first = cases[0]
    m0, s0 = to_case_units(first.prior.mean), to_case_units(first.prior.sd)
    for i, case in enumerate(cases):
        if getattr(case.measured, "error_scale", None) is not None:
            raise PlatesMismatch(
                i,
                "measured.error_scale",
                "given",
                "several plates are sampled with known deviations only (no error scale)",
            )
        if i == 0:
            continue
        for j in range(i):
            if case == cases[j]:
                raise PlatesMismatch(
                    i, "case", f"the same as plate {j + 1}", "each plate's test may be given once"
                )
        mean, sd = to_case_units(case.prior.mean), to_case_units(case.prior.sd)
        for k, key in enumerate(ENGINEERING_KEYS):
            if not (np.isclose(mean[k], m0[k], rtol=1e-9) and np.isclose(sd[k], s0[k], rtol=1e-9)):
                raise PlatesMismatch(
                    i,
                    f"prior.{key}",
                    f"{{ mean = {mean[k]:g}, sd = {sd[k]:g} }}",
                    f"plates of one material share one prior: the first "
                    f"plate's {{ mean = {m0[k]:g}, sd = {s0[k]:g} }}",
                )


def _covers(box, inner):
    return bool(np.all(box.lower <= inner.lower) and np.all(inner.upper <= box.upper))


def _hull(own, joint):
    """The smallest box holding a plate's own box and the joint one (its MAP stays inside).

    The joint box alone when the hull reaches non-physical laminae.
    """
    try:
        return Box(np.minimum(own.lower, joint.lower), np.maximum(own.upper, joint.upper))
    except ValueError:
        return joint


def _intersection(boxes):
    return Box(np.max([b.lower for b in boxes], axis=0), np.min([b.upper for b in boxes], axis=0))


@dataclass(frozen=True, eq=False)
class JointSetup:
    """The plates' setups, their joint MAP and the sampler's box.

    Attributes
    ----------
    setups : tuple of SamplingSetup
        Each plate's, with a fast model covering the joint box.
    singles : tuple of EstimateResult
        Each plate's own B estimate (its MAP alone, on its first fast model).
    estimate : EstimateResult
        B on the stacked problem (the joint MAP and ``P``).
    box : Box or None
        Intersection of the plates' fast-model boxes (None with the full model).
    rebuilt : tuple of int
        0-based plates whose fast model was rebuilt over the joint box.
    timings : dict
        Seconds: ``setup`` (every plate's prepare), ``joint_map``.
    """

    setups: tuple = field(repr=False)
    singles: tuple = field(repr=False)
    estimate: object = field(repr=False)
    box: object
    rebuilt: tuple
    timings: dict

    @property
    def problem(self):
        """The stacked problem on the plates' full models."""
        return joint_problem([s.problem for s in self.setups])

    def sampling_forward(self):
        """The plates' eigenvalues-only paths, stacked (:class:`JointForward`)."""
        return JointForward(
            [s.sampling_forward() for s in self.setups], [s.problem.pairing for s in self.setups]
        )


def prepare_joint(
    cases,
    *,
    models=None,
    rng=None,
    forward="reduced",
    box_sigma=6.0,
    pairing="auto",
    inputs="auto",
    fast_options=None,
):
    """Every plate's setup with the first case's prior, the joint MAP and the joint box.

    Parameters
    ----------
    cases : sequence of bayesplate.io.Case
        Plates of one material (:func:`check_plates`).
    models : sequence of PlateModel, optional
        Each plate's full model; default each case's own.
    rng : int, numpy.random.Generator or None
        Seeds the fast models' designs (one stream per plate, in order).
    forward, box_sigma, pairing, inputs, fast_options
        Of :func:`~bayesplate.sampling.setup.prepare`, for every plate.

    Returns
    -------
    JointSetup
    """
    check_plates(cases)
    rng = generator(resolve_rng(rng, None, "prepare_joint"))[1]
    streams = rng.spawn(len(cases))
    models = [None] * len(cases) if models is None else list(models)
    prior = cases[0].prior
    opts = {
        "forward": forward,
        "pairing": pairing,
        "inputs": inputs,
        "fast_options": fast_options,
        "prior_mean": prior.mean,
        "prior_sd": prior.sd,
    }
    started = time.perf_counter()
    setups = [
        prepare(c, model=m, rng=r, box_sigma=box_sigma, **opts)
        for c, m, r in zip(cases, models, streams, strict=True)
    ]
    singles = tuple(s.estimate for s in setups)
    if any(s.assigned is not None for s in setups):  # the joint density has no re-assignment
        log.warning(
            "plates sampled jointly keep each plate's assignment by likelihood as "
            "settled through the chain (it is re-made at every point for one plate)"
        )
    t_setup = time.perf_counter() - started
    started = time.perf_counter()
    start = np.mean([s.b for s in singles], axis=0)
    est = joint_estimate(setups, start=start, free=True)
    rebuilt = []
    if forward == "reduced":
        p = setups[0].problem
        joint_box = posterior_box(est, p.mu_b, p.V_b, box_sigma)
        for i, s in enumerate(setups):
            if s.fast is not None and _covers(s.fast.box, joint_box):
                continue
            log.info("plate %d: fast model rebuilt over the joint posterior's box", i + 1)
            setups[i] = prepare(
                cases[i],
                model=s.model,
                rng=streams[i],
                box=_hull(s.fast.box, joint_box) if s.fast else joint_box,
                box_sigma=box_sigma,
                **{**opts, "pairing": s.problem.pairing},
            )
            rebuilt.append(i)
    est = joint_estimate(setups, start=est.b)
    box = None if forward != "reduced" else _intersection([s.fast.box for s in setups])
    timings = {"setup": t_setup, "joint_map": time.perf_counter() - started}
    return JointSetup(tuple(setups), singles, est, box, tuple(rebuilt), timings)


@dataclass(frozen=True, eq=False)
class JointResult:
    """The joint posterior of several plates and how each plate agrees with the rest.

    Attributes
    ----------
    names : tuple of str
        The plates' case names.
    sampling : SamplingResult
        The shared constants' posterior (means, sd, HDI, chain; ``observed_data`` the
        stacked eigenvalues, plate after plate).
    setup : JointSetup
    checks : tuple of PlateCheck
        One per plate (:mod:`bayesplate.sampling.plate_checks`).
    status : str
        ``"consistent"`` (no plate flagged), ``"flagged"`` (some plate disagrees at
        ``alpha``) or ``"not_converged"`` (the chain missed its stopping rule).
    timings : dict
        Seconds: ``setup``, ``joint_map``, ``sampling``, ``checks``, ``total``.
    """

    names: tuple
    sampling: object = field(repr=False)
    setup: object = field(repr=False)
    checks: tuple
    status: str
    timings: dict

    @property
    def flagged(self):
        """0-based plates flagged as disagreeing with the rest."""
        return tuple(i for i, c in enumerate(self.checks) if c.flagged)


def sample_plates(
    cases,
    rng=None,
    n_walkers=32,
    max_steps=5000,
    target_tau_factor=50.0,
    min_ess=2000.0,
    check_every=20,
    backend_path=None,
    progress=True,
    *,
    max_rhat=1.01,
    setup=None,
    alpha=0.01,
    **prepare_options,
):
    """Sample the joint posterior of plates of one material; say which plate disagrees.

    Parameters
    ----------
    cases : sequence of bayesplate.io.Case
        Two or more plates of one material (:func:`check_plates`).
    rng : int, numpy.random.Generator or None
        Split as :func:`~bayesplate.sampling.pipeline.sample` splits it: one stream for the
        fast models, one for the chain; the same int, the same numbers.
    n_walkers, max_steps, target_tau_factor, min_ess, check_every, backend_path, \
progress, max_rhat
        Of :func:`~bayesplate.sampling.chain.sample_problem`.
    setup : JointSetup, optional
        From :func:`prepare_joint` (then `prepare_options` are not used).
    alpha : float
        Level of the disagreement flag (:func:`~bayesplate.sampling.plate_checks.plate_checks`).
    **prepare_options
        Of :func:`prepare_joint`.

    Returns
    -------
    JointResult
    """
    started = time.perf_counter()
    entropy, build_rng, walk_rng = streams(resolve_rng(rng, None, "sample_plates"))
    if setup is None:
        setup = prepare_joint(cases, rng=build_rng, **prepare_options)
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
        backend_path=backend_path,
        progress=progress,
        forward=setup.sampling_forward(),
        box=setup.box,
    )
    t0 = time.perf_counter()
    checks = plate_checks(
        setup.setups, result.mean_b, est.b, alpha=alpha, names=[c.name for c in cases]
    )
    timings = {**setup.timings, "sampling": result.wall_time, "checks": time.perf_counter() - t0}
    timings["total"] = time.perf_counter() - started
    if not result.converged:
        status = "not_converged"
    else:
        status = "flagged" if any(c.flagged for c in checks) else "consistent"
    result = replace(
        result, settings={**result.settings, "seed_entropy": entropy}, estimate=est, timings=timings
    )
    return JointResult(tuple(c.name for c in cases), result, setup, tuple(checks), status, timings)
