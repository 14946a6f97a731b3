"""Joint fit of the elastic constants and a candidate physics, with its Laplace evidence.

The unknowns are whitened by their priors: ``b = mu_b + L z_b`` with ``L L^T = V_b`` and
``theta = mean + sd z_theta``. The fit minimises ``|W (Y - g(b, theta))|^2 + |z|^2``
(``W = V_Y^(-1/2)``) by trust-region least squares from several starts, with modes paired by
order at every evaluation. Derivatives: ``d lambda / d b`` from the eigenvectors (eq. 28);
``d lambda / d theta = a^T (dK/dtheta - lambda dM/dtheta) a`` from the same eigenvectors
with the matrix derivatives taken by central differences of the assembled matrices (no
extra eigen solve).

The best fit is summarised by its Laplace approximation (:mod:`.laplace`: the covariance and
the evidence, :class:`.laplace.JointFit`).

Each fit may run on three levels: every start on a cheap model (a reduced model, or the
coarse mesh), the best optima polished on a reduced model of the working mesh, and the
result finished on the working mesh (:func:`fit`; tightly, at a canonical mirror image:
:mod:`.tight_finish`).
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
from scipy.stats import norm

from ... import laminate
from ..physics.reduced_model import PencilModes
from .laplace import summarise
from .local_fits import distinct as _distinct
from .local_fits import local_fits as _local_fits
from .settling import MAX_ROUNDS, polish_and_finish
from .tight_finish import finish

__all__ = ["JointProblem", "fit", "rough_fit", "settle"]

_UNPHYSICAL_RESIDUAL = 1e4  # residual returned outside the lamina's physical region
_NOT_YET = object()  # not in the cache
#: ``ftol`` and ``xtol`` of the local fits of :func:`rough_fit`: a rough optimum only says
#: where to refine from (the refinement converges on the working mesh), and its gain is
#: judged to ten nats (:data:`.rank.REACH`): chi-square steps under 1e-4 of itself (0.005 at
#: 50) are enough. Measured with :data:`.rank.ROUGH_NFEV` (see there).
ROUGH_TOL = 1e-4


class JointProblem:
    """Data, priors and forward model of one joint fit.

    Parameters
    ----------
    model : PlateModel
        The nominal plate.
    Y : numpy.ndarray, shape (m,)
        Measured eigenvalues, rad^2/s^2.
    sigma : numpy.ndarray, shape (m,)
        Their standard deviations (rad^2/s^2).
    mu_b : numpy.ndarray, shape (6,)
    V_b : numpy.ndarray, shape (6, 6)
        Prior of the stiffness coefficients (Pa, Pa^2).
    modes : numpy.ndarray of int, shape (m,)
        0-based computed elastic modes paired with the measured ones.
    physics : Physics, optional
        The candidate; None for the nominal model.
    """

    def __init__(self, model, Y, sigma, mu_b, V_b, modes, physics=None):
        self.model = model
        self.Y = np.asarray(Y, dtype=float)
        self.sigma = np.asarray(sigma, dtype=float)
        self.mu_b = np.asarray(mu_b, dtype=float)
        self.L = np.linalg.cholesky(np.asarray(V_b, dtype=float))
        self.modes = np.asarray(modes)
        self.physics = physics
        params = () if physics is None else physics.parameters(model, self.mu_b)
        self.theta_mean = np.array([p.mean for p in params])
        self.theta_sd = np.array([p.sd for p in params])
        self.theta_lower = np.array([p.lower for p in params])
        self.theta_upper = np.array([p.upper for p in params])
        self.n_solves = 0
        self.scale = None
        self.pencil = None
        self._cache = {}

    def on(self, model, scale=None):
        """The same problem on another mesh of the same plate (same unknowns ``z``).

        ``scale`` (m,) multiplies the predicted eigenvalues: the fine-to-coarse ratio at a
        reference point corrects most of a coarse mesh's discretisation error.
        """
        other = copy.copy(self)
        other.model, other.n_solves, other._cache = model, 0, {}
        other.scale = None if scale is None else np.asarray(scale, dtype=float)
        other.pencil = None
        return other

    def on_pencil(self, pencil, scale=None):
        """The same problem on a reduced candidate model.

        (:class:`..physics.reduced_model.CandidatePencil`.)

        ``scale`` as for :meth:`on` (the pencil's mesh to this problem's).
        """
        other = self.on(self.model, scale)
        other.pencil = pencil
        return other

    @property
    def k(self):
        """Number of physics parameters."""
        return self.theta_mean.size

    def unpack(self, z):
        """``(b, theta)`` from whitened unknowns ``z``."""
        z = np.asarray(z, dtype=float)
        return self.mu_b + self.L @ z[:6], self.theta_mean + self.theta_sd * z[6:]

    def pack(self, b, theta=()):
        """Whitened unknowns from ``(b, theta)``."""
        zb = np.linalg.solve(self.L, np.asarray(b, dtype=float) - self.mu_b)
        zt = (np.asarray(theta, dtype=float) - self.theta_mean) / self.theta_sd
        return np.concatenate([zb, zt])

    def bounds(self):
        """Bounds of the whitened unknowns (the physics parameters only)."""
        lo = np.concatenate(
            [np.full(6, -np.inf), (self.theta_lower - self.theta_mean) / self.theta_sd]
        )
        hi = np.concatenate(
            [np.full(6, np.inf), (self.theta_upper - self.theta_mean) / self.theta_sd]
        )
        return lo, hi

    def plate(self, theta):
        """The model with the physics applied at ``theta`` (the nominal one if none)."""
        return self.model if self.physics is None else self.physics.apply(self.model, theta)

    def evaluate(self, z):
        """Paired eigenvalues and their Jacobian in ``z``, cached by ``z``.

        ``(lam, J, modal)``, or None outside the lamina's physical region.
        """
        key = np.asarray(z, dtype=float).tobytes()
        out = self._cache.get(key, _NOT_YET)
        if isinstance(out, PencilModes):  # the residuals' modes: their derivatives now
            out = self._finish_reduced(out)
        elif out is _NOT_YET:
            out = self._evaluate(np.asarray(z, dtype=float))
        self._cache = {key: out}
        return out

    def values(self, z):
        """Paired eigenvalues in ``z`` (m,), or None outside the physical region.

        On a pencil without their derivatives, which :meth:`evaluate` adds at the same ``z``
        (the modes kept): a fit asks for the Jacobian at the steps it accepts only.
        """
        z = np.asarray(z, dtype=float)
        key = z.tobytes()
        out = self._cache.get(key, _NOT_YET)
        if out is _NOT_YET and self.pencil is not None:
            b, theta = self.unpack(z)
            out = self._pencil_modes(b, theta) if laminate.is_physical(b) else None
            self._cache = {key: out}
        if out is _NOT_YET:
            out = self.evaluate(z)
        if isinstance(out, PencilModes):
            lam = out.eigenvalues[self.modes]
            return lam if self.scale is None else lam * self.scale
        return None if out is None else out[0]

    def _evaluate(self, z):
        b, theta = self.unpack(z)
        if not laminate.is_physical(b):
            return None
        if self.pencil is not None:
            return self._evaluate_reduced(b, theta)
        plate = self.plate(theta)
        modal = plate.solve(b, int(self.modes.max()) + 3)
        self.n_solves += 1
        lam = modal.eigenvalues[self.modes]
        J = np.zeros((lam.size, 6 + self.k))
        J[:, :6] = modal.sensitivities[self.modes] @ self.L
        if self.k:  # (a reduced model's mode shapes are made on access: only when needed)
            vectors = modal.vectors[:, self.modes]
            for i in range(self.k):
                J[:, 6 + i] = self.theta_sd[i] * self._theta_derivative(theta, i, b, lam, vectors)
        if self.scale is not None:
            lam, J = lam * self.scale, J * self.scale[:, None]
        return lam, J, modal

    def _evaluate_reduced(self, b, theta):
        return self._finish_reduced(self._pencil_modes(b, theta))

    def _pencil_modes(self, b, theta):
        """The pencil's modes at ``(b, theta)``, as many as the pairing reaches."""
        return self.pencil.modes(b, theta, int(self.modes.max()) + 1)

    def _finish_reduced(self, modes):
        modal, d_theta = self.pencil.derivatives(modes)
        lam = modal.eigenvalues[self.modes]
        J = np.hstack(
            [modal.sensitivities[self.modes] @ self.L, d_theta[self.modes] * self.theta_sd]
        )
        if self.scale is not None:
            lam, J = lam * self.scale, J * self.scale[:, None]
        return lam, J, modal

    def _theta_derivative(self, theta, i, b, lam, vectors):
        """``d lambda / d theta_i`` from eigenvectors and differenced matrices."""
        h = 1e-4 * self.theta_sd[i]
        up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
        up[i] = min(theta[i] + h, self.theta_upper[i])
        down[i] = max(theta[i] - h, self.theta_lower[i])
        p_up, p_down = self.plate(up), self.plate(down)
        dK = (p_up.stiffness(b) - p_down.stiffness(b)) / (up[i] - down[i])
        dM = (p_up.mass - p_down.mass) / (up[i] - down[i])
        return np.einsum("di,di->i", vectors, dK @ vectors) - lam * np.einsum(
            "di,di->i", vectors, dM @ vectors
        )

    def residuals(self, z):
        """``[W (Y - g); z]``: whitened data misfit, then the prior terms."""
        lam = self.values(z)
        if lam is None:
            return np.full(self.Y.size + z.size, _UNPHYSICAL_RESIDUAL)
        return np.concatenate([(self.Y - lam) / self.sigma, z])

    def jacobian(self, z):
        """Jacobian of :meth:`residuals`."""
        out = self.evaluate(z)
        n = np.asarray(z).size
        if out is None:
            return np.vstack([np.zeros((self.Y.size, n)), np.eye(n)])
        return np.vstack([-out[1] / self.sigma[:, None], np.eye(n)])

    def log_truncation(self):
        """``sum ln P_trunc``: prior mass of each physics parameter inside its bounds."""
        lo = norm.cdf((self.theta_lower - self.theta_mean) / self.theta_sd)
        hi = norm.cdf((self.theta_upper - self.theta_mean) / self.theta_sd)
        return float(np.sum(np.log(hi - lo)))


