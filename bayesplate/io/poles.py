"""Modal extraction from FRFs with sdypy-EMA: LSCF poles, the stabilisation chart, stable poles.

:func:`extract_poles` fits the poles of the FRFs of an :class:`~bayesplate.io.frf.FRFData`
with the least-squares complex frequency-domain estimator (LSCF) of ``sdypy.EMA`` for every
model order up to ``order`` and classifies them with sdypy-EMA's stabilisation test (a pole
is stable when a pole of the previous order lies within 0.1 % in frequency and within 5 %
in damping ratio, and its damping is positive). The candidate modes are the stable poles of
the highest order in the band; a candidate is kept automatically when it has been stable
over the last :data:`DEFAULT_STABLE_ORDERS` orders. :func:`modal_data_from_poles` turns the
poles one keeps into measured modes: frequencies, damping ratios and, with several response
points with coordinates, real mode shapes from sdypy-EMA's LSFD modal constants.

``sdypy.EMA`` (which imports matplotlib) is imported only when poles are extracted.
"""

from __future__ import annotations

import contextlib
import io
import math
import warnings
from dataclasses import dataclass

import numpy as np

from .errors import CaseError
from .frf import FRFData
from .modal_data import ModalData

__all__ = [
    "DEFAULT_ORDER",
    "DEFAULT_STABLE_ORDERS",
    "Pole",
    "PoleAnalysis",
    "extract_poles",
    "modal_data_from_poles",
]

DEFAULT_ORDER = 60
"""Highest LSCF model order: up to 60 pole pairs, ample for the ~10-20 modes of a tap test."""
DEFAULT_STABLE_ORDERS = 5
"""A candidate is kept automatically when stable over this many of the highest orders."""
ERR_FREQUENCY = 0.001  # sdypy-EMA's defaults for its stabilisation chart
ERR_DAMPING = 0.05
MAX_DAMPING = 0.2  # a physical bound: poles damped more than this are not plate modes


@dataclass(frozen=True)
class Pole:
    """A candidate mode: one physical pole.

    Parameters
    ----------
    frequency_Hz : float
        Undamped natural frequency ``|lambda| / 2 pi``, Hz.
    damping : float
        Viscous damping ratio ``-Re(lambda) / |lambda|``.
    orders_stable : int
        Number of consecutive highest model orders over which the pole was stable.
    keep : bool
        Whether the pole is taken into the case.
    """

    frequency_Hz: float
    damping: float
    orders_stable: int = 0
    keep: bool = True


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
        Orders of stability needed at the top for a candidate to be kept automatically.

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

        model = EMA.Model(frf=frf.frf, freq=frequency, lower=lower, upper=upper,
                          pol_order_high=order, frf_form=frf.form)  # fmt: skip
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
    return PoleAnalysis((lower, upper), orders, candidates=candidates, **rows)


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
    top = len(frequency) - 1
    found: list[Pole] = []
    pairs = zip(frequency[top][stable[top]], damping[top][stable[top]], strict=True)
    for f, z in sorted(pairs):
        if found and f - found[-1].frequency_Hz < ERR_FREQUENCY * f:
            continue  # the same pole twice (sdypy keeps near-duplicates)
        count = 0
        for row in range(top, -1, -1):
            near = np.abs(frequency[row][stable[row]] - f) < ERR_FREQUENCY * f
            if not near.any():
                break
            count += 1
        found.append(Pole(float(f), float(z), count, count >= stable_orders))
    return tuple(found)


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
    notes = frf.notes
    if frf.points_mm is None or frf.n_points < 2:
        return ModalData(frequency, damping=damping, source=frf.source, notes=notes)
    lower, upper = _band(frf.frequency_Hz, band_Hz)
    omega = 2 * np.pi * frequency
    # the poles of the data as given: an exponential window's decay added back
    lam = -damping * omega - frf.added_decay_per_s + 1j * omega * np.sqrt(1 - damping**2)
    with _quiet():
        from sdypy import EMA

        model = EMA.Model(frf=frf.frf, freq=frf.frequency_Hz, lower=lower, upper=upper,
                          pol_order_high=1, frf_form=frf.form)  # fmt: skip
        chosen = _ChosenPoles([lam], [[0, i] for i in range(lam.size)])
        _, constants = model.get_constants(whose_poles=chosen)
    shapes = np.array([_realised(np.asarray(constants)[:, i]) for i in range(lam.size)])
    return ModalData(frequency, frf.points_mm, shapes, damping, source=frf.source, notes=notes)


@dataclass
class _ChosenPoles:
    """The poles one keeps, in the shape ``sdypy.EMA.Model.get_constants`` reads them."""

    all_poles: list
    pole_ind: list
