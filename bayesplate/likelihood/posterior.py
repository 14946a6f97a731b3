"""The one Gaussian likelihood and prior of the identification problem (paper sections 2, 3.6).

Parameters are the lamina stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)`` in
Pa (section 3.6). The data are the measured eigenvalues ``Y = (2 pi f)^2`` (eq. 27) and the
model is ``Y = g(b) + e`` (eq. 1) with Gaussian errors ``e ~ N(0, V_Y)`` and a Gaussian prior
``b ~ N(mu_b, V_b)`` (eqs. 3-4).

Observation covariance
    The deviation of a measured eigenvalue follows from the frequency deviation,
    ``d lambda = 8 pi^2 f df`` (section 3.6). The paper then prints
    ``V_Y = diag(d lambda)``: a deviation where a variance belongs, in rad^2/s^2 instead of
    rad^4/s^4, so its weight relative to the prior changes with the units. ``observation=
    "variance"`` uses ``diag(d lambda^2)``, the consistent choice; ``observation="deviation"``
    the printed formula, for comparison.

Prior covariance
    The prior of the case file is on the engineering constants ``e`` (independent, means
    ``mu_e`` and deviations ``sd_e``). It is carried to the stiffness coefficients by
    first-order propagation through eqs. 20-21: ``mu_b = b(mu_e)`` and, with the Jacobian
    ``J = d b / d e`` at ``mu_e`` (:func:`bayesplate.laminate.stiffness_jacobian`),
    ``dC_i = sqrt(sum_j J_ij^2 sd_j^2)``. The paper prints ``V_b = diag(dC_ij)``;
    ``prior="variance"`` uses ``diag(dC^2)`` (the diagonal of the propagated covariance),
    ``prior="full"`` the full propagated covariance ``J diag(sd_e^2) J^T`` (C11, C22 and C12
    are correlated through E1, E2, nu12) and ``prior="deviation"`` the printed formula.

Settled by reproduction (``studies/paper_tables.py``, ``reports/estimators_conventions.md``):
``observation="variance"`` with ``prior="variance"`` reproduces the B and MVE rows of Tables
3-8 to their printed digits and iteration counts; the printed (unsquared) formulas and the
full prior covariance do not. The paper's ``diag(d lambda)`` and ``diag(dC_ij)`` are
shorthand for diagonal matrices of squared deviations. Both are the library defaults.

Error scale (optional)
    With ``error_scale`` (an :class:`bayesplate.likelihood.error_scale.ErrorScalePrior`, the case's
    ``measured.error_scale``) the errors are ``e ~ N(0, s^2 V_Y)`` with one unknown scale
    ``s`` and a conjugate inverse-gamma prior on ``s^2``; :meth:`GaussianProblem.log_likelihood`
    is then the marginal over ``s^2``, a multivariate Student-t
    (:func:`bayesplate.likelihood.error_scale.log_marginal`). Without it, ``s = 1`` (unchanged).

The forward model is one callable, ``forward(b) -> ModalResult`` (anything with
``eigenvalues``, ``sensitivities`` and ``vectors`` for the requested modes), so a faster
evaluator (a reduced-basis model) can replace the finite-element solve unchanged.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .. import laminate
from ..matching.pairing import Pairing
from ..plate.forward import ForwardModel
from ..quantities import eigenvalue_from_hz, eigenvalue_sd, stiffness_covariance

__all__ = [
    "INPUT_TREATMENTS",
    "OBSERVATION_CONVENTIONS",
    "PRIOR_CONVENTIONS",
    "Prediction",
    "GaussianProblem",
    "observed_eigenvalues",
    "observation_covariance",
    "prior_in_stiffness",
]

log = logging.getLogger(__name__)

OBSERVATION_CONVENTIONS = ("variance", "deviation")
#: How the plate's measured inputs enter: as exact numbers, or marginalised (linearised).
INPUT_TREATMENTS = ("exact", "marginal")
PRIOR_CONVENTIONS = ("variance", "full", "deviation")


def observed_eigenvalues(frequency_Hz):
    """Measured eigenvalues ``Y = (2 pi f)^2`` (eq. 27), rad^2/s^2, shape (m,)."""
    return eigenvalue_from_hz(frequency_Hz)


def observation_covariance(frequency_Hz, sigma_Hz, convention="variance"):
    """Covariance ``V_Y`` of the measured eigenvalues (section 3.6).

    Parameters
    ----------
    frequency_Hz, sigma_Hz : array_like, shape (m,)
        Measured frequencies and their standard deviations, Hz.
    convention : {"variance", "deviation"}
        ``diag(d lambda^2)`` (consistent) or ``diag(d lambda)`` (as printed in the paper),
        with ``d lambda = 8 pi^2 f df``.

    Returns
    -------
    numpy.ndarray, shape (m, m)
    """
    _check(convention, OBSERVATION_CONVENTIONS, "observation")
    dlam = eigenvalue_sd(frequency_Hz, sigma_Hz)
    return np.diag(dlam**2 if convention == "variance" else dlam)


def prior_in_stiffness(mean_e, sd_e, convention="variance"):
    """Prior mean and covariance of ``b`` from those of ``e`` (first order, eqs. 20-21).

    Parameters
    ----------
    mean_e, sd_e : array_like, shape (6,)
        Prior means and deviations of ``(E1, E2, nu12, G12, G13, G23)``, SI.
    convention : {"variance", "full", "deviation"}
        ``diag(dC^2)``, ``J diag(sd_e^2) J^T`` or ``diag(dC)`` (as printed), where
        ``dC_i = sqrt(sum_j J_ij^2 sd_e_j^2)`` and ``J = d b / d e`` at ``mean_e``.

    Returns
    -------
    mu_b : numpy.ndarray, shape (6,)
        Pa.
    V_b : numpy.ndarray, shape (6, 6)
        Pa^2 (Pa for ``"deviation"``).
    """
    _check(convention, PRIOR_CONVENTIONS, "prior")
    mean_e = np.asarray(mean_e, dtype=float)
    full = stiffness_covariance(mean_e, np.diag(np.asarray(sd_e, dtype=float) ** 2))
    mu_b = laminate.stiffness_from_engineering(mean_e)
    if convention == "full":
        return mu_b, full
    dC = np.sqrt(np.diag(full))
    return mu_b, np.diag(dC**2 if convention == "variance" else dC)


def _check(value, allowed, what):
    if value not in allowed:
        raise ValueError(f"{what} = {value!r}: must be one of {allowed}")


@dataclass(frozen=True)
class Prediction:
    """Model eigenvalues paired with the measured ones, at one ``b``.

    Attributes
    ----------
    g : numpy.ndarray, shape (m,)
        Paired model eigenvalues, rad^2/s^2.
    S : numpy.ndarray, shape (m, 6)
        Sensitivity rows ``d g_i / d b_j`` (eq. 28), rad^2/s^2 per Pa.
    modal : object
        The forward result (a :class:`bayesplate.plate.model.ModalResult`).
    modes : numpy.ndarray of int, shape (m,)
        0-based computed elastic mode paired with each measured one.
    """

    g: np.ndarray
    S: np.ndarray
    modal: object = field(repr=False)
    modes: np.ndarray


class GaussianProblem:
    """Gaussian likelihood and prior in the stiffness coefficients ``b``.

    Parameters
    ----------
    Y : array_like, shape (m,)
        Measured eigenvalues, rad^2/s^2.
    V_Y : array_like, shape (m, m)
        Their covariance.
    mu_b : array_like, shape (6,)
        Prior mean of ``b``, Pa.
    V_b : array_like, shape (6, 6)
        Prior covariance of ``b``.
    forward : callable
        ``forward(b, n_modes) -> ModalResult``; e.g. ``PlateModel.solve``.
    pairing : Pairing
        Which computed mode goes with which measured one.
    error_scale : bayesplate.likelihood.error_scale.ErrorScalePrior, optional
        Prior of a common scale ``s`` of the deviations (module docstring); None: ``s = 1``.

    Attributes
    ----------
    n_solves : int
        Forward evaluations made so far.
    solve_seconds : float
        Wall time spent in them.
    """

    def __init__(self, Y, V_Y, mu_b, V_b, forward: Callable, pairing: Pairing, error_scale=None):
        self.error_scale = error_scale
        self.Y = np.asarray(Y, dtype=float)
        self.V_Y = np.asarray(V_Y, dtype=float)
        self.mu_b = np.asarray(mu_b, dtype=float)
        self.V_b = np.asarray(V_b, dtype=float)
        self.forward = forward
        self.pairing = pairing
        self.n_solves = 0
        self.solve_seconds = 0.0
        self._VY_inv = np.linalg.inv(self.V_Y)
        self._Vb_inv = np.linalg.inv(self.V_b)
        # normalising constants of eqs. 3 and 4
        self._norm_Y = np.linalg.slogdet(self.V_Y)[1] + self.Y.size * np.log(2 * np.pi)
        self._norm_b = np.linalg.slogdet(self.V_b)[1] + self.mu_b.size * np.log(2 * np.pi)
        self._logdet_Y = np.linalg.slogdet(self.V_Y)[1]

    @classmethod
    def from_case(
        cls,
        case,
        model: ForwardModel,
        pairing=None,
        observation="variance",
        prior="variance",
        prior_mean=None,
        prior_sd=None,
        inputs="exact",
        inputs_at=None,
    ):
        """The problem of a case file on a forward model.

        The case's ``measured.error_scale`` (None when absent) becomes the problem's
        ``error_scale``.

        Parameters
        ----------
        case : bayesplate.io.Case
        model : object
            Has ``solve(b, n_modes)`` (a :class:`bayesplate.plate.model.PlateModel`).
        pairing : Pairing, optional
            Default: by order, or by the case's ``measured.mode`` indices when given. Measured
            frequencies it leaves unpaired (:func:`bayesplate.matching.pairing.pair_measured`) are
            left out of ``Y``.
        observation, prior : str
            Conventions for ``V_Y`` and ``V_b`` (see the module docstring).
        prior_mean, prior_sd : array_like, shape (6,), optional
            Engineering prior (SI) replacing the case's.
        inputs : {"exact", "marginal"}
            The plate's thickness, density, length and width as exact numbers, or with the
            case's deviations (``plate.*_sd``) marginalised to first order: ``V_Y`` gains
            ``J_p Sigma_p J_p^T`` (:mod:`bayesplate.likelihood.inputs`), so every constant's
            posterior widens by the inputs' share. Needs ``model.mesh`` (a finite-element model's).
        inputs_at : array_like, shape (6,), optional
            Stiffness coefficients (Pa) where ``J_p`` is evaluated; default the prior mean.
            Six full solves; none when every input deviation is 0.

        Returns
        -------
        GaussianProblem
        """
        _check(inputs, INPUT_TREATMENTS, "inputs")
        measured = case.measured
        pairing = pairing or Pairing.from_measurement(measured)
        measured = pairing.select(measured)
        mean_e = case.prior.mean if prior_mean is None else prior_mean
        sd_e = case.prior.sd if prior_sd is None else prior_sd
        mu_b, V_b = prior_in_stiffness(mean_e, sd_e, prior)
        Y = observed_eigenvalues(measured.frequency_Hz)
        V_Y = observation_covariance(measured.frequency_Hz, measured.sigma_Hz, observation)
        if inputs == "marginal":
            from .inputs import input_covariance

            at = mu_b if inputs_at is None else inputs_at
            mesh = (model.mesh.nx, model.mesh.ny)
            V_Y = V_Y + input_covariance(case, at, pairing.modes, mesh=mesh)
        scale = getattr(case.measured, "error_scale", None)
        return cls(Y, V_Y, mu_b, V_b, model.solve, pairing, scale)

    @property
    def m(self):
        """Number of measured eigenvalues."""
        return self.Y.size

    def with_prior(self, mu_b, V_b):
        """The same data and forward model with another prior on ``b``."""
        return type(self)(self.Y, self.V_Y, mu_b, V_b, self.forward, self.pairing, self.error_scale)

    def with_forward(self, forward):
        """The same data and prior on another forward model, ``forward(b, n_modes)``."""
        return type(self)(
            self.Y, self.V_Y, self.mu_b, self.V_b, forward, self.pairing, self.error_scale
        )

    def with_observation_covariance(self, V_Y):
        """The same problem with another declared ``V_Y`` (e.g. the inputs marginalised)."""
        return type(self)(
            self.Y, V_Y, self.mu_b, self.V_b, self.forward, self.pairing, self.error_scale
        )

    def with_error_scale(self, error_scale):
        """The same problem with another error-scale prior (None: ``s = 1``)."""
        return type(self)(
            self.Y, self.V_Y, self.mu_b, self.V_b, self.forward, self.pairing, error_scale
        )

    def chi2(self, g):
        """``r^T V_Y^-1 r`` with the declared ``V_Y`` at paired model eigenvalues `g`, (m,)."""
        r = self.Y - g
        return float(r @ self._VY_inv @ r)

    def predict(self, b, modes=None):
        """Paired model eigenvalues and sensitivities at ``b``.

        Parameters
        ----------
        b : array_like, shape (6,)
            Pa.
        modes : array_like of int, shape (m,), optional
            0-based computed modes to pair (e.g. as tracked); default the pairing's own.

        Returns
        -------
        Prediction
        """
        modes = self.pairing.modes if modes is None else np.asarray(modes)
        started = time.perf_counter()
        modal = self.forward(np.asarray(b, dtype=float), self.pairing.n_modes(modes))
        self.solve_seconds += time.perf_counter() - started
        self.n_solves += 1
        return Prediction(modal.eigenvalues[modes], modal.sensitivities[modes], modal, modes)

    def log_likelihood(self, b, prediction=None):
        """``ln f(Y | b)`` of eq. 3, with its normalising constant.

        With an error scale, its marginal over ``s^2`` (a multivariate Student-t,
        :func:`bayesplate.likelihood.error_scale.log_marginal`).
        """
        prediction = prediction or self.predict(b)
        r = self.Y - prediction.g
        if self.error_scale is not None:
            from .error_scale import log_marginal

            chi2 = r @ self._VY_inv @ r
            return float(log_marginal(chi2, self.m, self._logdet_Y, self.error_scale))
        return -0.5 * (r @ self._VY_inv @ r + self._norm_Y)

    def log_prior(self, b):
        """``ln f(b)`` of eq. 4, with its normalising constant; -inf outside the lamina."""
        b = np.asarray(b, dtype=float)
        if not laminate.is_physical(b):
            return -np.inf
        d = b - self.mu_b
        return -0.5 * (d @ self._Vb_inv @ d + self._norm_b)

    def log_posterior(self, b):
        """``ln f(b | Y)`` up to ``ln f(Y)`` (eq. 2); -inf outside the physical region."""
        lp = self.log_prior(b)
        if not np.isfinite(lp):
            return -np.inf
        return lp + self.log_likelihood(b)

    def objective(self, b, prediction=None):
        """``S_B`` of eq. 5: ``(Y - g)^T V_Y^-1 (Y - g) + (b - mu)^T V_b^-1 (b - mu)``."""
        prediction = prediction or self.predict(b)
        r = self.Y - prediction.g
        d = np.asarray(b, dtype=float) - self.mu_b
        return float(r @ self._VY_inv @ r + d @ self._Vb_inv @ d)
