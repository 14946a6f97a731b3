"""Prior probabilities of the assignment from a tap test's own evidence.

The most probable assignment (:mod:`bayesplate.matching.assignment`) weighs, for each measured peak,
the prior probability ``p_s`` that it is no bending mode of the plate (spurious) and, for
each computed mode, the probability ``p_u`` that the test did not see it (unobserved).
Flat constants treat a clean, strong, stable pole like a pole in a coherence dip, and the
fundamental like the twentieth mode. Here both come from what the test shows.

**A peak spurious** (:func:`spurious_probability`): a clean pole starts at
:data:`P_SPURIOUS_CLEAN`; each piece of evidence multiplies its odds by a likelihood ratio
(naive Bayes: the pieces are taken as independent), each 1 for a pole that looks like a
mode and growing as it looks less so:

- the phase of its modal constant: a lightly damped structure has real modes, so the
  residues of one response point lie on one line through the origin (up to sign); a
  computational pole, a noise peak or a rattle has a residue off that line. With a
  deviation ``d`` from the line, the ratio is ``exp(d^2 / (2 d0^2))`` (``d0`` =
  :data:`PHASE_SCALE_DEG`), at most :data:`MAX_RATIO`;
- the coherence in its half-power band: a response not linearly related to the force (a
  rattle, a double hit, a nonlinearity) lowers it; ``(1 - c_min) / (1 - COHERENCE_CLEAN)``,
  between 1 and :data:`MAX_RATIO`;
- its damping against the median of the candidates: a plate's modes have loss factors of one
  order; beyond a factor :data:`DAMPING_FACTOR` either way, ``(r / DAMPING_FACTOR)^2``;
- how often the pole is stable over the model orders: below half of them,
  ``(0.5 / q)^2``, at most :data:`MAX_RATIO`;
- its amplitude: a modal constant below a tenth of the median is weak evidence of a peak
  that is not there, ``0.1 / a``, at most 3 (a mode near a node of the tap or the sensor
  is weak too, so this stays mild).

**A mode unobserved** (:func:`unobserved_probability`): a one-point test misses a mode when
its tap or sensor sits near one of the mode's nodal lines, and the lowest modes have the
fewest: ``p_u`` rises with the mode's number, :data:`UNOBSERVED_STEP` per mode, up to
:data:`bayesplate.matching.assignment.P_UNOBSERVED`. Where the tap and sensor points are known, the
mode's amplitude there decides instead (:func:`unobserved_from_amplitude`).

:func:`assignment_priors` gives the pair for a measurement: these where it carries its
peaks' ``p_spurious``, the flat constants of :mod:`bayesplate.matching.assignment` where not.

Pure array computation.
"""

from __future__ import annotations

import numpy as np

from .assignment import P_SPURIOUS, P_UNOBSERVED

__all__ = [
    "assignment_priors",
    "P_SPURIOUS_CLEAN",
    "PHASE_SCALE_DEG",
    "COHERENCE_CLEAN",
    "DAMPING_FACTOR",
    "MAX_RATIO",
    "UNOBSERVED_STEP",
    "P_NODE",
    "spurious_probability",
    "unobserved_probability",
    "unobserved_from_amplitude",
]

#: Prior probability that a clean, strong, stable pole is not a plate mode.
P_SPURIOUS_CLEAN = 0.03
#: The scale ``d0`` of the phase ratio ``exp(d^2 / 2 d0^2)``, degrees: measured modes of a
#: tap test deviate a few degrees (noise, a neighbour's leakage), a computational pole tens.
PHASE_SCALE_DEG = 10.0
#: Coherence of a clean pole: a dip to ``c_min`` multiplies the odds by
#: ``(1 - c_min) / (1 - COHERENCE_CLEAN)``.
COHERENCE_CLEAN = 0.95
#: Damping ratios within this factor of the candidates' median are unremarkable.
DAMPING_FACTOR = 2.0
#: No single piece of evidence multiplies the odds by more than this.
MAX_RATIO = 50.0
#: ``p_u`` of the ``j``-th computed mode (0-based) is ``UNOBSERVED_STEP (j + 1)``, capped.
UNOBSERVED_STEP = 0.02
#: ``p_u`` of a mode with no amplitude at the known tap or sensor point (a node): the test
#: all but certainly misses it.
P_NODE = 0.9


