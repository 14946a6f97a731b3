"""Each model under its own best assignment of the same measured peaks.

Without measured shapes, which computed mode explains which peak is settled once, by B
under the nominal model (:func:`bayesplate.estimators.settle_pairing`,
``pairing="likelihood"``), or is the order (the default). A plate
with an effect the nominal model leaves out may order its modes differently: the model
that explains the recordings may explain them under another assignment. So, after a pass,
the assignment is made again (:func:`bayesplate.matching.assignment.most_probable`) at the fit the
verdict rests on; where it differs, diagnose runs a second pass with it, and the two passes are
compared on one scale: the evidence of every measured peak, paired or spurious,

``ln p(all peaks | model, a) = ln f(Y_paired | model)   (Laplace, the fits', images counted)``
``    + n_paired ln(1 - p_s) + n_spurious (ln p_s - ln lambda_B)``
``    + sum over the model's computed modes in the band [ln(1 - p_u) if observed, else ln p_u]``,

the terms of :mod:`bayesplate.matching.assignment`'s model with the pairs' Gaussian densities left
to the Laplace evidence (in eigenvalues, as the fits' data are): a spurious peak is uniform over
``[0, lambda_B]``, ``lambda_B`` the eigenvalue of the band's upper end. The pass whose
verdict model scores higher is kept (the maximum over the assignments tried, not a sum over
all of them).

By order (the default, checked), the assignment is made again at the verdict's fit: the
order stands, and the diagnosis is one pass, when that assignment pairs no peak with another
mode (peaks it calls spurious in their own place are named as outliers). Otherwise the order
is set aside and the next pass takes the assignment B settles (``settled``: what
``--pairing likelihood`` starts from), not the one made at the order's verdict fit: a fit
of wrongly paired peaks is pulled away, and from its assignment further passes went astray
(the calibration's crossply recordings with the middle peak taken out, 2026-11-27: a local
stiffness loss named, the last peak on mode 15 instead of 14, where the assignment B settles
gives `consistent` with every peak right). From there the passes go on as by likelihood, and
all of them, the order's first, are compared on the one scale.

Pure computation on fits and arrays; one full solve per fit checked; the
passes themselves are diagnose's (:func:`made_again` is handed them).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...matching.assignment import P_SPURIOUS, P_UNOBSERVED, assignment_terms, most_probable
from ...matching.pairing import Pairing
from ...quantities import eigenvalue_from_hz

__all__ = [
    "EXTRA_MODES",
    "MAX_PASSES",
    "Reassignment",
    "assignment_log_prior",
    "check",
    "fitted_assignment",
    "full_modes",
    "made_again",
    "pairing_of",
    "verdict_fit",
]

#: Computed modes beyond the highest paired one that the assignment may use.
EXTRA_MODES = 2
#: Passes of diagnose at most when the assignment is made again at each verdict's fit.
MAX_PASSES = 3


@dataclass(frozen=True)
class Reassignment:
    """The assignment made again at a fit, and how it compares with the one used.

    Attributes
    ----------
    label : str
        Which fit (``"the nominal fit"``, a candidate's name).
    used, best : numpy.ndarray of int, shape (m,)
        0-based computed mode of every measured peak (-1: spurious): the assignment the pass
        used, and the most probable one at the fit.
    """

    label: str
    used: np.ndarray
    best: np.ndarray

    @property
    def changed(self):
        """Whether the fit's own best assignment differs from the one used."""
        return not np.array_equal(self.used, self.best)

    def describe(self):
        """One sentence: the peaks whose assignment differs (1-based numbers)."""
        moved = np.flatnonzero(self.used != self.best)
        parts = [f"peak {i + 1}: {_name(self.used[i])} -> {_name(self.best[i])}" for i in moved]
        return f"under {self.label}, " + ("; ".join(parts) if parts else "the same assignment")


def _name(mode):
    return "spurious" if mode < 0 else f"mode {mode + 1}"


def full_modes(pairing, m):
    """The computed mode of every measured peak, -1 where it is left out, shape (m,)."""
    out = np.full(m, -1)
    measured = np.arange(len(pairing.modes)) if pairing.measured is None else pairing.measured
    out[measured] = pairing.modes
    return out


def pairing_of(assignment, how):
    """The :class:`Pairing` of an assignment (its spurious peaks left out)."""
    paired = assignment.paired
    measured = None if np.array_equal(paired, np.arange(assignment.modes.size)) else paired
    return Pairing(assignment.modes[paired], how=how, measured=measured, assignment=assignment)


def fitted_assignment(model, fit, measured_Hz, sigma_Hz, n_modes, prior, start=None):
    """The most probable assignment under a fit's plate, and its computed frequencies (Hz).

    :func:`bayesplate.matching.assignment.most_probable` at the fit: the plate's eigenvalues are
    linearised at the fit's constants, which are integrated out under the prior (so that a
    fit that a wrong assignment pulled away does not hold the assignment where it is), the
    fit's physics parameters held at their values.

    Parameters
    ----------
    model : PlateModel
        The nominal plate; the fit's physics, if any, is applied to it.
    fit : JointFit
    measured_Hz, sigma_Hz : numpy.ndarray, shape (m,)
        Every measured peak (the spurious ones too) and its deviation.
    n_modes : int
        Computed modes to assign from.
    prior : tuple of numpy.ndarray
        ``(mu_b, V_b)``, Pa and Pa^2.
    start : numpy.ndarray of int, shape (m,), optional
        The assignment in use, searched from as well.

    Returns
    -------
    assignment : bayesplate.matching.assignment.Assignment
    computed_Hz : numpy.ndarray, shape (n_modes,)
    """
    plate = model if fit.physics is None else fit.physics.apply(model, fit.theta)
    modal = plate.solve(fit.b, n_modes)
    mu_b, V_b = prior
    found = most_probable(
        measured_Hz, sigma_Hz, modal.eigenvalues, modal.sensitivities, fit.b, mu_b, V_b, start=start
    )
    return found, modal.frequency_Hz


def assignment_log_prior(
    modes, computed_Hz, band_Hz, p_unobserved=P_UNOBSERVED, p_spurious=P_SPURIOUS, measured_Hz=None
):
    """The assignment's terms of ``ln p(all peaks | model, a)`` (module docstring), nats.

    :func:`bayesplate.matching.assignment.assignment_terms` with the model's computed modes in the
    band and a spurious peak's range in eigenvalues.

    Parameters
    ----------
    modes : numpy.ndarray of int, shape (m,)
        0-based computed mode of every measured peak; -1 spurious.
    computed_Hz : numpy.ndarray, shape (n,)
        The model's computed frequencies at its fit, ascending, Hz.
    band_Hz : float
        Upper end of a spurious peak's range
        (:func:`bayesplate.matching.assignment.spurious_band_Hz`).
    p_unobserved, p_spurious : float
    measured_Hz : numpy.ndarray, shape (m,)
        The measured frequencies: a computed mode is in the band up to the highest of them.

    Returns
    -------
    float
    """
    in_band = np.asarray(computed_Hz, dtype=float) <= np.max(measured_Hz)
    log_band = np.log(eigenvalue_from_hz(band_Hz))  # the fits' densities are in eigenvalues
    return assignment_terms(modes, in_band, log_band, p_unobserved, p_spurious)


def check(model, fit, label, used, measured_Hz, sigma_Hz, prior):
    """The assignment at `fit` against the one `used`, and the fit's scale term.

    Parameters
    ----------
    model, fit, measured_Hz, sigma_Hz, prior
        As for :func:`fitted_assignment`.
    label : str
    used : numpy.ndarray of int, shape (m,)
        The assignment in use (:func:`full_modes`).

    Returns
    -------
    Reassignment
    log_prior : float
        :func:`assignment_log_prior` of `used` under this fit's plate.
    assignment : bayesplate.matching.assignment.Assignment
        The fit's own most probable one.
    """
    n = int(max(used.max(), len(used) - 1)) + 1 + EXTRA_MODES
    best, computed = fitted_assignment(model, fit, measured_Hz, sigma_Hz, n, prior, start=used)
    prior_terms = assignment_log_prior(used, computed, best.band_Hz, measured_Hz=measured_Hz)
    return Reassignment(label, used, best.modes), prior_terms, best


def verdict_fit(d):
    """The fit the verdict rests on, its label and its log-evidence (mirror images counted)."""
    if d.chosen is not None:
        return d.chosen.fit, d.chosen.name, d.nominal.log_evidence + d.chosen.log_evidence_gain
    return d.nominal, "the nominal fit", d.nominal.log_evidence


def made_again(first, one_pass, model, pairing, measured, prior, say, settled):
    """The assignment made again at the verdict's fit; further passes where it differs.

    A pass whose verdict fit prefers another assignment is followed by one with it, up to
    :data:`MAX_PASSES` passes (a fit a wrong assignment pulled away may need two to let go
    of it) or until an assignment comes back; the pass whose verdict fit scores higher on
    ``ln p(all peaks | model, a)`` is kept, and a note says what was done.

    Parameters
    ----------
    first : Diagnosis
        The pass with the assignment settled at the start.
    one_pass : callable
        ``one_pass(pairing) -> Diagnosis``: diagnose again with another assignment.
    model : PlateModel
    pairing : bayesplate.matching.pairing.Pairing
        The assignment of the first pass (by likelihood, or by order checked: the order then
        stands unless the assignment at the verdict's fit pairs a peak with another mode;
        peaks it only calls spurious in their own place are outliers the verdict weighs).
    measured : Measurement
        Every measured peak and its deviation (Hz); a pass's paired peaks are assigned again
        with the deviations it fitted them with (its ``sigma_Hz``: widened by the mesh's
        error, which would otherwise call the upper peaks of a coarse mesh spurious).
    prior : tuple of numpy.ndarray
        ``(mu_b, V_b)``.
    say : callable
    settled : callable or None
        ``settled() -> Pairing``: the assignment B settles (by likelihood), the next pass's
        where the order is set aside; called only then (None where ``pairing`` is not by
        order).

    Returns
    -------
    Diagnosis
        The pass kept, with a note and its ``peak_modes``.
    """
    passes, last = _passes(first, one_pass, model, pairing, measured, prior, say, settled)
    if len(passes) == 1:
        return _first_kept(first, *last)
    return _best_kept(passes, pairing, say)


def _passes(first, one_pass, model, pairing, measured, prior, say, settled):
    """The passes run, and the last check.

    Returns ``[(diagnosis, assignment used, score, Reassignment)]`` and ``(label, change,
    the fit's own assignment, the assignment used)`` of the last pass checked.
    """
    f, s = np.asarray(measured.frequency_Hz), np.asarray(measured.sigma_Hz)
    current, used = first, full_modes(pairing, f.size)
    order = pairing.how == "order"  # the null (every peak its own mode) until set aside
    passes = []
    while True:
        fit_, label, log_evidence = verdict_fit(current)
        s_pass = np.array(s)  # the deviations the pass fitted (widened by its mesh's error)
        s_pass[used >= 0] = current.sigma_Hz
        change, terms, best = check(model, fit_, label, used, f, s_pass, prior)
        passes.append((current, used, log_evidence + terms, change))
        if order:  # checked: one pass unless set aside (see the module docstring)
            if not change.changed or best.keeps_order:
                break
            order = False
            again, peaks = _set_aside(settled(), best, used, f.size)
            say(
                f"pairing by order set aside at {label}'s constants ({change.describe()}); "
                "diagnosing again by likelihood"
            )
        else:
            if (
                not change.changed
                or len(passes) == MAX_PASSES
                or any(np.array_equal(best.modes, p[1]) for p in passes)
            ):
                break
            again, peaks = pairing_of(best, "likelihood"), best.modes
            say(f"assignment made again: {change.describe()}; diagnosing again with it")
        current, used = one_pass(again), peaks
    return passes, (label, change, best, used)


def _set_aside(settled, best, used, m):
    """The next pass's pairing and peaks where the order is set aside.

    B's (``settled``), unless B settles the order itself: then the verdict fit's own, as by
    likelihood.
    """
    peaks = full_modes(settled, m)
    if np.array_equal(peaks, used):  # B settles the order: on as by likelihood
        return pairing_of(best, "likelihood"), best.modes
    return settled, peaks


def _first_kept(first, label, change, best, used):
    """The one pass kept, with its note and its ``peak_modes``."""
    note = f"assignment made again at {label}'s constants: the most probable one is the one used"
    if change.changed:  # the order kept (one pass), its outliers named
        which = ", ".join(str(i + 1) for i in best.spurious)
        note = (
            f"assignment made again at {label}'s constants: it pairs no peak with "
            f"another mode than the order's (it would call peak(s) {which} spurious: "
            "outliers of this fit, kept)"
        )
    return replace(first, notes=[*first.notes, note], peak_modes=used)


def _best_kept(passes, pairing, say):
    """The pass of the highest ``ln p(all peaks | model, a)``, with a note of them all."""
    k = int(np.argmax([p[2] for p in passes]))
    kept, peaks = passes[k][0], passes[k][1]
    story = "; ".join(
        f"pass {i + 1} ({p[0].verdict}): ln p(all peaks) {p[2]:.1f}" for i, p in enumerate(passes)
    )
    say(f"assignment: {story}; pass {k + 1} kept")
    how = (
        "pairing by order set aside at the verdict's fit ({}) and diagnosed again by likelihood"
        if pairing.how == "order"
        else "assignment made again at the verdict's fit ({}) and diagnosed with it"
    )
    note = (
        f"{how.format(passes[0][3].describe())}, {len(passes)} passes in all; {story} "
        f"(ln p(all peaks | the verdict's model, assignment)); pass {k + 1} kept (the best "
        "of these assignments, not a sum over all)"
    )
    return replace(kept, notes=[*kept.notes, note], peak_modes=peaks, passes=len(passes))
