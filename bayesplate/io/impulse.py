"""An impulse recording (ASTM E1876-style tap) as a spectrum: WAV or CSV time series in, FRF out.

A tap test records the decaying response of the plate to a light impact (microphone or
accelerometer), optionally with the force of an instrumented hammer. :func:`read_impulse`
reads it and :func:`impulse_spectrum` turns it into an :class:`~bayesplate.io.frf.FRFData`
of one response point:

- with a force channel, ``H1 = conj(F) Y / conj(F) F`` (one record: ``Y / F``);
- without, the response spectrum ``Y`` alone (an ideal tap has a flat force spectrum, so
  ``Y`` has the poles of the FRF).

Window (``window="auto"``): none when the response has died out in the record (its last
5 % below 1 % of the peak magnitude): the FFT of a fully decayed response is the exact
sampled spectrum, no leakage. Otherwise an exponential window ``exp(-t / tau)`` that falls
to 1 % at the end of the record, which forces the decay and adds ``1 / tau`` to every
pole's decay rate; :attr:`FRFData.added_decay_per_s` carries it and the pole estimates are
corrected by it (the usual correction for exponential windows).
"""

from __future__ import annotations

import math
import os

import numpy as np

from .errors import CaseError
from .frf import FRFData

__all__ = ["read_impulse", "impulse_spectrum", "time_window", "WINDOWS"]

WINDOWS = ("auto", "none", "exponential")
"""Windows :func:`impulse_spectrum` knows."""

_TAIL = 0.05  # fraction of the record that must have decayed for no window
_DECAYED = 0.01  # ... below this fraction of the peak; also the exponential window's end value


def read_impulse(path, window: str = "auto", force_channel="auto", channel=None,
                 points=None) -> FRFData:  # fmt: skip
    """Read an impulse recording (``.wav`` or a CSV time series) and return its spectrum.

    WAV (scipy.io.wavfile, any sample format): one channel, the response; two, the response
    then the force (channels 0 and 1); more, see :mod:`bayesplate.io.taps` (``force_channel``,
    ``channel``, ``points``). CSV: a header line with ``time_s`` (s, evenly spaced,
    ascending) and ``signal`` (the response), optionally ``force``; ``#`` starts a comment.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    window : {"auto", "none", "exponential"}
        See the module docstring.
    force_channel, channel, points
        See :func:`bayesplate.io.taps.read_taps`.

    Returns
    -------
    FRFData
        One FRF per response channel, with coordinates when `points` is given.

    Raises
    ------
    CaseError
        Naming the file, the line and column (CSV) or the part of the WAV file, and the rule.
    """
    from .taps import read_taps

    path = os.fspath(path)
    try:
        return read_taps([path], window, force_channel, channel, points)
    except CaseError as err:
        raise err if err.path else err.with_path(path) from None


def time_window(y, rate_Hz: float, window: str = "auto"):
    """The window of impulse responses `y` and the decay it adds to every pole.

    Parameters
    ----------
    y : numpy.ndarray, shape (..., n)
        Response samples; "auto" leaves them unwindowed only if every one has decayed.
    rate_Hz : float
        Sampling rate, Hz.
    window : {"auto", "none", "exponential"}
        See the module docstring.

    Returns
    -------
    weights : numpy.ndarray, shape (n,)
    decay_per_s : float
        ``1 / tau`` of the exponential window, 1/s; 0 without.
    note : str
        The window chosen, in words.
    """
    if window not in WINDOWS:
        raise CaseError("--window", window, f"must be one of {', '.join(WINDOWS)}")
    y = np.asarray(y, dtype=float)
    n = y.shape[-1]
    tail = np.abs(y[..., -max(1, int(_TAIL * n)) :]).max(axis=-1)
    decayed = bool(np.all(tail < _DECAYED * np.abs(y).max(axis=-1)))
    if window == "auto":
        window = "none" if decayed else "exponential"
    if window == "exponential":
        decay = -math.log(_DECAYED) / (n / rate_Hz)  # exp(-decay t) = 1 % at the end
        note = f"exponential window, 1 % at the end: poles corrected by {decay:.4g} 1/s"
        return np.exp(-decay * np.arange(n) / rate_Hz), decay, note
    note = "no window: the response has decayed within the record" if decayed else (
        "no window, though the response has not decayed: expect leakage")  # fmt: skip
    return np.ones(n), 0.0, note


def impulse_spectrum(signal, rate_Hz: float, force=None, window: str = "auto") -> FRFData:
    """Spectrum (or H1 FRF with a force) of one impulse response.

    Parameters
    ----------
    signal : array_like, shape (n,)
        Response samples (any unit), from just before the tap.
    rate_Hz : float
        Sampling rate, Hz.
    force : array_like, shape (n,), optional
        Force samples of an instrumented hammer.
    window : {"auto", "none", "exponential"}
        See the module docstring.

    Returns
    -------
    FRFData
        Frequency lines ``k rate / n`` up to the Nyquist frequency, one response point.

    Raises
    ------
    CaseError
        For a signal too short, not finite or all zero, or an unknown window.
    """
    from .taps import Recording, average_taps

    y = np.asarray(signal, dtype=float).reshape(1, -1)
    if force is not None:
        force = np.asarray(force, dtype=float)
        if force.shape != y.shape[1:]:
            raise CaseError("force", force.size, f"must be as long as the signal ({y.size})")
    return average_taps([Recording(float(rate_Hz), y, force, (0,), "")], window)
