"""Several taps of one test, several response channels, and the points they were recorded at.

A tap test is often repeated: :func:`read_taps` reads K recordings (WAV or CSV time series,
same sampling rate and length) of the same set-up and averages them into one
:class:`~bayesplate.io.frf.FRFData`, one FRF per response channel:

- **with a force channel**, the H1 estimator over the taps,
  ``H1 = sum_k conj(F_k) Y_k / sum_k |F_k|^2``, and the ordinary coherence
  ``gamma^2 = |sum_k conj(F_k) Y_k|^2 / (sum_k |F_k|^2 sum_k |Y_k|^2)`` (1 where the
  response is explained linearly by the force, lower with noise, a double hit or a
  nonlinearity; identically 1 for one tap, so it is computed for two taps or more);
- **without a force**, each tap is first cut to start at its trigger, the first sample at
  5 % of its peak: the pre-trigger delay ``t0`` of a recording multiplies its spectrum by
  ``exp(-i omega t0)``, which the rational model of LSCF cannot follow (1 ms loses half the
  modes of a plate). Starting earlier, in the pre-trigger noise, was measured worse on
  synthetic taps (largest error 7.8 % two samples earlier, against 0.05 % at the trigger).
  The response spectra are then averaged after each tap's own normalisation: each tap is
  aligned on the first by the delay of their cross-correlation (sub-sample, applied as
  ``exp(i omega tau)``) and scaled by the complex least-squares factor that brings it onto
  the first tap. A plain average would not do: the taps differ in strength and trigger
  time, and averaging spectra of different delays cancels their high frequencies;
  averaging magnitudes would lose the phase LSCF needs. One delay and one scale per tap,
  shared by all its channels, keep the relative amplitudes that make the shapes.

Channels of a WAV file are numbered from 0. ``force_channel`` names the force (``None``: no
force; default ``"auto"``: channel 1 of a 2-channel file, as a hammer and a microphone are
recorded, else none); the other channels are responses, in channel order. Their points are
given by a points file (:func:`bayesplate.io.points.read_points`), one row per response
channel; ``channel`` picks a single response channel instead. Several response channels
without points are refused: the shapes need to know where they were measured.

One recording alone: :func:`read_impulse` (a file) and :func:`impulse_spectrum` (samples).
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from .errors import CaseError
from .frf import FRFData
from .impulse import Recording, read_recording, time_window
from .points import read_points

__all__ = [
    "read_points",
    "average_taps",
    "read_taps",
    "read_impulse",
    "impulse_spectrum",
    "coherence_at_poles",
    "COHERENCE_WARNING",
]

COHERENCE_WARNING = 0.9
"""A chosen pole whose coherence is below this is warned about."""

_TRIGGER = 0.05  # without a force, a tap starts where a response first reaches 5 % of its peak


def average_taps(recordings, window: str = "auto", points_mm=None) -> FRFData:
    """Average the spectra of several taps into one FRF per response channel.

    Parameters
    ----------
    recordings : sequence of Recording, length K >= 1
        All with the same rate, length, channels and presence of a force.
    window : {"auto", "none", "exponential"}
        As for :func:`bayesplate.io.impulse.impulse_spectrum`, decided once for all taps
        (no window only when every tap and channel has decayed).
    points_mm : numpy.ndarray, shape (p, 2), optional
        Coordinates of the response channels, mm.

    Returns
    -------
    FRFData
        H1 and its coherence (K >= 2) with a force; the aligned average without.

    Raises
    ------
    CaseError
        Naming the file whose rate, length or channels differ from the first tap's.
    """
    first = recordings[0]
    for rec in recordings:
        try:
            _check_signal(rec.responses, rec.rate_Hz)
        except CaseError as err:
            raise err.with_path(rec.source) if rec.source else err from None
        _check_same(first, rec)
    y = np.array([rec.responses for rec in recordings])  # (K, p, n)
    if first.force is None:
        y = np.array([_from_trigger(taps) for taps in y])
    weights, decay, note = time_window(y, first.rate_Hz, window)
    spectra = np.fft.rfft(y * weights, axis=-1) / first.rate_Hz  # (K, p, n_f)
    frequency = np.fft.rfftfreq(y.shape[-1], 1.0 / first.rate_Hz)
    k = len(recordings)
    coherence = None
    if first.force is not None:
        force = np.array([rec.force for rec in recordings])
        if force.shape != y[:, 0].shape:
            raise CaseError(
                "force", force.shape[-1], f"must be as long as the signal ({y.shape[-1]})"
            )
        if not (np.all(np.isfinite(force)) and np.all(np.any(force, axis=1))):
            raise CaseError("force", rule="must be finite and not all zero in every tap")
        f = np.fft.rfft(force, axis=-1)[:, None, :] / first.rate_Hz  # (K, 1, n_f)
        cross = np.sum(np.conj(f) * spectra, axis=0)
        auto_f = np.sum(np.abs(f) ** 2, axis=0)
        frf = cross / np.where(auto_f > 0, auto_f, np.inf)
        if k == 1:
            note += "; H1 = conj(F) Y / |F|^2"
        else:
            auto_y = np.sum(np.abs(spectra) ** 2, axis=0)
            denominator = auto_f * auto_y
            coherence = np.abs(cross) ** 2 / np.where(denominator > 0, denominator, np.inf)
            note += f"; H1 over {k} taps = sum conj(F) Y / sum |F|^2, with its coherence"
    elif k == 1:
        frf = spectra[0]
        note += "; no force channel: the response spectrum stands for the FRF"
    else:
        frf = np.mean([_aligned(s, spectra[0], frequency) for s in spectra], axis=0)
        note += (
            f"; no force channel: the response spectra of {k} taps, each aligned on the "
            "first (delay, complex scale), averaged"
        )
    source = first.source if k == 1 else f"{first.source} and {k - 1} more taps"
    return FRFData(
        frequency,
        frf,
        points_mm,
        added_decay_per_s=decay,
        source=source,
        notes=(note,),
        coherence=coherence,
    )


def _check_same(first: Recording, rec: Recording) -> None:
    if rec.rate_Hz != first.rate_Hz:
        rule = f"every tap must have the sampling rate of the first ({first.rate_Hz:g} Hz)"
        raise CaseError("sampling rate", rec.rate_Hz, rule, path=rec.source)
    if rec.responses.shape[1] != first.responses.shape[1]:
        rule = f"every tap must have the length of the first ({first.responses.shape[1]})"
        raise CaseError("samples", rec.responses.shape[1], rule, path=rec.source)
    if rec.channels != first.channels or (rec.force is None) != (first.force is None):
        rule = f"every tap must have the channels of the first ({len(first.channels)} "
        rule += "responses" + (", force)" if first.force is not None else ", no force)")
        raise CaseError("channels", len(rec.channels), rule, path=rec.source)


def _check_signal(y: np.ndarray, rate_Hz: float) -> None:
    if y.shape[-1] < 64:
        raise CaseError("signal", y.shape[-1], "needs at least 64 samples (the file is truncated?)")
    if not (np.all(np.isfinite(y)) and np.all(np.any(y, axis=-1))):
        raise CaseError("signal", rule="must be finite and not all zero in every channel")
    if not (math.isfinite(rate_Hz) and rate_Hz > 0):
        raise CaseError("sampling rate", rate_Hz, "must be a positive number (Hz)")


def _from_trigger(y: np.ndarray) -> np.ndarray:
    """Responses (p, n) of one tap moved to start at its trigger, zeros appended."""
    above = np.abs(y) >= _TRIGGER * np.abs(y).max()
    start = int(np.argmax(above.any(axis=0)))
    return np.concatenate([y[:, start:], np.zeros((y.shape[0], start))], axis=1)


def _aligned(spectrum: np.ndarray, reference: np.ndarray, frequency: np.ndarray) -> np.ndarray:
    """`spectrum` (p, n_f) delayed and scaled onto `reference` (p, n_f): see the module."""
    cross = np.sum(np.conj(reference) * spectrum, axis=0)
    upsample = 8
    n_time = upsample * 2 * (frequency.size - 1)
    correlation = np.abs(np.fft.irfft(cross, n_time))
    i = int(np.argmax(correlation))
    left, mid, right = correlation[i - 1], correlation[i], correlation[(i + 1) % n_time]
    curvature = left - 2 * mid + right
    shift = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
    lag = i + shift if i < n_time // 2 else i + shift - n_time
    delay_s = lag / (upsample * 2 * frequency[-1])  # n_time samples span 1 / (2 f_max) each
    moved = spectrum * np.exp(2j * np.pi * frequency * delay_s)
    scale = np.sum(np.conj(moved) * reference) / np.sum(np.abs(moved) ** 2)
    return scale * moved


def read_taps(
    paths,
    window="auto",
    force_channel="auto",
    channel=None,
    points=None,
    rate_Hz=None,
    force_column=None,
    response_column=None,
) -> FRFData:
    """Read and average the taps in `paths`, with the points of their response channels.

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        WAV files or CSV time series, one tap each.
    window : {"auto", "none", "exponential"}
    force_channel : int, None or "auto"
    channel : int, optional
        See the module docstring.
    points : str or os.PathLike, optional
        Points file (:func:`read_points`), one row per response channel in channel order.
    rate_Hz : float, optional
        Sampling rate, Hz, of CSV time series without a time column (checked against a
        time column or a WAV header that gives one).
    force_column, response_column : str, optional
        A CSV's force and response columns by name (:mod:`bayesplate.io.time_csv`).

    Returns
    -------
    FRFData
        With the readers' notes (a CSV's columns, its rate) before the average's.

    Raises
    ------
    CaseError
        Naming the file (or option) and the rule, e.g. several response channels without
        points, or a points file whose rows do not match the response channels.
    """
    recordings = [
        read_recording(path, force_channel, channel, rate_Hz, force_column, response_column)
        for path in paths
    ]
    count = len(recordings[0].channels)
    points_mm = None
    if points is not None:
        names, points_mm = read_points(points)
        if len(names) != count:
            rule = f"must have one row per response channel ({count} in {recordings[0].source})"
            raise CaseError("rows", len(names), rule, path=os.fspath(points))
    elif count > 1:
        rule = (
            f"{count} response channels {list(recordings[0].channels)}: which points? give "
            "--points (point,x_mm,y_mm, one row per channel) or pick one with --channel"
        )
        raise CaseError("WAV channels", count, rule, path=recordings[0].source)
    frf = average_taps(recordings, window, points_mm)
    notes = tuple(dict.fromkeys(note for rec in recordings for note in rec.notes))
    return dataclasses.replace(frf, notes=notes + frf.notes)


def coherence_at_poles(frf: FRFData, poles) -> list[tuple[float, float]]:
    """Coherence at each pole: ``(frequency_Hz, coherence)``, empty without a coherence.

    Taken at the frequency line nearest the pole, in the FRF of the response point where
    the pole is strongest there (largest ``|H|``): a point at a node of the mode sees
    only noise at that line, which says nothing of the pole.

    Parameters
    ----------
    frf : FRFData
    poles : sequence of Pole

    Returns
    -------
    list of (float, float)
    """
    if frf.coherence is None:
        return []
    found = []
    for pole in poles:
        line = int(np.argmin(np.abs(frf.frequency_Hz - pole.frequency_Hz)))
        point = int(np.argmax(np.abs(frf.frf[:, line])))
        found.append((pole.frequency_Hz, float(frf.coherence[point, line])))
    return found


def read_impulse(
    path,
    window: str = "auto",
    force_channel="auto",
    channel=None,
    points=None,
    rate_Hz=None,
    force_column=None,
    response_column=None,
) -> FRFData:
    """Read an impulse recording (``.wav`` or a CSV time series) and return its spectrum.

    WAV (scipy.io.wavfile, any sample format): one channel, the response; two, the response
    then the force (channels 0 and 1); more, see :mod:`bayesplate.io.taps` (``force_channel``,
    ``channel``, ``points``). CSV: a header line, then one row per sample: a time column
    (optional: else give `rate_Hz`), a response and optionally a force, found by their
    names as a DAQ writes them (``time_s``, ``Time (s)``, ``signal``, ``acceleration``,
    ``force``, ...; :mod:`bayesplate.io.time_csv`); ``#`` starts a comment.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    window : {"auto", "none", "exponential"}
        See the module docstring.
    force_channel, channel, points, rate_Hz, force_column, response_column
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
    path = os.fspath(path)
    try:
        return read_taps(
            [path], window, force_channel, channel, points, rate_Hz, force_column, response_column
        )
    except CaseError as err:
        raise err if err.path else err.with_path(path) from None


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
    y = np.asarray(signal, dtype=float).reshape(1, -1)
    if force is not None:
        force = np.asarray(force, dtype=float)
        if force.shape != y.shape[1:]:
            raise CaseError("force", force.size, f"must be as long as the signal ({y.size})")
    return average_taps([Recording(float(rate_Hz), y, force, (0,), "")], window)
