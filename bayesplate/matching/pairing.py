"""Which computed mode goes with which measured one.

The paper pairs the i-th measured frequency with the i-th computed elastic mode (by order).
A case file may instead name the 1-based elastic mode of each measured frequency
(``measured.mode``). When it carries measured mode shapes (``points_mm`` and ``shapes``),
:func:`pair_measured` pairs by shape and frequency together: the computed ``w`` at the
measurement points against every measured shape (MAC), scored with the frequency residual
(:func:`bayesplate.matching.assignment.assign_with_shapes`), one-to-one by the Hungarian method over
more computed modes than measured, so that a mode missing from the test or an extra one is
tolerated; a measured mode that no computed mode resembles is left unpaired and dropped.
Without shapes or mode numbers the default is pairing by order, the paper's, *checked*
(:func:`checks_order`): the most probable assignment of frequencies
(:mod:`bayesplate.matching.assignment`) is made again at the answer, and where it is not the order
(a mode the test missed, a spurious peak) the answer is made by that assignment instead
(:mod:`bayesplate.matching.checked_order`);
the assignment by likelihood throughout is an option. While an
estimator iterates, the computed modes can change order
(two close frequencies cross); :func:`track` follows them from one iterate to the next by the
modal assurance criterion (MAC) of successive eigenvectors.

All functions are pure; :class:`Pairing` is a small immutable record. Mode numbers are
0-based computed elastic modes throughout the code (1-based only in case files and output).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..plate.forward import ForwardModel
from ..quantities import stiffness_covariance
from .assignment import MAC_SCALE, assign_with_shapes, most_probable, predictive_sd_Hz
from .peak_prior import assignment_priors

__all__ = [
    "DEFAULT_EXTRA_MODES",
    "DEFAULT_MAC_THRESHOLD",
    "MAC_EXTRA_MODES",
    "PAIRINGS",
    "NEGLIGIBLE_SHAPE",
    "Pairing",
    "UnpairedModeWarning",
    "mac_matrix",
    "pair_by_order",
    "pair_by_index",
    "assign_by_mac",
    "track",
    "pair_measured",
    "resolve_pairing",
    "shape_mac",
]

#: Computed modes beyond the highest paired one, so that a tracked mode can move up.
DEFAULT_EXTRA_MODES = 2
#: MAC below which a measured shape is taken to match no computed mode: less than half of
#: the measured shape's variance over the points is explained by the computed one. Noisy
#: shapes at a few points rarely reach the 0.9 of a clean match, but a different mode
#: rarely reaches 0.5 once the assignment is one-to-one.
DEFAULT_MAC_THRESHOLD = 0.5
#: Computed modes beyond the measured ones offered to the MAC assignment (missing modes).
MAC_EXTRA_MODES = 6
#: The pairings :func:`pair_measured` knows.
PAIRINGS = ("auto", "mac", "likelihood", "index", "order")
#: Squared norm, relative to the largest of its set, below which a shape counts as zero in
#: the MAC (a norm ratio of 1e-6: measurement noise is far above it, solver round-off on a
#: quantity that is zero in exact arithmetic, about 1e-12 of the norm, far below).
NEGLIGIBLE_SHAPE = 1e-12


class UnpairedModeWarning(UserWarning):
    """A measured mode matches no computed mode by shape and is left out of the fit."""


def mac_matrix(A, B, weight=None, negligible=NEGLIGIBLE_SHAPE):
    """Modal assurance criterion between two sets of vectors.

    ``MAC_ij = (a_i^T W b_j)^2 / ((a_i^T W a_i) (b_j^T W b_j))``.

    A vector with no content is like no other: its MAC is 0. "No content" is judged
    relative to its own set, ``a_i^T W a_i <= negligible * max_k a_k^T W a_k``, because a
    quantity that is zero in exact arithmetic (``w`` of an in-plane mode, about 1e-11 of a
    bending mode's) comes out of a solver as round-off, and its MAC, once normalised, would
    be round-off too: different on another CPU, and able to win an assignment.

    Parameters
    ----------
    A : array_like, shape (n, p)
        One vector per column.
    B : array_like, shape (n, q)
    weight : array_like or sparse matrix, shape (n, n), optional
        ``W``, e.g. the mass matrix; identity when None.
    negligible : float
        Squared norm, relative to the largest of the same set, at or below which a vector
        counts as zero.

    Returns
    -------
    numpy.ndarray, shape (p, q)
        Entries in [0, 1]; exactly 0 against a vector with no content.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    WB = B if weight is None else weight @ B
    WA = A if weight is None else weight @ A
    cross = A.T @ WB
    na = _significant(np.einsum("ij,ij->j", A, WA), negligible)
    nb = _significant(np.einsum("ij,ij->j", B, WB), negligible)
    norms = np.outer(na, nb)
    return np.divide(cross**2, norms, out=np.zeros_like(norms), where=norms > 0)


def _significant(squared_norms, negligible):
    """Squared norms with those at or below `negligible` x the largest set to 0."""
    squared_norms = np.asarray(squared_norms, dtype=float)
    if squared_norms.size == 0:
        return squared_norms
    floor = negligible * np.max(squared_norms)
    return np.where(squared_norms > floor, squared_norms, 0.0)


def pair_by_order(m):
    """Measured frequency i goes with computed elastic mode i: ``arange(m)``."""
    return np.arange(int(m))


def pair_by_index(mode):
    """0-based computed modes from the case file's 1-based ``measured.mode`` indices."""
    mode = np.asarray(mode, dtype=int)
    if mode.ndim != 1 or np.any(mode < 1):
        raise ValueError(f"mode = {mode}: must be 1-based elastic mode numbers")
    return mode - 1


def assign_by_mac(mac, threshold=0.0):
    """One-to-one assignment of rows to columns maximising the total MAC (Hungarian).

    Parameters
    ----------
    mac : array_like, shape (p, q)
        E.g. measured shapes (rows) against computed modes (columns).
    threshold : float
        Pairs with a MAC below this are left unassigned.

    Returns
    -------
    numpy.ndarray of int, shape (p,)
        Column assigned to each row, -1 where none reaches `threshold` (or p > q).
    """
    mac = np.asarray(mac, dtype=float)
    rows, cols = linear_sum_assignment(mac, maximize=True)
    out = np.full(mac.shape[0], -1)
    keep = mac[rows, cols] >= threshold
    out[rows[keep]] = cols[keep]
    return out


def track(prev_vectors, vectors, modes, weight=None):
    """Follow paired modes from one iterate to the next by MAC.

    Parameters
    ----------
    prev_vectors : array_like, shape (n, q0)
        Eigenvectors at the previous iterate (all computed modes).
    vectors : array_like, shape (n, q)
        Eigenvectors at the current iterate.
    modes : array_like of int, shape (m,)
        0-based previous mode of each measured frequency.
    weight : array_like or sparse matrix, shape (n, n), optional
        MAC weight (the mass matrix); plain MAC when None.

    Returns
    -------
    new_modes : numpy.ndarray of int, shape (m,)
        Current mode most like each previously paired one (one-to-one).
    mac : numpy.ndarray, shape (m,)
        The MAC of each match.
    """
    modes = np.asarray(modes, dtype=int)
    mac = mac_matrix(np.asarray(prev_vectors)[:, modes], vectors, weight)
    new = assign_by_mac(mac)
    return new, mac[np.arange(len(modes)), new]


@dataclass(frozen=True)
class Pairing:
    """The computed mode of each measured frequency.

    Parameters
    ----------
    modes : array_like of int, shape (k,)
        0-based computed elastic mode of each paired measured frequency.
    how : str
        ``"order"``, ``"index"`` or ``"mac"``, for messages.
    extra : int
        Modes computed beyond the highest paired one (room for tracking).
    measured : array_like of int, shape (k,), optional
        0-based measured frequencies that are paired, in the order of `modes`; None when
        all ``k = m`` of them are, in order. The others are left out of the fit.
    mac : array_like, shape (m, q), optional
        MAC of every measured shape against every computed mode (``how == "mac"``).
    threshold : float, optional
        The MAC a pair had to reach.
    assignment : bayesplate.matching.assignment.Assignment, optional
        ``how`` "likelihood" or "mac": the assignment it came from (unobserved modes,
        spurious peaks, its log-probability).
    """

    modes: np.ndarray
    how: str = "order"
    extra: int = DEFAULT_EXTRA_MODES
    measured: np.ndarray | None = None
    mac: np.ndarray | None = field(default=None, repr=False)
    threshold: float | None = None
    assignment: object = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        for name in ("modes", "measured"):
            value = getattr(self, name)
            if value is not None:
                value = np.array(value, dtype=int)
                value.setflags(write=False)
                object.__setattr__(self, name, value)
        if self.measured is not None and self.measured.shape != self.modes.shape:
            raise ValueError("Pairing: `measured` needs one entry per paired mode")
        if self.mac is not None:
            mac = np.array(self.mac, dtype=float)
            mac.setflags(write=False)
            object.__setattr__(self, "mac", mac)

    @classmethod
    def from_measurement(cls, measured, how="auto", extra=DEFAULT_EXTRA_MODES):
        """Pairing of a :class:`bayesplate.io.Measurement` by order or mode index.

        Parameters
        ----------
        measured : Measurement
        how : {"auto", "order", "index"}
            ``"auto"`` uses the case's mode indices when it has them, else the order.
        extra : int

        Returns
        -------
        Pairing
        """
        if how not in ("auto", "order", "index"):
            raise ValueError(f"pairing = {how!r}: must be 'auto', 'order' or 'index'")
        if how == "auto":
            how = "order" if measured.mode is None else "index"
        if how == "index":
            if measured.mode is None:
                raise ValueError("pairing = 'index' needs measured.mode in the case file")
            return cls(pair_by_index(measured.mode), "index", extra)
        return cls(pair_by_order(measured.size), "order", extra)

    def n_modes(self, modes=None):
        """Computed modes needed for `modes` (default the pairing's own), with the extra."""
        modes = self.modes if modes is None else np.asarray(modes)
        return int(np.max(modes)) + 1 + self.extra

    def kept(self, m):
        """0-based measured frequencies that are paired, out of `m`, shape (k,)."""
        return np.arange(int(m)) if self.measured is None else self.measured

    def unpaired(self, m):
        """0-based measured frequencies left out (no computed mode matched), shape (m - k,)."""
        return np.setdiff1d(np.arange(int(m)), self.kept(m))

    def select(self, measurement):
        """The :class:`bayesplate.io.Measurement` restricted to the paired frequencies.

        The frequencies keep their measured order, so the pairing's `modes` must then be in
        the order of ``measured`` (always so for :func:`pair_measured`).
        """
        return measurement if self.measured is None else measurement.select(self.measured)

    def describe(self, m=None):
        """One sentence on how the modes were paired, for reports and messages."""
        m = self.modes.size if m is None and self.measured is None else m
        if self.how == "order":
            text = "by order: the i-th measured frequency with the i-th computed elastic mode"
            if self.assignment is not None:
                text += " (checked: the most probable assignment of the frequencies)"
        elif self.how == "index":
            text = "by the mode numbers the case file gives (measured.mode)"
        elif self.how == "likelihood":
            text = (
                "by the most probable assignment of frequencies (a computed mode may go "
                "unobserved, a peak may be spurious)"
            )
            if self.assignment is not None:
                text += f": {self.assignment.describe()}"
                return text
        else:
            p = self.mac.shape[1] if self.mac is not None else "?"
            text = (
                f"by mode shape and frequency: MAC of the measured shapes against {p} computed "
                f"modes with the frequency residuals, one-to-one (Hungarian), pairs below MAC "
                f"{self.threshold:g} rejected"
            )
            missed = [] if self.assignment is None else self.assignment.unobserved
            if len(missed):
                which = "mode" if len(missed) == 1 else "modes"
                text += f"; computed {which} {', '.join(str(j + 1) for j in missed)} unobserved"
        lost = [] if m is None else [str(i + 1) for i in self.unpaired(m)]
        if lost:
            which = "mode" if len(lost) == 1 else "modes"
            text += f"; measured {which} {', '.join(lost)} unpaired and left out of the fit"
        return text


def resolve_pairing(measured, how="auto"):
    """The pairing a name stands for, for a measurement.

    Parameters
    ----------
    measured : bayesplate.io.Measurement
    how : {"auto", "mac", "likelihood", "index", "order"}
        ``"auto"``: by shape and frequency (MAC) when the measurement has shapes, else by its
        mode numbers when it has them, else by order (the paper's), which the estimators,
        the sampler and diagnose check at their answer
        (:func:`bayesplate.matching.checked_order.checks_order`).
        ``"likelihood"`` (the most probable assignment of frequencies made before the fit)
        is chosen by name, or by default for a measurement that carries each peak's
        ``p_spurious`` (a tap test imported with its poles' evidence, where spurious peaks
        and missed modes are expected): as the default for every measurement it let
        diagnose explain concealed defects away as missed modes and spurious peaks.

    Returns
    -------
    str
        One of ``"mac"``, ``"likelihood"``, ``"index"``, ``"order"``.
    """
    if how not in PAIRINGS:
        raise ValueError(f"pairing = {how!r}: must be one of {PAIRINGS}")
    if how != "auto":
        return how
    if measured.shapes is not None and measured.points is not None:
        return "mac"
    if measured.mode is not None:
        return "index"
    return "order" if getattr(measured, "p_spurious", None) is None else "likelihood"


def shape_mac(measurement, model, vectors):
    """MAC of measured shapes against computed modes at the measurement points.

    Parameters
    ----------
    measurement : bayesplate.io.Measurement
        With ``points`` (p, 2) in m and ``shapes`` (m, p).
    model : bayesplate.plate.model.PlateModel
        Evaluates ``w`` at the points (:meth:`~bayesplate.plate.model.PlateModel.interpolation`).
    vectors : array_like, shape (n_dofs, q)
        Computed mode shapes on all unknowns.

    Returns
    -------
    numpy.ndarray, shape (m, q)
        Entries in [0, 1]; rows measured modes, columns computed ones.
    """
    if measurement.shapes is None or measurement.points is None:
        raise ValueError("MAC pairing needs measured.points_mm and measured.shapes")
    w = model.interpolation(measurement.points, "w") @ np.asarray(vectors)
    return mac_matrix(np.asarray(measurement.shapes, dtype=float).T, w)


def pair_measured(
    case,
    model: ForwardModel,
    b,
    how="auto",
    threshold=DEFAULT_MAC_THRESHOLD,
    extra_modes=MAC_EXTRA_MODES,
    modal=None,
    prior=None,
    start=None,
):
    """Pair a case's measured modes with computed ones: by shape when it has shapes.

    Parameters
    ----------
    case : bayesplate.io.Case
    model : bayesplate.plate.model.PlateModel
        Used for ``how`` "mac" and "likelihood" (one eigen solve at `b`, unless `modal` is
        given).
    b : array_like, shape (6,)
        Stiffness coefficients at which to compute the modes (e.g. the prior mean), Pa.
    how : {"auto", "mac", "likelihood", "index", "order"}
        ``"auto"``: by shape and frequency ("mac") when the case carries measured shapes,
        else by the case's mode numbers when it has them, else by order (see
        :func:`resolve_pairing`). ``"mac"``: the assignment maximising the MAC-and-frequency
        score of :func:`bayesplate.matching.assignment.assign_with_shapes` (``s_MAC`` =
        :data:`bayesplate.matching.assignment.MAC_SCALE`). ``"likelihood"``: by frequency, the most
        probable assignment of :func:`bayesplate.matching.assignment.most_probable` (a computed mode
        may go unobserved, a measured peak may be spurious and is then left out).
    threshold : float
        Smallest MAC of an allowed pair; a measured mode that pairs with no computed mode
        (every MAC below it, or more probably spurious) is left unpaired (with an
        :class:`UnpairedModeWarning`).
    extra_modes : int
        Computed modes offered beyond the number measured (``m + extra_modes`` in all), so
        that modes missing from the test do not force wrong pairs.
    modal : ModalResult, optional
        Modes already computed at `b` (at least ``m + extra_modes`` of them to be safe).
    prior : tuple of array_like, optional
        ``(mu_b, V_b)``, the prior mean (Pa) and covariance (Pa^2) of ``b``: the constants'
        uncertainty that :func:`bayesplate.matching.assignment.most_probable` integrates over
        ("likelihood") and that sets the computed frequencies' predictive deviations
        ("mac"); default ``b`` and the covariance of the case's prior (first order).
    start : Pairing, optional
        ``how == "likelihood"``: a pairing in use (an assignment, or a fixed pairing such as
        by order), searched from as well.

    Returns
    -------
    Pairing
        With ``measured`` (the paired measured frequencies) and ``mac`` (the matrix the
        assignment used) for ``how == "mac"``.
    """
    measured = case.measured
    how = resolve_pairing(measured, how)
    m = measured.size
    if how not in ("likelihood", "mac"):
        return Pairing.from_measurement(measured, how)
    if prior is None:
        cov_e = np.diag(np.asarray(case.prior.sd, dtype=float) ** 2)
        prior = (np.asarray(b, dtype=float), stiffness_covariance(case.prior.mean, cov_e))
    if how == "likelihood":
        return _pair_by_likelihood(measured, model, b, extra_modes, modal, prior, start)
    if modal is None:
        modal = model.solve(np.asarray(b, dtype=float), m + int(extra_modes))
    mac = shape_mac(measured, model, modal.vectors)
    computed_Hz = modal.frequency_Hz
    spread = predictive_sd_Hz(computed_Hz, modal.sensitivities, prior[1])
    a = assign_with_shapes(
        measured.frequency_Hz, measured.sigma_Hz, computed_Hz, spread, mac, threshold, MAC_SCALE
    )
    assigned = a.modes
    kept = a.paired
    empty = _significant(np.sum(np.asarray(measured.shapes, float) ** 2, axis=1), NEGLIGIBLE_SHAPE)
    for i in a.spurious:
        why = (
            "its shape has no transverse amplitude at the points (an in-plane mode?)"
            if empty[i] == 0
            else f"best MAC {mac[i].max():.2f} < {threshold:g}"
            if mac[i].max() < threshold
            else "more probably a spurious peak, its frequency far from every mode it resembles"
        )
        warnings.warn(
            f"measured mode {i + 1} ({measured.frequency_Hz[i]:.6g} Hz) matches no computed "
            f"mode by shape ({why}): left out of the fit",
            UnpairedModeWarning,
            stacklevel=2,
        )
    if kept.size == 0:
        raise ValueError("MAC pairing: no measured shape matches a computed mode")
    return Pairing(assigned[kept], "mac", DEFAULT_EXTRA_MODES, kept, mac, float(threshold), a)


def _tap_amplitude(measured, model, modal, n):
    """``|phi_j(tap) phi_j(sensor)|`` of the `n` modes, or None without the points."""
    points = getattr(measured, "tap_points", None)
    if points is None or not hasattr(model, "interpolation") or modal.vectors is None:
        return None
    w = np.asarray(model.interpolation(points, "w") @ modal.vectors[:, :n])
    return np.abs(w[0] * w[1])


def _pair_by_likelihood(measured, model, b, extra_modes, modal, prior, start):
    """:func:`pair_measured` by the most probable assignment of frequencies."""
    m = measured.size
    b = np.asarray(b, dtype=float)
    n = m + int(extra_modes)
    if modal is None:
        modal = model.solve(b, n)
    mu_b, V_b = prior
    initial = None
    if start is not None and start.assignment is not None:
        initial = start.assignment.modes
    elif start is not None:  # a fixed pairing (by order, say): its peaks' modes, -1 left out
        initial = np.full(m, -1)
        initial[start.kept(m)] = start.modes
    a = most_probable(
        measured.frequency_Hz,
        measured.sigma_Hz,
        modal.eigenvalues[:n],
        modal.sensitivities[:n],
        b,
        mu_b,
        V_b,
        *assignment_priors(measured, n, _tap_amplitude(measured, model, modal, n)),
        start=initial,
    )
    kept = a.paired
    if kept.size == 0:
        raise ValueError("assignment: no measured frequency matches a computed mode")
    return Pairing(a.modes[kept], "likelihood", DEFAULT_EXTRA_MODES, kept, assignment=a)
