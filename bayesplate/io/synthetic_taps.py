"""Synthetic hammer-tap recordings from the finite-element model, with known answers.

Real tap recordings (an instrumented hammer's force and an accelerometer, several taps at
one point) carry artefacts an import must survive: a mode split into two close poles, a
response component not linearly related to the force (a rattle: a pole in a coherence dip),
modes missed at a node of the tap or the sensor, weak modes, noise, a clipped response, a
double hit. This module makes such recordings from the model, so that the import (LSCF
poles -> case file) and the estimators can be tested against the truth:

- :func:`plate_modes_at`: natural frequencies and modal amplitudes
  ``phi_j(tap) phi_j(sensor)`` (mass-normalised modes, 1/kg) of a :class:`PlateModel`,
  optionally of a plate a little thicker, denser or tapered than the model's;
- :func:`recorded_poles`: the poles the recordings hold (splits included), the known answer;
- :func:`accelerance`: their FRF, ``H(w) = sum_k A_k (-w^2) / (w_k^2 - w^2 + 2 i zeta_k w_k w)``
  ((m/s^2)/N, the sign convention of :func:`numpy.fft.rfft`, ``d/dt <-> i w``);
- :func:`synthetic_taps`: the taps, ``(response, force)`` sample arrays, artefacts from a
  :class:`TapArtefacts`;
- :func:`write_taps`: 2-channel float32 WAV files like the real ones (channel 0 the
  response, channel 1 the force).

How a tap is made: a half-sine force pulse of random strength, length and onset (the
pre-trigger delay) is sampled; the response is ``irfft(H F)`` on a grid ``m`` times the
record long, ``m`` chosen so that the slowest pole has decayed below 1e-9 of its start
within it (at most 64 records), then cut to the record. That is the linear convolution of
a band-limited recorder (an ideal anti-aliasing filter): the record's DFT at its lines is
exactly ``H F`` there, less the part of the response that rings past the record's end. A record
too short for the decay therefore leaks as a real one does, and the import's exponential
window (:func:`bayesplate.io.impulse.time_window`) treats it as it treats a real one. Being
band-limited (its spectrum stops at the Nyquist frequency, where the FRF is not yet zero),
the response starts a little before the force, as behind a linear-phase anti-aliasing
filter: about 2e-3 of its peak one sample before the onset, 4e-4 five samples before,
falling as 1 / t with alternating sign; the force is exactly zero before its pulse. The
part of it before the record's start is cut, which leaves ``H1 = H`` to 3e-7 of the
FRF's peak below 3 kHz and 3e-6 at 10 kHz (at 25.6 kHz).

Random numbers: the hammer (strength, pulse length, onset of every tap) is drawn first,
then the rattle, then the noise, so that the same seed gives the same taps and the same
hammer whatever artefacts are switched on.
"""

from __future__ import annotations

import math
import os
import pathlib
from dataclasses import dataclass

import numpy as np

from ..plate.model import PlateModel

__all__ = [
    "TapArtefacts",
    "plate_modes_at",
    "recorded_poles",
    "accelerance",
    "synthetic_taps",
    "write_taps",
]

_TAIL = 1e-9  # the padded grid is long enough for every pole to decay below this
_MAX_PERIODS = 64  # ... but at most this many records long


def plate_modes_at(
    model: PlateModel,
    b,
    tap_mm,
    sensor_mm,
    n_modes: int,
    *,
    thickness_scale: float = 1.0,
    density_scale: float = 1.0,
    taper=None,
):
    """Natural frequencies and modal amplitudes of the plate for one tap and sensor.

    Parameters
    ----------
    model : PlateModel
        The plate (its mesh decides the accuracy).
    b : array_like, shape (6,)
        Lamina stiffness coefficients, Pa (:func:`bayesplate.laminate.stiffness_from_engineering`).
    tap_mm : array_like, shape (2,)
        Where the hammer hits, ``(x, y)`` in mm in the plate frame (origin at a corner).
    sensor_mm : array_like, shape (2,) or (p, 2)
        Where the response is measured, mm; several rows give several sensors.
    n_modes : int
        Lowest elastic modes.
    thickness_scale, density_scale : float
        A plate not quite the model's: every ply ``thickness_scale`` times as thick, the
        density ``density_scale`` times the model's (the model is rebuilt on its mesh; a
        :meth:`PlateModel.modified` model loses its changes then).
    taper : tuple (str, float), optional
        ``(direction, ratio)``: thickness ``h (1 + ratio (2 s - 1))`` along ``"x"`` or
        ``"y"`` (:class:`bayesplate.discrepancy.ThicknessTaper`), mean thickness kept.

    Returns
    -------
    frequency_Hz : numpy.ndarray, shape (n_modes,)
    amplitude : numpy.ndarray, shape (n_modes,) or (p, n_modes)
        ``phi_j(tap) phi_j(sensor)`` of the mass-normalised modes, 1/kg.
    """
    if thickness_scale != 1.0 or density_scale != 1.0:
        mesh = model.mesh
        model = PlateModel(
            mesh.a,
            mesh.b,
            model.thickness * thickness_scale,
            model.density * density_scale,
            model.layup_deg,
            model.ply_thickness * thickness_scale,
            mesh=(mesh.nx, mesh.ny),
            boundary=model.boundary,
            shear_order=model.element.shear_order,
        )
    if taper is not None:
        from ..discrepancy.physics.thickness_taper import ThicknessTaper

        direction, ratio = taper
        model = ThicknessTaper(direction).apply(model, (float(ratio),))
    result = model.solve(np.asarray(b, dtype=float), n_modes)
    sensor = np.asarray(sensor_mm, dtype=float)
    points = np.vstack([np.asarray(tap_mm, dtype=float).reshape(1, 2), sensor.reshape(-1, 2)])
    w = np.asarray(model.interpolation(points * 1e-3, "w") @ result.vectors)
    amplitude = w[0] * w[1:]
    return np.asarray(result.frequency_Hz), amplitude[0] if sensor.ndim == 1 else amplitude