def fit(
    problem,
    starts,
    max_nfev=40,
    coarse=None,
    scale=None,
    refine=None,
    keep=1,
    workers=1,
    rough=None,
    distinct=False,
    rough_nfev=None,
    polish=None,
    tol=1e-8,
    rounds=MAX_ROUNDS,
):
    """Best joint fit over several starts, with its Laplace evidence.

    Parameters
    ----------
    problem : JointProblem
    starts : sequence of array_like, each shape (6 + k,)
        Whitened starting points (see :meth:`JointProblem.pack`).
    max_nfev : int
        Evaluation cap of each local fit.
    coarse : PlateModel, optional
        A cheaper mesh of the same plate: every start is fitted there, and only the best
        result is refined on ``problem``'s own mesh.
    scale : numpy.ndarray, shape (m,), optional
        Correction of the coarse mesh's eigenvalues (see :meth:`JointProblem.on`).
    refine : callable, optional
        ``refine(coarse_fit) -> bool``: whether to refine on the fine mesh; a fit that is not
        refined is returned as fitted on the (corrected) coarse mesh, ``refined`` False.
    keep : int
        How many of the best coarse results to refine (the best fine one is returned).
    workers : int
        Processes for the local fits from the starts (see :func:`bayesplate.parallel.fork_map`).
    rough : JointProblem, optional
        A cheaper version of ``problem`` (a reduced model: :meth:`JointProblem.on_pencil`)
        used as ``coarse`` is; it takes precedence over ``coarse``.
    rough_nfev : int, optional
        Evaluation cap of each local fit on ``rough`` (default ``max_nfev``).
    polish : callable, optional
        ``polish(z, basis=None) -> JointProblem``: a reduced model of ``problem`` on its own
        mesh, exact at ``z`` (a finite-element snapshot there; :meth:`JointProblem.on_pencil`)
        and keeping the vectors ``basis``. Each of the ``keep`` rough optima is then polished
        on it and, where it can still win, settled in rounds checked by the finite-element
        model (:mod:`.settling`); the best settled one is reported, its chi-square, evidence
        and derivatives those of the finite-element model at its answer.
    tol : float
        ``ftol`` and ``xtol`` of the fits on ``problem`` after a rough stage.
    distinct : bool
        Refine the ``keep`` best *distinct* rough optima (whitened distance above
        ``DISTINCT``), not the ``keep`` best ones (many starts reach the same optimum).
    rounds : int
        Rounds at most of each settling with ``polish`` (fewer: a provisional fit, its
        ``check.settled`` False unless it settled anyway; :func:`settle` it later).

    Returns
    -------
    JointFit
    """
    if rough is None and coarse is not None:
        rough = problem.on(coarse, scale)
    if rough is not None:
        rough_problem = rough
        rough = _local_fits(rough_problem, starts, rough_nfev or max_nfev, workers)
        if refine is not None and not refine(summarise(rough_problem, rough[0], refined=False)):
            return summarise(rough_problem, rough[0], refined=False)
        starts = [r.x for r in (_distinct(rough) if distinct else rough)[:keep]]
        if polish is not None:
            return settle(problem, polish, starts, rounds)
    results = _local_fits(problem, starts, max_nfev, workers, tol if rough is not None else 1e-8)
    others = tuple((problem.unpack(r.x)[0], 2.0 * r.cost) for r in results[1:])
    best = results[0] if rough is None else finish(problem, results[0], max_nfev)
    return replace(summarise(problem, best), alternatives=others)


