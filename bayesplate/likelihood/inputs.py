"""Uncertain measured inputs: how the eigenvalues move with them, and their share in the estimate.

The plate's thickness h, density rho, length a and width b are measured, not known; a case may
give each one standard deviation (``plate.thickness_sd`` and so on, SI). This module linearises
their effect.

Input Jacobian
    ``J_p[i, k] = d lambda_i / d p_k`` at fixed stiffness coefficients, rad^2/s^2 per SI unit
    of ``p_k`` (m or kg/m^3). Density is exact: ``M`` is proportional to rho and ``K`` does
    not depend on it, so ``lambda ~ 1/rho`` and ``d lambda / d rho = -lambda / rho``. The
    others are central differences on the finite-element model rebuilt with the changed
    geometry (same element counts), each perturbed mode followed by MAC to the nominal one.
    Identities the tests check: a uniform scaling of a, b and h by ``s`` scales every eigenvalue
    of the discrete model by ``1/s^2``, so ``sum_k d ln lambda / d ln p_k = -2`` over (h, a, b);
    for a thin isotropic plate (Kirchhoff limit) ``d ln lambda / d ln h = 2`` for bending modes.

Mass-derived density
    A lab that weighs the plate computes ``rho = m / (a b h)`` (case key ``mass_g``); the
    measured inputs are then (h, m, a, b), independent, and the density's error is not
    independent of the thickness's. :func:`input_sources` gives the effect of one deviation of
    each independent reading on ``p = (h, rho, a, b)``, the columns of ``A`` (4, 4):
    ``d p / d (h, m, a, b)`` times their deviations, with ``d rho / d h = -rho / h`` (likewise
    a, b) and ``d rho / d m = rho / m``. The eigenvalues then move with ``J_p A``: at fixed
    geometry ``lambda ~ 1 / rho ~ 1 / m`` (exact: ``M`` is proportional to rho, hence to m),
    and a thickness change carries the density with it, ``d lambda / d h |_m = J_h - (rho /
    h) J_rho`` (chain rule): bending eigenvalues go as ``E h^2 / rho``, i.e. ``E h^3 a b /
    m``, so a thickness error weighs 3 sd_h / h in a modulus, not 2. Without a mass ``A`` is
    ``diag(sd)`` and the inputs are (h, rho, a, b), independent.

Variance budget
    The estimators' covariance (B's ``P`` of eq. 9; MVE's reported ``V - V S^T (S V S^T +
    V_Y)^-1 S V``, the same ``P`` at its own estimate) is that of the linear map
    ``b = G Y + (I - G S) mu`` with ``G = P S^T V_Y^-1``. So ``P = G V_Y G^T + P V_b^-1 P``:
    the frequencies' share and the prior's. An input error ``dp`` shifts the model eigenvalues
    by ``J_p dp``, which the estimate absorbs as a data error: its share is
    ``G J_p Sigma_p J_p^T G^T`` (one per input, the inputs independent). All shares are carried
    to the engineering constants at the estimate (first order). The total is the estimator's own
    covariance plus the inputs' shares, so with zero input deviations it is today's covariance,
    bit for bit.

Marginalising the inputs
    ``GaussianProblem.from_case(..., inputs="marginal")`` adds ``J_p Sigma_p J_p^T``
    (:func:`input_covariance`) to the eigenvalue covariance: the inputs integrated out to first
    order, so the estimators' and the sampler's deviations include them.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from .. import laminate
from ..matching.pairing import track
from ..plate.model import DEFAULT_MESH, PlateModel
from ..quantities import engineering_covariance

__all__ = [
    "INPUT_NAMES",
    "INPUT_UNITS",
    "InputJacobian",
    "READING_UNITS",
    "VarianceBudget",
    "input_sd",
    "input_sources",
    "describe_inputs",
    "input_jacobian",
    "input_covariance",
    "variance_budget",
]

log = logging.getLogger(__name__)

#: The plate's measured inputs, in the order of every array here.
INPUT_NAMES = ("thickness", "density", "length", "width")
#: Their SI units.
INPUT_UNITS = ("m", "kg/m^3", "m", "m")
#: Relative central-difference step: the derivative is flat (to 1e-7) from 1e-5 to 1e-3
#: (tests/test_inputs.py), far from both round-off and curvature.
DEFAULT_STEP = 1e-4
_EXTRA_MODES = 4  # computed beyond the highest paired mode, so MAC can follow a crossing


def input_sd(plate) -> np.ndarray:
    """Standard deviations of the inputs of a plate, shape (4,), SI (order of INPUT_NAMES)."""
    return np.array([float(getattr(plate, f"{name}_sd", 0.0)) for name in INPUT_NAMES])


def input_sources(plate):
    """The independent readings behind a plate's inputs and one deviation's effect of each.

    Parameters
    ----------
    plate : bayesplate.io.Plate

    Returns
    -------
    names : tuple of str
        ``INPUT_NAMES``, or ``("thickness", "mass", "length", "width")`` when the density was
        derived from the mass (``plate.mass`` given).
    A : numpy.ndarray, shape (4, 4)
        Column k: the change of ``(h, rho, a, b)`` (SI) from one standard deviation of
        reading k; the inputs' covariance is ``A A^T``.
    """
    sd = input_sd(plate)
    if plate.mass is None:
        return INPUT_NAMES, np.diag(sd)
    rho = plate.density
    h, a, b = plate.thickness, plate.length, plate.width
    sd[1] = plate.mass_sd
    D = np.array(
        [  # d (h, rho, a, b) / d (h, m, a, b)
            [1.0, 0.0, 0.0, 0.0],
            [-rho / h, rho / plate.mass, -rho / a, -rho / b],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    return ("thickness", "mass", "length", "width"), D * sd[None, :]


#: Each reading's multiplier from SI to case units and the unit (the case keys' units).
READING_UNITS = {
    "thickness": (1e3, "mm"),
    "length": (1e3, "mm"),
    "width": (1e3, "mm"),
    "density": (1.0, "kg/m^3"),
    "mass": (1e3, "g"),
}


def describe_inputs(plate) -> str:
    """The deviations a plate gives, in case units: ``"thickness 0.11 mm, mass 0.1 g"``."""
    names, _ = input_sources(plate)
    sd = input_sd(plate)
    if plate.mass is not None:
        sd[1] = plate.mass_sd
    parts = [
        f"{name} {value * READING_UNITS[name][0]:.3g} {READING_UNITS[name][1]}"
        for name, value in zip(names, sd, strict=True)
        if value > 0
    ]
    return ", ".join(parts) or "none"


@dataclass(frozen=True)
class InputJacobian:
    """How the paired eigenvalues move with the plate's inputs.

    Attributes
    ----------
    J : numpy.ndarray, shape (m, 4)
        ``d lambda_i / d p_k``, rad^2/s^2 per m (thickness, length, width) or per kg/m^3.
    eigenvalues : numpy.ndarray, shape (m,)
        Nominal paired eigenvalues, rad^2/s^2.
    nominal : numpy.ndarray, shape (4,)
        The inputs' nominal values, SI.
    step : float
        Relative central-difference step used.
    """

    J: np.ndarray
    eigenvalues: np.ndarray
    nominal: np.ndarray
    step: float

    @property
    def relative(self):
        """``d ln lambda_i / d ln p_k``, shape (m, 4): -1 for density, about 2 for h."""
        return self.J * self.nominal[None, :] / self.eigenvalues[:, None]


def input_jacobian(case, b, modes, mesh=None, step=DEFAULT_STEP) -> InputJacobian:
    """``d lambda / d (h, rho, a, b)`` of the paired modes at stiffness coefficients `b`.

    Parameters
    ----------
    case : bayesplate.io.Case
        Its plate gives the nominal inputs.
    b : array_like, shape (6,)
        Stiffness coefficients, Pa (the nominal constants or an estimate).
    modes : array_like of int, shape (m,)
        0-based computed elastic modes (a pairing's ``modes``).
    mesh : tuple of int, optional
        Elements along x and y; default the case's mesh.
    step : float
        Relative step of the central differences.

    Returns
    -------
    InputJacobian
    """
    modes = np.asarray(modes, dtype=int)
    mesh = tuple(mesh or case.mesh or DEFAULT_MESH)
    n_modes = int(modes.max()) + 1 + _EXTRA_MODES
    b = np.asarray(b, dtype=float)
    plate = case.plate
    nominal = np.array([plate.thickness, plate.density, plate.length, plate.width])
    base = PlateModel.from_case(case, mesh=mesh).solve(b, n_modes)
    lam = base.eigenvalues[modes]
    J = np.empty((modes.size, 4))
    J[:, 1] = -lam / plate.density  # exact: M ~ rho, K independent of rho
    for k, name in ((0, "thickness"), (2, "length"), (3, "width")):
        dp = step * nominal[k]
        up, down = (
            _tracked(_scaled(case, name, nominal[k] + sign * dp), mesh, b, n_modes, base, modes)
            for sign in (1.0, -1.0)
        )
        J[:, k] = (up - down) / (2.0 * dp)
    return InputJacobian(J, lam, nominal, step)


def input_covariance(case, b, modes, mesh=None) -> np.ndarray:
    """``J_p Sigma_p J_p^T``: the eigenvalue covariance the inputs' deviations add.

    Parameters
    ----------
    case : bayesplate.io.Case
        Its plate's ``*_sd`` (independent inputs; with a mass, the readings of
        :func:`input_sources`: ``J_p A A^T J_p^T``).
    b : array_like, shape (6,)
        Stiffness coefficients where ``J_p`` is evaluated, Pa.
    modes : array_like of int, shape (m,)
        0-based computed modes paired with the measured eigenvalues.
    mesh : tuple of int, optional
        As for :func:`input_jacobian`.

    Returns
    -------
    numpy.ndarray, shape (m, m)
        rad^4/s^4; zeros (and no solve) when every deviation is 0.
    """
    _, A = input_sources(case.plate)
    modes = np.asarray(modes, dtype=int)
    if not np.any(A):
        return np.zeros((modes.size, modes.size))
    J = input_jacobian(case, b, modes, mesh=mesh).J @ A
    return J @ J.T


def _scaled(case, name, value):
    """The case with one input changed (plies keep their fractions of the thickness)."""
    plate = case.plate
    changes = {name: value}
    if name == "thickness":
        ratio = value / plate.thickness
        changes["ply_thickness"] = tuple(t * ratio for t in plate.ply_thickness)
    return dataclasses.replace(case, plate=dataclasses.replace(plate, **changes))


def _tracked(case, mesh, b, n_modes, base, modes):
    """Eigenvalues of the perturbed plate's modes most like the nominal paired ones."""
    modal = PlateModel.from_case(case, mesh=mesh).solve(b, n_modes)
    moved, mac = track(base.vectors, modal.vectors, modes)
    if np.any(moved != modes):
        log.warning("input perturbation reorders modes %s -> %s", modes + 1, moved + 1)
    return modal.eigenvalues[moved]


