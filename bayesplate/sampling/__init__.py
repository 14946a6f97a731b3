"""Posterior sampling with emcee on the estimators' own Gaussian problem (issue 4).

The target is ``ln f(b | Y)`` of :class:`bayesplate.likelihood.posterior.GaussianProblem`: the same
``V_Y``, prior and pairing as the estimators (``CONVENTIONS["paper"]`` by default), -inf
outside the physical region. Only the forward model is swapped for a fast one; the
log-density is still :meth:`GaussianProblem.log_posterior` of a problem built from the
same arrays (:class:`WhitenedLogPosterior`).

Fast model
    A certified reduced-basis model (:func:`bayesplate.reduced.fast_model`) over the
    *posterior* box (:func:`posterior_box`): a pilot B estimate +- 6 linearised deviations,
    and, in the coefficients the data barely inform, the prior's 3-sigma range as well; cut
    to physical laminae. Not the prior's 3-sigma box throughout: the posterior is 5 to 20
    times narrower than the prior in the well-identified coefficients, and the prior box of
    the Frederiksen case needs 37 full solves to certify (``reports/benchmark_reduced.md``),
    which alone spends the two minutes the whole posterior may take. The pilot B run (TOL
    1e-2, within ~0.1 deviations of the converged estimate) uses the case mesh or, above
    400 elements, a mesh halved in each direction (within ~0.7 deviations on the
    Frederiksen plate). The certificate (held-out points against the full model, relative
    frequency error below 1e-4) is kept in the result; where it fails, or a walker steps
    out of the box, the full model is used with a
    :class:`bayesplate.reduced.ReducedModelWarning`, and the result counts those
    evaluations. The sampler needs eigenvalues only (the fastest reduced path); the MAP and
    its covariance ``P`` come from B iterated to TOL 1e-7 on the same fast model.

Uncertain inputs
    ``inputs="marginal"`` (the default when the case gives any ``plate.*_sd`` or a mass
    with ``mass_sd``): the plate's thickness, density (or mass), length and width deviations
    are integrated out to first order, ``V_Y + J_p Sigma_p J_p^T``
    (:mod:`bayesplate.likelihood.inputs`), a constant matrix: the fast model needs no new
    parameters, only a box placed with the marginal ``P``. ``V_Y`` is then full: the pointwise terms
    are leave-one-out conditionals and the Ritz screen bounds the misfit on the sub-block of the
    eigenvalues it constrains. After the chain, the declared inputs are drawn once per kept
    draw from their Gaussian conditional given ``b``
    (:mod:`bayesplate.likelihood.inputs_posterior`): exact draws of the joint posterior under the
    linear input model (collapsed sampling), whose certificate at the MAP (full solves at +- 2 sd of
    each input) the result carries.

Parameterisation and moves
    Walkers move in whitened log coordinates (:class:`WhitenedLogPosterior`): the
    logarithms of the positive coefficients and C12 itself, whitened by ``P`` at the MAP;
    the density carries the Jacobian. Two emcee moves are mixed: :class:`LaplaceMove`
    (90 %), an independence Metropolis-Hastings proposal (Student-t, 10 degrees of
    freedom, scale 1.1) tuned on the ensemble, and :class:`ScreenedDEMove` (10 %), emcee's
    differential evolution, local and adaptive, for where the posterior is not Gaussian.
    Tuning: three rounds of 30 steps, after each of which the proposal takes the mean and
    covariance of the ensemble; then it is frozen and the tuning steps are discarded. The
    independence proposals are truncated to the fast model's box; DE proposals outside it
    are first screened with an upper bound of the posterior from the reduced model's Ritz
    values (upper bounds of the eigenvalues everywhere), so that most of them are rejected
    without a full solve, exactly as the evaluation would. Every move leaves the posterior
    invariant whatever ``P`` and the tuning are; they only set the efficiency.

Stopping
    Every ``check_every`` steps after tuning the integrated autocorrelation time ``tau`` of
    each coordinate is estimated (``get_autocorr_time(tol=0)`` on the chain after tuning);
    the run stops once that chain is longer than ``target_tau_factor`` (50) times the
    largest ``tau``, the smallest bulk ESS of the engineering constants (after a further
    burn-in of 3 ``tau``) reaches ``min_ess`` and the largest R-hat is below ``max_rhat``
    (1.01), or at ``max_steps``.

Pairing by likelihood
    The assignment of peaks to computed modes settled by B places the box and the MAP; the
    chain then re-makes it at every point: the likelihood of all the measured peaks,
    maximised over the assignments (:mod:`~bayesplate.sampling.assigned`, continuous in the
    constants), two computed modes beyond the highest settled one offered. The result's
    ``assignment`` gives, per peak, the fraction of draws with each mode or spurious. With
    the inputs marginalised (a full ``V_Y``) or an error scale, and for several plates
    sampled jointly, the settled assignment is kept (a warning; ``settings["assignment"]``).
    Other pairings stay fixed, their chains unchanged.

Output
    :class:`SamplingResult` with an ArviZ ``InferenceData``: ``posterior`` in the engineering
    constants in case-file units (``E1_GPa``, ..., ``nu12``), ``log_likelihood`` (the
    pointwise log-likelihood of each measured eigenvalue, for WAIC/LOO), ``sample_stats``
    (``lp``), ``observed_data`` (``Y``, rad^2/s^2) and ``constant_data`` (frequencies, Hz),
    indexed by the measured mode number (``mode``). Walkers are ArviZ chains.

Modules
    :mod:`~bayesplate.sampling.density` (the target), :mod:`~bayesplate.sampling.moves`,
    :mod:`~bayesplate.sampling.setup` (problem, pilot, box, fast model, MAP; on
    :mod:`~bayesplate.sampling.pilot` and :mod:`~bayesplate.sampling.map_estimate`),
    :mod:`~bayesplate.sampling.chain` (walkers, tuning, run loop),
    :mod:`~bayesplate.sampling.stopping`, :mod:`~bayesplate.sampling.storage` (HDF backend),
    :mod:`~bayesplate.sampling.result`, :mod:`~bayesplate.sampling.pipeline` (:func:`sample`),
    :mod:`~bayesplate.sampling.checks` (the linearised covariance against the posterior),
    :mod:`~bayesplate.sampling.seeding` (the ``rng`` argument),
    :mod:`~bayesplate.sampling.options` (:class:`ChainOptions`, :class:`SetupOptions`: the
    chain's and the setup's settings, each in one frozen object),
    :mod:`~bayesplate.sampling.assigned` (the assignment re-made in the chain),
    :mod:`~bayesplate.sampling.box` (the fast model's box); several plates of one material:
    :mod:`~bayesplate.sampling.stacked` (their stacked problem),
    :mod:`~bayesplate.sampling.joint` (:func:`sample_plates`, the shared constants) and
    :mod:`~bayesplate.sampling.plate_checks` (which plate disagrees),
    :mod:`~bayesplate.sampling.hierarchical` (the population and each plate in it, on
    :mod:`~bayesplate.sampling.plate_laplace`, :mod:`~bayesplate.sampling.population` and
    :mod:`~bayesplate.sampling.population_draws`).
"""