def _pairs(value, size, name):
    """`value` as a tuple of `size`-tuples: one tuple alone is taken as a list of one."""
    value = tuple(value)
    if value and not isinstance(value[0], (tuple, list, np.ndarray)):
        value = (value,)
    value = tuple(tuple(item) for item in value)
    for item in value:
        if len(item) != size:
            raise ValueError(f"{name} = {item}: must have {size} values")
    return value


@dataclass(frozen=True)
class TapArtefacts:
    """What goes wrong in a real tap test; every artefact off by default.

    Parameters
    ----------
    noise : float
        White noise on the response, standard deviation this times the tap's response peak.
    force_noise : float
        White noise on the force, this times the tap's force peak.
    split : sequence of (int, float, float)
        ``(mode, relative split s, amplitude ratio r)``: mode ``mode`` (0-based) gets a
        partner pole at ``f (1 + s)`` of amplitude ``r A`` and the mode's damping: a double
        peak. One triple alone is taken as a list of one.
    rattle_Hz : sequence of float
        Frequencies of components not linearly related to the force: in every tap a damped
        oscillation (damping ratio ``rattle_damping``) set off by the tap after a random
        delay (a random phase) with a random amplitude, ``rattle_level`` times 0.5 to 1.5
        times the tap's response peak. Across taps: a coherence dip with a pole in it. The
        default level (0.02) keeps the dip to a few % around it on the bundled plate1; at
        0.05 the rattle's tail also lowers the coherence at the deep antiresonances.
    rattle_level, rattle_damping : float
    double_hit : sequence of (int, float, float)
        ``(tap, delay_s, ratio)``: in tap ``tap`` (0-based) a second hit ``delay_s`` after
        the first, ``ratio`` times as strong, same pulse length. The response follows it.
    clip : sequence of (int, float)
        ``(tap, fraction)``: the response of tap ``tap`` clipped at ``fraction`` of its peak
        (after the noise, as a recorder's range clips).
    damping : float or sequence of float
        Viscous damping ratio of the modes (what the import reports; a loss factor is
        twice it at resonance): one value for all, ``(first, last)`` rising linearly with
        the mode number, or one per mode.
    """

    noise: float = 0.0
    force_noise: float = 0.0
    split: tuple = ()
    rattle_Hz: tuple = ()
    rattle_level: float = 0.02
    rattle_damping: float = 0.01
    double_hit: tuple = ()
    clip: tuple = ()
    damping: float | tuple = (0.005, 0.01)

    def __post_init__(self):
        object.__setattr__(self, "split", _pairs(self.split, 3, "split"))
        object.__setattr__(self, "double_hit", _pairs(self.double_hit, 3, "double_hit"))
        object.__setattr__(self, "clip", _pairs(self.clip, 2, "clip"))
        rattle = np.atleast_1d(np.asarray(self.rattle_Hz, dtype=float))
        object.__setattr__(self, "rattle_Hz", tuple(float(f) for f in rattle))
        if not isinstance(self.damping, (int, float)):
            object.__setattr__(self, "damping", tuple(float(d) for d in self.damping))
        for name in ("noise", "force_noise", "rattle_level"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} = {getattr(self, name)}: must be >= 0")
        for _, fraction in self.clip:
            if not 0 < fraction <= 1:
                raise ValueError(f"clip fraction = {fraction}: must be in (0, 1]")

    def damping_of(self, n: int) -> np.ndarray:
        """Damping ratio of each of `n` modes."""
        d = np.atleast_1d(np.asarray(self.damping, dtype=float))
        if d.size == 1:
            d = np.full(n, d[0])
        elif d.size == 2 and n != 2:
            d = np.linspace(d[0], d[1], n)
        elif d.size != n:
            raise ValueError(f"damping has {d.size} values: give 1, 2 or one per mode ({n})")
        if not np.all((d > 0) & (d < 1)):
            raise ValueError(f"damping = {d}: every ratio must be in (0, 1)")
        return d


