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
inputs from it after the chain, :mod:`bayesplate.inputs_posterior`) and the linear input
model's certificate at the MAP (``input_certificate``: full solves at +- 2 sd of each
declared reading).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..checked_order import assignment_at, checks_order, refuted_order
from ..estimators import resolve_conventions, run, settle_pairing
from ..inputs import input_jacobian, input_sources
from ..inputs_posterior import declared_readings, input_conditional, linear_input_certificate
from ..model import PlateModel
from ..pairing import Pairing
from ..posterior import INPUT_TREATMENTS, GaussianProblem, prior_in_stiffness
from ..reduced import fast_model
from .assigned import reassignment
from .box import check_box as _check_box
from .box import posterior_box
from .density import EigenvalueForward
from .seeding import resolve_rng

__all__ = [
    "FAST_DEFAULTS",
    "MAP_TOL",
    "PILOT_MAX_ELEMENTS",
    "PILOT_TOL",
    "SamplingSetup",
    "posterior_box",
    "prepare",
    "resolve_inputs",
]

log = logging.getLogger(__name__)

#: Meshes above this many elements get a pilot B run on a mesh halved in each direction.
PILOT_MAX_ELEMENTS = 400
#: Pilot B: a relative change of 1e-2 leaves it within ~0.1 deviations of the converged
#: estimate (Frederiksen plate: 0.12 after 5 iterations), far inside a 6-deviation box.
PILOT_TOL = 1e-2
#: B to this relative change is the MAP to ~1e-6 posterior deviations (linear convergence,
#: ratio ~0.37 per iteration on the bundled plates).
MAP_TOL = 1e-7
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
    input_model : bayesplate.inputs_posterior.InputConditional or None
        With the inputs marginalised and some deviation declared: the readings' conditional
        ``f(z | b, Y)`` (``J_p`` where the marginal problem has it), for their draws.
    input_certificate : bayesplate.inputs_posterior.InputCertificate or None
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
        return _run_on_fast(self, method, tol, **kwargs)


def _pilot_model(case, model, pilot_mesh):
    """The model of the pilot B run: the model itself, or the case on a coarser mesh."""
    if pilot_mesh is None:
        return model
    if pilot_mesh == "auto":
        mesh = model.mesh
        if mesh.nx * mesh.ny <= PILOT_MAX_ELEMENTS:
            return model
        pilot_mesh = (math.ceil(mesh.nx / 2), math.ceil(mesh.ny / 2))
    return PlateModel.from_case(case, mesh=tuple(pilot_mesh))


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


def _marginal(case, model, problem, at):
    """The problem with the inputs marginalised (``J_p`` at `at`), full solves, conditional.

    The conditional is the readings' :class:`~bayesplate.inputs_posterior.InputConditional`
    (None when every deviation is 0). ``V_Y + B B^T`` with ``B = J_p A``: the arithmetic of
    :func:`bayesplate.inputs.input_covariance`, to the bit.
    """
    names, A = input_sources(case.plate)
    modes = problem.pairing.modes
    if not np.any(A):
        return problem.with_observation_covariance(problem.V_Y + 0.0), 0, None
    J = input_jacobian(case, at, modes, mesh=(model.mesh.nx, model.mesh.ny)).J
    B = J @ A
    marginal = problem.with_observation_covariance(problem.V_Y + B @ B.T)
    _, value, sd = declared_readings(case.plate)
    conditional = input_conditional(J, A, problem.V_Y, names, value, sd, at)
    return marginal, 7, conditional  # the nominal solve and 3 central differences


def _place_box(case, model, problem, pilot, inputs, box_sigma):
    """The (marginal) problem and the fast model's box from the pilot; full solves spent.

    With the inputs marginalised, the box is placed with ``P`` of the marginal problem at the
    pilot's ``b`` (one more full solve for the sensitivities): the pilot's own ``P`` ignores
    the inputs and would leave a box a few marginal deviations wide.
    """
    if inputs != "marginal":
        placed, spent = _widened(problem, pilot)
        return problem, posterior_box(placed, problem.mu_b, problem.V_b, box_sigma), spent, None
    problem, spent, conditional = _marginal(case, model, problem, pilot.b)
    S = problem.predict(pilot.b).S
    info = S.T @ np.linalg.solve(problem.V_Y, S) + np.linalg.inv(problem.V_b)
    placed, more = _widened(problem, replace(pilot, covariance_b=np.linalg.inv(info)))
    box = posterior_box(placed, problem.mu_b, problem.V_b, box_sigma)
    return problem, box, spent + 1 + more, conditional


def _widened(problem, pilot):
    """The pilot with ``P`` widened by an inferred error scale (linearised), full solves spent.

    With ``s`` unknown the posterior is ``s_hat`` times wider than ``P`` at ``s = 1``
    (:func:`bayesplate.error_scale.linearised_scale`); a box placed with ``P`` would leave
    most walkers to the full model's fallback when the misfit is large.
    """
    if problem.error_scale is None:
        return pilot, 0
    from ..error_scale import linearised_at

    return replace(pilot, covariance_b=linearised_at(problem, pilot.b).covariance_b), 1


