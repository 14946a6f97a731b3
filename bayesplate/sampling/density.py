"""The sampler's target: ``ln f(b | Y)`` of a Gaussian problem in whitened log coordinates.

:class:`WhitenedLogPosterior` is the log-density the walkers move on;
:class:`EigenvalueForward` is the forward model it evaluates, a model's eigenvalues-only path
(the likelihood needs no sensitivities), which also says which reduced model, if any, bounds
the eigenvalues everywhere (for screening proposals, :mod:`bayesplate.sampling.moves`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import laminate
from ..quantities import LOG_STIFFNESS

__all__ = ["EigenvalueForward", "WhitenedLogPosterior", "engineering_constants"]


@dataclass(frozen=True)
class _Eigenvalues:
    """Eigenvalues without sensitivities (NaN): all the log-posterior needs."""

    eigenvalues: np.ndarray
    sensitivities: np.ndarray


class EigenvalueForward:
    """``forward(b, n_modes)`` from a model's eigenvalues-only path (``model.eigenvalues``).

    Parameters
    ----------
    model : bayesplate.plate.forward.ForwardModel
        The model evaluated (e.g. a :class:`bayesplate.reduced.CertifiedModel`).
    reduced : bayesplate.reduced.ReducedModel, optional
        A reduced model whose eigenvalues are upper bounds of ``model``'s everywhere (the
        certified model's reduced part when its certificate passed), for bounds of the
        log-posterior off the certified box; None when there is none.

    Attributes
    ----------
    model, reduced
        As given.
    """

    def __init__(self, model, reduced=None):
        self.model = model
        self.reduced = reduced

    def __call__(self, b, n_modes):
        """Eigenvalues at `b` (Pa), shape (n_modes,), with NaN sensitivities (n_modes, 6)."""
        values = np.asarray(self.model.eigenvalues(b, n_modes))
        return _Eigenvalues(values, np.full((values.size, 6), np.nan))


class WhitenedLogPosterior:
    """``ln f(b | Y)`` of a Gaussian problem in whitened log coordinates ``z``.

    ``u = L^-1 (h(b) - h(b_0))``-style coordinates: ``h`` takes the logarithm of the
    positive coefficients (``C11, C22, C66, C44, C55``) and leaves ``C12``; ``u = c + L z``
    with ``c = h(b_0)`` and ``L L^T`` the covariance of ``b`` carried to ``h`` to first
    order at ``b_0``. The weakly identified shear moduli have a steep likelihood below and
    a prior tail above (Frederiksen G13: 9 linearised deviations above the MAP); in
    logarithms that is closer to Gaussian, and the default moves give 3 to 10 times more
    effective samples per evaluation than in ``b`` (tuning runs on the Frederiksen plate).

    Calling it on ``z`` (shape (6,)) returns ``(log_density, pointwise)``: ``log_density``
    is :meth:`GaussianProblem.log_posterior` of a problem built from the same ``Y``,
    ``V_Y``, ``mu_b``, ``V_b`` and pairing (only the forward model may differ) at
    ``b(z)``, plus :meth:`log_jacobian` (the density of ``z``); ``pointwise`` (shape (m,))
    is the log-likelihood of each measured eigenvalue, summing to the log-likelihood when
    ``V_Y`` is diagonal; NaN outside the physical region. With a full ``V_Y`` (the inputs
    marginalised) the eigenvalues are not independent and ``pointwise`` is each one's
    leave-one-out predictive density ``ln f(Y_i | Y_-i, b)``: with ``Q = V_Y^-1``,
    ``-((Q r)_i^2 / Q_ii + ln(2 pi / Q_ii)) / 2`` (Buerkner et al. 2021, non-factorised normal
    models), which is what LOO needs; it equals the diagonal formula when ``V_Y`` is diagonal.
    With an error scale (``problem.error_scale``: ``s`` unknown, integrated out) the
    likelihood is a Student-t and ``pointwise`` is each one's leave-one-out density with ``s``
    integrated out too (:func:`bayesplate.likelihood.error_scale.loo_pointwise`); the sampler still
    moves in the six constants alone.

    With `assigned` (a :class:`~bayesplate.sampling.assigned.ReassignedLikelihood`, pairing
    by likelihood) the log-likelihood is instead that of ALL measured peaks with the
    assignment re-made at ``b(z)`` (its maximum over assignments), and the second value
    returned holds ``2 m`` numbers for the ``m`` peaks: each peak's term of the best
    assignment, then the assignment's 0-based modes (-1 spurious) as floats
    (:meth:`split_blob`). Only with a diagonal ``V_Y`` and no error scale.

    Parameters
    ----------
    problem : GaussianProblem
    center : array_like, shape (6,)
        ``b_0``, the point at ``z = 0`` (the MAP), Pa.
    covariance : array_like, shape (6, 6)
        Covariance of ``b`` at ``b_0`` (``P`` of B), Pa^2.
    forward : callable, optional
        ``forward(b, n_modes)`` replacing the problem's (anything with ``eigenvalues`` and
        ``sensitivities``); default the problem's own.
    assigned : bayesplate.sampling.assigned.ReassignedLikelihood, optional
        The likelihood with the assignment re-made at every point; None: the problem's own
        with its fixed pairing.

    Attributes
    ----------
    center, chol : numpy.ndarray, shapes (6,), (6, 6)
        ``c`` and ``L`` in the coordinates ``h(b)``.
    n_forward : int
        Forward evaluations made in this process.
    """

    def __init__(self, problem, center, covariance, forward=None, assigned=None):
        var = np.diag(problem.V_Y)
        # None: diagonal (independent eigenvalues); else the precision for conditional terms
        self._Q = None if np.array_equal(problem.V_Y, np.diag(var)) else np.linalg.inv(problem.V_Y)
        if assigned is not None and (self._Q is not None or problem.error_scale is not None):
            raise ValueError(
                "the assignment is re-made only with a diagonal V_Y and no error scale "
                "(inputs exact): keep the settled pairing for this problem"
            )
        self.assigned = assigned
        self._source = problem.forward if forward is None else forward
        self.problem = problem.with_forward(self._forward)
        b0 = np.array(center, dtype=float)
        if not laminate.is_physical(b0):
            raise ValueError("the centre of the sampler's coordinates is not a physical lamina")
        scale = np.where(LOG_STIFFNESS, b0, 1.0)  # d h / d b = 1 / b for the logarithms
        self.center = np.where(LOG_STIFFNESS, np.log(np.abs(b0)), b0)
        cov_h = np.asarray(covariance, dtype=float) / np.outer(scale, scale)
        self.chol = np.linalg.cholesky(cov_h)
        self._var = var
        self._last = None
        self.n_forward = 0

    @property
    def m(self):
        """Number of measured eigenvalues (all peaks when the assignment is re-made)."""
        return self.problem.m if self.assigned is None else self.assigned.m

    @property
    def blob_size(self):
        """Numbers returned beside the log-density: ``m``, or ``2 m`` with re-assignment."""
        return self.m if self.assigned is None else 2 * self.m

    def split_blob(self, blobs):
        """``(pointwise, modes)`` of blobs shaped (..., blob_size); modes None when fixed."""
        blobs = np.asarray(blobs, dtype=float)
        if self.assigned is None:
            return blobs, None
        return blobs[..., : self.m], blobs[..., self.m :]

    def _forward(self, b, n_modes):
        modal = self._source(b, n_modes)
        self._last = modal.eigenvalues
        self.n_forward += 1
        return modal

    def _h(self, z):
        return self.center + np.asarray(z, dtype=float) @ self.chol.T

    def to_b(self, z):
        """Stiffness coefficients (Pa) of whitened points ``z``, shape (..., 6)."""
        u = self._h(z)
        return np.where(LOG_STIFFNESS, np.exp(np.where(LOG_STIFFNESS, u, 0.0)), u)

    def to_z(self, b):
        """Whitened coordinates of physical ``b`` (Pa), shape (..., 6)."""
        b = np.asarray(b, dtype=float)
        u = np.where(LOG_STIFFNESS, np.log(np.where(LOG_STIFFNESS, b, 1.0)), b)
        return np.linalg.solve(self.chol, (u - self.center).T).T

    def log_jacobian(self, z):
        """``ln |d b / d z|`` up to the constant ``ln det L``: the sum of the logarithms."""
        u = self._h(z)
        return np.sum(u[..., LOG_STIFFNESS], axis=-1)

    def pointwise(self, g):
        """Log-likelihood of each measured eigenvalue given paired model ones ``g``, (m,)."""
        r = self.problem.Y - g
        if self.problem.error_scale is not None:
            from ..likelihood.error_scale import loo_pointwise

            Q = 1.0 / self._var if self._Q is None else self._Q
            return loo_pointwise(r, Q, self.problem.error_scale)
        if self._Q is None:
            return -0.5 * (r**2 / self._var + np.log(2 * np.pi * self._var))
        q = np.diag(self._Q)
        return -0.5 * ((self._Q @ r) ** 2 / q + np.log(2 * np.pi / q))

    def __call__(self, z):
        """``(log_density, pointwise)`` at whitened ``z``, shape (6,)."""
        if self.assigned is not None:
            return self._reassigned(z)
        self._last = None
        lp = self.problem.log_posterior(self.to_b(z))
        if not np.isfinite(lp) or self._last is None:
            return -np.inf, np.full(self.blob_size, np.nan)
        g = self._last[self.problem.pairing.modes]
        return lp + self.log_jacobian(z), self.pointwise(g)

    def _reassigned(self, z):
        """The log-density with the assignment re-made at ``b(z)``; pointwise and modes."""
        b = self.to_b(z)
        lp = self.problem.log_prior(b)
        if not np.isfinite(lp):
            return -np.inf, np.full(self.blob_size, np.nan)
        g = self._forward(b, self.assigned.n).eigenvalues
        ll, pointwise, modes = self.assigned.evaluate(g)
        return lp + ll + self.log_jacobian(z), np.concatenate([pointwise, modes.astype(float)])


def engineering_constants(density, z):
    """Engineering constants (SI) of whitened points, shape (..., 6) as `z`.

    Parameters
    ----------
    density : WhitenedLogPosterior
    z : array_like, shape (..., 6)
        Whitened coordinates (e.g. a chain, (steps, walkers, 6)).

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        ``(E1, E2, nu12, G12, G13, G23)``, Pa and dimensionless.
    """
    return laminate.engineering_from_stiffness(density.to_b(z))
