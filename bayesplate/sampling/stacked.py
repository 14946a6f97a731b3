"""The stacked problem of several plates: their paired eigenvalues one after another.

:func:`joint_problem` stacks the plates' Gaussian problems into one: ``Y`` the plates'
paired eigenvalues plate after plate, ``V_Y`` block-diagonal (the plates are independent
given ``b``), one prior (the first problem's), and :class:`JointForward` (every plate's
model at the same ``b``). Its log-posterior is the first prior plus the sum of the plates'
log-likelihoods, exactly; :func:`joint_estimate` is B on it (the joint MAP and ``P``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..estimators import run
from ..likelihood.posterior import GaussianProblem
from ..matching.pairing import Pairing
from .setup import MAP_TOL

__all__ = ["JointForward", "joint_estimate", "joint_problem"]


@dataclass(frozen=True)
class _Stacked:
    """Concatenated paired eigenvalues (m,) and sensitivities (m, 6) of the plates."""

    eigenvalues: np.ndarray
    sensitivities: np.ndarray


class JointForward:
    """``forward(b, n_modes)``: every plate's paired eigenvalues at one ``b``, concatenated.

    Parameters
    ----------
    forwards : sequence of callable
        Each plate's ``forward(b, n_modes)`` (eigenvalues, and sensitivities if it has them).
    pairings : sequence of Pairing
        Each plate's pairing: plate ``p`` contributes ``eigenvalues[pairing.modes]``.

    Notes
    -----
    ``n_modes`` is ignored: each plate computes the modes its pairing needs. The result's
    eigenvalues are already paired (shape (m,), ``m`` the sum of the plates' paired
    frequencies), so the stacked problem's pairing is the identity.
    """

    def __init__(self, forwards, pairings):
        self.forwards = tuple(forwards)
        self.pairings = tuple(pairings)

    def __call__(self, b, n_modes=None):
        """Paired eigenvalues, rad^2/s^2, shape (m,), and sensitivities (m, 6), at `b` (Pa)."""
        values, sens = [], []
        for forward, pairing in zip(self.forwards, self.pairings, strict=True):
            modal = forward(b, pairing.n_modes())
            values.append(np.asarray(modal.eigenvalues)[pairing.modes])
            sens.append(np.asarray(modal.sensitivities)[pairing.modes])
        return _Stacked(np.concatenate(values), np.concatenate(sens))


def joint_problem(problems, forwards=None):
    """The stacked Gaussian problem of several plates with the first plate's prior.

    Parameters
    ----------
    problems : sequence of GaussianProblem
        One per plate (e.g. each :class:`SamplingSetup`'s ``problem``).
    forwards : sequence of callable, optional
        Each plate's forward model; default each problem's own.

    Returns
    -------
    GaussianProblem
        ``Y`` (m,), block-diagonal ``V_Y`` (m, m), the first problem's ``mu_b``, ``V_b``,
        a :class:`JointForward` and the identity pairing (``m`` modes, no extra).
    """
    forwards = [p.forward for p in problems] if forwards is None else list(forwards)
    forward = JointForward(forwards, [p.pairing for p in problems])
    Y = np.concatenate([p.Y for p in problems])
    V_Y = scipy.linalg.block_diag(*[p.V_Y for p in problems])
    first = problems[0]
    pairing = Pairing(np.arange(Y.size), how="order", extra=0)
    return GaussianProblem(Y, V_Y, first.mu_b, first.V_b, forward, pairing)


def _reduced_forward(setup):
    """A plate's reduced model anywhere (no fallback), for B's path; else its fast model."""
    fast = setup.fast
    if fast is not None and fast.certified:
        return fast.reduced.solve
    return setup.forward_with_sensitivities()


def joint_estimate(setups, start=None, tol=MAP_TOL, free=False):
    """B on the stacked problem of some plates: their joint MAP and ``P`` (eq. 9).

    Parameters
    ----------
    setups : sequence of SamplingSetup
    start : array_like, shape (6,), optional
        First iterate (Pa); default the prior mean.
    tol : float
        B's TOL.
    free : bool
        Use the plates' reduced models everywhere (no full-model fallback off their
        boxes: for paths and box placement), or their certified models.

    Returns
    -------
    EstimateResult
    """
    fwd = [_reduced_forward(s) if free else s.forward_with_sensitivities() for s in setups]
    problem = joint_problem([s.problem for s in setups], fwd)
    return run(problem, "B", tol=tol, tracking="off", start=start)
