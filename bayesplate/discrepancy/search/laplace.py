"""The Laplace summary of a joint fit: :class:`JointFit`, made by :func:`summarise`.

The unknowns are whitened by their priors (:class:`.joint_fit.JointProblem`). The evidence is
the Laplace approximation around the best fit,
``ln Z = -chi2_total / 2 - ln det(H) / 2 - ln det(2 pi V_Y) / 2 - sum ln P_trunc``, with the
Gauss-Newton Hessian ``H = J^T J`` in the whitened unknowns and ``P_trunc`` the prior mass
inside each parameter's bounds. It was chosen over nested sampling or WAIC/LOO because it
costs nothing beyond the fit, and with 10-20 frequencies and up to 11 unknowns the posterior
of a well-identified fit is close to Gaussian; where a parameter is unidentified the Laplace
volume is its prior volume, which is the right Occam penalty.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from ... import laminate
from ...quantities import engineering_covariance, hz_from_eigenvalue

__all__ = ["JointFit", "summarise"]


@dataclass(frozen=True)
class JointFit:
    """Best joint fit of constants and physics parameters.

    Attributes
    ----------
    physics : Physics or None
        None for the nominal model.
    b : numpy.ndarray, shape (6,)
        Stiffness coefficients, Pa.
    theta : numpy.ndarray, shape (k,)
        Physics parameters in their units.
    covariance : numpy.ndarray, shape (6 + k, 6 + k)
        Laplace covariance of ``(b, theta)`` (Pa and parameter units).
    chi2 : float
        ``|W (Y - g)|^2`` of the data alone.
    chi2_prior : float
        ``|z|^2`` of the prior terms.
    log_evidence : float
        Laplace approximation of ``ln f(Y | physics)``.
    residual_sigma : numpy.ndarray, shape (m,)
        Standardised residuals ``(Y - g) / sigma_lambda`` (measured minus model).
    eigenvalues : numpy.ndarray, shape (m,)
        Model eigenvalues paired with the measured ones, rad^2/s^2.
    effective_parameters : float
        ``trace`` of the data's share of the Hessian: how many parameters the data fix.
    n_solves : int
        Eigen solves used.
    success : bool
    message : str
    modal : ModalResult
        The forward solution at the best fit.
    refined : bool
        False when the fit stayed on a corrected coarse mesh (see :func:`.joint_fit.fit`).
    alternatives : tuple of (numpy.ndarray, float)
        The other local optima reached on the working mesh: their stiffness coefficients
        ``b`` (Pa) and objective ``chi2 + chi2_prior``, best first.
    check : FitCheck or None
        When the fit was settled on reduced models of the working mesh (:mod:`.settling`):
        the full model at its answer. None when it ran on the finite-element model itself
        or was not refined.
    rough_optima : tuple of numpy.ndarray
        Of a fit not refined (:func:`.joint_fit.rough_fit`): the whitened unknowns of its best
        distinct rough optima, best first, to refine from.
    """

    physics: object
    b: np.ndarray
    theta: np.ndarray
    covariance: np.ndarray
    chi2: float
    chi2_prior: float
    log_evidence: float
    residual_sigma: np.ndarray
    eigenvalues: np.ndarray
    effective_parameters: float
    n_solves: int
    success: bool
    message: str
    modal: object = field(repr=False, default=None)
    refined: bool = True
    alternatives: tuple = ()
    check: object = None
    rough_optima: tuple = ()

    @property
    def constants(self):
        """Engineering constants ``(E1, E2, nu12, G12, G13, G23)``, SI."""
        return laminate.engineering_from_stiffness(self.b)

    @property
    def constants_sd(self):
        """First-order deviations of the engineering constants, SI."""
        return np.sqrt(np.diag(engineering_covariance(self.constants, self.covariance[:6, :6])))

    @property
    def theta_sd(self):
        """Laplace deviations of the physics parameters."""
        return np.sqrt(np.diag(self.covariance)[6:])

    @property
    def frequency_Hz(self):
        """Model frequencies paired with the measured ones, Hz."""
        return hz_from_eigenvalue(self.eigenvalues)


def _log_mass_inside(z, sd, lo, hi):
    """``sum ln P(lo < z_i < hi)`` of the Laplace Gaussian's marginals.

    At a bound (a mass or a foundation stiffness fitted as zero) only part of the Gaussian
    around the best fit is admissible; without this term the evidence would count the
    inadmissible half as well.
    """
    inside = norm.cdf((hi - z) / sd) - norm.cdf((lo - z) / sd)
    return float(np.sum(np.log(np.maximum(inside, 1e-300))))


def summarise(problem, res, refined=True, modal=None):
    """The :class:`JointFit` of the best least-squares result.

    ``modal``: the forward solution to report instead of ``problem``'s (the finite-element
    one at the answer of a fit on a pencil, whose own vectors are Ritz coefficients).
    """
    z = res.x
    out = problem.evaluate(z)
    b, theta = problem.unpack(z)
    if out is None:
        return JointFit(
            problem.physics,
            b,
            theta,
            np.full((z.size, z.size), np.nan),
            np.inf,
            np.inf,
            -np.inf,
            np.full(problem.Y.size, np.nan),
            np.full(problem.Y.size, np.nan),
            np.nan,
            problem.n_solves,
            False,
            "the fit left the physical region",
            refined=refined,
        )
    lam, Jg, own = out
    modal = own if modal is None else modal
    Jd = Jg / problem.sigma[:, None]
    H = Jd.T @ Jd + np.eye(z.size)
    H_inv = np.linalg.inv(H)
    T = np.zeros((z.size, z.size))  # d(b, theta) / dz
    T[:6, :6] = problem.L
    T[6:, 6:] = np.diag(problem.theta_sd)
    r = (problem.Y - lam) / problem.sigma
    chi2, chi2_prior = float(r @ r), float(z @ z)
    lo, hi = problem.bounds()
    log_z = (
        -0.5 * (chi2 + chi2_prior)
        - 0.5 * np.linalg.slogdet(H)[1]
        - 0.5 * np.sum(np.log(2 * np.pi * problem.sigma**2))
        - problem.log_truncation()
        + _log_mass_inside(z, np.sqrt(np.diag(H_inv)), lo, hi)
    )
    p_eff = float(np.trace(H_inv @ (Jd.T @ Jd)))
    return JointFit(
        problem.physics,
        b,
        theta,
        T @ H_inv @ T.T,
        chi2,
        chi2_prior,
        log_z,
        r,
        lam,
        p_eff,
        problem.n_solves,
        bool(res.success),
        str(res.message),
        modal,
        refined,
    )
