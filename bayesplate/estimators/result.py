"""The outcome of one estimator run: :class:`EstimateResult`, with its status."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["METHODS", "STATUSES", "EstimateResult", "FullModelCheck"]

METHODS = ("B", "MVE", "MVE-mod")
#: How a run ended (:attr:`EstimateResult.status`); only the first is a success.
#: "rejected": the iteration stopped but the fit is rejected (chi-square p < 0.01);
#: "implausible": it stopped but a constant is far from its prior, most low modes are
#: unobserved or a second basin rivals it (:mod:`bayesplate.estimators.assess`).
#: "unidentified": MVE stopped drifting along directions the data barely determine.
STATUSES = (
    "converged",
    "rejected",
    "implausible",
    "oscillating",
    "iteration_cap",
    "unidentified",
    "unphysical",
    "linalg_failed",
    "solve_failed",
    "unconfirmed",
)


@dataclass(frozen=True, eq=False)
class FullModelCheck:
    """The full model at an answer the fast (reduced-basis) model gave.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        The answer checked, Pa.
    fast_Hz, full_Hz : numpy.ndarray, shape (m,)
        Paired frequencies there by the fast and by the full model, Hz.
    tolerance : float
        Largest relative frequency difference accepted (the fast model's certificate's).
    rounds : int
        Runs on the fast model: one, plus one after each enrichment of its basis with the
        full solution at an answer it got wrong.
    n_full_solves : int
        Full solves of the runs (iterates off the certified box) and of the checks (the
        build's are in ``build_solves``).
    build_solves : int
        Full solves spent building and certifying the fast model (0 when it was given).
    build_seconds : float
        Seconds spent building it.
    """

    b: np.ndarray
    fast_Hz: np.ndarray
    full_Hz: np.ndarray
    tolerance: float
    rounds: int
    n_full_solves: int
    build_solves: int = 0
    build_seconds: float = 0.0

    @property
    def rel_error(self):
        """``|f_fast / f_full - 1|`` of each paired frequency, shape (m,)."""
        return np.abs(self.fast_Hz / self.full_Hz - 1.0)

    @property
    def max_rel_error(self):
        """The largest relative difference (NaN where the full solve failed)."""
        return float(np.max(self.rel_error)) if self.rel_error.size else 0.0

    @property
    def confirmed(self):
        """Whether the full model agrees within the tolerance."""
        return bool(self.max_rel_error <= self.tolerance)

    def __str__(self):
        verdict = "confirmed" if self.confirmed else "DISAGREES"
        return (
            f"full-model check {verdict}: largest relative frequency difference "
            f"{self.max_rel_error:.1e} (tolerance {self.tolerance:.0e}) after {self.rounds} "
            f"fast run(s)"
        )


@dataclass(frozen=True)
class EstimateResult:
    """Outcome of one estimator run.

    Attributes
    ----------
    method : str
        ``"B"``, ``"MVE"`` or ``"MVE-mod"``.
    b : numpy.ndarray, shape (6,)
        Estimated ``(C11, C22, C12, C66, C44, C55)``, Pa (the last physical iterate when the
        run failed).
    constants : numpy.ndarray, shape (6,)
        ``(E1, E2, nu12, G12, G13, G23)``, SI.
    covariance_b : numpy.ndarray, shape (6, 6)
        B: ``P^k`` of eq. 9 at the final iterate; MVE: the updated ``V_b^{k+1}``; Pa^2.
    covariance : numpy.ndarray, shape (6, 6)
        The same carried to the engineering constants (first order), SI.
    sd : numpy.ndarray, shape (6,)
        Square roots of the diagonal of `covariance`.
    history : numpy.ndarray, shape (iterations + 1, 6)
        Engineering constants of every iterate, the initial values first.
    history_b : numpy.ndarray, shape (iterations + 1, 6)
        The same iterates as stiffness coefficients, Pa.
    iterations : int
        Updates performed.
    converged : bool
        Whether the iteration stopped normally (its stopping rule met). It says nothing of
        the fit: ``status`` is ``"converged"`` only when, besides, nothing was flagged.
    message : str
        Why the run ended, in words.
    n_solves : int
        Forward (eigen) solves.
    frequency_Hz, measured_Hz : numpy.ndarray, shape (m,)
        Paired model frequencies at the estimate and the measured ones.
    residual : numpy.ndarray, shape (m,)
        ``frequency_Hz - measured_Hz``, Hz.
    modes : numpy.ndarray of int, shape (m,)
        1-based computed elastic mode paired with each measured frequency at the estimate.
    mode_swaps : list of tuple
        ``(iteration, measured index, old mode, new mode)`` (0-based indices, 1-based modes)
        where MAC tracking found a paired mode changing place.
    stages : tuple of EstimateResult
        MVE-mod: the two stages; empty otherwise.
    wall_time : float
        Seconds.
    settings : dict
        Tolerance, iteration cap, conventions, pairing; ``"frozen_pairing"`` when a pairing
        by order or index flipped and was frozen (iteration, 1-based peaks and modes);
        ``"unidentified"`` when status is ``"unidentified"`` (coefficients and constants
        named, the data's information along the drift relative to the step covariance's over
        the last iterations, contraction per iteration, relative change, predicted
        iterations).
    status : str
        How the run ended, one of :data:`STATUSES`: test this, never the message's text.
        ``"rejected"`` and ``"implausible"`` (set by
        :func:`bayesplate.estimators.assess.assess`) are runs that stopped (``converged``
        True) with an answer that should not be trusted: see ``warnings``.
    pairing : bayesplate.matching.pairing.Pairing or None
        The measured-to-computed pairing the run used (for ``"likelihood"``, the settled
        assignment, with its unobserved modes and spurious peaks).
    check : FullModelCheck or None
        When the run was on the fast model: the full model at its answer (status
        ``"unconfirmed"`` when they disagree beyond the certificate); None on the full model.
    fit : bayesplate.estimators.assess.FitStatement or None
        Chi-square of the paired peaks with the declared deviations, its degrees of freedom,
        p-value and worst residuals (None until assessed; :func:`estimate` assesses).
    warnings : tuple of str
        Why the answer should not be trusted, one sentence each (empty when nothing is).
    """

    method: str
    b: np.ndarray
    constants: np.ndarray
    covariance_b: np.ndarray
    covariance: np.ndarray
    sd: np.ndarray
    history: np.ndarray
    history_b: np.ndarray
    iterations: int
    converged: bool
    message: str
    n_solves: int
    frequency_Hz: np.ndarray
    measured_Hz: np.ndarray
    residual: np.ndarray
    modes: np.ndarray
    mode_swaps: list = field(default_factory=list)
    stages: tuple = ()
    wall_time: float = 0.0
    settings: dict = field(default_factory=dict)
    status: str = ""
    pairing: object = field(default=None, repr=False, compare=False)
    check: object = field(default=None, repr=False, compare=False)
    fit: object = field(default=None, repr=False, compare=False)
    warnings: tuple = ()

    def __post_init__(self):
        if not self.status:
            object.__setattr__(self, "status", "converged" if self.converged else "")
        if self.status not in STATUSES:
            raise ValueError(f"status = {self.status!r}: must be one of {STATUSES}")

    @property
    def residual_percent(self):
        """``100 (f - f_meas) / f_meas``, shape (m,)."""
        return 100.0 * self.residual / self.measured_Hz