from .chain import sample_problem
from .checks import covariance_agreement, curvature_covariance, linearisation_band
from .density import EigenvalueForward, WhitenedLogPosterior
from .hierarchical import HierarchicalResult, sample_hierarchical, sample_population
from .joint import (
    JointResult,
    JointSetup,
    PlatesMismatch,
    check_plates,
    prepare_joint,
    sample_plates,
)
from .moves import LaplaceMove, ScreenedDEMove, default_moves
from .options import ChainOptions, SetupOptions
from .pipeline import sample
from .plate_checks import PlateCheck, plate_checks, predictive_check
from .plate_laplace import PlateFit, PlateLaplace, fit_plate
from .result import CASE_UNITS, HDI_PROB, SamplingResult
from .setup import SamplingSetup, posterior_box, prepare, resolve_inputs
from .stacked import JointForward, joint_estimate, joint_problem

__all__ = [
    "CASE_UNITS",
    "HDI_PROB",
    "ChainOptions",
    "EigenvalueForward",
    "HierarchicalResult",
    "JointForward",
    "JointResult",
    "JointSetup",
    "LaplaceMove",
    "PlateCheck",
    "PlateFit",
    "PlateLaplace",
    "PlatesMismatch",
    "SamplingResult",
    "SamplingSetup",
    "ScreenedDEMove",
    "SetupOptions",
    "WhitenedLogPosterior",
    "check_plates",
    "covariance_agreement",
    "curvature_covariance",
    "default_moves",
    "fit_plate",
    "joint_estimate",
    "joint_problem",
    "linearisation_band",
    "plate_checks",
    "posterior_box",
    "predictive_check",
    "prepare",
    "prepare_joint",
    "resolve_inputs",
    "sample",
    "sample_hierarchical",
    "sample_plates",
    "sample_population",
    "sample_problem",
]
