"""The likelihood of all measured peaks, the assignment re-made at every point of the chain.

With ``pairing="likelihood"`` the estimators settle which computed mode explains which
measured peak (:mod:`bayesplate.matching.assignment`); the chain then moves the constants ``b`` and
the best assignment may change with them (a peak's mode moves away and its neighbour comes
closer). :class:`ReassignedLikelihood` is the likelihood of ALL measured peaks at ``b``
maximised over the assignments ``a``, with the model of :mod:`bayesplate.matching.assignment`
written in eigenvalues (the space of :class:`bayesplate.likelihood.posterior.GaussianProblem`) and
zero predictive deviation of the computed eigenvalues (at a point of the chain the constants are
given):

``ln L(b) = max_a ln P(Y | b, a)``,

``ln P(Y | b, a) = sum_paired [ln N(Y_i; g_j(b), v_i) + ln(1 - p_s) + ln(1 - p_u)]``
``               + sum_spurious [ln p_s - ln B] + sum_unpaired ln(p_u) rho(g_j(b))``,

with ``Y_i`` the measured eigenvalues (rad^2/s^2) and ``v_i`` their variances (the diagonal of
``V_Y``, rad^4/s^4, same convention as the problem), ``g_j`` the ``n`` lowest computed
eigenvalues, a spurious peak uniform on ``[0, B]`` (``B`` the eigenvalue of the highest
measured frequency plus three deviations, as in :mod:`bayesplate.matching.assignment`) and ``rho``
the share of the searched band a computed mode nobody paired lies in: 1 up to the highest measured
eigenvalue ``Y_top``, 0 above ``B``, linear between. Its maximum is a linear assignment
problem (Hungarian method, ``scipy.optimize.linear_sum_assignment``) on an ``m x (n + m)``
score matrix.

Continuity. Each ``ln P(Y | b, a)`` is continuous in ``b`` (the eigenvalues are), and a
maximum of finitely many continuous functions is continuous: where the best assignment
changes, the two assignments score the same, so the chain sees no jump. ``ln L`` is the
dominant-term approximation of the sum over assignments, ``ln sum_a P(Y | b, a)``: it lies
below it by at most the logarithm of the number of assignments scoring near the best (``ln
2`` where two tie, a peak halfway between two modes: the sum counts both, the maximum one),
and equals it to within ``exp(-gap)`` where the best leads the next by ``gap`` nats.
Two choices differ from the letter of :mod:`bayesplate.matching.assignment`, both for continuity:
a paired computed mode counts as observed (``ln(1 - p_u)``) wherever it lies (there, a
paired mode above the highest peak counts 0, a step of ``ln(1 - p_u)`` as it crosses the
peak, right at the posterior's centre for the highest peak); a computed mode nobody paired
counts ``ln p_u`` below ``Y_top`` and 0 above ``B`` as there, with the ramp ``rho`` between
(there, a step of ``ln p_u``).

With the settled assignment, every peak paired and none spurious, ``ln P`` is
:meth:`GaussianProblem.log_likelihood` (diagonal ``V_Y``, no error scale) plus the constant
``m ln(1 - p_s) + m ln(1 - p_u) + sum_unpaired ln(p_u) rho(g_j)`` (the last term constant
where the unpaired modes stay in, or above, the band).

:class:`ChainAssignment` records what the chain did: per measured peak, the fraction of
draws in which each computed mode (or none: spurious) explained it.

Pure array computation: no files, no figures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..likelihood.posterior import observation_covariance
from ..matching.assignment import P_SPURIOUS, P_UNOBSERVED, best_assignment, spurious_band_Hz
from ..quantities import eigenvalue_from_hz

__all__ = ["REASSIGN_EXTRA_MODES", "ChainAssignment", "ReassignedLikelihood", "reassignment"]

#: Computed modes beyond the highest settled one that the chain may pair a peak with.
REASSIGN_EXTRA_MODES = 2


class ReassignedLikelihood:
    """``ln L(b) = max_a ln P(Y | b, a)`` of all measured peaks (module docstring).

    Parameters
    ----------
    frequency_Hz, sigma_Hz : array_like, shape (m,)
        All measured peaks and their deviations, Hz.
    n_modes : int
        ``n``: computed elastic modes offered to the peaks (the lowest ``n``).
    observation : {"variance", "deviation"}
        Convention of ``V_Y`` (:func:`bayesplate.likelihood.posterior.observation_covariance`): the
        problem's, so that ``v_i`` is its diagonal.
    p_unobserved, p_spurious : float
        Prior probabilities that a computed mode in the band is not seen and that a peak is
        spurious, in (0, 1).

    Attributes
    ----------
    Y : numpy.ndarray, shape (m,)
        Measured eigenvalues, rad^2/s^2.
    variance : numpy.ndarray, shape (m,)
        ``v_i``, the diagonal of ``V_Y``.
    frequency_Hz : numpy.ndarray, shape (m,)
    n : int
    band : float
        ``B``, rad^2/s^2.
    """

    def __init__(
        self,
        frequency_Hz,
        sigma_Hz,
        n_modes,
        observation="variance",
        p_unobserved=P_UNOBSERVED,
        p_spurious=P_SPURIOUS,
    ):
        f = np.asarray(frequency_Hz, dtype=float)
        s = np.asarray(sigma_Hz, dtype=float)
        if f.ndim != 1 or f.shape != s.shape or f.size == 0:
            raise ValueError(f"frequency_Hz {f.shape} and sigma_Hz {s.shape}: need equal (m,)")
        if int(n_modes) < 1:
            raise ValueError(f"n_modes = {n_modes}: need at least one computed mode")
        for name, p in (("p_unobserved", p_unobserved), ("p_spurious", p_spurious)):
            if not 0.0 < p < 1.0:
                raise ValueError(f"{name} = {p}: must lie strictly between 0 and 1")
        self.frequency_Hz = f
        self.Y = eigenvalue_from_hz(f)
        self.variance = np.diag(observation_covariance(f, s, observation)).copy()
        self.n = int(n_modes)
        self.top = float(np.max(self.Y))
        self.band = float(eigenvalue_from_hz(spurious_band_Hz(f, s)))
        self.p_unobserved, self.p_spurious = float(p_unobserved), float(p_spurious)
        self._paired = np.log1p(-p_spurious) + np.log1p(-p_unobserved)
        self._spurious = np.log(p_spurious) - np.log(self.band)
        self._norm = -0.5 * np.log(2 * np.pi * self.variance)

    @property
    def m(self):
        """Number of measured peaks."""
        return self.Y.size

    def _rho(self, g):
        """Share of the searched band each computed eigenvalue lies in, shape (n,)."""
        return np.clip((self.band - g) / (self.band - self.top), 0.0, 1.0)

    def _terms(self, g, gap=None):
        """Pair scores ``(m, n)`` and unpaired-mode scores ``(n,)`` at eigenvalues `g`."""
        residual = self.Y[:, None] - g[None, :] if gap is None else gap
        pair = self._norm[:, None] - 0.5 * residual**2 / self.variance[:, None] + self._paired
        return pair, np.log(self.p_unobserved) * self._rho(g)

    def _computed(self, g):
        g = np.asarray(g, dtype=float)
        if g.ndim != 1 or g.size < self.n:
            raise ValueError(f"computed eigenvalues {g.shape}: need at least {self.n}")
        return g[: self.n]

    def evaluate(self, g):
        """``ln L``, its per-peak terms and the best assignment at computed eigenvalues `g`.

        Parameters
        ----------
        g : array_like, shape (>= n,)
            Computed elastic eigenvalues, ascending, rad^2/s^2 (the first ``n`` are used).

        Returns
        -------
        log_likelihood : float
            ``max_a ln P(Y | b, a)``.
        pointwise : numpy.ndarray, shape (m,)
            Each peak's term of the best assignment: ``ln N(Y_i; g_j, v_i) + ln(1 - p_s)``
            paired, ``ln p_s - ln B`` spurious (the modes' terms belong to no peak).
        modes : numpy.ndarray of int, shape (m,)
            0-based computed mode of each peak in the best assignment; -1 spurious.
        """
        g = self._computed(g)
        pair, unpaired = self._terms(g)
        modes, total = _solve(pair, np.full(self.m, self._spurious), unpaired)
        pointwise = np.full(self.m, self._spurious)
        on = modes >= 0
        pointwise[on] = pair[on, modes[on]] - np.log1p(-self.p_unobserved)
        return total, pointwise, modes

    def log_probability(self, g, modes):
        """``ln P(Y | b, a)`` of one assignment `modes` (shape (m,), -1 spurious)."""
        g = self._computed(g)
        modes = np.asarray(modes, dtype=int)
        paired = modes[modes >= 0]
        if modes.shape != (self.m,) or paired.size != np.unique(paired).size:
            raise ValueError(f"modes = {modes}: need one entry per peak, each mode at most once")
        if paired.size and (paired.max() >= self.n):
            raise ValueError(f"modes = {modes}: only modes 0 to {self.n - 1} are offered")
        pair, unpaired = self._terms(g)
        on = np.flatnonzero(modes >= 0)
        rest = np.setdiff1d(np.arange(self.n), paired)
        return float(
            pair[on, modes[on]].sum() + (self.m - on.size) * self._spurious + unpaired[rest].sum()
        )

    def upper_bound(self, R):
        """An upper bound of ``ln L`` over all ``g <= R`` (e.g. Ritz values), float.

        Each pair scores at most its Gaussian at the residual ``max(Y_i - R_j, 0)`` and each
        unpaired mode at most ``ln(p_u) rho(R_j)`` (``rho`` falls as ``g`` rises), so the
        best assignment of these bounds bounds the best assignment.
        """
        R = self._computed(R)
        gap = np.maximum(self.Y[:, None] - R[None, :], 0.0)
        pair, unpaired = self._terms(R, gap)
        return _solve(pair, np.full(self.m, self._spurious), unpaired)[1]


def reassignment(pairing, frequency_Hz, sigma_Hz, observation, full_covariance, error_scale):
    """Whether the chain re-makes a pairing's assignment: its likelihood, and one sentence.

    Only a pairing by likelihood is re-made, and only where the peaks are independent at
    ``s = 1`` (the model of this module): with a full ``V_Y`` (inputs marginalised) or an
    inferred error scale it stays as settled, and the sentence says why.

    Parameters
    ----------
    pairing : bayesplate.matching.pairing.Pairing
        The settled pairing (``how``, ``modes``).
    frequency_Hz, sigma_Hz : array_like, shape (m,)
        ALL measured peaks (spurious ones included), Hz.
    observation : {"variance", "deviation"}
        The problem's ``V_Y`` convention.
    full_covariance, error_scale : bool
        Whether ``V_Y`` is full, whether an error scale is inferred.

    Returns
    -------
    assigned : ReassignedLikelihood or None
        Over the modes up to :data:`REASSIGN_EXTRA_MODES` above the highest settled one.
    note : str or None
        None when the pairing is not by likelihood.
    """
    if pairing.how != "likelihood":
        return None, None
    why = [
        text
        for flag, text in (
            (full_covariance, "the inputs are marginalised (V_Y is full)"),
            (error_scale, "an error scale is inferred"),
        )
        if flag
    ]
    if why:
        return None, (
            "assignment by likelihood kept as settled through the chain, not re-made "
            f"at every point: {' and '.join(why)}"
        )
    n = int(np.max(pairing.modes)) + 1 + REASSIGN_EXTRA_MODES
    m = np.asarray(frequency_Hz).size
    return ReassignedLikelihood(frequency_Hz, sigma_Hz, n, observation), (
        f"assignment by likelihood re-made at every point of the chain ({m} peaks against "
        f"the {n} lowest computed modes; a peak may be spurious)"
    )


def _solve(pair, spurious, unpaired):
    """The assignment maximising ``sum pair + sum spurious + sum unpaired``; its total.

    ``sum_unpaired u_j = sum_all u_j - sum_paired u_j``: a pair scores ``pair_ij - u_j``
    (:func:`bayesplate.matching.assignment.best_assignment`).
    """
    modes, total = best_assignment(pair - unpaired[None, :], spurious)
    return modes, total + float(unpaired.sum())


@dataclass(frozen=True)
class ChainAssignment:
    """Which computed mode explained each measured peak, over the chain's kept draws.

    Attributes
    ----------
    frequency_Hz : numpy.ndarray, shape (m,)
        The measured peaks, Hz.
    fractions : numpy.ndarray, shape (m, n + 1)
        Fraction of the draws in which peak ``i`` was paired with computed mode ``j``
        (0-based, columns 0 to n - 1) or spurious (column n); rows sum to 1.
    n_draws : int
        Draws counted.
    """

    frequency_Hz: np.ndarray
    fractions: np.ndarray
    n_draws: int

    @classmethod
    def from_draws(cls, frequency_Hz, modes, n_modes):
        """From the best assignment at every draw, `modes` shape (draws, m), -1 spurious."""
        modes = np.asarray(modes)
        if modes.ndim != 2 or modes.shape[0] == 0:
            raise ValueError(f"modes {modes.shape}: need (draws, m) with draws > 0")
        if not np.all(np.isfinite(modes)):
            raise ValueError("modes: a kept draw holds no assignment (NaN)")
        modes = modes.astype(int)
        column = np.where(modes < 0, n_modes, modes)
        counts = np.stack([np.bincount(c, minlength=n_modes + 1) for c in column.T])
        f = np.asarray(frequency_Hz, dtype=float)
        return cls(f, counts / modes.shape[0], int(modes.shape[0]))

    @property
    def spurious(self):
        """Fraction of draws in which each peak was spurious, shape (m,)."""
        return self.fractions[:, -1]

    def varying(self):
        """0-based peaks whose assignment is not the same in all draws, shape (k,)."""
        return np.flatnonzero(np.max(self.fractions, axis=1) < 1.0)

    def describe(self, i):
        """One line on peak `i` (1-based numbers): its modes and spurious, most draws first."""
        row = self.fractions[i]
        order = np.argsort(-row, kind="stable")
        parts = []
        for j in order[row[order] > 0]:
            what = "spurious" if j == row.size - 1 else f"mode {j + 1}"
            percent = 100 * row[j]
            digits = 0 if 1 <= percent <= 99 else 1 if 0.1 <= percent <= 99.9 else 2
            parts.append(f"{what} in {percent:.{digits}f} %")
        return f"peak {i + 1} ({self.frequency_Hz[i]:.1f} Hz): " + ", ".join(parts) + " of draws"

    def lines(self):
        """:meth:`describe` of every peak whose assignment varied, list of str."""
        return [self.describe(i) for i in self.varying()]