@dataclass(frozen=True)
class VarianceBudget:
    """Each engineering constant's variance split by source (first order, at the estimate).

    Attributes
    ----------
    method : str
        The estimator (``"B"``, ``"MVE"``, ``"MVE-mod"``).
    sources : tuple of str
        ``("frequencies", "thickness", "density", "length", "width", "prior")``.
    variance : numpy.ndarray, shape (n_sources, 6)
        Variance of ``(E1, E2, nu12, G12, G13, G23)`` from each source, SI^2.
    covariance : numpy.ndarray, shape (6, 6)
        Total: the estimator's covariance plus the inputs' shares, SI^2.
    estimator_covariance : numpy.ndarray, shape (6, 6)
        The estimator's own covariance (frequencies and prior), as it reports it.
    closure : float
        Largest ``|frequencies + prior - P| / sqrt(P_ii P_jj)`` in ``b``: how well the
        estimator's covariance splits as ``G V_Y G^T + P V_b^-1 P`` (round-off when it does).
    status : str
        ``"ok"`` (`closure` at round-off, <= 1e-6); ``"approximate"`` (<= 1e-2: the
        estimator's covariance came from another model than the sensitivities, e.g. the fast
        model's answer split with the full model's sensitivities); ``"not_closed"`` beyond
        (an MVE run with the updated covariance: the split is then not its covariance);
        ``"failed"`` when the estimator gave no covariance. The total is the estimator's own
        covariance plus the inputs' shares in every case.
    """

    method: str
    sources: tuple
    variance: np.ndarray
    covariance: np.ndarray
    estimator_covariance: np.ndarray
    closure: float
    status: str

    @property
    def sd(self):
        """Total standard deviation of each constant, shape (6,), SI."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def source_sd(self):
        """Standard deviation from each source alone, shape (n_sources, 6), SI."""
        return np.sqrt(np.maximum(self.variance, 0.0))

    @property
    def share(self):
        """Fraction of each constant's total variance from each source, (n_sources, 6)."""
        return self.variance / np.diag(self.covariance)[None, :]