def prepare(
    case,
    *,
    model=None,
    forward="reduced",
    rng=None,
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
    """The sampler's problem, fast model and MAP for a case.

    Parameters
    ----------
    case : bayesplate.io.Case
    model : PlateModel, optional
        Full model; default ``PlateModel.from_case(case)``.
    forward : {"reduced", "full"}
        Sample with the certified fast model (falling back to the full one where it is not
        certified) or with the full model throughout.
    rng : int, numpy.random.Generator or None
        Seed of the fast model's designs.
    convention : str or Conventions
        As for :func:`bayesplate.estimators.estimate` (default ``"paper"``).
    prior_mean, prior_sd : array_like, shape (6,), optional
        Engineering prior (SI) replacing the case's.
    pairing : {"auto", "mac", "likelihood", "index", "order"} or Pairing
        As for :func:`bayesplate.estimators.estimate` (:func:`bayesplate.pairing.pair_measured`
        at the prior mean; ``"likelihood"``: the assignment B settles on, on the working
        model, placing the box and the MAP; the chain re-makes it at every point unless
        the inputs are marginalised or an error scale is inferred (:func:`.assigned.\
reassignment`); any other pairing stays fixed, no modes computed beyond the paired ones.
    box_sigma : float
        Half-width of the posterior box in deviations of the pilot B estimate.
    box : Box, optional
        Explicit box for the fast model (no pilot run).
    pilot_mesh : "auto", None or (nx, ny)
        Mesh of the pilot B run: ``"auto"`` halves meshes above 400 elements (only when the
        model is the case's own); None runs it on ``model``.
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model already built (e.g. shared by several priors); no pilot, no build.
    fast_options : dict, optional
        Keywords of :func:`bayesplate.reduced.fast_model` (default ``FAST_DEFAULTS``).
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    inputs : {"auto", "exact", "marginal"}
        The plate's measured inputs as exact numbers or with the case's deviations
        marginalised (:meth:`GaussianProblem.from_case`); ``"auto"``: marginal when the case
        gives any ``plate.*_sd``. ``J_p`` is evaluated at the pilot (or settling) B estimate,
        else at the prior mean; with a fast model built here, its box is placed with the
        marginal problem's ``P`` there (one more full solve); then ``J_p`` again at the
        marginal MAP, which is found again with it (module docstring). A `fast` model or a `box`
        given is kept as it is: if it was placed for the exact posterior, walkers beyond it
        use the full model (counted in the result).

    Returns
    -------
    SamplingSetup
    """
    rng = resolve_rng(rng, seed, "prepare")
    inputs = resolve_inputs(case, inputs)
    if forward not in ("reduced", "full"):
        raise ValueError(f"forward = {forward!r}: must be 'reduced' or 'full'")
    conventions = resolve_conventions(convention)
    own_model = model is None
    model = model or PlateModel.from_case(case)
    mean = np.asarray(case.prior.mean if prior_mean is None else prior_mean, dtype=float)
    sd = np.asarray(case.prior.sd if prior_sd is None else prior_sd, dtype=float)
    settled = None
    checked = checks_order(case.measured, pairing)
    if checked:  # the arguments, to begin again by likelihood if the order is set aside
        again = dict(model=model, forward=forward, rng=rng, convention=convention,
                     prior_mean=prior_mean, prior_sd=prior_sd, pairing="likelihood",
                     box_sigma=box_sigma, box=box, pilot_mesh=pilot_mesh if own_model else None,
                     fast=None, fast_options=fast_options, inputs=inputs)  # fmt: skip
    if not isinstance(pairing, Pairing):
        # by likelihood, B settles the assignment on the working model (a coarser mesh's
        # error in the upper modes would call their peaks spurious), and that B run is the
        # pilot too (the pilot mesh may number the upper modes otherwise)
        pairing, settled = settle_pairing(case, model, pairing, tol=PILOT_TOL,
                                          convention=conventions, prior_mean=mean,
                                          prior_sd=sd, fast=fast)  # fmt: skip
    pair = replace(pairing, extra=0)
    problem = GaussianProblem.from_case(
        case, model, pair, conventions.observation, conventions.prior, mean, sd
    )
    assigned, assignment = _reassignment(case, pairing, inputs, conventions.observation)
    n_modes = pair.n_modes() if assigned is None else assigned.n
    exact = problem
    timings = {"pilot": 0.0, "build": 0.0, "map": 0.0}
    pilot, solves, conditional = None, 0, None
    if forward == "reduced" and fast is None:
        if box is None and settled is not None:
            pilot, solves = settled, settled.n_solves
            problem, box, spent, conditional = _place_box(case, model, problem, pilot, inputs,
                                                          box_sigma)  # fmt: skip
            solves += spent
        if box is None:
            started = time.perf_counter()
            pilot_model = _pilot_model(case, model, pilot_mesh if own_model else None)
            pilot_problem = GaussianProblem.from_case(
                case, pilot_model, pair, conventions.observation, conventions.prior, mean, sd
            )
            pilot = run(pilot_problem, "B", tol=PILOT_TOL, conventions=conventions)
            solves += pilot.n_solves if pilot_model is model else 0
            problem, box, spent, conditional = _place_box(case, model, problem, pilot, inputs,
                                                          box_sigma)  # fmt: skip
            solves += spent
            timings["pilot"] = time.perf_counter() - started
            log.info("pilot B (%s): %s", _mesh_text(pilot_model), pilot.message)
        started = time.perf_counter()
        options = {**FAST_DEFAULTS, **(fast_options or {})}
        center = box.center if pilot is None else pilot.b
        fast = fast_model(model, center, box, n_modes, rng=rng, **options)
        timings["build"] = time.perf_counter() - started
        solves += fast.build_solves
        log.info("fast model: %s", fast.certificate)
    if inputs == "marginal" and problem is exact:  # no pilot here: J_p at the settling B
        at = problem.mu_b if settled is None else settled.b
        problem, spent, conditional = _marginal(case, model, problem, at)
        solves += spent
    setup = SamplingSetup(problem, model, fast if forward == "reduced" else None, None,
                          pilot, None if fast is None else fast.box, timings, solves,
                          inputs, conditional, assigned=assigned,
                          assignment=assignment)  # fmt: skip
    started = time.perf_counter()
    # B from the settled assignment's estimate (B's fixed point from the prior mean may be
    # another optimum with a pairing that skips modes); from the prior mean otherwise
    estimate = _map(setup, conventions, None if settled is None else settled.b)
    estimate = _scaled_map(setup, estimate)
    if conditional is not None and estimate.converged:  # J_p again, at the marginal MAP
        problem, spent, conditional = _marginal(case, model, exact, estimate.b)
        solves += spent
        setup = replace(setup, problem=problem, input_model=conditional, n_full_solves=solves)
        estimate = _scaled_map(setup, _map(setup, conventions, estimate.b))
    timings["map"] = time.perf_counter() - started
    if checked:  # pairing by order, checked at the MAP on the sampler's model
        found = assignment_at(case, setup.fast or model, estimate.b,
                              prior_in_stiffness(mean, sd, "full")[1], pair)  # fmt: skip
        if not found.keeps_order:
            log.warning("%s: the sampler's setup is made again", refuted_order(found))
            return prepare(case, **again)
        log.info("pairing by order checked at the MAP: the most probable assignment")
    if not estimate.converged:
        log.warning("B (the MAP) did not converge: %s", estimate.message)
    _check_box(setup.box, estimate)
    certificate = None
    if conditional is not None:  # the linear input model against full solves at the MAP
        started = time.perf_counter()
        certificate = linear_input_certificate(
            case,
            estimate.b,
            conditional.B,
            pair.modes,
            np.sqrt(np.diag(exact.V_Y)),
            mesh=(model.mesh.nx, model.mesh.ny),
        )
        solves += certificate.n_solves
        timings["input_certificate"] = time.perf_counter() - started
    return replace(setup, estimate=estimate, n_full_solves=solves,
                   input_certificate=certificate)  # fmt: skip


def _map(setup, conventions, start=None):
    """B to ``MAP_TOL`` on the sampler's model: the MAP and ``P`` (eq. 9)."""
    return _run_on_fast(setup, "B", MAP_TOL, conventions=conventions, start=start)


def _scaled_map(setup, estimate):
    """B's estimate with ``P`` widened by an inferred error scale (linearised; none: as is).

    The walkers' coordinates are whitened with ``P`` and the default moves propose from a
    Student-t of that shape (:mod:`bayesplate.sampling.moves`): with ``s`` unknown the
    posterior is ``s_hat`` times wider than ``P`` at ``s = 1``, and proposals that narrow
    mix slowly. The estimate stays B's (``s = 1`` weights).
    """
    if setup.problem.error_scale is None:
        return estimate
    from ..error_scale import linearised_at
    from ..quantities import engineering_covariance

    cov_b = linearised_at(setup.problem_on_fast_model(), estimate.b).covariance_b
    cov = engineering_covariance(estimate.constants, cov_b)
    return replace(estimate, covariance_b=cov_b, covariance=cov, sd=np.sqrt(np.diag(cov)))


def _run_on_fast(setup, method, tol, **kwargs):
    """B or MVE on the sampler's model, early iterates on the reduced model even off-box.

    The estimators start from the prior mean, outside the posterior box; their early
    iterates only set the path, not the fixed point, so they use the reduced model beyond
    its certified box too (no full solves, no warnings). The fixed point is then checked to
    lie in the box; if it does not, the run is repeated with the full-model fallback.
    """
    fast = setup.fast
    if fast is None or not fast.certified:
        return run(setup.problem_on_fast_model(), method, tol=tol, **kwargs)
    p = setup.problem
    free = p.with_forward(fast.reduced.solve)
    result = run(free, method, tol=tol, **kwargs)
    if fast.box.contains(result.b) and result.status != "solve_failed":
        return result
    log.warning("%s ends outside the fast model's box (%s); again with the full fallback",
                method, result.message)  # fmt: skip
    return run(setup.problem_on_fast_model(), method, tol=tol, **kwargs)


def _mesh_text(model):
    return f"{model.mesh.nx} x {model.mesh.ny} mesh"