def rough_fit(rough, starts, max_nfev, keep, more=None):
    """Every start fitted on a rough (reduced) model: the best, with its distinct optima.

    Parameters
    ----------
    rough : JointProblem
        On a reduced model (:meth:`JointProblem.on_pencil`).
    starts : sequence of array_like, each shape (6 + k,)
    max_nfev : int
        Evaluation cap of each local fit.
    keep : int
        Distinct optima kept (whitened distance above ``DISTINCT``), best first.
    more : callable, optional
        ``more(optima) -> starts``: further starts made from the distinct optima of the
        first ones (best first), fitted in turn.

    Returns
    -------
    JointFit
        On ``rough``, ``refined`` False, its ``rough_optima`` the ``keep`` best distinct ones.
    """
    results = _local_fits(rough, starts, max_nfev, tol=ROUGH_TOL)
    if more is not None:
        extra = more([r.x for r in _distinct(results)])
        if extra:
            results += _local_fits(rough, extra, max_nfev, tol=ROUGH_TOL)
            results.sort(key=lambda r: r.cost)
    optima = tuple(r.x for r in _distinct(results)[:keep])
    return replace(summarise(rough, results[0], refined=False), rough_optima=optima)


def settle(problem, polish, starts, rounds=MAX_ROUNDS):
    """The best of the optima ``starts`` settled on reduced models of the working mesh.

    Each is settled in rounds of reduced models exact where they reach, each checked by
    the finite-element model (:func:`.settling.polish_and_finish`); the reported fit's
    chi-square, evidence and derivatives are the finite-element model's at its answer.

    Parameters
    ----------
    problem : JointProblem
        On the working mesh.
    polish : callable
        ``polish(z, earlier=()) -> JointProblem`` (see :func:`fit`).
    starts : sequence of numpy.ndarray, each shape (6 + k,)
        Whitened starting points (rough optima, or an earlier provisional answer).
    rounds : int
        Rounds at most per optimum.

    Returns
    -------
    JointFit
        With its ``check`` and the other optima as ``alternatives``.
    """
    settled, others = polish_and_finish(problem, polish, starts, rounds)
    best = settled[0]
    fitted = summarise(best.problem, best.result, modal=best.snapshot)
    solves = problem.n_solves + sum(s.check.full_solves for s in settled)
    return replace(fitted, alternatives=tuple(others), check=best.check, n_solves=solves)
