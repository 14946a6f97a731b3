"""What the sampler needs first: the problem, its fast model over the posterior box, the MAP.

:func:`prepare` builds a :class:`SamplingSetup`: the estimators' Gaussian problem (same
conventions, prior and pairing), a pilot B run (on a halved mesh above
:data:`PILOT_MAX_ELEMENTS` elements) placing the posterior box (:func:`posterior_box`), the
certified reduced-basis model over it (:func:`bayesplate.reduced.fast_model`), and B
iterated to :data:`MAP_TOL` on that fast model: the MAP and its covariance ``P``.

Uncertain inputs (``inputs="marginal"``): the plate's thickness, density, length and width
deviations are marginalised to first order, ``V_Y + J_p Sigma_p J_p^T``
(:meth:`GaussianProblem.from_case`), with ``J_p`` first at the pilot (or settling) B estimate.
That covariance is a constant matrix, so the fast model needs no new parameters; only its box
is placed with the widened covariance (``P`` of the marginal problem at the pilot estimate),
so that it spans the wider posterior. ``J_p`` is then evaluated again at the marginal MAP and
the MAP found again with it (7 more full solves): the pilot is the *exact* problem's estimate,
which the inputs' freedom moves the posterior away from (by a few % of the moduli on the
synthetic plates of ``studies/input_coverage.py``, 10 % on the spruce plate), and ``J_p``
(proportional to the eigenvalues) is best where the posterior is; at the pilot it doubled the
certificate's error on a synthetic plate (0.32 against 0.16 of a measurement deviation).
The setup keeps the readings' conditional given ``b`` (``input_model``: the sampler draws the
inputs from it after the chain, :mod:`bayesplate.likelihood.inputs_posterior`) and the linear input
model's certificate at the MAP (``input_certificate``: full solves at +- 2 sd of each
declared reading).

:func:`prepare` is a row of stages, module functions handing on a small frozen state
(``_Start``) and the :class:`SamplingSetup` as it grows; its options are one
:class:`~bayesplate.sampling.options.SetupOptions`. The pilot's model, the box placed from it
and the inputs' marginal problem are :mod:`~bayesplate.sampling.pilot`'s; the MAP's B runs
:mod:`~bayesplate.sampling.map_estimate`'s.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..estimators import resolve_conventions, run, settle_pairing
from ..likelihood.inputs import input_sources
from ..likelihood.inputs_posterior import linear_input_certificate
from ..likelihood.posterior import INPUT_TREATMENTS, GaussianProblem, prior_in_stiffness
from ..matching.checked_order import assignment_at, checks_order, refuted_order
from ..matching.pairing import Pairing
from ..plate.model import PlateModel
from ..reduced import fast_model
from .assigned import reassignment
from .box import check_box as _check_box
from .box import posterior_box
from .density import EigenvalueForward
from .map_estimate import MAP_TOL, map_estimate, run_on_fast, scaled_map
from .options import SetupOptions
from .pilot import PILOT_MAX_ELEMENTS, marginal, mesh_text, pilot_model, place_box
from .seeding import resolve_rng

__all__ = [
    "FAST_DEFAULTS",
    "MAP_TOL",
    "PILOT_MAX_ELEMENTS",
    "PILOT_TOL",
    "SamplingSetup",
    "SetupOptions",
    "posterior_box",
    "prepare",
    "resolve_inputs",
]

log = logging.getLogger(__name__)

#: Pilot B: a relative change of 1e-2 leaves it within ~0.1 deviations of the converged
#: estimate (Frederiksen plate: 0.12 after 5 iterations), far inside a 6-deviation box.
PILOT_TOL = 1e-2
#: Default fast-model settings for a posterior box: 10 design points besides the centre
#: (6 needed a second round on the Frederiksen plate, 10 passed in one: 17 full solves),
#: rounds of 4 random + 2 probe held-out points (see :func:`bayesplate.reduced.fast_model`).
FAST_DEFAULTS = {"n_snapshots": 10, "n_test": 4, "n_probe": 2}


@dataclass(frozen=True, eq=False)
class SamplingSetup:
    """The problem, its fast model and its MAP: everything :func:`sample` needs first.

    Attributes
    ----------
    problem : GaussianProblem
        On the full model, with the estimators' conventions, prior and pairing (no extra
        modes beyond the paired ones: the sampler does not track modes).
    model : PlateModel
        The full model.
    fast : bayesplate.reduced.CertifiedModel or None
        None when the full model is sampled.
    estimate : EstimateResult
        B on the sampler's forward model: the MAP and ``P``.
    pilot : EstimateResult or None
        The pilot B run that placed the box.
    box : bayesplate.reduced.Box or None
    timings : dict
        Seconds: ``pilot``, ``build``, ``map`` (and ``input_certificate`` when it was made).
    n_full_solves : int
        Full finite-element solves spent (pilot on the case mesh, build, certification,
        the input Jacobian and its certificate).
    inputs : str
        ``"exact"`` or ``"marginal"``: how the plate's measured inputs enter ``problem``.
    input_model : bayesplate.likelihood.inputs_posterior.InputConditional or None
        With the inputs marginalised and some deviation declared: the readings' conditional
        ``f(z | b, Y)`` (``J_p`` where the marginal problem has it), for their draws.
    input_certificate : bayesplate.likelihood.inputs_posterior.InputCertificate or None
        The linear input model against full solves at the MAP (its solves counted in
        ``n_full_solves``).
    assigned : bayesplate.sampling.assigned.ReassignedLikelihood or None
        Pairing by likelihood: the likelihood of all the measured peaks with the assignment
        re-made at every point of the chain (:mod:`bayesplate.sampling.assigned`); None
        with any other pairing, and by likelihood where it is kept fixed (`assignment`).
    assignment : str or None
        Pairing by likelihood: how the chain treats the assignment, one sentence (re-made
        at every point, or kept as settled and why); None with any other pairing.
    """

    problem: GaussianProblem = field(repr=False)
    model: object = field(repr=False)
    fast: object
    estimate: object = field(repr=False)
    pilot: object = field(repr=False)
    box: object
    timings: dict
    n_full_solves: int
    inputs: str = "exact"
    input_model: object = field(default=None, repr=False)
    input_certificate: object = None
    assigned: object = field(default=None, repr=False)
    assignment: str | None = None

    @property
    def certificate(self):
        """The fast model's certificate, or None."""
        return None if self.fast is None else self.fast.certificate

    def forward_with_sensitivities(self):
        """``forward(b, n_modes)`` of the sampler's model with sensitivities (for B, MVE)."""
        return self.model.solve if self.fast is None else self.fast.solve

    def sampling_forward(self):
        """``forward(b, n_modes)`` the sampler uses: the fast model's eigenvalues path.

        An :class:`~bayesplate.sampling.density.EigenvalueForward` holding the certified
        model's reduced part (its eigenvalues bound the full model's from above, for
        screening proposals off the box) when its certificate passed; the full model's
        ``solve`` when no fast model is used.
        """
        if self.fast is None:
            return self.model.solve
        reduced = self.fast.reduced if self.fast.certified else None
        return EigenvalueForward(self.fast, reduced)

    def problem_on_fast_model(self, mu_b=None, V_b=None):
        """The same problem (or another prior) on the sampler's model with sensitivities."""
        p = self.problem
        mu_b = p.mu_b if mu_b is None else mu_b
        V_b = p.V_b if V_b is None else V_b
        return p.with_prior(mu_b, V_b).with_forward(self.forward_with_sensitivities())

    def run_estimator(self, method="MVE", tol=1e-3, **kwargs):
        """B or MVE (:func:`bayesplate.estimators.run`) on the sampler's model.

        Iterates outside the certified box use the reduced model uncertified; the result is
        recomputed with the full-model fallback if it ends outside the box.
        """
        return run_on_fast(self, method, tol, **kwargs)


