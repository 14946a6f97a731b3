"""The band of a tap test's modal fit, from the plate sheet: where the prior puts the modes.

LSCF over a recording's whole axis (0 to half the sampling rate) meets hundreds of modes
and finds no stable pole at a usable model order. A modal analyst fits the band of the modes
wanted. :func:`prior_band_Hz` sets it from the plate sheet: the lowest ``n`` elastic modes
at the prior mean, from :data:`BAND_LOW_FACTOR` times the first (below it the suspension's
rigid-body modes) to :data:`BAND_HIGH_FACTOR` times the ``n``-th (the poles are fitted
up to :data:`FIT_HIGH_FACTOR` times it). The factor covers a
plate stiffer than its prior: frequencies go as the square root of the moduli, so 1.25
covers moduli about 1.5 times the prior mean's (two prior deviations of 25 %); a softer
plate only puts more modes in the band, which the assignment of peaks to modes handles.
"""

from __future__ import annotations

__all__ = [
    "BAND_LOW_FACTOR",
    "BAND_HIGH_FACTOR",
    "FIT_HIGH_FACTOR",
    "DEFAULT_BAND_MODES",
    "prior_band_Hz",
]

BAND_LOW_FACTOR = 0.5
"""The band starts at this fraction of the first mode at the prior mean."""
BAND_HIGH_FACTOR = 1.25
"""The band ends at this multiple of the ``n``-th mode at the prior mean."""
FIT_HIGH_FACTOR = 1.6
"""LSCF fits up to this multiple of the ``n``-th mode: the top of a fit's band is fitted less
well (the modes above it are missing), so the band's modes are taken from a wider fit. On a
synthetic tap of ten modes the largest frequency error was 0.14 % with the fit ending at 1.06
times the tenth mode, 0.05 % at 1.57 times."""
DEFAULT_BAND_MODES = 10
"""Modes wanted from a tap test by default: a one-point test sees the lowest ones best."""


def prior_band_Hz(case, n_modes: int = DEFAULT_BAND_MODES) -> tuple[float, float, float]:
    """The band (Hz) where the case's prior mean puts its lowest `n_modes` elastic modes.

    Parameters
    ----------
    case : bayesplate.io.Case
        A case or a plate sheet read as one (:func:`bayesplate.io.case_writer.sheet_case`).
    n_modes : int
        Number of elastic modes the band should hold, >= 1.

    Returns
    -------
    tuple of float
        ``(BAND_LOW_FACTOR f_1, BAND_HIGH_FACTOR f_n, FIT_HIGH_FACTOR f_n)``, Hz: the band
        and the top of the fit.
    """
    from ..laminate import stiffness_from_engineering
    from ..plate.model import PlateModel

    model = PlateModel.from_case(case)
    frequency = model.solve(stiffness_from_engineering(case.prior.mean), n_modes).frequency_Hz
    top = float(frequency[n_modes - 1])
    return BAND_LOW_FACTOR * float(frequency[0]), BAND_HIGH_FACTOR * top, FIT_HIGH_FACTOR * top
