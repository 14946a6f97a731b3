"""Every estimate's fit, and when it should not be trusted (issue 37, items 3-4).

:func:`assess` gives an :class:`~.result.EstimateResult` its :class:`FitStatement` and its
warnings, and sets its status; :func:`bayesplate.estimators.estimate` applies it once, to the
answer it returns. All of it is array arithmetic on the result: no forward solve.

Fit statement
    The chi-square of the paired peaks with the declared deviations, in the eigenvalues the
    estimators fit (:mod:`bayesplate.likelihood.posterior`): ``chi2 = r^T V_Y^-1 r`` with
    ``r = g - Y`` and ``V_Y = diag(d lambda^2)``, ``d lambda = 8 pi^2 f sigma`` (the declared
    frequency deviations, whatever convention the estimator weighted with). Its degrees of freedom
    are the paired peaks less the effective number of constants the data determine,
    ``p_eff = trace(S P S^T V_Y^-1)`` with ``P = (S^T V_Y^-1 S + V_b^-1)^-1``; as
    ``P^-1 = S^T V_Y^-1 S + V_b^-1``, that is ``6 - trace(P V_b^-1)``, read off the
    estimator's own ``P`` (``covariance_b``: B's at the estimate, MVE's updated covariance)
    and the prior it ran with (MVE-mod: stage 2's). Exact for B and for MVE with the fixed
    prior covariance (the ``"paper"`` and ``"full-prior"`` conventions); with the
    ``"printed"`` conventions it is the estimator's own weighting's count. The standardised
    residual of a peak is ``r_i / d lambda_i`` (model minus measured, in deviations: about
    the frequency residual over ``sigma`` for small residuals), so that ``chi2`` is the sum of
    their squares.

Warnings (each a sentence naming the cause and its numbers)
    - the fit is rejected: ``p < REJECT_P`` (status ``"rejected"``);
    - a constant more than :data:`PRIOR_SD_LIMIT` prior deviations from its prior mean (the
      initial prior: MVE-mod's stage 1);
    - with an assignment by likelihood: the fundamental unobserved, more than a third of the
      computed modes below the highest paired one unobserved, or the lowest peak called
      spurious;
    - a rival (another local optimum, ``rivals`` or ``settings["rivals"]``) within
      :data:`RIVAL_NATS` of the estimate's log posterior with a constant more than
      :data:`RIVAL_SD` sd away.

The last three make the status ``"implausible"``. A run whose iteration did not stop
normally keeps its own status (the fit and warnings are added all the same); ``converged``
always says only that the iteration stopped.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from ..likelihood.posterior import observation_covariance, observed_eigenvalues, prior_in_stiffness
from ..quantities import ENGINEERING_NAMES, ENGINEERING_UNITS, to_case_units

__all__ = [
    "PRIOR_SD_LIMIT",
    "REJECT_P",
    "RIVAL_NATS",
    "RIVAL_SD",
    "FitStatement",
    "WorstResidual",
    "assess",
    "effective_constants",
    "effective_constants_from_covariance",
    "fit_statement",
    "plausibility_warnings",
]

#: A fit with a chi-square p-value below this is rejected.
REJECT_P = 0.01
#: A constant farther than this many prior deviations from its prior mean is implausible.
PRIOR_SD_LIMIT = 3.0
#: A rival optimum within this many nats of the estimate's log posterior ...
RIVAL_NATS = 3.0
#: ... with a constant more than this many sd away is a second basin.
RIVAL_SD = 2.0
#: Worst residuals named in a fit statement.
N_WORST = 3


@dataclass(frozen=True)
class WorstResidual:
    """One of the largest standardised residuals.

    Attributes
    ----------
    peak : int
        1-based measured peak (its row in the case).
    measured_Hz, computed_Hz : float
    sd : float
        ``(lambda_computed - lambda_measured) / d lambda`` (model minus measured).
    """

    peak: int
    measured_Hz: float
    computed_Hz: float
    sd: float

    def __str__(self):
        return f"peak {self.peak} {self.sd:+.1f} sd"


@dataclass(frozen=True, eq=False)
class FitStatement:
    """The chi-square of an estimate's paired peaks with the declared deviations.

    Attributes
    ----------
    chi2 : float
        ``r^T V_Y^-1 r`` (module docstring).
    dof : float
        ``max(m - p_effective, 1)``.
    p_value : float
        ``P(chi2_dof >= chi2)`` (:func:`scipy.stats.chi2.sf`).
    p_effective : float
        Effective number of constants the data determine.
    n_paired : int
        Paired peaks ``m``.
    residual_sd : numpy.ndarray, shape (m,)
        Standardised residuals, model minus measured, in the order of the paired peaks.
    peaks : numpy.ndarray of int, shape (m,)
        1-based measured peak of each.
    worst_residuals : tuple of WorstResidual
        The :data:`N_WORST` largest ``|residual_sd|``, largest first.
    """

    chi2: float
    dof: float
    p_value: float
    p_effective: float
    n_paired: int
    residual_sd: np.ndarray
    peaks: np.ndarray
    worst_residuals: tuple = ()

    @property
    def rejected(self):
        """Whether ``p_value < REJECT_P``."""
        return bool(self.p_value < REJECT_P)

    def __str__(self):
        worst = ", ".join(map(str, self.worst_residuals)) or "none"
        return (
            f"fit: chi-square {self.chi2:.3g} on {self.dof:.1f} dof, p {self.p_value:.2g}; "
            f"worst residuals: {worst}"
        )

    def to_dict(self):
        """Plain data (the JSON ``fit`` entry)."""
        return {
            "chi2": float(self.chi2),
            "dof": float(self.dof),
            "p_value": float(self.p_value),
            "p_effective": float(self.p_effective),
            "n_paired": int(self.n_paired),
            "worst_residuals": [
                {
                    "peak": w.peak,
                    "measured_Hz": w.measured_Hz,
                    "computed_Hz": w.computed_Hz,
                    "sd": w.sd,
                }
                for w in self.worst_residuals
            ],
        }


def effective_constants(S, V_Y, V_b):
    """``trace(S (S^T V_Y^-1 S + V_b^-1)^-1 S^T V_Y^-1)``: the constants the data determine.

    Parameters
    ----------
    S : array_like, shape (m, n)
    V_Y : array_like, shape (m, m)
    V_b : array_like, shape (n, n)

    Returns
    -------
    float
    """
    S, V_Y, V_b = (np.asarray(a, dtype=float) for a in (S, V_Y, V_b))
    info = S.T @ np.linalg.solve(V_Y, S)
    P = np.linalg.inv(info + np.linalg.inv(V_b))
    return float(np.trace(P @ info))


def effective_constants_from_covariance(P, V_b):
    """The same count from the posterior covariance ``P``: ``n - trace(P V_b^-1)``.

    Scaled by the prior deviations before inverting (``V_b`` in Pa^2 spans many decades).
    NaN when ``P`` is not finite.
    """
    P, V_b = np.asarray(P, dtype=float), np.asarray(V_b, dtype=float)
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(V_b))):
        return float("nan")
    d = np.sqrt(np.diag(V_b))
    scaled_P, scaled_V = P / np.outer(d, d), V_b / np.outer(d, d)
    return float(P.shape[0] - np.trace(np.linalg.solve(scaled_V, scaled_P)))


def fit_statement(measured_Hz, computed_Hz, sigma_Hz, p_effective, peaks=None, n_worst=N_WORST):
    """The :class:`FitStatement` of paired frequencies with their declared deviations.

    Parameters
    ----------
    measured_Hz, computed_Hz, sigma_Hz : array_like, shape (m,)
        Paired measured and model frequencies and the measured ones' deviations, Hz.
    p_effective : float
        Effective number of constants fitted (:func:`effective_constants`); NaN counts
        ``min(6, m)``.
    peaks : array_like of int, shape (m,), optional
        1-based measured peak of each (default ``1..m``).
    n_worst : int
        Worst residuals kept.

    Returns
    -------
    FitStatement
    """
    f = np.asarray(measured_Hz, dtype=float)
    fc = np.asarray(computed_Hz, dtype=float)
    m = f.size
    peaks = np.arange(1, m + 1) if peaks is None else np.asarray(peaks, dtype=int)
    V_Y = observation_covariance(f, sigma_Hz, "variance")
    r = observed_eigenvalues(fc) - observed_eigenvalues(f)
    chi2 = float(r @ np.linalg.solve(V_Y, r)) if m else 0.0
    z = r / np.sqrt(np.diag(V_Y))
    p_eff = float(p_effective)
    if not np.isfinite(p_eff):
        p_eff = float(min(6, m))
    p_eff = min(max(p_eff, 0.0), float(m))
    dof = max(m - p_eff, 1.0)
    p_value = float(stats.chi2.sf(chi2, dof)) if np.isfinite(chi2) else float("nan")
    order = np.argsort(-np.abs(np.nan_to_num(z, nan=np.inf)), kind="stable")[:n_worst]
    worst = tuple(
        WorstResidual(int(peaks[i]), float(f[i]), float(fc[i]), float(z[i])) for i in order
    )
    return FitStatement(chi2, float(dof), p_value, p_eff, m, z, peaks, worst)


def plausibility_warnings(
    constants,
    prior_mean,
    prior_sd,
    *,
    sd=None,
    settings=None,
    modes=None,
    measured_Hz=None,
    rivals=(),
    limit=PRIOR_SD_LIMIT,
):
    """Warnings (b)-(d) of the module docstring, each one sentence.

    Parameters
    ----------
    constants, prior_mean, prior_sd : array_like, shape (6,)
        The estimate and its (initial) engineering prior, SI.
    sd : array_like, shape (6,), optional
        The estimate's deviations (for a rival's distance; the prior's where not finite).
    settings : dict, optional
        The result's: ``"unobserved_modes"`` and ``"spurious_peaks"`` (1-based) when the
        pairing is an assignment by likelihood.
    modes : array_like of int, shape (m,), optional
        1-based computed mode of each paired peak.
    measured_Hz : array_like, shape (n_peaks,), optional
        Every measured peak of the case (which is the lowest).
    rivals : sequence of (constants, float)
        Other optima: constants (SI, shape (6,)) and ``ln p(estimate) - ln p(rival)``, nats.
    limit : float
        Prior deviations beyond which a constant is implausible.

    Returns
    -------
    tuple of str
    """
    out = []
    e = np.asarray(constants, dtype=float)
    mean, psd = np.asarray(prior_mean, dtype=float), np.asarray(prior_sd, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (e - mean) / psd
    shown, shown_mean, shown_sd = to_case_units(e), to_case_units(mean), to_case_units(psd)
    for i in np.flatnonzero(np.abs(np.nan_to_num(z, nan=0.0)) > limit):
        unit = "" if ENGINEERING_UNITS[i] == "-" else f" {ENGINEERING_UNITS[i]}"
        side = "above" if z[i] > 0 else "below"
        out.append(
            f"{ENGINEERING_NAMES[i]} is {abs(z[i]):.1f} prior sd {side} its prior mean "
            f"({shown[i]:.4g}{unit} against {shown_mean[i]:.4g} +/- {shown_sd[i]:.2g}{unit})"
        )
    out += _assignment_warnings(settings or {}, modes, measured_Hz)
    out += _rival_warnings(e, sd, psd, rivals)
    return tuple(out)


def _assignment_warnings(settings, modes, measured_Hz):
    """(c): most low modes unobserved, or the lowest peak spurious (likelihood assignments)."""
    if "unobserved_modes" not in settings or modes is None or not len(modes):
        return []
    out = []
    top = int(np.max(modes))
    unobserved = sorted(int(j) for j in settings["unobserved_modes"] if int(j) < top)
    below = top - 1
    if 1 in unobserved:
        out.append("the fundamental (computed mode 1) is unobserved: no peak is paired with it")
    if below and len(unobserved) > below / 3:
        out.append(
            f"{len(unobserved)} of the {below} computed modes below the highest paired one "
            f"(mode {top}) are unobserved (modes {', '.join(map(str, unobserved))})"
        )
    spurious = [int(p) for p in settings.get("spurious_peaks", [])]
    if measured_Hz is not None and len(measured_Hz) and spurious:
        lowest = int(np.argmin(np.asarray(measured_Hz, dtype=float))) + 1
        if lowest in spurious:
            f = float(np.asarray(measured_Hz)[lowest - 1])
            out.append(f"the lowest peak (peak {lowest}, {f:.1f} Hz) is called spurious")
    return out


def _rival_warnings(e, sd, prior_sd, rivals):
    """(d): another optimum nearly as probable with constants far from the estimate's."""
    out = []
    sd = prior_sd if sd is None else np.asarray(sd, dtype=float)
    sd = np.where(np.isfinite(sd) & (sd > 0), sd, prior_sd)
    for constants, nats in rivals or ():
        other = np.asarray(constants, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            apart = np.abs(other - e) / sd
        apart = np.nan_to_num(apart, nan=0.0)
        if float(nats) <= RIVAL_NATS and np.max(apart) > RIVAL_SD:
            i = int(np.argmax(apart))
            shown = to_case_units(other)[i]
            unit = "" if ENGINEERING_UNITS[i] == "-" else f" {ENGINEERING_UNITS[i]}"
            out.append(
                f"a second basin: another optimum {float(nats):.1f} nats below the estimate's "
                f"log posterior has {ENGINEERING_NAMES[i]} {shown:.4g}{unit}, "
                f"{apart[i]:.1f} sd away"
            )
    return out


def assess(result, case, *, rivals=None):
    """`result` with its :class:`FitStatement`, its warnings and its status.

    Parameters
    ----------
    result : EstimateResult
    case : bayesplate.io.Case
        The case it was estimated for (the declared deviations, the peaks).
    rivals : sequence of (constants, float), optional
        Other optima (SI constants, and how many nats below the estimate's log posterior
        each is); default ``result.settings.get("rivals", ())``.

    Returns
    -------
    EstimateResult
        ``fit`` and ``warnings`` set; ``status`` ``"rejected"`` when the fit is rejected,
        ``"implausible"`` when another warning holds, ``"converged"`` when the iteration
        stopped and nothing was flagged, else the run's own.
    """
    measured = case.measured
    kept = _paired_peaks(result, measured.frequency_Hz)
    sigma = np.asarray(measured.sigma_Hz, dtype=float)[kept]
    fit = fit_statement(
        result.measured_Hz, result.frequency_Hz, sigma, _p_effective(result, case), peaks=kept + 1
    )
    warnings = []
    if fit.rejected:
        warnings.append(
            f"fit rejected: chi-square {fit.chi2:.3g} on {fit.dof:.1f} dof (p {fit.p_value:.2g}); "
            f"run `bayesplate diagnose {_case_ref(case)}`"
        )
    initial = (result.stages[0] if result.stages else result).settings
    mean = initial.get("prior_mean", case.prior.mean)
    sd = initial.get("prior_sd", case.prior.sd)
    rivals = result.settings.get("rivals", ()) if rivals is None else rivals
    other = plausibility_warnings(
        result.constants,
        mean,
        sd,
        sd=result.sd,
        settings=result.settings,
        modes=result.modes,
        measured_Hz=measured.frequency_Hz,
        rivals=rivals,
    )
    warnings += other
    status = result.status
    if result.converged and status in ("converged", "rejected", "implausible"):
        status = "rejected" if fit.rejected else ("implausible" if other else "converged")
    return replace(result, fit=fit, warnings=tuple(warnings), status=status)


def _paired_peaks(result, frequency_Hz):
    """0-based case peak of each of the result's measured frequencies, shape (m,).

    The pairing's own when it holds (a result by likelihood whose assignment did not
    settle carries the assignment remade at its estimate, not the one it fitted); else each
    measured frequency's row in the case, found by value (the same to round-off).
    """
    f = np.asarray(frequency_Hz, dtype=float)
    fm = np.asarray(result.measured_Hz, dtype=float)
    if result.pairing is not None:
        kept = np.asarray(result.pairing.kept(f.size), dtype=int)
        if kept.shape == fm.shape and np.allclose(f[kept], fm, rtol=1e-9, atol=0.0):
            return kept
    return np.argmin(np.abs(f[None, :] - fm[:, None]), axis=1)


def _p_effective(result, case):
    """``6 - trace(P V_b^-1)`` with the estimator's ``P`` and the prior it ran with."""
    s = result.settings
    conventions = s.get("conventions")
    how = getattr(conventions, "prior", "variance")
    mean = s.get("prior_mean", case.prior.mean)
    sd = s.get("prior_sd", case.prior.sd)
    try:
        _, V_b = prior_in_stiffness(mean, sd, how)
        return effective_constants_from_covariance(result.covariance_b, V_b)
    except (np.linalg.LinAlgError, ValueError):
        return float("nan")


def _case_ref(case):
    """How to name the case to the command line: its file's path, else ``CASE``."""
    path = getattr(case, "path", None)
    return str(path) if path else "CASE"