def recorded_poles(frequencies_Hz, amplitudes, artefacts: TapArtefacts = TapArtefacts()):
    """The poles in the recordings: the modes and their split partners, ascending.

    Parameters
    ----------
    frequencies_Hz : array_like, shape (n,)
    amplitudes : array_like, shape (n,) or (p, n)
        Modal amplitudes (1/kg) at each sensor.
    artefacts : TapArtefacts

    Returns
    -------
    frequency_Hz : numpy.ndarray, shape (m,)
    amplitude : numpy.ndarray, shape (m,) or (p, m)
    damping : numpy.ndarray, shape (m,)
    """
    frequency = np.asarray(frequencies_Hz, dtype=float).copy()
    amplitude = np.asarray(amplitudes, dtype=float)
    if amplitude.shape[-1] != frequency.size:
        raise ValueError(f"amplitudes {amplitude.shape}: need one per mode ({frequency.size})")
    damping = artefacts.damping_of(frequency.size)
    extra_f, extra_a, extra_d = [], [], []
    for mode, split, ratio in artefacts.split:
        mode = int(mode)
        extra_f.append(frequency[mode] * (1 + split))
        extra_a.append(ratio * amplitude[..., mode])
        extra_d.append(damping[mode])
    if extra_f:
        frequency = np.concatenate([frequency, extra_f])
        amplitude = np.concatenate([amplitude, np.stack(extra_a, axis=-1)], axis=-1)
        damping = np.concatenate([damping, extra_d])
    order = np.argsort(frequency, kind="stable")
    return frequency[order], amplitude[..., order], damping[order]


def accelerance(axis_Hz, frequencies_Hz, amplitudes, damping):
    """``H(f) = sum_k A_k (-w^2) / (w_k^2 - w^2 + 2 i zeta_k w_k w)``, (m/s^2)/N.

    Parameters
    ----------
    axis_Hz : array_like, shape (n_f,)
    frequencies_Hz, damping : array_like, shape (m,)
    amplitudes : array_like, shape (m,) or (p, m)

    Returns
    -------
    numpy.ndarray of complex, shape (n_f,) or (p, n_f)
    """
    omega = 2 * np.pi * np.asarray(axis_Hz, dtype=float)[:, None]
    omega_k = 2 * np.pi * np.asarray(frequencies_Hz, dtype=float)
    zeta = np.asarray(damping, dtype=float)
    modal = -(omega**2) / (omega_k**2 - omega**2 + 2j * zeta * omega_k * omega)  # (n_f, m)
    return np.asarray(amplitudes, dtype=float) @ modal.T


def _pulse(t, onset, length, strength):
    """Half-sine force pulse sampled at times `t`."""
    inside = (t >= onset) & (t < onset + length)
    return strength * np.where(inside, np.sin(np.pi * (t - onset) / length), 0.0)