def _reassignment(case, pairing, inputs, observation):
    """:func:`.assigned.reassignment` for a case; a warning where it is kept as settled."""
    full = inputs == "marginal" and bool(np.any(input_sources(case.plate)[1]))
    scaled = getattr(case.measured, "error_scale", None) is not None
    f, s = case.measured.frequency_Hz, case.measured.sigma_Hz
    assigned, note = reassignment(pairing, f, s, observation, full, scaled)
    if note is not None and assigned is None:
        log.warning(note)
    return assigned, note


def resolve_inputs(case, inputs="auto"):
    """``"exact"`` or ``"marginal"``: ``"auto"`` is marginal when the case gives any input sd.

    Parameters
    ----------
    case : bayesplate.io.Case
    inputs : {"auto", "exact", "marginal"}

    Returns
    -------
    str
    """
    if inputs == "auto":
        return "marginal" if np.any(input_sources(case.plate)[1]) else "exact"
    if inputs not in INPUT_TREATMENTS:
        raise ValueError(f"inputs = {inputs!r}: must be 'auto' or one of {INPUT_TREATMENTS}")
    return inputs


def prepare(case, *, model=None, rng=None, options=None, seed=None, **settings):
    """The sampler's problem, fast model and MAP for a case.

    The stages: the problem and its pairing (:func:`_start`), the pilot B run, the box and
    the fast model (:func:`_with_fast_model`), B to the MAP (:func:`_with_map`), pairing by
    order checked there (:func:`_order_holds`; the setup made again by likelihood where the
    data refute it), the linear input model's certificate (:func:`_with_input_certificate`).

    Parameters
    ----------
    case : bayesplate.io.Case
    model : PlateModel, optional
        Full model; default ``PlateModel.from_case(case)``.
    rng : int, numpy.random.Generator or None
        Seed of the fast model's designs.
    options : SetupOptions, optional
        The forward model, conventions, prior, pairing, box, pilot mesh, fast model and the
        treatment of the inputs (default ``SetupOptions()``).
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    **settings
        Any field of :class:`SetupOptions` by name (``pairing="order"``, ``box_sigma=5``,
        ...), over `options`.

    Returns
    -------
    SamplingSetup
    """
    rng = resolve_rng(rng, seed, "prepare")
    options = SetupOptions.of(options, "prepare", **settings)
    start = _start(case, model, options)
    setup = _with_map(start, _with_fast_model(start, rng))
    if start.checked and not _order_holds(start, setup):
        again = replace(start.options, pairing="likelihood", fast=None)
        return prepare(case, model=start.model, rng=rng, options=again)
    if not setup.estimate.converged:
        log.warning("B (the MAP) did not converge: %s", setup.estimate.message)
    _check_box(setup.box, setup.estimate)
    return _with_input_certificate(start, setup)


