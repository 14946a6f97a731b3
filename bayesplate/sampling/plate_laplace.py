"""One plate's likelihood as a Gaussian in ``z = ln c``: the hierarchical model's building block.

At a point ``z0`` (first the plate's own MAP under the case's weak prior, from
:func:`~bayesplate.sampling.setup.prepare` on its certified fast model), the paired model
eigenvalues are linearised in ``z`` with the exact sensitivities,
``g(z) ~ g0 + G (z - z0)``, ``G = S(b0) (d b / d c) diag(c0)``, so that the plate's
log-likelihood (its declared ``V_Y``, with the measured inputs' deviations marginalised when
the case gives them, as for one plate) is, up to a constant,

    ln L_p(z) = -1/2 z^T H z + h^T z,   H = G^T V_Y^-1 G,   h = G^T V_Y^-1 (Y - g0 + G z0).

The same likelihood as a Gaussian in the in-plane stiffness and the transverse shear
compliance (``A``, ``a``: much closer to the exact one) is what the population's density
uses (:mod:`bayesplate.sampling.plate_marginal`); ``H``, ``h`` give the plate's own
deviations and the refinement's distances. The prior is not in ``H``: the population is the
plate's prior. This is the information form
(:mod:`bayesplate.sampling.population`): a constant the plate does not identify has a near-zero
row and column of ``H``, and nothing divides by it. :func:`relinearise` repeats it at another
point (the plate's shrunk estimate) on the same model.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import laminate
from .plate_marginal import coordinates, stiffness_per_coordinate

__all__ = [
    "PlateFit",
    "PlateLaplace",
    "PlateMode",
    "fit_plate",
    "linearise",
    "plate_mode",
    "relinearise",
]


@dataclass(frozen=True, eq=False)
class PlateLaplace:
    """A plate's Gaussian likelihood in ``z = ln c`` (information form).

    Attributes
    ----------
    z0 : numpy.ndarray, shape (6,)
        The linearisation point, ``ln`` of SI constants.
    H : numpy.ndarray, shape (6, 6)
        Gauss-Newton precision in ``z`` (symmetric, positive semi-definite).
    h : numpy.ndarray, shape (6,)
        Information vector.
    chi2 : float
        ``(Y - g0)^T V_Y^-1 (Y - g0)`` at ``z0``.
    m : int
        Paired eigenvalues.
    status : str
        ``"ok"``, or ``"not_physical"`` when ``z0`` is not a physical lamina.
    A : numpy.ndarray, shape (6, 6), optional
        Gauss-Newton precision in ``y`` (in-plane stiffness and transverse shear compliance,
        :func:`~bayesplate.sampling.plate_marginal.coordinates`): the likelihood as a
        Gaussian in which it nearly is; None: the plate is known only in ``z`` (``H``, ``h``).
    a : numpy.ndarray, shape (6,), optional
        Information vector in ``y``.
    """

    z0: np.ndarray
    H: np.ndarray
    h: np.ndarray
    chi2: float
    m: int
    status: str = "ok"
    A: np.ndarray | None = None
    a: np.ndarray | None = None

    @property
    def sd(self):
        """Deviations of ``z`` from ``H`` alone (``inf`` where ``H`` does not identify), (6,)."""
        w, V = np.linalg.eigh(self.H)
        cov = (V / np.where(w > 1e-12 * max(w.max(), 1e-300), w, np.nan)) @ V.T
        return np.where(np.isfinite(np.diag(cov)), np.sqrt(np.abs(np.diag(cov))), np.inf)


def linearise(problem, b):
    """:class:`PlateLaplace` of `problem`'s likelihood at stiffness `b` (one forward solve).

    Parameters
    ----------
    problem : GaussianProblem
        With a forward model giving sensitivities (e.g. the certified fast model's).
    b : array_like, shape (6,)
        Stiffness coefficients, Pa.

    Returns
    -------
    PlateLaplace
    """
    b = np.asarray(b, dtype=float)
    c = laminate.engineering_from_stiffness(b)
    z0 = np.log(c)
    if not laminate.is_physical(b) or not np.all(np.isfinite(z0)):
        zero = np.zeros((6, 6)), np.zeros(6)
        return PlateLaplace(z0, *zero, np.inf, problem.m, "not_physical", A=zero[0], a=zero[1])
    pred = problem.predict(b)
    G = pred.S @ (laminate.stiffness_jacobian(c) * c[None, :])
    r = problem.Y - pred.g
    VinvG = np.linalg.solve(problem.V_Y, G)
    H = G.T @ VinvG
    h = VinvG.T @ (r + G @ z0)
    S_y = pred.S * stiffness_per_coordinate(b)[None, :]  # in y = coordinates(c)
    VinvS = np.linalg.solve(problem.V_Y, S_y)
    A = S_y.T @ VinvS
    a = VinvS.T @ (r + S_y @ coordinates(c))
    chi2 = float(r @ np.linalg.solve(problem.V_Y, r))
    return PlateLaplace(z0, 0.5 * (H + H.T), h, chi2, problem.m, A=0.5 * (A + A.T), a=a)


@dataclass(frozen=True, eq=False)
class PlateFit:
    """A plate ready for the hierarchical model: its own answer and its likelihood's Laplace.

    Attributes
    ----------
    name : str
    laplace : PlateLaplace
    estimate : EstimateResult
        The plate's own B estimate (its MAP under the case's prior): its single-plate answer.
    problem : GaussianProblem or None
        The plate's problem on the model with sensitivities it was linearised on (its
        certified fast model), for :func:`relinearise`; None: not refined.
    seconds : float
        Wall time of the setup and the linearisation.
    """

    name: str
    laplace: PlateLaplace
    estimate: object = field(repr=False)
    problem: object = field(default=None, repr=False)
    seconds: float = 0.0


def fit_plate(case, *, model=None, rng=None, prior_mean=None, prior_sd=None, **prepare_options):
    """One plate's setup on its certified fast model and its likelihood's Laplace at the MAP.

    The MAP is B's (:func:`~bayesplate.sampling.setup.prepare`); where B did not converge
    (a step out of the physical region from a weak prior), :func:`plate_mode`'s.

    Parameters
    ----------
    case : bayesplate.io.Case
    model : PlateModel, optional
    rng : int, numpy.random.Generator or None
        Seeds the fast model's designs.
    prior_mean, prior_sd : array_like, shape (6,), optional
        The material's prior (SI), the first case's; it places the MAP and the box only.
    **prepare_options
        Of :func:`~bayesplate.sampling.setup.prepare` (``forward``, ``pairing``, ``inputs``,
        ``box_sigma``, ``fast_options``).

    Returns
    -------
    PlateFit
    """
    import time

    from .setup import prepare

    started = time.perf_counter()
    setup = prepare(
        case, model=model, rng=rng, prior_mean=prior_mean, prior_sd=prior_sd, **prepare_options
    )
    problem = setup.problem_on_fast_model()
    own = setup.estimate
    if not own.converged:  # B left the physical region: the mode by damped steps in ln c
        start = None if setup.pilot is None or not setup.pilot.converged else setup.pilot.b
        own = plate_mode(problem, start)
    laplace = linearise(problem, own.b)
    return PlateFit(case.name, laplace, own, problem, time.perf_counter() - started)


def relinearise(fit, z):
    """`fit` with its Laplace taken again at ``z = ln c`` (6,) on the same model."""
    b = laminate.stiffness_from_engineering(np.exp(np.asarray(z, dtype=float)))
    return replace(fit, laplace=linearise(fit.problem, b))


@dataclass(frozen=True, eq=False)
class PlateMode:
    """A plate's posterior mode under its case's prior, found in ``z = ln c``.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        Pa.
    constants, sd : numpy.ndarray, shape (6,)
        The mode's engineering constants and their Laplace deviations, SI.
    converged : bool
    iterations : int
    status : str
        ``"converged"`` or ``"max_iterations"``.
    """

    b: np.ndarray
    constants: np.ndarray
    sd: np.ndarray
    converged: bool
    iterations: int
    status: str


def _prior_terms(problem, z):
    """The prior's ``S_B`` term, gradient and Gauss-Newton Hessian in ``z`` at ``z``."""
    c = np.exp(z)
    J = laminate.stiffness_jacobian(c) * c[None, :]
    d = laminate.stiffness_from_engineering(c) - problem.mu_b
    Vi = np.linalg.inv(problem.V_b)
    return float(d @ Vi @ d), J.T @ Vi @ d, J.T @ Vi @ J