def spurious_probability(phase_deviation_deg, coherence, damping, stable_fraction, amplitude):
    """Prior probability that each candidate pole is not a mode of the plate.

    Parameters
    ----------
    phase_deviation_deg : array_like, shape (m,)
        Deviation of each pole's modal constant from the residues' common line, degrees in
        [0, 90]; NaN where unknown (ratio 1).
    coherence : array_like, shape (m,)
        Lowest coherence in each pole's half-power band; NaN without a force channel.
    damping : array_like, shape (m,)
        Viscous damping ratios.
    stable_fraction : array_like, shape (m,)
        Fraction of the model orders over which each pole was stable, in (0, 1].
    amplitude : array_like, shape (m,)
        Magnitude of each pole's modal constant relative to the candidates' median; NaN
        where unknown.

    Returns
    -------
    numpy.ndarray, shape (m,)
        ``p_s`` in ``[P_SPURIOUS_CLEAN, 1)``.
    """
    ratios = likelihood_ratios(phase_deviation_deg, coherence, damping, stable_fraction, amplitude)
    odds = P_SPURIOUS_CLEAN / (1.0 - P_SPURIOUS_CLEAN) * np.prod(ratios, axis=0)
    return odds / (1.0 + odds)


def likelihood_ratios(phase_deviation_deg, coherence, damping, stable_fraction, amplitude):
    """The five ratios of :func:`spurious_probability`, shape (5, m), in its order."""
    d = np.nan_to_num(np.asarray(phase_deviation_deg, dtype=float), nan=0.0)
    phase = np.minimum(np.exp(0.5 * (d / PHASE_SCALE_DEG) ** 2), MAX_RATIO)
    c = np.nan_to_num(np.asarray(coherence, dtype=float), nan=1.0)
    dip = np.clip((1.0 - c) / (1.0 - COHERENCE_CLEAN), 1.0, MAX_RATIO)
    z = np.asarray(damping, dtype=float)
    r = z / np.median(z) if z.size else z
    r = np.maximum(r, 1.0 / np.maximum(r, 1e-12))
    spread = np.maximum(r / DAMPING_FACTOR, 1.0) ** 2
    q = np.clip(np.asarray(stable_fraction, dtype=float), 1e-3, 1.0)
    unstable = np.minimum(np.maximum(0.5 / q, 1.0) ** 2, MAX_RATIO)
    a = np.nan_to_num(np.asarray(amplitude, dtype=float), nan=1.0)
    weak = np.clip(0.1 / np.maximum(a, 1e-12), 1.0, 3.0)
    return np.array([phase, dip, np.minimum(spread, MAX_RATIO), unstable, weak])


def unobserved_probability(n, p_max):
    """``p_u`` of each of the ``n`` lowest computed modes without tap and sensor points.

    Parameters
    ----------
    n : int
        Number of computed modes.
    p_max : float
        The cap, in (0, 1) (the flat prior of the assignment).

    Returns
    -------
    numpy.ndarray, shape (n,)
    """
    return np.minimum(UNOBSERVED_STEP * (np.arange(n) + 1.0), p_max)


def unobserved_from_amplitude(amplitude, p_max, p_min=0.01):
    """``p_u`` of each computed mode from its amplitude at the tap and sensor points.

    A mode's peak in a one-point FRF has the height of its modal constant
    ``phi(tap) phi(sensor)`` (mass-normalised shapes); relative to the median over the
    modes, ``a``, the mode is missed with probability ``p_max`` where ``a`` is zero,
    falling as ``p_max / (1 + (a / 0.1)^2)`` to ``p_min``.

    Parameters
    ----------
    amplitude : array_like, shape (n,)
        ``|phi_j(tap) phi_j(sensor)|``, any common unit.
    p_max : float
    p_min : float

    Returns
    -------
    numpy.ndarray, shape (n,)
    """
    a = np.abs(np.asarray(amplitude, dtype=float))
    scale = np.median(a) if a.size and np.median(a) > 0 else 1.0
    return np.maximum(p_max / (1.0 + (a / scale / 0.1) ** 2), p_min)


def assignment_priors(measured, n, amplitude=None):
    """``(p_unobserved, p_spurious)`` of the assignment for a measurement and `n` modes.

    Parameters
    ----------
    measured : bayesplate.io.Measurement
        With ``p_spurious`` (a tap-test import) or without.
    n : int
        Number of computed modes offered.
    amplitude : array_like, shape (n,), optional
        ``|phi_j(tap) phi_j(sensor)|`` of each computed mode, where the measurement gives
        its tap and sensor points.

    Returns
    -------
    p_unobserved : float or numpy.ndarray, shape (n,)
        :func:`unobserved_from_amplitude` (up to :data:`P_NODE`) with `amplitude`, else
        :func:`unobserved_probability` with ``p_spurious``, else
        :data:`~bayesplate.matching.assignment.P_UNOBSERVED`.
    p_spurious : float or numpy.ndarray, shape (m,)
        The measurement's, else :data:`~bayesplate.matching.assignment.P_SPURIOUS`.
    """
    p_spurious = getattr(measured, "p_spurious", None)
    p_s = P_SPURIOUS if p_spurious is None else np.asarray(p_spurious, dtype=float)
    if amplitude is not None:
        return unobserved_from_amplitude(amplitude, P_NODE), p_s
    if p_spurious is None:
        return P_UNOBSERVED, p_s
    return unobserved_probability(n, P_UNOBSERVED), p_s
