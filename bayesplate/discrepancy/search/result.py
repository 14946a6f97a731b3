"""What diagnose found: :class:`Diagnosis`, frozen, with its verdict as the status."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .laplace import JointFit
from .rank import CandidateResult
from .separation import Separation
from .unnamed import UnnamedChange

__all__ = ["Diagnosis"]


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`..diagnose.diagnose` found; see its module docstring for the steps.

    Attributes
    ----------
    verdict : {"consistent", "explained", "ambiguous", "unexplained"}
    nominal : JointFit
    dof : float
        Degrees of freedom of the nominal chi-square.
    p_value : float
    mode_p_values : numpy.ndarray, shape (m,)
        Predictive two-sided p-value of each measured frequency under the nominal fit.
    located_modes : list of int
        1-based measured modes whose standardised residual exceeds 2.
    mode_kinds : list of str
    maps : dict of LocationMap
        One per located candidate among ``physics``, keyed by its
        :attr:`~..physics.base.Physics.name`, in the order of ``physics``.
    region_mm : tuple or None
        Best location of a local change, mm; ``region_mirrors_mm`` fit equally.
    candidates : list of CandidateResult
        Best first; every variant of a candidate is one (a taper along x and one along y,
        told apart by ``parameters["direction"]``), and so is every pair of effects fitted
        (named ``first+second``, :mod:`..physics.combined`).
    chosen : CandidateResult or None
        The best candidate when ``explained`` or ``ambiguous``.
    refit_dof, refit_p_value : float
    unidentified : list of str
        Constants the data do not inform (nominal fit, and refit when there is one).
    sigma_Hz, mesh_error_Hz : numpy.ndarray, shape (m,)
    notes : list of str
    scans : dict of Scan
        The Ritz scan of each located candidate, keyed as ``maps``.
    probabilities : dict
        Posterior probability of ``"nominal"`` (nothing left out) and of each candidate by
        name, variants summed (:func:`.probabilities.model_probabilities`).
    rival : CandidateResult or None
        When ``ambiguous``: the runner-up, a different candidate.
    separation : Separation or None
        When ``ambiguous``: the measurement that would tell ``chosen`` from ``rival``.
    also_tied : list of CandidateResult
        When ``ambiguous``: the further candidates that tie with ``chosen`` as well.
    peak_modes : numpy.ndarray of int, shape (m_all,), or None
        The computed mode (0-based) of every measured peak in the pass kept, -1 where it was
        left out as spurious; set when the assignment was made again at the verdict's fit
        (:mod:`.reassign`).
    passes : int
        Passes diagnose ran, each with another assignment of the peaks (:mod:`.reassign`).
    unnamed : UnnamedChange or None
        The rival every named candidate must beat, an unnamed local change fitted at the
        nominal fit (:mod:`.unnamed`); None when the nominal fit is consistent.
    """

    verdict: str
    nominal: JointFit = field(repr=False)
    dof: float
    p_value: float
    mode_p_values: np.ndarray
    located_modes: list
    mode_kinds: list
    maps: dict = field(repr=False)
    region_mm: tuple | None
    region_mirrors_mm: list
    candidates: list = field(repr=False)
    chosen: CandidateResult | None
    refit_dof: float
    refit_p_value: float
    unidentified: list
    sigma_Hz: np.ndarray
    mesh_error_Hz: np.ndarray
    measured_Hz: np.ndarray
    notes: list
    scans: dict = field(default_factory=dict, repr=False)
    probabilities: dict = field(default_factory=dict)
    rival: CandidateResult | None = None
    separation: Separation | None = None
    peak_modes: np.ndarray | None = None
    also_tied: list = field(default_factory=list, repr=False)
    passes: int = 1
    unnamed: UnnamedChange | None = field(default=None, repr=False)