def plate_mode(problem, b0=None, max_iter=50, tol=1e-9):
    """The posterior mode by Levenberg-Marquardt in ``z = ln c`` (positive constants always).

    B's fixed-point iteration in ``b`` may leave the physical region from a weak prior's
    mean (a step too long); damped Gauss-Newton steps in ``z`` on ``S_B`` (eq. 5) do not.

    Parameters
    ----------
    problem : GaussianProblem
        With a forward model giving sensitivities.
    b0 : array_like, shape (6,), optional
        Start (Pa); default the prior mean.
    max_iter : int
    tol : float
        Stop when a step changes ``S_B`` by less than `tol` relative.

    Returns
    -------
    PlateMode
    """
    b = problem.mu_b if b0 is None else np.asarray(b0, dtype=float)
    z = np.log(laminate.engineering_from_stiffness(b))
    lam, done, iterations = 1e-3, False, 0

    def terms(z):
        lap = linearise(problem, laminate.stiffness_from_engineering(np.exp(z)))
        s0, g0, H0 = _prior_terms(problem, z)
        return lap.chi2 + s0, lap, g0, H0

    f, lap, g0, H0 = terms(z)
    while iterations < max_iter and not done:
        iterations += 1
        A = lap.H + H0
        grad = (lap.H @ z - lap.h) + g0  # half the gradient of S_B
        step = np.linalg.solve(A + lam * np.diag(np.diag(A)), -grad)
        trial = terms(z + step) if np.all(np.abs(step) < 5) else (np.inf,) * 4
        if trial[0] < f:
            done = f - trial[0] < tol * max(f, 1.0)
            z, (f, lap, g0, H0), lam = z + step, trial, max(lam / 3, 1e-9)
        else:
            lam *= 10
            done = lam > 1e8  # no step lowers S_B: a minimum to round-off
    c = np.exp(z)
    cov = np.linalg.inv(lap.H + H0) * np.outer(c, c)
    status = "converged" if done else "max_iterations"
    b = laminate.stiffness_from_engineering(c)
    return PlateMode(b, c, np.sqrt(np.diag(cov)), done, iterations, status)