CLOSURE_TOL = 1e-6  # relative: far above round-off (1e-12), far below any real mismatch
#: A covariance from the certified fast model split with the full model's sensitivities:
#: 1.8e-4 on the spruce plate (certificate 1e-4 in frequency); beyond this, not closed.
APPROXIMATE_TOL = 1e-2


def variance_budget(P, S, V_Y, V_b, J_p, sd_p, b, method="B", names=INPUT_NAMES) -> VarianceBudget:
    """Split an estimator's covariance by source and add the inputs' shares.

    Parameters
    ----------
    P : array_like, shape (6, 6)
        The estimator's covariance of ``b`` (``EstimateResult.covariance_b``), Pa^2.
    S : array_like, shape (m, 6)
        Sensitivities ``d lambda / d b`` at the estimate, rad^2/s^2 per Pa.
    V_Y : array_like, shape (m, m)
        Eigenvalue covariance, rad^4/s^4.
    V_b : array_like, shape (6, 6)
        Prior covariance of ``b``, Pa^2.
    J_p : array_like, shape (m, 4)
        Input Jacobian (:attr:`InputJacobian.J`).
    sd_p : array_like, shape (4,)
        Input standard deviations, SI (order of :data:`INPUT_NAMES`).
    b : array_like, shape (6,)
        The estimate, Pa (where ``b -> e`` is linearised).
    method : str
        Named in the result.
    names : tuple of str
        The inputs' names in the sources (``("thickness", "mass", ...)`` when `J_p` is
        ``J_p A`` of :func:`input_sources`, with `sd_p` ones).

    Returns
    -------
    VarianceBudget
    """
    P, S, V_Y, V_b, J_p = (np.asarray(x, dtype=float) for x in (P, S, V_Y, V_b, J_p))
    sd_p = np.asarray(sd_p, dtype=float)
    sources = ("frequencies", *names, "prior")
    e = laminate.engineering_from_stiffness(np.asarray(b, dtype=float))
    T = np.linalg.inv(laminate.stiffness_jacobian(e))  # d e / d b
    cov_e = engineering_covariance(e, P)  # the estimator's, as its result reports it
    if not np.all(np.isfinite(P)):
        nan = np.full((len(sources), 6), np.nan)
        return VarianceBudget(method, sources, nan, cov_e, cov_e, np.nan, "failed")
    G = P @ S.T @ np.linalg.inv(V_Y)  # d b / d Y, shape (6, m)
    shares_b = [G @ V_Y @ G.T]
    shares_b += [np.outer(G @ J_p[:, k], G @ J_p[:, k]) * sd_p[k] ** 2 for k in range(4)]
    shares_b.append(P @ np.linalg.solve(V_b, P))
    shares = [T @ s @ T.T for s in shares_b]
    variance = np.array([np.diag(s) for s in shares])
    covariance = cov_e
    for s in shares[1:5]:
        covariance = covariance + s
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))
    closure = float(np.max(np.abs(shares_b[0] + shares_b[-1] - P) / scale))
    status = "ok" if closure <= CLOSURE_TOL else "not_closed"
    if status != "ok" and closure <= APPROXIMATE_TOL:
        status = "approximate"
    return VarianceBudget(method, sources, variance, covariance, cov_e, closure, status)