@dataclass(frozen=True, eq=False)
class _Start:
    """What the stages of :func:`prepare` share: the case's problem before any fast model.

    ``options`` has its ``inputs`` resolved (``"exact"`` or ``"marginal"``) and its
    ``pilot_mesh`` None with a model given (the pilot runs on it then); ``pair`` is the
    pairing without extra modes; ``settled`` B's run that settled a pairing by name (None
    for a :class:`Pairing` given); ``exact`` the problem with the inputs exact; ``checked``
    whether the pairing is by order, to check at the MAP.
    """

    case: object
    model: PlateModel
    options: SetupOptions
    conventions: object
    mean: np.ndarray
    sd: np.ndarray
    pair: Pairing
    settled: object
    exact: GaussianProblem
    assigned: object
    assignment: str | None
    checked: bool

    @property
    def n_modes(self):
        """Modes the fast model computes: the paired ones, or the re-assignment's."""
        return self.pair.n_modes() if self.assigned is None else self.assigned.n


def _start(case, model, options):
    """The model, prior, conventions and pairing (settled by B when given by name).

    By likelihood, B settles the assignment on the working model (a coarser mesh's error in
    the upper modes would call their peaks spurious), and that B run is the pilot too (the
    pilot mesh may number the upper modes otherwise).
    """
    inputs = resolve_inputs(case, options.inputs)
    conventions = resolve_conventions(options.convention)
    pilot_mesh = options.pilot_mesh if model is None else None
    options = replace(options, inputs=inputs, pilot_mesh=pilot_mesh)
    model = model or PlateModel.from_case(case)
    mean = np.asarray(
        case.prior.mean if options.prior_mean is None else options.prior_mean, dtype=float
    )
    sd = np.asarray(case.prior.sd if options.prior_sd is None else options.prior_sd, dtype=float)
    checked = checks_order(case.measured, options.pairing)
    pairing, settled = options.pairing, None
    if not isinstance(pairing, Pairing):
        pairing, settled = settle_pairing(
            case,
            model,
            pairing,
            tol=PILOT_TOL,
            convention=conventions,
            prior_mean=mean,
            prior_sd=sd,
            fast=options.fast,
        )
    pair = replace(pairing, extra=0)
    exact = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    reassigned = _reassignment(case, pairing, options.inputs, conventions.observation)
    return _Start(
        case, model, options, conventions, mean, sd, pair, settled, exact, *reassigned, checked
    )


