"""Modal extraction from FRFs with sdypy-EMA: LSCF poles, the stabilisation chart, stable poles.

:func:`extract_poles` fits the poles of the FRFs of an :class:`~bayesplate.io.frf.FRFData`
with the least-squares complex frequency-domain estimator (LSCF) of ``sdypy.EMA`` for every
model order up to ``order`` and classifies them with sdypy-EMA's stabilisation test (a pole
is stable when a pole of the previous order lies within 0.1 % in frequency and within 5 %
in damping ratio, and its damping is positive). The candidate modes are the clusters of
stable poles over all orders; a candidate is kept automatically when it is stable over at
least :data:`KEEP_FRACTION` of the orders, and then carries the evidence that it is a mode
of the plate (:func:`assess_poles`: coherence, the phase and size of its modal constant,
damping, stability) and from it the prior probability that it is spurious, which the
assignment of peaks to modes weighs. :func:`modal_data_from_poles` turns the
poles one keeps into measured modes: frequencies, damping ratios and, with several response
points with coordinates, real mode shapes from sdypy-EMA's LSFD modal constants.

``sdypy.EMA`` (which imports matplotlib) is imported only when poles are extracted.
"""

from __future__ import annotations

import contextlib
import io
import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from .errors import CaseError
from .frf import FRFData
from .modal_data import ModalData

__all__ = [
    "DEFAULT_ORDER",
    "DEFAULT_STABLE_ORDERS",
    "Pole",
    "PoleAnalysis",
    "assess_poles",
    "extract_poles",
    "modal_data_from_poles",
]

DEFAULT_ORDER = 60
"""Highest LSCF model order: up to 60 pole pairs, ample for the ~10-20 modes of a tap test."""
DEFAULT_STABLE_ORDERS = 5
"""A candidate is kept automatically when stable over at least this many orders ..."""
KEEP_FRACTION = 0.3
"""... and over at least this fraction of them."""
ERR_FREQUENCY = 0.001  # sdypy-EMA's defaults for its stabilisation chart
ERR_DAMPING = 0.05
MAX_DAMPING = 0.2  # a physical bound: poles damped more than this are not plate modes


@dataclass(frozen=True)
class Pole:
    """A candidate mode: one physical pole, with the evidence that it is a mode of the plate.

    Parameters
    ----------
    frequency_Hz : float
        Undamped natural frequency ``|lambda| / 2 pi``, Hz.
    damping : float
        Viscous damping ratio ``-Re(lambda) / |lambda|``.
    orders_stable : int
        Number of model orders over which the pole was stable.
    keep : bool
        Whether the pole is taken into the case.
    coherence : float
        Lowest coherence in the pole's half-power band (NaN without a force channel).
    phase_deviation_deg : float
        Deviation of its modal constant from the line of the candidates' modal constants,
        degrees in [0, 90] (NaN where not fitted).
    amplitude : float
        Magnitude of its modal constant relative to the candidates' median (NaN where not
        fitted).
    p_spurious : float
        Prior probability that it is no mode of the plate
        (:func:`bayesplate.matching.peak_prior.spurious_probability`; NaN where not assessed).
    spread_Hz : float
        Standard deviation of its frequency over the model orders it is stable in, Hz
        (1.4826 times the median absolute deviation: a robust spread); NaN where unknown.
    """

    frequency_Hz: float
    damping: float
    orders_stable: int = 0
    keep: bool = True
    coherence: float = math.nan
    phase_deviation_deg: float = math.nan
    amplitude: float = math.nan
    p_spurious: float = math.nan
    spread_Hz: float = math.nan


@dataclass(frozen=True, eq=False)
class PoleAnalysis:
    """The LSCF poles of all model orders, classified, and the candidate modes.

    Parameters
    ----------
    band_Hz : tuple of float
        (lower, upper) frequency band of the fit, Hz.
    orders : numpy.ndarray of int, shape (k,)
        Model order (pole pairs) of each chart row.
    frequency_Hz, damping : list of numpy.ndarray
        Per model order, the frequency (Hz) and damping ratio of each pole in the band.
    stable_frequency, stable : list of numpy.ndarray of bool
        Per model order and pole: stable in frequency; stable in frequency and damping.
    candidates : tuple of Pole
        Stable poles of the highest order, ascending in frequency, ``keep`` set for those
        stable over the last orders.
    """

    band_Hz: tuple[float, float]
    orders: np.ndarray
    frequency_Hz: list
    damping: list
    stable_frequency: list
    stable: list
    candidates: tuple[Pole, ...]

    @property
    def kept(self) -> tuple[Pole, ...]:
        """The candidates kept automatically."""
        return tuple(pole for pole in self.candidates if pole.keep)


