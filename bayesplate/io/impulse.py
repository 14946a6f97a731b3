"""An impulse recording (ASTM E1876-style tap) as a spectrum: WAV or CSV time series in, FRF out.

A tap test records the decaying response of the plate to a light impact (microphone or
accelerometer), optionally with the force of an instrumented hammer. This module reads one
recording's channels (:func:`read_recording`) and chooses its window (:func:`time_window`);
:func:`bayesplate.io.taps.read_impulse` and :func:`bayesplate.io.taps.impulse_spectrum` turn
it into an :class:`~bayesplate.io.frf.FRFData` of one response point:

- with a force channel, ``H1 = conj(F) Y / conj(F) F`` (one record: ``Y / F``);
- without, the response spectrum ``Y`` alone (an ideal tap has a flat force spectrum, so
  ``Y`` has the poles of the FRF).

Window (``window="auto"``): none when the response has died out in the record (its last
5 % below 1 % of the peak magnitude): the FFT of a fully decayed response is the exact
sampled spectrum, no leakage. Otherwise an exponential window ``exp(-t / tau)`` that falls
to 1 % at the end of the record, which forces the decay and adds ``1 / tau`` to every
pole's decay rate; :attr:`FRFData.added_decay_per_s` carries it and the pole estimates are
corrected by it (the usual correction for exponential windows).

:func:`read_recording` reads the channels of one tap (:class:`Recording`); a CSV time series
is read by :mod:`bayesplate.io.time_csv` (columns found by the names a DAQ writes, the rate
from a time column or given). Several channels and several taps, their points and their
average are the subject of :mod:`bayesplate.io.taps`.
"""

from __future__ import annotations

import math
import os
import pathlib
from dataclasses import dataclass

import numpy as np

from .errors import CaseError

__all__ = [
    "Recording",
    "is_recording",
    "read_recording",
    "time_window",
    "WINDOWS",
]

WINDOWS = ("auto", "none", "exponential")
"""Windows :func:`time_window` knows."""

_TAIL = 0.05  # fraction of the record that must have decayed for no window
_DECAYED = 0.01  # ... below this fraction of the peak; also the exponential window's end value


@dataclass(frozen=True, eq=False)
class Recording:
    """One tap as recorded: the channels kept, before any spectrum.

    Parameters
    ----------
    rate_Hz : float
        Sampling rate, Hz.
    responses : numpy.ndarray, shape (p, n)
        Response samples of each kept response channel (any unit).
    force : numpy.ndarray, shape (n,), optional
        Force samples of an instrumented hammer; None without.
    channels : tuple of int
        The file's channel number of each response row (0-based; 0 for a CSV's response).
    source : str
        The file.
    notes : tuple of str
        What the reader found or assumed (a CSV's columns, where its rate came from).
    """

    rate_Hz: float
    responses: np.ndarray
    force: np.ndarray | None
    channels: tuple[int, ...]
    source: str
    notes: tuple[str, ...] = ()


def is_recording(path, named=()) -> bool:
    """Whether `path` is an impulse recording: ``.wav``, or a ``.csv`` time series.

    A CSV is a time series when its header has a time or a response column, or one of the
    columns `named` (``--force-column``, ``--response-column``), and no frequency column
    (``frequency_Hz``: modes; ``Hk_re``: FRFs); see :func:`bayesplate.io.time_csv.column_role`.
    """
    from .time_csv import is_time_series_header, sniff_header

    suffix = pathlib.Path(path).suffix.lower()
    if suffix != ".csv":
        return suffix == ".wav"
    return is_time_series_header(sniff_header(path)[1], [n for n in named if n is not None])


def read_recording(
    path, force_channel="auto", channel=None, rate_Hz=None, force_column=None, response_column=None
) -> Recording:
    """Read one tap (WAV or CSV time series) and keep the channels asked for.

    Parameters
    ----------
    path : str or os.PathLike
    force_channel : int, None or "auto"
        WAV channel of the force (see the module docstring); a CSV's force is its force
        column, whatever this says.
    channel : int, optional
        The one WAV response channel to keep; default all but the force.
    rate_Hz : float, optional
        Sampling rate, Hz: required for a CSV without a time column; must agree with the
        time column or the WAV header when they give one.
    force_column, response_column : str, optional
        The CSV's force and response columns by their header cells, when the names do not
        say which they are (:mod:`bayesplate.io.time_csv`); refused for a WAV file.

    Returns
    -------
    Recording

    Raises
    ------
    CaseError
        Naming the file and the part of it, or the option, and the rule.
    """
    from .time_csv import read_time_csv

    path = os.fspath(path)
    try:
        if pathlib.Path(path).suffix.lower() == ".wav":
            for option, name in (
                ("--force-column", force_column),
                ("--response-column", response_column),
            ):
                if name is not None:
                    raise CaseError(option, name, "is for a CSV time series (WAV: --channel)")
            wav_rate_Hz, data = _read_wav(path)
            if rate_Hz is not None and rate_Hz != wav_rate_Hz:
                rule = f"disagrees with the WAV file's sampling rate ({wav_rate_Hz:g} Hz)"
                raise CaseError("--rate-Hz", rate_Hz, rule)
            return _channels(path, wav_rate_Hz, data, force_channel, channel)
        rate_Hz, signal, force, notes = read_time_csv(path, rate_Hz, force_column, response_column)
    except CaseError as err:
        raise err if err.path else err.with_path(path) from None
    if channel not in (None, 0):
        raise CaseError("--channel", channel, f"must be 0: {path} has one response column")
    return Recording(rate_Hz, signal[None, :], force, (0,), path, notes)


def _channels(path, rate_Hz, data, force_channel, channel) -> Recording:
    count = data.shape[1]
    if force_channel == "auto":
        force_channel = 1 if count == 2 else None
    for option, value in (("--force-channel", force_channel), ("--channel", channel)):
        if value is not None and not 0 <= value < count:
            rule = f"must be a channel of {path}: 0 to {count - 1} ({count} channels)"
            raise CaseError(option, value, rule)
    if channel is not None and channel == force_channel:
        raise CaseError("--channel", channel, "must not be the force channel (--force-channel)")
    responses = [c for c in range(count) if c != force_channel]
    if channel is not None:
        responses = [channel]
    if not responses:
        raise CaseError("WAV channels", count, "need a response channel besides the force")
    force = None if force_channel is None else data[:, force_channel]
    return Recording(rate_Hz, data[:, responses].T, force, tuple(responses), path)


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
    return float(rate), data[:, None] if data.ndim == 1 else data


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
    note = (
        "no window: the response has decayed within the record"
        if decayed
        else ("no window, though the response has not decayed: expect leakage")
    )
    return np.ones(n), 0.0, note