def _with_fast_model(start, rng):
    """The setup before its MAP: the pilot, the box and the fast model; the inputs' problem.

    A fast model is built over the posterior box only with ``forward="reduced"`` and none
    given. With the inputs marginalised and no pilot to place a box, ``J_p`` is taken at the
    settling B estimate, else at the prior mean.
    """
    o, case, model = start.options, start.case, start.model
    timings = {"pilot": 0.0, "build": 0.0, "map": 0.0}
    problem, fast, pilot, solves, conditional = start.exact, o.fast, None, 0, None
    if o.forward == "reduced" and fast is None:
        problem, box, pilot, solves, conditional = _pilot_and_box(start, timings)
        started = time.perf_counter()
        settings = {**FAST_DEFAULTS, **(o.fast_options or {})}
        center = box.center if pilot is None else pilot.b
        fast = fast_model(model, center, box, start.n_modes, rng=rng, **settings)
        timings["build"] = time.perf_counter() - started
        solves += fast.build_solves
        log.info("fast model: %s", fast.certificate)
    if o.inputs == "marginal" and problem is start.exact:
        at = problem.mu_b if start.settled is None else start.settled.b
        problem, spent, conditional = marginal(case, model, problem, at)
        solves += spent
    return SamplingSetup(
        problem,
        model,
        fast if o.forward == "reduced" else None,
        None,
        pilot,
        None if fast is None else fast.box,
        timings,
        solves,
        o.inputs,
        conditional,
        assigned=start.assigned,
        assignment=start.assignment,
    )


def _pilot_and_box(start, timings):
    """The box given, or placed from the settling B run or else a pilot B run (timed).

    Returns the problem (marginal where the inputs are), the box, the pilot (None with a box
    given), the full solves spent and the inputs' conditional (or None).
    """
    o = start.options
    if o.box is not None:
        return start.exact, o.box, None, 0, None
    started = time.perf_counter()
    pilot, solves = _pilot(start)
    problem, box, spent, conditional = place_box(
        start.case, start.model, start.exact, pilot, o.inputs, o.box_sigma
    )
    if start.settled is None:
        timings["pilot"] = time.perf_counter() - started
    return problem, box, pilot, solves + spent, conditional


def _pilot(start):
    """The settling B run, else B to :data:`PILOT_TOL` on the pilot model; full solves spent.

    Only solves on the case's mesh count as full solves (a pilot on a coarser mesh is none).
    """
    if start.settled is not None:
        return start.settled, start.settled.n_solves
    o, c = start.options, start.conventions
    coarse = pilot_model(start.case, start.model, o.pilot_mesh)
    pilot_problem = GaussianProblem.from_case(
        start.case, coarse, start.pair, c.observation, c.prior, start.mean, start.sd
    )
    pilot = run(pilot_problem, "B", tol=PILOT_TOL, conventions=c)
    log.info("pilot B (%s): %s", mesh_text(coarse), pilot.message)
    return pilot, pilot.n_solves if coarse is start.model else 0


def _with_map(start, setup):
    """B to the MAP on the sampler's model, ``P`` widened by an inferred error scale.

    B starts from the settled assignment's estimate (B's fixed point from the prior mean may
    be another optimum with a pairing that skips modes), from the prior mean otherwise. With
    the inputs marginalised, ``J_p`` is evaluated again at that MAP and the MAP found again.
    """
    started = time.perf_counter()
    conventions, settled = start.conventions, start.settled
    estimate = map_estimate(setup, conventions, None if settled is None else settled.b)
    estimate = scaled_map(setup, estimate)
    if setup.input_model is not None and estimate.converged:
        problem, spent, conditional = marginal(start.case, start.model, start.exact, estimate.b)
        setup = replace(
            setup,
            problem=problem,
            input_model=conditional,
            n_full_solves=setup.n_full_solves + spent,
        )
        estimate = scaled_map(setup, map_estimate(setup, conventions, estimate.b))
    timings = {**setup.timings, "map": time.perf_counter() - started}
    return replace(setup, estimate=estimate, timings=timings)


def _order_holds(start, setup):
    """Pairing by order, checked at the MAP on the sampler's model: whether it stands."""
    prior_V_b = prior_in_stiffness(start.mean, start.sd, "full")[1]
    found = assignment_at(
        start.case, setup.fast or start.model, setup.estimate.b, prior_V_b, start.pair
    )
    if not found.keeps_order:
        log.warning("%s: the sampler's setup is made again", refuted_order(found))
        return False
    log.info("pairing by order checked at the MAP: the most probable assignment")
    return True


def _with_input_certificate(start, setup):
    """The linear input model against full solves at the MAP (as it is: exact inputs)."""
    if setup.input_model is None:
        return setup
    started = time.perf_counter()
    model = start.model
    certificate = linear_input_certificate(
        start.case,
        setup.estimate.b,
        setup.input_model.B,
        start.pair.modes,
        np.sqrt(np.diag(start.exact.V_Y)),
        mesh=(model.mesh.nx, model.mesh.ny),
    )
    timings = {**setup.timings, "input_certificate": time.perf_counter() - started}
    solves = setup.n_full_solves + certificate.n_solves
    return replace(setup, input_certificate=certificate, n_full_solves=solves, timings=timings)