def synthetic_taps(
    frequencies_Hz,
    amplitudes,
    rate_Hz: float,
    duration_s: float,
    n_taps: int,
    artefacts: TapArtefacts,
    rng,
    *,
    pulse_s=(0.4e-3, 0.7e-3),
    onset_s=(0.8e-3, 1.5e-3),
    strength_N=(0.5, 2.0),
):
    """Tap recordings of modes with amplitudes, with the artefacts asked for.

    Parameters
    ----------
    frequencies_Hz : array_like, shape (n,)
        Natural frequencies (e.g. :func:`plate_modes_at`).
    amplitudes : array_like, shape (n,) or (p, n)
        Modal amplitudes ``phi(tap) phi(sensor)``, 1/kg, of one sensor or p sensors.
    rate_Hz : float
        Sampling rate.
    duration_s : float
        Record length.
    n_taps : int
    artefacts : TapArtefacts
    rng : numpy.random.Generator or int
        The random numbers (an int seeds a new generator): the same seed, the same taps.
    pulse_s, onset_s, strength_N : (float, float)
        Ranges of each tap's half-sine length (its spectrum's first zero is at
        ``1.5 / length``: 0.4-0.7 ms excites up to ~2 kHz, as the real spruce taps; shorten
        it for higher modes), onset (pre-trigger delay) and peak force, drawn uniformly.

    Returns
    -------
    list of (numpy.ndarray, numpy.ndarray)
        Per tap, the response (acceleration, m/s^2; shape (n_samples,) or (p, n_samples))
        and the force (N, shape (n_samples,)).
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    n = int(round(duration_s * rate_Hz))
    frequency, amplitude, damping = recorded_poles(frequencies_Hz, amplitudes, artefacts)
    for tap, *_ in artefacts.double_hit + artefacts.clip:
        if not 0 <= int(tap) < n_taps:
            raise ValueError(f"tap {tap}: must be one of the {n_taps} taps (0-based)")
    # a grid long enough for the slowest pole (or rattle) to decay, a whole number of records
    rates = (
        2
        * np.pi
        * np.concatenate(
            [frequency * damping, np.asarray(artefacts.rattle_Hz) * artefacts.rattle_damping]
        )
    )
    ring = -math.log(_TAIL) / rates.min() * rate_Hz if rates.size else 0.0
    periods = min(_MAX_PERIODS, 1 + math.ceil(ring / n))
    size = periods * n
    t = np.arange(size) / rate_Hz
    axis = np.fft.rfftfreq(size, 1.0 / rate_Hz)
    H = accelerance(axis, frequency, amplitude, damping)
    hammer = np.column_stack(
        [
            rng.uniform(*strength_N, n_taps),
            rng.uniform(*pulse_s, n_taps),
            rng.uniform(*onset_s, n_taps),
        ]
    )
    rattle = [
        (
            accelerance(axis, [f], [1.0], [artefacts.rattle_damping]),
            rng.uniform(0.0, 1.0 / f, n_taps),
            rng.uniform(0.5, 1.5, n_taps),
        )
        for f in artefacts.rattle_Hz
    ]
    taps = []
    for k, (strength, length, onset) in enumerate(hammer):
        unit = np.fft.rfft(_pulse(t, onset, length, 1.0))
        force = _pulse(t, onset, length, strength)
        for tap, delay, ratio in artefacts.double_hit:
            if int(tap) == k:
                force = force + _pulse(t, onset + delay, length, ratio * strength)
        y = np.fft.irfft(H * np.fft.rfft(force), size)[..., :n]
        peak = np.abs(y).max(axis=-1, keepdims=True)
        for H_r, delay, scale in rattle:
            r = np.fft.irfft(H_r * unit * np.exp(-2j * np.pi * axis * delay[k]), size)[:n]
            y = y + artefacts.rattle_level * scale[k] * peak * r / np.abs(r).max()
        taps.append([y, force[:n]])
    for k, (y, force) in enumerate(taps):  # the noise after every tap's hammer and rattle
        if artefacts.noise:
            peak = np.abs(y).max(axis=-1, keepdims=True)
            y = y + artefacts.noise * peak * rng.standard_normal(y.shape)
        if artefacts.force_noise:
            force = force + artefacts.force_noise * np.abs(force).max() * rng.standard_normal(n)
        for tap, fraction in artefacts.clip:
            if int(tap) == k:
                top = fraction * np.abs(y).max(axis=-1, keepdims=True)
                y = np.clip(y, -top, top)
        taps[k] = (y, force)
    return taps


def write_taps(directory, taps, rate_Hz) -> list[pathlib.Path]:
    """Write taps as 32-bit float WAV files ``tap1.wav``, ``tap2.wav``, ... in `directory`.

    One response: 2 channels, channel 0 the response and channel 1 the force, as the real
    recordings (``bayesplate import`` finds the force there by itself). p responses:
    channels 0 to p-1 the responses, channel p the force (``--force-channel p --points``).

    Parameters
    ----------
    directory : str or os.PathLike
        Created if missing.
    taps : sequence of (response, force)
        As :func:`synthetic_taps` returns.
    rate_Hz : int
        Sampling rate (a WAV file's rate is a whole number of Hz).

    Returns
    -------
    list of pathlib.Path
    """
    from scipy.io import wavfile

    if rate_Hz != int(rate_Hz):
        raise ValueError(f"rate_Hz = {rate_Hz}: a WAV file's rate is a whole number of Hz")
    directory = pathlib.Path(os.fspath(directory))
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, (response, force) in enumerate(taps, start=1):
        channels = np.vstack([np.atleast_2d(response), np.asarray(force)[None, :]])
        path = directory / f"tap{k}.wav"
        wavfile.write(path, int(rate_Hz), channels.T.astype(np.float32))
        paths.append(path)
    return paths