def extract_poles(
    frf: FRFData,
    band_Hz=None,
    order: int = DEFAULT_ORDER,
    stable_orders: int = DEFAULT_STABLE_ORDERS,
    keep_below_Hz: float | None = None,
) -> PoleAnalysis:
    """LSCF poles of every model order up to `order`, classified by stability.

    Parameters
    ----------
    frf : FRFData
        The spectra; an exponential window's added decay is removed from every pole.
    band_Hz : tuple of float, optional
        (lower, upper) band of the fit, Hz; default the whole axis above 0 Hz.
    order : int
        Highest model order (sdypy-EMA's ``pol_order_high``).
    stable_orders : int
        Orders of stability needed for a candidate to be kept automatically.
    keep_below_Hz : float, optional
        Keep no candidate above this frequency: the band's top is fitted less well (the
        modes above it are missing from the fit), so a band wider than the modes wanted
        gives them more accurately.

    Returns
    -------
    PoleAnalysis

    Raises
    ------
    CaseError
        For a band outside the data or an order too high or too low for the data.
    """
    frequency = frf.frequency_Hz
    lower, upper = _band(frequency, band_Hz)
    lines = int(np.count_nonzero((frequency >= lower) & (frequency <= upper)))
    if not (isinstance(order, int) and stable_orders + 2 <= order <= lines // 4):
        rule = f"must be an integer from {stable_orders + 2} to {lines // 4} (a quarter of the "
        raise CaseError("--order", order, rule + f"{lines} frequency lines in the band)")
    with _quiet():
        from sdypy import EMA
        from sdypy.EMA import stabilization

        model = EMA.Model(
            frf=frf.frf,
            freq=frequency,
            lower=lower,
            upper=upper,
            pol_order_high=order,
            frf_form=frf.form,
        )
        model.get_poles(method="lscf", show_progress=False)
        poles = [p + frf.added_decay_per_s for p in model.all_poles]
        fn, xi, test_fn, test_xi = stabilization._stabilization(
            poles, order, err_fn=ERR_FREQUENCY, err_xi=ERR_DAMPING
        )
    # sdypy-EMA's chart: column c holds the poles of all_poles[c + 1] (c + 2 pole pairs),
    # compared with those of the order below; its last column is its first order: dropped.
    stable_f = test_fn > 0
    stable = stable_f & (test_xi > 0) & (xi > 0) & (xi < MAX_DAMPING)
    rows = dict(frequency_Hz=[], damping=[], stable_frequency=[], stable=[])
    for c in range(order - 1):
        inside = (fn[:, c] >= lower) & (fn[:, c] <= upper)
        for name, values in zip(rows, (fn, xi, stable_f, stable), strict=True):
            rows[name].append(values[inside, c])
    orders = np.arange(2, order + 1)
    candidates = _candidates(rows["frequency_Hz"], rows["damping"], rows["stable"], stable_orders)
    if keep_below_Hz is not None:
        candidates = tuple(
            replace(pole, keep=pole.keep and pole.frequency_Hz <= keep_below_Hz)
            for pole in candidates
        )
    analysis = PoleAnalysis((lower, upper), orders, candidates=candidates, **rows)
    return assess_poles(frf, analysis)


@contextlib.contextmanager
def _quiet():
    """Silence sdypy-EMA's progress bars (stderr), prints and numerical warnings."""
    with (
        contextlib.redirect_stderr(io.StringIO()),
        contextlib.redirect_stdout(io.StringIO()),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        yield


def _band(frequency: np.ndarray, band_Hz) -> tuple[float, float]:
    positive = frequency[frequency > 0]
    if band_Hz is None:
        return float(positive[0]), float(frequency[-1])
    lower, upper = (float(v) for v in band_Hz)
    if not (math.isfinite(lower) and math.isfinite(upper) and 0 < lower < upper):
        raise CaseError("--band", [lower, upper], "must be two frequencies 0 < lower < upper (Hz)")
    if lower < positive[0] or upper > frequency[-1]:
        rule = f"must lie within the data's {positive[0]:g} to {frequency[-1]:g} Hz"
        raise CaseError("--band", [lower, upper], rule)
    return lower, upper


def _candidates(frequency, damping, stable, stable_orders: int) -> tuple[Pole, ...]:
    """The clusters of stable poles over all model orders, ascending in frequency.

    Stable poles of every order, sorted by frequency, are chained where neighbours lie
    within :data:`ERR_FREQUENCY` of each other; a cluster is one physical pole, stable over
    as many orders as it has members in, taken at its member of the highest order (the
    lower orders' poles are biased by the modes they cannot fit yet), its spread that of
    its members in the upper half of its orders. It is kept when that is at least
    :data:`KEEP_FRACTION` of the orders (and `stable_orders`): a pole that only the
    highest orders find, or that comes and goes, is more often a computational one than a
    mode.
    """
    f = np.concatenate([row[ok] for row, ok in zip(frequency, stable, strict=True)])
    z = np.concatenate([row[ok] for row, ok in zip(damping, stable, strict=True)])
    order = np.concatenate([np.full(np.count_nonzero(ok), k) for k, ok in enumerate(stable)])
    if f.size == 0:
        return ()
    by_f = np.argsort(f, kind="stable")
    f, z, order = f[by_f], z[by_f], order[by_f]
    breaks = np.flatnonzero(np.diff(f) >= ERR_FREQUENCY * f[1:]) + 1
    needed = max(stable_orders, math.ceil(KEEP_FRACTION * len(frequency)))
    found = []
    for members in np.split(np.arange(f.size), breaks):
        count = int(np.unique(order[members]).size)
        top = members[order[members] == order[members].max()]
        best = top[np.argmin(np.abs(f[top] - np.median(f[members])))]
        upper = members[order[members] >= np.median(order[members])]
        spread = 1.4826 * float(np.median(np.abs(f[upper] - np.median(f[upper]))))
        pole = Pole(float(f[best]), float(z[best]), count, count >= needed, spread_Hz=spread)
        found.append(pole)
    return tuple(found)


def assess_poles(frf: FRFData, analysis: PoleAnalysis) -> PoleAnalysis:
    """The analysis with each kept candidate's evidence and its prior of being spurious.

    For the kept candidates: the lowest coherence in the half-power band (at least two
    lines each side), the modal constants of an LSFD fit with exactly these poles at the
    response point where each is strongest (their magnitude against the median, their
    phase against the candidates' common line, weighted by magnitude), the fraction of
    model orders each was stable over, and from these
    :func:`bayesplate.matching.peak_prior.spurious_probability`.

    Parameters
    ----------
    frf : FRFData
    analysis : PoleAnalysis

    Returns
    -------
    PoleAnalysis
        The same, the kept candidates with their evidence filled in.
    """
    from ..matching.peak_prior import spurious_probability

    kept = analysis.kept
    if not kept:
        return analysis
    coherence = np.array([_coherence_near(frf, pole) for pole in kept])
    residues = _residues(frf, kept, analysis.band_Hz)  # (p, k)
    strongest = residues[np.argmax(np.abs(residues), axis=0), np.arange(len(kept))]
    magnitude = np.abs(strongest)
    amplitude = magnitude / np.median(magnitude)
    deviation = _phase_deviation_deg(strongest)
    fraction = np.array([pole.orders_stable for pole in kept]) / len(analysis.orders)
    damping = np.array([pole.damping for pole in kept])
    p = spurious_probability(deviation, coherence, damping, fraction, amplitude)
    assessed = iter(
        replace(
            pole,
            coherence=float(c),
            phase_deviation_deg=float(d),
            amplitude=float(a),
            p_spurious=float(ps),
        )
        for pole, c, d, a, ps in zip(kept, coherence, deviation, amplitude, p, strict=True)
    )
    candidates = tuple(next(assessed) if pole.keep else pole for pole in analysis.candidates)
    return replace(analysis, candidates=candidates)


def _coherence_near(frf: FRFData, pole: Pole) -> float:
    """Lowest coherence within the pole's half-power band (two lines at least), NaN without."""
    if frf.coherence is None:
        return math.nan
    axis = frf.frequency_Hz
    half = max(pole.damping * pole.frequency_Hz, 2.0 * (axis[1] - axis[0]))
    near = (axis >= pole.frequency_Hz - half) & (axis <= pole.frequency_Hz + half)
    line = int(np.argmin(np.abs(axis - pole.frequency_Hz)))
    point = int(np.argmax(np.abs(frf.frf[:, line])))
    return float(np.min(frf.coherence[point, near]))


def _residues(frf: FRFData, poles, band_Hz) -> np.ndarray:
    """Modal constants (p, k) of an LSFD fit with exactly `poles` (sdypy-EMA)."""
    lower, upper = _band(frf.frequency_Hz, band_Hz)
    damping = np.array([pole.damping for pole in poles])
    omega = 2 * np.pi * np.array([pole.frequency_Hz for pole in poles])
    # the poles of the data as given: an exponential window's decay added back
    lam = -damping * omega - frf.added_decay_per_s + 1j * omega * np.sqrt(1 - damping**2)
    with _quiet():
        from sdypy import EMA

        model = EMA.Model(
            frf=frf.frf,
            freq=frf.frequency_Hz,
            lower=lower,
            upper=upper,
            pol_order_high=1,
            frf_form=frf.form,
        )
        chosen = _ChosenPoles([lam], [[0, i] for i in range(lam.size)])
        _, constants = model.get_constants(whose_poles=chosen)
    return np.asarray(constants).reshape(frf.n_points, lam.size)


def _phase_deviation_deg(residues: np.ndarray) -> np.ndarray:
    """Each residue's angle from their common line through 0 (axial mean, |r|-weighted), deg."""
    axis = 0.5 * np.angle(np.sum(np.abs(residues) * np.exp(2j * np.angle(residues))))
    off = np.angle(residues * np.exp(-1j * axis))  # in (-pi, pi]
    return np.degrees(np.abs(np.arctan(np.tan(off))))  # folded to [0, 90]


def modal_data_from_poles(frf: FRFData, poles, band_Hz=None) -> ModalData:
    """Measured modes from the poles one keeps, with shapes when the FRFs allow.

    Shapes are the modal constants of sdypy-EMA's LSFD fit of the FRFs with exactly these
    poles (lower and upper residuals), one complex value per response point, turned real by
    the rotation to the dominant phase (:func:`bayesplate.io.uff._realised`). They need at
    least two response points with coordinates; otherwise only frequencies are returned.

    Parameters
    ----------
    frf : FRFData
    poles : sequence of Pole
        The poles to keep (their ``keep`` flag is not looked at), any order.
    band_Hz : tuple of float, optional
        Band of the LSFD fit, Hz; default the whole axis above 0 Hz.

    Returns
    -------
    ModalData
        Modes ascending in frequency, with damping ratios.
    """
    from .uff import _realised

    poles = sorted(poles, key=lambda pole: pole.frequency_Hz)
    frequency = np.array([pole.frequency_Hz for pole in poles])
    damping = np.array([pole.damping for pole in poles])
    evidence = _evidence(poles)
    notes = frf.notes
    if frf.points_mm is None or frf.n_points < 2:
        return ModalData(frequency, damping=damping, source=frf.source, notes=notes, **evidence)
    constants = _residues(frf, poles, band_Hz)
    shapes = np.array([_realised(constants[:, i]) for i in range(len(poles))])
    return ModalData(
        frequency, frf.points_mm, shapes, damping, source=frf.source, notes=notes, **evidence
    )


def _evidence(poles) -> dict:
    """``p_spurious`` and ``spread_Hz`` of ModalData, where every pole has them."""
    p = np.array([pole.p_spurious for pole in poles])
    spread = np.array([pole.spread_Hz for pole in poles])
    return {
        "p_spurious": None if np.isnan(p).any() else p,
        "spread_Hz": None if np.isnan(spread).any() else spread,
    }


@dataclass
class _ChosenPoles:
    """The poles one keeps, in the shape ``sdypy.EMA.Model.get_constants`` reads them."""

    all_poles: list
    pole_ind: list
