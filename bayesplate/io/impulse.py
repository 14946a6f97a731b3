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
import pathlib

import numpy as np

from .errors import CaseError
from .frf import FRFData, numeric_table, read_csv_rows

__all__ = ["read_impulse", "impulse_spectrum", "WINDOWS"]

WINDOWS = ("auto", "none", "exponential")
"""Windows :func:`impulse_spectrum` knows."""

_TAIL = 0.05  # fraction of the record that must have decayed for no window
_DECAYED = 0.01  # ... below this fraction of the peak; also the exponential window's end value


def read_impulse(path, window: str = "auto") -> FRFData:
    """Read an impulse recording (``.wav`` or a CSV time series) and return its spectrum.

    WAV (scipy.io.wavfile, any sample format): channel 1 is the response, channel 2, if
    present, the force. CSV: a header line with ``time_s`` (s, evenly spaced, ascending)
    and ``signal`` (the response), optionally ``force``; ``#`` starts a comment.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    window : {"auto", "none", "exponential"}
        See the module docstring.

    Returns
    -------
    FRFData
        One response point, no coordinates.

    Raises
    ------
    CaseError
        Naming the file, the line and column (CSV) or the part of the WAV file, and the rule.
    """
    path = os.fspath(path)
    try:
        if pathlib.Path(path).suffix.lower() == ".wav":
            rate_Hz, signal, force = _read_wav(path)
        else:
            rate_Hz, signal, force = _read_time_csv(path)
        spectrum = impulse_spectrum(signal, rate_Hz, force=force, window=window)
    except CaseError as err:
        raise err.with_path(path) from None
    return FRFData(
        spectrum.frequency_Hz,
        spectrum.frf,
        form=spectrum.form,
        added_decay_per_s=spectrum.added_decay_per_s,
        source=path,
        notes=spectrum.notes,
    )


def _read_wav(path: str):
    from scipy.io import wavfile

    try:
        rate, data = wavfile.read(path)
    except OSError as err:
        raise CaseError(None, rule=f"cannot read the file ({err.strerror or err})") from None
    except Exception as err:  # noqa: BLE001 - scipy raises ValueError and others, text varies
        rule = f"not a readable WAV file ({' '.join(str(err).split())[:80]})"
        raise CaseError(None, rule=rule) from None
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    if data.shape[1] > 2:
        rule = "must be 1 (response) or 2 (response, force)"
        raise CaseError("WAV channels", data.shape[1], rule)
    force = data[:, 1] if data.shape[1] == 2 else None
    return float(rate), data[:, 0], force


def _read_time_csv(path: str):
    header_line, header, rows = read_csv_rows(path)
    for name in ("time_s", "signal"):
        if name not in header:
            rule = f"required column is missing from the header ({', '.join(header)})"
            raise CaseError(f"line {header_line}, column {name}", rule=rule)
    for name in header:
        if name not in ("time_s", "signal", "force"):
            rule = "unknown column; allowed: time_s, signal, force"
            raise CaseError(f"line {header_line}, column {name}", name, rule)
    table = numeric_table(header, rows)
    step = np.diff(table["time_s"])
    if not np.all(step > 0) or np.ptp(step) > 1e-6 * step.mean():
        raise CaseError("column time_s", rule="times must be ascending and evenly spaced (s)")
    return 1.0 / step.mean(), table["signal"], table.get("force")


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
    y = np.asarray(signal, dtype=float)
    if window not in WINDOWS:
        raise CaseError("--window", window, f"must be one of {', '.join(WINDOWS)}")
    if y.size < 64:
        raise CaseError("signal", y.size, "needs at least 64 samples (the file is truncated?)")
    if not (np.all(np.isfinite(y)) and np.any(y)):
        raise CaseError("signal", rule="must be finite and not all zero")
    if not (math.isfinite(rate_Hz) and rate_Hz > 0):
        raise CaseError("sampling rate", rate_Hz, "must be a positive number (Hz)")
    duration_s = y.size / rate_Hz
    tail = np.abs(y[-max(1, int(_TAIL * y.size)) :]).max()
    decayed = tail < _DECAYED * np.abs(y).max()
    if window == "auto":
        window = "none" if decayed else "exponential"
    decay = 0.0
    if window == "exponential":
        decay = -math.log(_DECAYED) / duration_s  # exp(-decay t) = 1 % at the end
        weights = np.exp(-decay * np.arange(y.size) / rate_Hz)
        note = f"exponential window, 1 % at the end: poles corrected by {decay:.4g} 1/s"
    else:
        weights = np.ones(y.size)
        note = "no window: the response has decayed within the record" if decayed else (
            "no window, though the response has not decayed: expect leakage")  # fmt: skip
    spectrum = np.fft.rfft(y * weights) / rate_Hz
    frequency = np.fft.rfftfreq(y.size, 1.0 / rate_Hz)
    if force is not None:
        f = np.asarray(force, dtype=float)
        if f.shape != y.shape or not np.all(np.isfinite(f)) or not np.any(f):
            raise CaseError("force", rule="must be finite, not all zero, as long as the signal")
        # the force pulse is short: no window on it (the exponential one is ~1 there anyway)
        force_spectrum = np.fft.rfft(f) / rate_Hz
        auto = np.abs(force_spectrum) ** 2
        frf = np.conj(force_spectrum) * spectrum / np.where(auto > 0, auto, np.inf)
        note += "; H1 = conj(F) Y / |F|^2"
    else:
        frf = spectrum
        note += "; no force channel: the response spectrum stands for the FRF"
    return FRFData(frequency, frf[None, :], added_decay_per_s=decay, notes=(note,))
